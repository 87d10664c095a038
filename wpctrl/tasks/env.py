"""``TaskEnv``: a ManiSkill table-top task on Newton, with the vectorised gymnasium API of ManiSkill's GPU envs
(``ManiSkillVectorEnv``): torch tensors on the env's device, partial resets, auto reset of finished envs inside the
step, the state dict in ManiSkill's layout. Build it with :func:`wpctrl.tasks.make`.

One step: the action is copied into a fixed device buffer; then wpctrl's ``set_action``, K = sim_freq / control_freq
physics steps of ``before_simulation_step`` and MuJoCo-Warp (``TaskPhysics.substeps`` solver steps each; the contact
forces of the last one go to Newton's contact sensor), then evaluation, observation, reward, the episode bookkeeping
and the reset of finished envs as Warp kernels. The whole step is one captured graph (on CUDA and on the CPU, where
Warp replays it without Python's per-launch cost: ~30x faster than eager launches): no host sync.
"""

from __future__ import annotations

import gymnasium as gym
import newton
import numpy as np
import warp as wp

from .arm_drive import ArmDrive
from .definitions import ROBOT_INIT_QPOS_NOISE
from .external_wrench import ExternalWrenchMixin
from .funcs import Sim
from .geometry import GEOMETRY_FLAGS, apply_episode_geometry
from .kernels import episode_kernel, task_kernels
from .physics import TaskPhysics
from .randomization import TaskRandomization
from .randomizer import Randomizer
from .registry import Task
from .scene import build_scene
from .state_dict import StateDictMixin

__all__ = ["RESET_OPTIONS", "REWARD_MODES", "TaskEnv"]

REWARD_MODES = ("normalized_dense", "dense", "sparse", "none")
RESET_OPTIONS = ("env_idx", "reconfigure")
"""The keys :meth:`TaskEnv.reset` takes in ``options``."""
_REWARD_CODE = {"dense": 0, "normalized_dense": 1, "sparse": 2, "none": 3}


class TaskEnv(StateDictMixin, ExternalWrenchMixin, gym.vector.VectorEnv):
    """``num_envs`` copies of a ManiSkill task on Newton's MuJoCo-Warp, controlled by wpctrl (see the module docstring).

    ``step(action)`` returns ``obs, reward, terminated, truncated, info`` as torch tensors on :attr:`device`:
    ``info`` holds ``success``, ``fail`` (always False: the tasks define no failure), ``elapsed_steps`` and the
    task's evaluation flags (its ``info_keys``), and, for the envs reset inside the step (``info["_final_info"]``),
    the observation and info they ended with (``final_observation``, ``final_info``), as ``ManiSkillVectorEnv``
    returns them.
    """

    def __init__(
        self,
        task: Task,
        num_envs: int,
        device,
        control_mode: str,
        obs_mode: str,
        reward_mode: str,
        seed: int,
        auto_reset: bool,
        ignore_terminations: bool,
        physics: TaskPhysics,
        controller_semantics: str,
        asset_dir: str | None,
        graph: bool | None,
        max_episode_steps: int | None = None,
        reconfiguration_freq: int | None = None,
        randomization: TaskRandomization | None = None,
        robot_uids: str | None = None,
    ):
        import torch

        import wpctrl
        from wpctrl.robots import panda_control_modes

        self.task_spec = task
        self.robot_uids = robot_uids or task.robot_uids
        """The robot built (:data:`wpctrl.tasks.names.ROBOTS`), the state dict's articulation."""
        self.physics = physics
        self.control_mode = control_mode
        self.obs_mode = obs_mode
        self.reward_mode = reward_mode
        self.auto_reset = bool(auto_reset)
        self.ignore_terminations = bool(ignore_terminations)
        self.controller_semantics = controller_semantics
        self.max_episode_steps = int(max_episode_steps or task.max_episode_steps)
        """The time limit in control steps: the task's registered one unless ``make(max_episode_steps=...)``."""
        self.sim_freq, self.control_freq = 100, 20
        self.num_envs = n = int(num_envs)
        self._torch = torch
        self.wp_device = dev = wp.get_device(device)
        self.device = torch.device("cuda", dev.ordinal) if dev.is_cuda else torch.device("cpu")
        if dev.is_cuda:  # one stream for torch and Warp: the graph is ordered with the caller's torch work
            self._torch_stream = torch.cuda.Stream(device=self.device)
            torch.cuda.set_stream(self._torch_stream)
            wp.set_stream(wp.stream_from_torch(self._torch_stream), dev)

        self.scene = sc = build_scene(task, n, dev, physics, asset_dir, self.robot_uids)
        self.model = model = sc.model
        seeds = episode_seeds(seed, n)
        self.reconfiguration_freq = int(task.reconfiguration_freq(n) if reconfiguration_freq is None
                                        else reconfiguration_freq)  # fmt: skip
        """Every how many :meth:`reset` calls the scene is drawn again (ManiSkill's ``reconfiguration_freq``)."""
        self._reconfig_counter = max(self.reconfiguration_freq - 1, 0)  # the build drew the first scene
        self.episode_params = task.draw_episode_params(seeds)
        """(num_envs, len(task.episode_params)) the numbers each env's scene was drawn with (host copy)."""
        apply_episode_geometry(sc, task, self.episode_params)
        mode = panda_control_modes()[control_mode]
        if controller_semantics == "physx_cpu":  # SAPIEN's CLIK, as ManiSkill's EE controllers on its CPU sim
            for cfg in mode.values():
                if hasattr(cfg, "delta_solver_config"):
                    cfg.delta_solver_config = dict(cfg.delta_solver_config, solver_iterations=100)
        self.ctrl = wpctrl.build_controller(mode, model, self.control_freq, self.sim_freq)
        self.dt = 1.0 / (self.sim_freq * physics.substeps)
        self._arm_drive = None
        if physics.arm_drive == "physx_tgs":  # before the solver: it makes no actuator for the arm's DOFs then
            self._arm_drive = ArmDrive(self.ctrl, model, 1.0 / self.sim_freq, self.dt)
            self._arm_drive.switch_off_solver_drive(model)
        self.solver = newton.solvers.SolverMuJoCo(model, **physics.solver_kwargs())
        contacts_per_world = -(-self.solver.get_max_contact_count() // n)
        rows = physics.constraint_rows(contacts_per_world, sc.dofs_per_env)
        if self.solver.mjw_data.njmax < rows:  # room for every contact's rows, else MuJoCo-Warp drops some
            self.solver = newton.solvers.SolverMuJoCo(model, njmax=rows, nconmax=contacts_per_world,
                                                      **physics.solver_kwargs())  # fmt: skip
        self.state = model.state()
        self._other = model.state()
        self.control = model.control()
        self._contacts = newton.CollisionPipeline(
            model, rigid_contact_max=self.solver.get_max_contact_count(), soft_contact_max=0
        ).contacts()
        z = lambda dtype, *shape: wp.zeros(shape if len(shape) > 1 else shape[0], dtype=dtype, device=dev)  # noqa: E731
        finger_force, finger_friction = self._contact_sensor(task)
        self.info_keys = ("success",) + tuple(task.info_keys)
        """The columns of :attr:`info_buf`: ``evaluate()``'s keys, ``success`` first."""
        m = max(len(task.markers), 1)
        self.obs_buf = z(wp.float32, n, task.obs_dim)
        self.final_obs_buf = z(wp.float32, n, task.obs_dim)
        self.action_buf = z(wp.float32, n, self.ctrl.action_dim)
        self.marker_pos = z(wp.vec3, n, m)
        quats = [mk.quat for mk in task.markers] + [(1.0, 0.0, 0.0, 0.0)] * (m - len(task.markers))
        self.marker_quat = wp.array(np.tile(np.asarray(quats, np.float32), (n, 1, 1)), dtype=wp.vec4, device=dev)
        self.rest_qpos = wp.array(np.asarray(task.robot_rest_qpos(self.robot_uids), np.float32), dtype=wp.float32,
                                  device=dev)  # fmt: skip
        self.param_buf = wp.array(_param_rows(self.episode_params), dtype=wp.float32, device=dev)
        self.seed_buf = wp.array(seeds, dtype=wp.int32, device=dev)
        """(num_envs,) each env's episode seed (:meth:`reset`)."""
        self.reset_count = z(wp.int32, n)
        self.elapsed = z(wp.int32, n)
        self.final_elapsed = z(wp.int32, n)
        self.info_buf = z(wp.bool, n, len(self.info_keys))
        self.final_info_buf = z(wp.bool, n, len(self.info_keys))
        self.reward_dense = z(wp.float32, n)
        self.reward_buf = z(wp.float32, n)
        self.terminated = z(wp.bool, n)
        self.truncated = z(wp.bool, n)
        self.done = z(wp.bool, n)
        self._all = wp.ones(n, dtype=wp.bool, device=dev)
        self._fail = torch.zeros(n, dtype=torch.bool, device=self.device)
        self._t = {name: wp.to_torch(a) for name, a in self._torch_views().items()}
        for i, k in enumerate(self.info_keys):
            self._t[k], self._t["final_" + k] = self._t["info"][:, i], self._t["final_info"][:, i]

        self.randomization = randomization
        self._randomizer = Randomizer(self, randomization) if randomization is not None else None

        self._sim = self._sim_struct(task, finger_force, finger_friction)
        self._reset_kernel, self._observe_kernel = task_kernels(task)

        self.single_action_space = self.ctrl.single_action_space
        self.action_space = self.ctrl.action_space
        self.single_observation_space = gym.spaces.Box(-np.inf, np.inf, (task.obs_dim,), np.float32)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (n, task.obs_dim), np.float32)
        self.metadata = {"autoreset_mode": gym.vector.AutoresetMode.SAME_STEP}

        self._reset_envs(self._all)
        self.graph = None
        if graph is None:
            graph = True  # on the CPU too: Warp replays the recorded launches without Python's per-launch cost
        if graph:
            self._step_impl()  # compile every kernel outside the capture
            self._reset_envs(self._all)
            with wp.ScopedCapture(device=dev) as cap:
                self._step_impl()
            self.graph = cap.graph
        self._reset_envs(self._all)

    # -- device work ------------------------------------------------------------------------------------------------

    def _contact_sensor(self, task: Task) -> tuple[wp.array, wp.array]:
        """Newton's contact sensor between every env's fingers and its task's ``contact_actors`` (none without them);
        the (2 num_envs, actors) force matrix the device functions read and its friction part."""
        sc, n = self.scene, self.num_envs
        self._sensor = self._observables = None
        if not task.contact_actors:
            return tuple(wp.zeros((2 * n, 1), dtype=wp.vec3, device=self.wp_device) for _ in range(2))
        fingers = [b + e * sc.bodies_per_env for e in range(n) for b in sc.finger_bodies0]
        touched = [sc.actor_body0[a] + e * sc.bodies_per_env for e in range(n) for a in task.contact_actors]
        self._sensor = newton.sensors.SensorContact(
            self.model, sensing_bodies=fingers, counterpart_bodies=touched, measure_total=False,
            request_contact_attributes=False,
        )  # fmt: skip
        self._observables = self.solver.observables(self._sensor.solver_observable_kinds, contacts=self._contacts)
        return self._sensor.force_matrix, self._sensor.force_matrix_friction

    def _sim_struct(self, task: Task, finger_force: wp.array, finger_friction: wp.array) -> Sim:
        """The :class:`~wpctrl.tasks.funcs.Sim` the kernels get: the scene's layout and the env's arrays (the same
        arrays for the env's life: a captured graph binds them)."""
        sc, S = self.scene, Sim()
        S.nq, S.nqd, S.nb = sc.coords_per_env, sc.dofs_per_env, sc.bodies_per_env
        S.robot_q0, S.robot_qd0, S.tcp_body0 = sc.robot_coord0, sc.robot_dof0, sc.tcp_body0
        S.lfinger_body0, S.rfinger_body0 = sc.finger_bodies0
        index = lambda where: wp.array([where[a.name] for a in task.bodies] or [0], dtype=wp.int32,  # noqa: E731
                                       device=self.wp_device)  # fmt: skip
        S.actor_q0, S.actor_qd0, S.actor_body0 = index(sc.actor_coord0), index(sc.actor_dof0), index(sc.actor_body0)
        S.joint_q, S.joint_qd, S.body_q = self.state.joint_q, self.state.joint_qd, self.state.body_q
        S.finger_force, S.finger_friction = finger_force, finger_friction
        S.marker_pos, S.marker_quat = self.marker_pos, self.marker_quat
        S.info, S.param = self.info_buf, self.param_buf
        return S

    def _torch_views(self) -> dict:
        v = {"obs": self.obs_buf, "final_obs": self.final_obs_buf, "action": self.action_buf, "reward": self.reward_buf,
             "terminated": self.terminated, "truncated": self.truncated, "elapsed": self.elapsed,
             "final_elapsed": self.final_elapsed, "reset_count": self.reset_count, "info": self.info_buf,
             "final_info": self.final_info_buf}  # fmt: skip
        return v

    def _observe(self) -> None:
        newton.eval_fk(self.model, self.state.joint_q, self.state.joint_qd, self.state)
        wp.launch(self._observe_kernel, dim=self.num_envs, inputs=[self._sim],
                  outputs=[self.obs_buf, self.reward_dense], device=self.wp_device)  # fmt: skip

    def _reset_envs(self, mask: wp.array) -> None:
        """Initialise the episodes of ``mask``'s envs (device draws), their controller targets and observations."""
        if self._randomizer is not None:  # before the reset kernel counts the episode: the draws of the same one
            self._randomizer.apply(mask)
        wp.launch(
            self._reset_kernel,
            dim=self.num_envs,
            inputs=[self._sim, self.seed_buf, mask, self.rest_qpos, ROBOT_INIT_QPOS_NOISE, self.reset_count],
            outputs=[self.elapsed],
            device=self.wp_device,
        )
        self._after_state_write(mask)

    def _after_state_write(self, mask: wp.array) -> None:
        """The envs of ``mask`` hold a new state: no contact force yet, drive targets at their qpos, fresh obs."""
        forces = [self._sim.finger_force, self._sim.finger_friction]
        wp.launch(_zero_forces, dim=self.num_envs, inputs=[mask, *forces], device=self.wp_device)
        newton.eval_fk(self.model, self.state.joint_q, self.state.joint_qd, self.state)
        self.ctrl.reset(self.state, mask, control=self.control)
        self._observe()

    def _simulate(self) -> None:
        ctrl, solver = self.ctrl, self.solver
        ctrl.set_action(self.action_buf, self.state)
        src, dst = self.state, self._other
        steps = ctrl.num_substeps * self.physics.substeps
        i = 0
        drive = self._arm_drive
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(src, self.control)
            if drive is not None:
                drive.begin_step(src)
            for _ in range(self.physics.substeps):
                if drive is not None:
                    drive.before_solver_step(src, self.control)
                i += 1
                obs = self._observables if i == steps else None
                solver.step(src, dst, self.control, self._contacts if obs is not None else None, self.dt,
                            observables=obs)  # fmt: skip
                src, dst = dst, src
        if src is not self.state:
            self.state.assign(src)  # the env's state is always self.state (a captured graph binds its arrays)
        if self._sensor is not None:
            self._sensor.update(None, self._contacts, observables=self._observables)

    def _step_impl(self) -> None:
        self._simulate()
        self._bookkeep()

    def _bookkeep(self) -> None:
        """Evaluation, observation, reward and episode bookkeeping of the step just simulated; the auto reset."""
        self._observe()
        wp.launch(
            episode_kernel,
            dim=self.num_envs,
            inputs=[self.max_episode_steps, self.task_spec.max_reward, _REWARD_CODE[self.reward_mode],
                    int(self.ignore_terminations), self.info_buf, self.reward_dense],
            outputs=[self.elapsed, self.reward_buf, self.terminated, self.truncated, self.done],
            device=self.wp_device,
        )  # fmt: skip
        wp.copy(self.final_obs_buf, self.obs_buf)
        wp.copy(self.final_elapsed, self.elapsed)
        wp.copy(self.final_info_buf, self.info_buf)
        if self.auto_reset:
            self._reset_envs(self.done)

    # -- the vectorised gymnasium API -------------------------------------------------------------------------------

    @property
    def unwrapped(self):
        return self

    def __repr__(self) -> str:
        return (
            f"TaskEnv({self.task_spec.env_id}, num_envs={self.num_envs}, device={self.wp_device.alias}, "
            f"robot_uids={self.robot_uids}, control_mode={self.control_mode}, obs_mode={self.obs_mode}, "
            f"reward_mode={self.reward_mode})"
        )

    @property
    def randomization_factors(self):
        """(num_envs, 3) torch view: each env's friction, contact-time and mass factors of its running episode
        (:class:`~wpctrl.tasks.randomization.TaskRandomization`); None without randomisation."""
        return None if self._randomizer is None else wp.to_torch(self._randomizer.factors)

    @property
    def elapsed_steps(self):
        """(num_envs,) int32 torch view: control steps taken in each env's episode."""
        return self._t["elapsed"]

    def _info(self, final: bool) -> dict:
        t = self._t
        info = {"success": t["success"].clone(), "fail": self._fail.clone(), "elapsed_steps": t["elapsed"].clone()}
        for k in self.task_spec.info_keys:
            info[k] = t[k].clone()
        if final and self.auto_reset:
            done = t["terminated"] | t["truncated"]
            fin = {"success": t["final_success"].clone(), "fail": self._fail.clone(),
                   "elapsed_steps": t["final_elapsed"].clone()}  # fmt: skip
            for k in self.task_spec.info_keys:
                fin[k] = t["final_" + k].clone()
            info.update(final_observation=self._format_obs(t["final_obs"].clone()), final_info=fin,
                        _final_info=done, _final_observation=done.clone(), _elapsed_steps=done.clone())  # fmt: skip
        return info

    def _format_obs(self, flat):
        if self.obs_mode == "state":
            return flat
        out = {}
        for group, fields_ in self.task_spec.obs_slices().items():
            out[group] = {name: flat[:, s] for name, s in fields_.items()}
        for f in self.task_spec.obs_fields:
            if f.boolean:
                out[f.group][f.name] = out[f.group][f.name][:, 0] > 0.5
        return out

    def reset(self, *, seed=None, options: dict | None = None):
        """Start new episodes: every env, or ``options["env_idx"]``'s (a partial reset); returns ``obs, info`` of all
        envs. Other ``options`` keys are refused (:data:`RESET_OPTIONS` lists those it takes).

        ``seed`` gives every env an episode seed, as ManiSkill's vectorised envs take it: a list of ``num_envs`` ints
        (env e's seed ``seed[e]``; with ``env_idx`` only the reset envs take theirs), or one int ``s``, which
        ManiSkill expands to ``[s, *np.random.RandomState(s).randint(2**31, size=num_envs - 1)]``
        (:func:`episode_seeds`). Env e's initial state is drawn by Warp's RNG from its own seed alone (and the
        count of its episodes since that seed): an env seeded ``s`` starts the same episode whichever env it is and
        whatever the other envs' seeds are, as a ManiSkill env seeded ``s`` does. The draws are not ManiSkill's
        numbers (its ``torch.rand`` stream is not reproduced), only its distribution (``tests/test_tasks_envs.py``).
        Without a seed, each env draws its next episode from its seed's stream.

        ``options["reconfigure"]`` (or every ``reconfiguration_freq``-th reset, ManiSkill's default for the task: for
        PegInsertionSide-v1 every reset of a single env) draws every env's scene again from its episode seed, as
        ManiSkill's ``_load_scene`` does (a task whose geometry comes from the seed: ``Task.episode_params``); a partial
        reset cannot reconfigure."""
        from ._validate import env_mask, reset_options, seed_value

        options = reset_options(options, RESET_OPTIONS)
        mask = self._all
        reconfigure = bool(options.get("reconfigure", False)) or (
            self._reconfig_counter == 0 and self.reconfiguration_freq != 0
        )
        if options.get("env_idx") is not None:
            mask = env_mask(options["env_idx"], self.num_envs, self.wp_device)
            if reconfigure and not mask.numpy().all():
                from ..config import ConfigError

                raise ConfigError("reset: options['reconfigure'] draws every env's scene again and cannot go with "
                                  "a partial reset (options['env_idx'] selects some envs only), as in ManiSkill")
        if seed is not None:
            if _is_sequence(seed):
                chosen = mask.numpy()
                seeds = np.where(chosen, per_env_seeds(seed, self.num_envs), self.seed_buf.numpy())
                counts = np.where(chosen, 0, self.reset_count.numpy())
                self.seed_buf.assign(seeds.astype(np.int32))
                self.reset_count.assign(counts.astype(np.int32))
            else:
                self.seed_buf.assign(episode_seeds(seed_value(seed), self.num_envs))
                self.reset_count.zero_()
        if reconfigure:
            self._reconfigure(fresh=seed is None)
        if self.reconfiguration_freq != 0:  # ManiSkill's counter: freq after a reconfiguration, then one less per reset
            self._reconfig_counter = (self.reconfiguration_freq if reconfigure else self._reconfig_counter) - 1
        self._reset_envs(mask)
        return self._format_obs(self._t["obs"].clone()), self._info(final=False)

    def _reconfigure(self, fresh: bool) -> None:
        """Draw every env's scene again from its episode seed (``fresh``: first give each env a new seed drawn from
        its current one, as ManiSkill draws one from its main RNG when reconfiguring without a seed), resize the
        worlds' shapes and tell the solver. Auto resets inside :meth:`step` never reconfigure (nor do ManiSkill's)."""
        if fresh:
            old = self.seed_buf.numpy().astype(np.int64) + self.reset_count.numpy()
            self.seed_buf.assign(np.array([np.random.RandomState(s % 2**31).randint(2**31) for s in old], np.int32))
            self.reset_count.zero_()
        params = self.task_spec.draw_episode_params(self.seed_buf.numpy())
        if apply_episode_geometry(self.scene, self.task_spec, params):
            self.solver.notify_model_changed(GEOMETRY_FLAGS)
            if self._randomizer is not None:  # the solver's model holds the new scene's values: the draws scale them
                self._randomizer.capture_base()
        self.episode_params = params
        self.param_buf.assign(_param_rows(params))

    def step(self, action):
        """One control step of every env (finished envs are reset inside it when ``auto_reset``)."""
        from ._validate import action_tensor

        self._t["action"].copy_(action_tensor(action, self.num_envs, self.ctrl.action_dim, self.device))
        if self.graph is not None:
            wp.capture_launch(self.graph)
        else:
            self._step_impl()
        t = self._t
        reward = t["reward"].clone() if self.reward_mode != "none" else self._torch.zeros_like(t["reward"])
        return (self._format_obs(t["obs"].clone()), reward, t["terminated"].clone(), t["truncated"].clone(),
                self._info(final=True))  # fmt: skip

    def get_obs(self):
        """The observation of the current state (e.g. after :meth:`set_state_dict`)."""
        self._observe()
        return self._format_obs(self._t["obs"].clone())

    def evaluate(self) -> dict:
        """ManiSkill's ``evaluate()`` of the current state: ``success`` and the task's flags (torch bool)."""
        self._observe()
        out = {"success": self._t["success"].clone()}
        for k in self.task_spec.info_keys:
            out[k] = self._t[k].clone()
        return out

    def close(self) -> None:
        self.graph = None


def episode_seeds(seed: int, num_envs: int) -> np.ndarray:
    """One reset seed as ``num_envs`` episode seeds, as ManiSkill expands it (``BaseEnv._set_episode_rng``,
    ``mani_skill/envs/sapien_env.py``): env 0 takes ``seed``, envs 1.. ``np.random.RandomState(seed).randint(2**31,
    size=num_envs - 1)``."""
    rest = np.random.RandomState(int(seed)).randint(2**31, size=num_envs - 1) if num_envs > 1 else []
    return np.asarray([int(seed), *rest], np.int32)


def _param_rows(params: np.ndarray) -> np.ndarray:
    """The episode parameters as the device's (num_envs, >= 1) float32 rows (a zero column for a task without any)."""
    p = np.asarray(params, np.float32)
    return p if p.shape[1] else np.zeros((p.shape[0], 1), np.float32)


def _is_sequence(seed) -> bool:
    return isinstance(seed, (list, tuple, np.ndarray)) or hasattr(seed, "detach")


def per_env_seeds(seed, num_envs: int) -> np.ndarray:
    """``reset``'s list of per-env seeds as (num_envs,) int32 (each taken modulo 2**31, as one int seed is); anything
    but ``num_envs`` integers is refused naming ``seed``."""
    from ..config import ConfigError

    a = seed.detach().cpu().numpy() if hasattr(seed, "detach") else np.asarray(seed, dtype=object)
    if a.ndim != 1 or len(a) != num_envs:
        raise ConfigError(f"reset: seed expected one int or a list of num_envs = {num_envs} ints (one per env), got "
                          f"{'shape ' + str(a.shape) if a.ndim != 1 else f'a list of {len(a)}'}")  # fmt: skip
    out = []
    for i, v in enumerate(a.tolist()):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
            raise ConfigError(f"reset: seed[{i}] expected an int, got {v!r}")
        out.append(int(v) % (2**31))
    return np.asarray(out, np.int32)


@wp.kernel
def _zero_forces(mask: wp.array[wp.bool], force: wp.array2d[wp.vec3], friction: wp.array2d[wp.vec3]):
    e = wp.tid()
    if mask[e]:
        for i in range(2):
            for j in range(force.shape[1]):
                force[2 * e + i, j] = wp.vec3(0.0)
                friction[2 * e + i, j] = wp.vec3(0.0)
