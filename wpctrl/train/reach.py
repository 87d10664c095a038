"""The reach task: Panda, a random TCP goal per episode, PPO through rsl-rl. An rsl-rl ``VecEnv`` whose every buffer
lives on the device and whose whole step is one CUDA graph on a GPU.

One step of the env: the policy's action (a torch tensor) is copied into a fixed action buffer (zero-copy Warp view),
then, inside the captured graph, wpctrl's ``set_action``, K x (``before_simulation_step`` + MuJoCo-Warp step), the
observations, reward and done flags (Warp kernels), and the partial reset of the envs whose episode ended (their
joint state and a new goal by a Warp kernel, ``ctrl.reset`` with a device mask) run without a host sync. On the CPU
the same calls run eagerly.

Streams (CUDA): torch and Warp share one stream, so the graph is ordered with the policy's kernels without the host
waiting. Torch's default stream is CUDA's legacy stream, on which no graph can be captured, so the env makes a torch
stream of its own current for torch (``torch.cuda.set_stream``, for the whole process) and for Warp
(``wp.stream_from_torch``).
"""

from __future__ import annotations

import numpy as np
import warp as wp
from rsl_rl.env import VecEnv

from . import task_kernels

GOAL_LO = (0.35, -0.25, 0.15)
"""The goal box in the robot's base frame [m] (reachable by the Panda's TCP from its rest pose)."""
GOAL_HI = (0.65, 0.25, 0.55)


class ReachEnv(VecEnv):
    """``num_envs`` Pandas reaching random goals with the TCP (rsl-rl ``VecEnv`` interface).

    Observations (group ``"policy"``): the 9 joint positions [rad, m] and velocities, the TCP position and
    ``goal - TCP`` [m], in the robot's base frame. A dense reward on the TCP-goal distance ``d``
    (:func:`~wpctrl.train.task_kernels.observe_kernel`); an episode
    is ``episode_steps`` control steps at ``control_freq``; success: ``d < success_radius`` at its end.
    """

    def __init__(
        self,
        num_envs: int,
        device: str = "cpu",
        control_mode: str = "pd_ee_delta_pos",
        seed: int = 0,
        episode_steps: int = 50,
        control_freq: int = 20,
        sim_freq: int = 100,
        success_radius: float = 0.025,
        start_noise: float = 0.1,
        graph: bool | None = None,
    ):
        import newton
        import torch
        from tensordict import TensorDict  # noqa: F401  (rsl-rl's observation container)

        import wpctrl
        from wpctrl.robots import PANDA_INITIAL_Q, panda, panda_control_modes

        modes = panda_control_modes()
        if control_mode not in modes:
            raise ValueError(f"control_mode: expected one of {sorted(modes)}, got {control_mode!r}")
        for name, value in (("num_envs", num_envs), ("episode_steps", episode_steps)):
            if int(value) != value or value < 1:
                raise ValueError(f"{name}: expected a positive integer, got {value!r}")
        if not success_radius > 0.0:
            raise ValueError(f"success_radius: expected a positive distance [m], got {success_radius!r}")
        if not start_noise >= 0.0:
            raise ValueError(f"start_noise: expected a non-negative angle [rad], got {start_noise!r}")
        self.device = device
        self.num_envs = E = int(num_envs)
        self.max_episode_length = int(episode_steps)
        self.success_radius = float(success_radius)
        self.start_noise = float(start_noise)
        self.seed = int(seed)
        self.cfg = {"task": "reach", "control_mode": control_mode, "num_envs": E, "episode_steps": episode_steps}
        self._torch = torch
        self.wp_device = wp.get_device(device)
        if self.wp_device.is_cuda:
            # One stream for torch and Warp, so the graph is ordered with the policy's kernels: a torch stream of our
            # own made current for torch (its legacy default stream cannot be wrapped) and Warp's stream.
            self.torch_stream = torch.cuda.Stream(device=torch.device(device))
            torch.cuda.set_stream(self.torch_stream)
            wp.set_stream(wp.stream_from_torch(self.torch_stream), self.wp_device)
        builder = newton.ModelBuilder()
        builder.replicate(panda(), E)
        self.model = model = builder.finalize(device=device)
        # ManiSkill's Panda mode (its dict has no balance_passive_force key: gravity is off the robot, exactly, in
        # MuJoCo-Warp), built before the solver.
        self.ctrl = wpctrl.build_controller(modes[control_mode], model, control_freq, sim_freq)
        self.solver = newton.solvers.SolverMuJoCo(model, disable_contacts=True)
        self.dt = 1.0 / sim_freq
        self.state = model.state()
        self._other = model.state()
        self.control = model.control()
        self.num_actions = self.ctrl.action_dim
        self.dofs = model.joint_dof_count // E
        self.coords = model.joint_coord_count // E
        self.bodies = model.body_count // E
        # The TCP: the site panda() keeps on panda_link7.
        labels = list(model.shape_label)
        site = next(i for i, lb in enumerate(labels) if lb.endswith("panda_hand_tcp"))
        self.tcp_body = int(model.shape_body.numpy()[site])
        st = model.shape_transform.numpy()[site]
        self.tcp_offset = wp.transform(wp.vec3(*st[:3]), wp.quat(*st[3:]))
        newton.eval_fk(model, model.joint_q, model.joint_qd, self.state)
        first = self.state.body_q.numpy().reshape(E, self.bodies, 7)[:, 0, :3]
        base = first - first[:1]  # each env's placement (env 0's robot base is the world origin)
        dev = self.wp_device
        self.env_origin = wp.array(base.astype(np.float32), dtype=wp.vec3, device=dev)
        q0 = np.asarray(PANDA_INITIAL_Q, np.float32)[: self.dofs]
        self.start_q = wp.array(q0, dtype=wp.float32, device=dev)
        n_obs = 2 * self.dofs + 6
        self.obs = wp.zeros((E, n_obs), dtype=wp.float32, device=dev)
        self.reward = wp.zeros(E, dtype=wp.float32, device=dev)
        self.done = wp.zeros(E, dtype=wp.bool, device=dev)
        self.time_out = wp.zeros(E, dtype=wp.float32, device=dev)
        self.distance = wp.zeros(E, dtype=wp.float32, device=dev)
        self.goal = wp.zeros(E, dtype=wp.vec3, device=dev)
        self.episode_step = wp.zeros(E, dtype=wp.int32, device=dev)
        self.episode_return = wp.zeros(E, dtype=wp.float32, device=dev)
        self.stats = wp.zeros(5, dtype=wp.float32, device=dev)
        self.counter = wp.zeros(1, dtype=wp.int32, device=dev)
        self.action = wp.zeros((E, self.num_actions), dtype=wp.float32, device=dev)
        self._all = wp.ones(E, dtype=wp.bool, device=dev)
        # Zero-copy torch views of the buffers rsl-rl reads and writes.
        self.obs_t = wp.to_torch(self.obs)
        self.reward_t = wp.to_torch(self.reward)
        self.done_t = wp.to_torch(self.done)
        self.time_out_t = wp.to_torch(self.time_out)
        self.action_t = wp.to_torch(self.action)
        self._episode_step_t = wp.to_torch(self.episode_step)
        # Every env starts an episode.
        self._reset_envs(self._all)
        self.ctrl.reset(self.state, control=self.control)
        self._observe_obs_only()
        self.graph = None
        if graph is None:
            graph = self.wp_device.is_cuda
        if graph:
            self._step_impl()  # compile and warm up every kernel outside the capture
            self._reset_all()
            with wp.ScopedCapture(device=dev) as cap:
                self._step_impl()
            self.graph = cap.graph

    # -- the step (captured on CUDA) -------------------------------------------------------------------------------

    def _reset_envs(self, mask: wp.array) -> None:
        inputs = [self.seed, self.dofs, self.coords, self.start_noise, wp.vec3(*GOAL_LO), wp.vec3(*GOAL_HI),
                  self.start_q, mask, self.counter, self.state.joint_q, self.state.joint_qd, self.goal]  # fmt: skip
        wp.launch(task_kernels.reset_kernel, dim=self.num_envs, inputs=inputs, device=self.wp_device)
        wp.launch(task_kernels.bump_kernel, dim=1, inputs=[self.counter], device=self.wp_device)

    def _kinematics(self) -> list:
        """Forward kinematics of the current state, and the inputs both observation kernels start with: the env
        layout, the TCP, the state's arrays and the goals."""
        import newton

        newton.eval_fk(self.model, self.state.joint_q, self.state.joint_qd, self.state)
        return [self.dofs, self.coords, self.bodies, self.tcp_body, self.tcp_offset, self.env_origin,
                self.state.joint_q, self.state.joint_qd, self.state.body_q, self.goal]  # fmt: skip

    def _observe(self) -> None:
        """Reward, done flags and episode bookkeeping of the control step just taken (and its observations)."""
        inputs = [*self._kinematics(), self.max_episode_length, self.success_radius, self.episode_step,
                  self.episode_return, self.obs, self.reward, self.done, self.time_out, self.distance,
                  self.stats]  # fmt: skip
        wp.launch(task_kernels.observe_kernel, dim=self.num_envs, inputs=inputs, device=self.wp_device)

    def _step_impl(self) -> None:
        ctrl, s0, s1 = self.ctrl, self.state, self._other
        ctrl.set_action(self.action, s0)
        for k in range(ctrl.num_substeps):
            src, dst = (s0, s1) if k % 2 == 0 else (s1, s0)
            ctrl.before_simulation_step(src, self.control)
            self.solver.step(src, dst, self.control, None, self.dt)
        if ctrl.num_substeps % 2 == 1:
            s0.assign(s1)  # the env's state is always self.state (a captured graph binds its arrays)
        self._observe()  # reward, done, episode bookkeeping of the step just taken
        self._reset_envs(self.done)
        ctrl.reset(s0, self.done, control=self.control)
        self._observe_obs_only()

    def _observe_obs_only(self) -> None:
        """Observations again after the reset (reset envs start their new episode); reward and done are kept."""
        wp.launch(task_kernels.obs_kernel, dim=self.num_envs, inputs=[*self._kinematics(), self.obs],
                  device=self.wp_device)  # fmt: skip

    def _reset_all(self) -> None:
        self._reset_envs(self._all)
        self.episode_step.zero_()
        self.episode_return.zero_()
        self.stats.zero_()
        self.ctrl.reset(self.state, self._all, control=self.control)
        self._observe_obs_only()

    # -- rsl-rl's VecEnv -------------------------------------------------------------------------------------------

    @property
    def episode_length_buf(self):
        """(num_envs,) int32 torch view of each env's step in its episode (the device buffer the step kernels use)."""
        return self._episode_step_t

    @episode_length_buf.setter
    def episode_length_buf(self, value) -> None:
        # rsl-rl's ``learn(init_at_random_ep_len=True)`` assigns a new tensor: copy it into the device buffer.
        self._episode_step_t.copy_(value)

    def randomize_episode_phase(self, seed: int = 0) -> None:
        """Start every env at a random step of its episode (rsl-rl's ``init_at_random_ep_len``), so that episode ends
        spread over the iterations instead of arriving in waves."""
        rng = np.random.default_rng(seed)
        self.episode_step.assign(rng.integers(0, self.max_episode_length, self.num_envs).astype(np.int32))

    def get_observations(self):
        from tensordict import TensorDict

        return TensorDict({"policy": self.obs_t.clone()}, batch_size=[self.num_envs])

    def step(self, actions):
        """One control step for every env; done envs are reset inside it (their returned observation is the new
        episode's first)."""
        from tensordict import TensorDict

        self.action_t.copy_(actions.clamp(-1.0, 1.0))
        if self.graph is not None:
            wp.capture_launch(self.graph)
        else:
            self._step_impl()
        # Copies: the graph rewrites these buffers in place at the next step, while rsl-rl keeps the observation of
        # this step (PPO.act holds it until the transition is stored).
        obs = TensorDict({"policy": self.obs_t.clone()}, batch_size=[self.num_envs])
        return obs, self.reward_t.clone(), self.done_t.clone(), {"time_outs": self.time_out_t.clone()}

    def reset(self):
        """Every env starts a new episode (new goals); its first observations."""
        self._reset_all()
        return self.get_observations()

    def take_stats(self) -> dict:
        """Since the last call: finished episodes (count, mean return, success rate), env steps and their mean
        reward (one host read, between iterations)."""
        s = self.stats.numpy().copy()
        self.stats.zero_()
        n = float(s[0])
        return {
            "episodes": int(n),
            "mean_episode_reward": float(s[1] / n) if n else None,
            "success_rate": float(s[2] / n) if n else None,
            "env_steps": int(s[3]),
            "mean_step_reward": float(s[4] / s[3]) if s[3] else None,
        }
