"""Controller objects: the ManiSkill-shaped API over one control mode's device engine.

A control mode (a single config or a ManiSkill ``{uid: config}`` dict) is one :class:`wpctrl.engine._Engine`;
child controllers of a dict are views into the parent's arrays.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import newton
import numpy as np
import warp as wp

from ..binding import bind_joints
from ..config import ee as cfg_ee
from ..config import impedance as cfg_imp
from ..config import rows as cfg
from ..config.options import Actuation, ControllerOptions, Delay, Diagnostics
from ..engine.core import _Engine
from ..engine.parts import gravity
from ..engine.plan import Options, make_plan
from .drive_properties import DrivePropertiesMixin
from .inputs import _action_array, _as_rows_array, _claim, _env_selection, _raise_on_nonfinite, _type_name


class BaseController(DrivePropertiesMixin):
    """A ManiSkill-style joint controller over all envs of a Newton model.

    Build it with :func:`wpctrl.build_controller` (or ``Config.controller_cls(config, model, control_freq, sim_freq,
    actuation=wpctrl.Actuation(...), ...)``, which takes the option groups as objects only). Per control
    step call :meth:`set_action` once, then :meth:`before_simulation_step` before every solver substep. Drive
    targets are written into the ``Control`` in :meth:`before_simulation_step` (implicit actuation:
    ``joint_target_q``/``joint_target_qd``, the solver's built-in PD acts); explicit actuation also writes
    ``joint_f = clamp(Kp (q* - q) + Kd (qd* - qd), -force_limit, force_limit)`` [N·m or N]. Without per-substep
    work (implicit actuation, no interpolation, delay or effort readout) the targets are constant over the control
    step: :meth:`set_action` writes them into the Control last given to :meth:`before_simulation_step` or
    :meth:`reset`, and :meth:`before_simulation_step` launches nothing unless it is handed another Control.
    """

    sets_target_qpos = False
    sets_target_qvel = False

    def __init__(
        self,
        config,
        model: newton.Model,
        control_freq: int = 20,
        sim_freq: int = 100,
        *,
        actuation: Actuation | None = None,
        delay: Delay | None = None,
        diagnostics: Diagnostics | None = None,
        solver: Any = None,
        balance_passive_force: bool | None = None,
    ):
        self.config = config
        self.control_freq = control_freq
        self.sim_freq = sim_freq
        num_substeps = _num_substeps(control_freq, sim_freq)
        actuation = Actuation() if actuation is None else actuation
        diagnostics = Diagnostics() if diagnostics is None else diagnostics
        for name, value, kind in (("actuation", actuation, Actuation), ("diagnostics", diagnostics, Diagnostics)):
            if not isinstance(value, kind):
                raise cfg.ConfigError(f"{name}: expected a wpctrl.{kind.__name__}, got {value!r}")
        if delay is not None and not isinstance(delay, Delay):
            raise cfg.ConfigError(f"delay: expected a wpctrl.Delay or None, got {delay!r}")
        if isinstance(config, Mapping):
            configs = dict(config)
            balance = configs.pop("balance_passive_force", None)  # an agent-level option, not a controller
            cfg.check_mode_dict(configs)
        else:
            configs, balance = {"": config}, None
        balance = _balance_passive_force(balance, balance_passive_force)
        if balance:
            gravity.check_solver(solver)
        names: list[str] = []
        for c in configs.values():
            if not isinstance(c, cfg.ControllerConfig):
                raise cfg.ConfigError(f"config: expected a controller config, got {type(c).__name__}")
            names += cfg._joint_names(c)
        binding = bind_joints(model, names)  # once for the whole mode
        parts: list[tuple[str, Any, cfg.Rows]] = []
        ee_specs: dict[int, tuple] = {}  # first row -> (first action column, rows, EESpec)
        r0 = c0 = 0
        for uid, c in configs.items():
            n = len(c.joint_names)
            if isinstance(c, cfg_ee.EE_CONFIGS):  # end-effector controllers: position rows + an EE launch
                rows, spec = cfg_ee.ee_rows(c, binding.qlimits[r0 : r0 + n])
                ee_specs[r0] = (c0, rows.count, spec)
            elif isinstance(c, cfg_imp.IMPEDANCE_CONFIGS):  # OSC / joint impedance: effort rows + their launches
                rows, spec = cfg_imp.impedance_rows(c, binding.qlimits[r0 : r0 + n])
                ee_specs[r0] = (c0, rows.count, spec)
            else:
                rows = cfg.config_rows(c, binding.qlimits[r0 : r0 + n])
            parts.append((uid, c, rows))
            r0 += n
            c0 += rows.action_dim
        all_rows = cfg.Rows.concat([p[2] for p in parts])
        options = Options(
            num_substeps=num_substeps,
            sim_dt=1.0 / sim_freq,
            actuation=actuation,
            delay=delay,
            diagnostics=diagnostics,
            balance_passive_force=balance,
        )
        # The engine: plan (host) -> device state -> parts' model writes -> the first reset; nothing after it.
        self._engine = _Engine(make_plan(all_rows, binding, options, ee_specs), model, solver)
        if solver is not None and self._engine.mode_changed and type(solver).__name__ == "SolverMuJoCo":
            warnings.warn(
                "wpctrl changed Model.joint_target_mode after the MuJoCo solver was built; MuJoCo creates its "
                "actuators at construction, so build the controller before the solver",
                stacklevel=3,
            )
        self._rows = slice(0, all_rows.count)
        self._cols = slice(0, all_rows.action_dim)
        self._owner = True
        ee = self._engine.part("ee")
        ee_parts = {} if ee is None else dict(ee.parts)  # by first row
        imp = self._engine.part("impedance")
        if imp is not None:
            ee_parts.update(imp.units)
        self._ee = ee_parts.get(0) if not isinstance(config, Mapping) else None
        self.children: dict[str, BaseController] = {}
        if isinstance(config, Mapping):
            r0 = c0 = 0
            for uid, c, rows in parts:
                child_cls = type(c).controller_cls
                child = child_cls.__new__(child_cls)
                child._init_view(c, self, slice(r0, r0 + rows.count), slice(c0, c0 + rows.action_dim), rows)
                child._ee = ee_parts.get(r0)
                self.children[uid] = child
                r0 += rows.count
                c0 += rows.action_dim
            self.single_action_space = _flat_space([ch.single_action_space for ch in self.children.values()])
            self.action_mapping = {uid: (ch._cols.start, ch._cols.stop) for uid, ch in self.children.items()}
            self.sets_target_qpos = any(ch.sets_target_qpos for ch in self.children.values())
            self.sets_target_qvel = any(ch.sets_target_qvel for ch in self.children.values())
        else:
            self._set_spaces(parts[0][2])
        self.action_space = _batched(self.single_action_space, self.num_envs)

    def _init_view(self, config, parent: BaseController, rows_slice: slice, cols_slice: slice, rows: cfg.Rows):
        self.config = config
        self.control_freq = parent.control_freq
        self.sim_freq = parent.sim_freq
        self._engine = parent._engine
        self._rows = rows_slice
        self._cols = cols_slice
        self._owner = False
        self.children = {}
        self._set_spaces(rows)
        self.action_space = _batched(self.single_action_space, self.num_envs)

    def _set_spaces(self, rows: cfg.Rows) -> None:
        raw = gym.spaces.Box(rows.action_low, rows.action_high, shape=(rows.action_dim,), dtype=np.float32)
        if rows.normalized:
            self._original_single_action_space = raw
            self.single_action_space = gym.spaces.Box(-1.0, 1.0, shape=(rows.action_dim,), dtype=np.float32)
        else:
            self._original_single_action_space = None
            self.single_action_space = raw

    # -- metadata -------------------------------------------------------------------------------------------------

    @property
    def num_envs(self) -> int:
        return self._engine.num_envs

    @property
    def device(self):
        return self._engine.device

    @property
    def joint_names(self) -> list[str]:
        return self._engine.rows.joint_names[self._rows]

    @property
    def action_dim(self) -> int:
        return self._cols.stop - self._cols.start

    @property
    def num_substeps(self) -> int:
        """K = sim_freq // control_freq: solver substeps per control step."""
        return self._engine.num_substeps

    # -- the options that run (resolved: what the engine does, not what was asked) ---------------------------------

    @property
    def options(self) -> ControllerOptions:
        """The mode's option groups as they run: :class:`wpctrl.Actuation` with the explicit law and the inertia
        update resolved (None where nothing of the kind runs), :class:`wpctrl.Delay` (or None),
        :class:`wpctrl.Diagnostics`, and whether gravity is off the robot."""
        return self._engine.plan.resolved_options

    @property
    def actuation(self) -> str:
        """``"implicit"`` or ``"explicit"``: who computes the drive force."""
        return self.options.actuation.mode

    @property
    def explicit_pd(self) -> str | None:
        """The explicit PD law that runs (``"naive"``, ``"stable"``, ``"coupled"``), or None with implicit
        actuation."""
        return self.options.actuation.explicit_pd

    @property
    def inertia_update(self) -> str | None:
        """When the inertia is recomputed (``"control"`` or ``"substep"``), or None when the mode computes none."""
        return self.options.actuation.inertia_update

    @property
    def nan_policy(self) -> str:
        return self.options.diagnostics.nan_policy

    @property
    def clip_targets(self) -> str:
        return self.options.diagnostics.clip_targets

    @property
    def track_effort(self) -> bool:
        return self.options.diagnostics.track_effort

    @property
    def balance_passive_force(self) -> bool:
        """Whether gravity is off the controlled robot's links (ManiSkill's agent-level switch)."""
        return self.options.balance_passive_force

    @property
    def is_graphable(self) -> bool:
        """Every per-step call (set_action, before_simulation_step, reset with device env ids) can be captured."""
        return True

    def __getitem__(self, uid: str) -> BaseController:
        try:
            return self.children[uid]
        except KeyError:
            raise KeyError(f"no child controller {uid!r}; known: {list(self.children)}") from None

    # -- device views ---------------------------------------------------------------------------------------------

    def _view(self, arr: wp.array) -> wp.array:
        if self._owner:
            return arr
        return arr[:, self._rows.start : self._rows.stop]

    @property
    def target_qpos(self) -> wp.array:
        """(num_envs, n_joints) position targets [rad or m] at the end of the control step (live view)."""
        return self._view(self._engine.target_qpos)

    @property
    def target_qvel(self) -> wp.array:
        """(num_envs, n_joints) velocity targets [rad/s or m/s] (live view)."""
        return self._view(self._engine.target_qvel)

    @property
    def start_qpos(self) -> wp.array:
        """(num_envs, n_joints) measured positions at the last set_action or reset [rad or m] (live view)."""
        return self._view(self._engine.start_qpos)

    @property
    def processed_action(self) -> wp.array:
        """(num_envs, action_dim) last action after clip and scale (raw units) (live view)."""
        arr = self._engine.processed_action
        if self._owner:
            return arr
        if self._cols.start == self._cols.stop:  # a child without action columns (passive)
            return wp.zeros((self.num_envs, 0), dtype=wp.float32, device=self.device)
        return arr[:, self._cols.start : self._cols.stop]

    @property
    def step_counter(self) -> wp.array:
        """(num_envs,) int32 substeps since the last set_action or reset (ManiSkill's ``_step``, per env).

        With per-substep work (explicit actuation, interpolation) this is the live device counter. Without it no
        substep launch exists to count: the value is the device's per-env part (set by set_action / reset) plus the
        host's count of before_simulation_step calls since the last set_action, refreshed (one launch) at every read
        of this property. A graph bakes the host's count at capture, so it is exact when replayed at the point of the
        control step where it was captured: a graph of set_action + K substeps (+ a reset) replayed back to back
        reads K, as eagerly, with eager resets between replays too. What it cannot follow: the host does not see
        replays, so eager substeps run between replays of such a graph (or a graph of substeps alone, replayed) are
        miscounted."""
        return self._engine.step_counter()

    @property
    def bad_action_count(self) -> wp.array:
        """(num_envs,) int32 count of actions rejected for NaN/Inf; those envs kept their previous targets."""
        return self._engine.bad_action_count

    def attach_solver(self, solver) -> None:
        """Notify ``solver`` of the drive properties now, and after every per-env gain update (implicit acceleration
        drives, :meth:`set_drive_properties`, :meth:`randomize_drive_properties`). Use it when the solver is built
        after the controller (as MuJoCo requires)."""
        self._require_owner("attach_solver")
        self._engine.attach_solver(solver)

    @property
    def response(self) -> wp.array | None:
        """(num_envs, n_joints) joint-space response r = (H^-1)_ii [1/(kg m^2) or 1/kg] of the last update (1/r is
        the effective inertia), when acceleration drives or stable explicit PD use it; otherwise None."""
        if not self._engine.needs_response:
            return None
        return self._view(self._engine.response)

    # -- per-step API ---------------------------------------------------------------------------------------------

    def _require_owner(self, what: str) -> None:
        if not self._owner:
            raise RuntimeError(f"{what}: this is a child of a combined controller; call it on the parent")

    def _check_state(self, state, what: str) -> None:
        eng = self._engine
        if not isinstance(state, newton.State):
            raise TypeError(f"{what}: expected a newton.State (model.state()), got {_type_name(state)}")
        if state.joint_q is None or state.joint_q.device != eng.device:
            where = None if state.joint_q is None else state.joint_q.device
            raise ValueError(f"{what}: state is on {where}, the controller on {eng.device}")
        if (
            state.joint_q.shape[0] != eng.model.joint_coord_count
            or state.joint_qd.shape[0] != eng.model.joint_dof_count
        ):
            raise ValueError(
                f"{what}: state has {state.joint_q.shape[0]} coordinates / {state.joint_qd.shape[0]} DOFs, the "
                f"controller's model {eng.model.joint_coord_count} / {eng.model.joint_dof_count}: another model?"
            )
        _claim(state, eng.model, what, "state")

    def _check_control(self, control, what: str) -> None:
        eng = self._engine
        if not isinstance(control, newton.Control):
            raise TypeError(f"{what}: expected a newton.Control (model.control()), got {_type_name(control)}")
        if control.joint_target_q is None or control.joint_target_q.device != eng.device:
            raise ValueError(f"{what}: control is not on the controller's device {eng.device}")
        if control.joint_target_qd.shape[0] != eng.model.joint_dof_count:
            raise ValueError(
                f"{what}: control has {control.joint_target_qd.shape[0]} DOFs, the controller's model "
                f"{eng.model.joint_dof_count}: another model?"
            )
        _claim(control, eng.model, what, "control")

    def set_action(self, action, state: newton.State) -> None:
        """Set this control step's targets from ``action`` (num_envs, action_dim) and the measured ``state``.

        ``action`` may be a torch tensor (used zero-copy when float32), a numpy array or a wp.array on the
        controller's device. An env whose action holds NaN/Inf keeps its previous targets and its
        :attr:`bad_action_count` grows. One kernel launch; no allocation or host sync for float32 device input.
        """
        self._require_owner("set_action")
        self._check_state(state, "set_action")
        eng = self._engine
        a = _action_array(action, eng.num_envs, eng.action_dim, eng.device, eng.action_buffer, eng.wrappers)
        if self.nan_policy == "raise":
            _raise_on_nonfinite(a)
        eng.set_action(a, state)

    def before_simulation_step(self, state: newton.State, control: newton.Control) -> None:
        """Call once before every solver substep: writes the (interpolated) drive targets and, for explicit
        actuation, the PD torques into ``control``. One kernel launch.

        Without per-substep work (implicit actuation, no interpolating row, delay or effort readout) the drive
        targets do not change between substeps and set_action already wrote them into the known Control (the one
        last given here or to :meth:`reset`): no launch. A different Control (other ``joint_target_q``/``qd``
        arrays: double-buffered controls) gets the targets written (one launch) and becomes the known one. If you
        overwrite the known Control's targets yourself (e.g. ``Control.clear()``), call :meth:`invalidate_control`."""
        self._require_owner("before_simulation_step")
        self._check_state(state, "before_simulation_step")
        self._check_control(control, "before_simulation_step")
        self._engine.substep(state, control)

    def invalidate_control(self) -> None:
        """Forget which Control holds the current drive targets: the next :meth:`before_simulation_step` writes them
        again. Only needed without per-substep work, after something other than wpctrl wrote the targets."""
        self._require_owner("invalidate_control")
        self._engine.forget_control()

    def reset(self, state: newton.State, env_ids=None, control: newton.Control | None = None) -> None:
        """Re-initialise the targets of ``env_ids`` (None: all) from the measured ``state``: start = target = q.

        Unlike ManiSkill, only the given envs are touched. The first call initialises every env, as ManiSkill's
        first reset does (PDJointPosVel then takes the measured velocity as its velocity target; later resets set
        it to 0). With ``control``, the reset envs' drive targets are written at once (and explicit torques zeroed);
        otherwise the next :meth:`before_simulation_step` writes them (without per-substep work: they are written at
        once into the known Control, if any; a ``control`` not known yet gets every env's targets). ``env_ids``: None,
        an int, a sequence of ints, a bool mask of shape (num_envs,), or a torch/numpy/wp array of either (device
        arrays: graph-capturable).
        """
        self._require_owner("reset")
        self._check_state(state, "reset")
        if control is not None:
            self._check_control(control, "reset")
        eng = self._engine
        first = eng._reset_count == 0
        ids, mask = _env_selection(env_ids, eng.num_envs, eng.device)  # validated on every call
        if first:
            ids = mask = None  # the first reset initialises every env, as ManiSkill's
        eng.reset(state, ids, mask, control, first=first)
        eng._reset_count += 1

    # -- state ----------------------------------------------------------------------------------------------------

    @property
    def _uses_target(self) -> bool:
        return bool(getattr(self.config, "use_delta", False) and getattr(self.config, "use_target", False))

    def get_state(self) -> dict:
        """``{"target_qpos": wp.array}`` (a live view) for a ``use_target`` controller, ``{}`` otherwise; a combined
        controller returns ``{uid: state}`` for its children with a state."""
        if self.children:
            return {uid: s for uid, ch in self.children.items() if (s := ch.get_state())}
        if self._uses_target:
            return {"target_qpos": self.target_qpos}
        return {}

    def set_state(self, state: dict | None) -> None:
        """Restore :meth:`get_state`'s result (values are copied into the controller's arrays)."""
        if self.children:
            state = state or {}
            for uid, ch in self.children.items():
                ch.set_state(state.get(uid))
            return
        if not state or not self._uses_target:
            return
        eng = self._engine
        new = _as_rows_array("target_qpos", state["target_qpos"], (eng.num_envs, self._rows.stop - self._rows.start))
        full = eng.target_qpos.numpy()
        full[:, self._rows] = new
        eng.target_qpos.assign(full)
        eng.forget_control()  # the Control's drive targets are now stale: the next substep rewrites them

    def __repr__(self) -> str:
        inner = ", ".join(self.joint_names)
        return f"{type(self).__name__}(dof={self.action_dim}, num_envs={self.num_envs}, joints=({inner}))"


def _balance_passive_force(in_mode_dict, keyword) -> bool:
    """The one value of ``balance_passive_force``: the keyword or the mode dict's entry (given both ways they must
    agree), else True (ManiSkill's default)."""
    for v in (keyword, in_mode_dict):
        if v is not None and not isinstance(v, (bool, np.bool_)):
            raise cfg.ConfigError(f"balance_passive_force: expected True or False, got {v!r}")
    if keyword is not None and in_mode_dict is not None and bool(keyword) != bool(in_mode_dict):
        raise cfg.ConfigError(
            f"balance_passive_force: expected None or the mode dict's 'balance_passive_force' entry "
            f"({bool(in_mode_dict)}), got {keyword!r}"
        )
    return bool(True if keyword is None and in_mode_dict is None else (in_mode_dict if keyword is None else keyword))


def _num_substeps(control_freq, sim_freq) -> int:
    for name, v in (("control_freq", control_freq), ("sim_freq", sim_freq)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v <= 0:
            raise cfg.ConfigError(f"{name}: expected a positive int [Hz], got {v!r}")
    if sim_freq % control_freq != 0:
        raise cfg.ConfigError(
            f"sim_freq: expected a multiple of control_freq={control_freq} so that each control step spans whole "
            f"substeps, got sim_freq={sim_freq} (ManiSkill's env asserts this too)"
        )
    return int(sim_freq // control_freq)


def _flat_space(spaces: Sequence[gym.spaces.Box]) -> gym.spaces.Box:
    low = np.concatenate([s.low for s in spaces]).astype(np.float32) if spaces else np.zeros(0, np.float32)
    high = np.concatenate([s.high for s in spaces]).astype(np.float32) if spaces else np.zeros(0, np.float32)
    return gym.spaces.Box(low, high, shape=low.shape, dtype=np.float32)


def _batched(space: gym.spaces.Box, num_envs: int) -> gym.spaces.Box:
    if num_envs > 1:
        return gym.vector.utils.batch_space(space, num_envs)
    return space


class CombinedController(BaseController):
    """A control mode ``{uid: config}``: one flat action in dict insertion order, see :attr:`action_mapping`."""
