"""Controller objects: the ManiSkill-shaped API over one control mode's device engine.

A control mode (a single config or a ManiSkill ``{uid: config}`` dict) is one :class:`wpctrl.engine._Engine`, built
from the configs' families (:mod:`.mode`); child controllers of a dict are views into the parent's arrays, each of
its config's controller class.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import newton
import numpy as np
import warp as wp

from ..config.options import Actuation, Delay, Diagnostics
from ..config.rows import Rows
from ..engine.core import _Engine
from ..engine.parts import gravity
from ..engine.plan import make_plan
from .drive_properties import DrivePropertiesMixin
from .inputs import _action_array, _as_rows_array, _claim, _env_selection, _raise_on_nonfinite, _type_name
from .introspection import IntrospectionMixin
from .mode import make_mode


class BaseController(IntrospectionMixin, DrivePropertiesMixin):
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
        mode = make_mode(
            config,
            model,
            control_freq,
            sim_freq,
            actuation=actuation,
            delay=delay,
            diagnostics=diagnostics,
            balance_passive_force=balance_passive_force,
        )
        if mode.options.balance_passive_force:
            gravity.check_solver(solver)
        # The engine: plan (host) -> device state -> parts' model writes -> the first reset; nothing after it.
        self._engine = _Engine(make_plan(mode.rows, mode.binding, mode.options, mode.specs), model, solver)
        if solver is not None and self._engine.mode_changed and type(solver).__name__ == "SolverMuJoCo":
            warnings.warn(
                "wpctrl changed Model.joint_target_mode after the MuJoCo solver was built; MuJoCo creates its "
                "actuators at construction, so build the controller before the solver",
                stacklevel=3,
            )
        children = mode.children
        self._rows = slice(0, self._engine.rows.count)
        self._cols = slice(0, self._engine.action_dim)
        self._owner = True
        self.children: dict[str, BaseController] = {}
        if isinstance(config, Mapping):
            self._ee = None
            for ch in children:
                child_cls = type(ch.config).controller_cls
                child = child_cls.__new__(child_cls)
                child._init_view(ch.config, self, ch.row_slice, ch.col_slice, ch.rows)
                self.children[ch.uid] = child
            self.single_action_space = _flat_space([ch.single_action_space for ch in self.children.values()])
            self.action_mapping = {uid: (ch._cols.start, ch._cols.stop) for uid, ch in self.children.items()}
            self.joint_mapping = {uid: (ch._rows.start, ch._rows.stop) for uid, ch in self.children.items()}
            self.sets_target_qpos = any(ch.sets_target_qpos for ch in self.children.values())
            self.sets_target_qvel = any(ch.sets_target_qvel for ch in self.children.values())
        else:
            self._ee = self._unit(self._engine, 0)
            self._set_spaces(children[0].rows)
        self.action_space = _batched(self.single_action_space, self.num_envs)

    @staticmethod
    def _unit(engine, row0: int):
        """The device side of the controller whose rows start at ``row0`` in its family's engine part (``_ee``), or
        None for a family that runs in the joint kernels alone. A family with a part overrides it."""
        return None

    def _init_view(self, config, parent: BaseController, rows_slice: slice, cols_slice: slice, rows: Rows):
        self.config = config
        self.control_freq = parent.control_freq
        self.sim_freq = parent.sim_freq
        self._engine = parent._engine
        self._rows = rows_slice
        self._cols = cols_slice
        self._owner = False
        self._ee = self._unit(self._engine, rows_slice.start)
        self.children = {}
        self._set_spaces(rows)
        self.action_space = _batched(self.single_action_space, self.num_envs)

    def _set_spaces(self, rows: Rows) -> None:
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
        return self._view(self._engine.core.target_qpos)

    @property
    def target_qvel(self) -> wp.array:
        """(num_envs, n_joints) velocity targets [rad/s or m/s] (live view)."""
        return self._view(self._engine.core.target_qvel)

    @property
    def start_qpos(self) -> wp.array:
        """(num_envs, n_joints) measured positions at the last set_action or reset [rad or m] (live view)."""
        return self._view(self._engine.core.start_qpos)

    @property
    def processed_action(self) -> wp.array:
        """(num_envs, action_dim) last action after clip and scale (raw units) (live view)."""
        arr = self._engine.core.processed_action
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
        return self._engine.core.bad_action_count

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
        full = eng.core.target_qpos.numpy()
        full[:, self._rows] = new
        eng.core.target_qpos.assign(full)
        eng.forget_control()  # the Control's drive targets are now stale: the next substep rewrites them

    def __repr__(self) -> str:
        inner = ", ".join(self.joint_names)
        return f"{type(self).__name__}(dof={self.action_dim}, num_envs={self.num_envs}, joints=({inner}))"


def _flat_space(spaces: Sequence[gym.spaces.Box]) -> gym.spaces.Box:
    low = np.concatenate([s.low for s in spaces]).astype(np.float32) if spaces else np.zeros(0, np.float32)
    high = np.concatenate([s.high for s in spaces]).astype(np.float32) if spaces else np.zeros(0, np.float32)
    return gym.spaces.Box(low, high, shape=low.shape, dtype=np.float32)


def _batched(space: gym.spaces.Box, num_envs: int) -> gym.spaces.Box:
    if num_envs > 1:
        return gym.vector.utils.batch_space(space, num_envs)
    return space


class CombinedController(BaseController):
    """A control mode ``{uid: config}``: one flat action in dict insertion order, see :attr:`action_mapping`; the
    children's joints in the same order, see :attr:`joint_mapping`."""
