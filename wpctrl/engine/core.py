"""The device engine of one control mode: plan → state → launches, and the parts that make up its options.

Construction runs one way: :func:`~wpctrl.engine.plan.make_plan` decides everything on the host (rows, index tables,
options, active parts, the step kernels' compile-time layout); :class:`~wpctrl.engine.state.CoreArrays` and each
active part (:mod:`wpctrl.engine.parts`) allocate their device arrays once; the parts' ``build`` hooks write what
they own into the model (drive properties, gravity compensation, the EE chains, the initial response); a reset of
every env from the model's initial pose ends it. :class:`_Engine` then only runs the stages, one launch each:

- ``set_action``: the parts' pre-launch hooks (EE targets, the response update), then the joint kernel of the mode's
  layout (:mod:`wpctrl.kernels.pd_step`).
- ``substep``: the substep kernel, plus the parts' hooks (per-substep response, the coupled drive's launch, the
  actuator networks' launches; a network run in the substep's launch, ``ActuatorNet.launch``, is part of it). A mode
  without per-substep work (implicit actuation, no interpolation, delay, effort readout or per-substep response)
  has drive targets that do not change between substeps: ``set_action`` writes them into the Control it knows (the
  last one given to ``substep`` or ``reset``) and ``substep`` launches nothing, unless it is handed another Control
  (a small write there, which it then knows). The per-env substep counter is then ``step + host_substeps``.
- ``reset``: one launch (:mod:`wpctrl.kernels.pd`), plus the parts' hooks.

Launches are recorded once and re-bound only where an argument changed (:class:`~wpctrl.engine.launch._Launch`);
their arguments are looked up by name among the core arrays and the active parts'
(:class:`~wpctrl.engine.state.Arrays`).
"""

from __future__ import annotations

import newton
import warp as wp

from ..kernels import pd_step
from ..kernels.actuator_net import NetIO
from ..kernels.dims import step_block_dim
from ..kernels.pd import _reset_kernel, _step_view_kernel, _targets_kernel
from .launch import _Launch, _Targets
from .parts import PARTS, Part, part_classes
from .plan import Plan
from .state import Alloc, Arrays, CoreArrays


class _ModelState:
    """The model's initial joint state, shaped like a State (the build-time response and reset)."""

    def __init__(self, model: newton.Model):
        self.joint_q = model.joint_q
        self.joint_qd = model.joint_qd


class _Engine:
    """Device arrays, parts and launches of one control mode (all rows, all envs).

    Every attribute is defined here: the arrays every mode has are ``core`` (:class:`~.state.CoreArrays`), a part's
    are reached through :meth:`part` (None when the mode does not need it); nothing is looked up by searching.
    """

    def __init__(self, plan: Plan, model: newton.Model, solver=None, write_model: bool = True):
        self.plan = plan
        self.rows = plan.rows
        self.binding = plan.binding
        self.model = model
        self.device = model.device
        self.num_envs = plan.num_envs
        self.num_rows = plan.num_rows
        self.action_dim = plan.action_dim
        self.num_substeps = plan.options.num_substeps
        self.explicit = plan.explicit
        self.per_substep = plan.per_substep
        self.layout = plan.layout
        self.solver = solver  # notified after per-env gain edits (implicit acceleration drive, set / randomise)
        alloc = Alloc(self.device, self.num_envs)
        self.core = CoreArrays(plan, alloc)
        classes = part_classes()
        self.parts = [classes[name](plan, alloc) for name in plan.parts]
        self._by_name = {p.name: p for p in self.parts}
        optional = {n for cls in classes.values() for n in cls.OPTIONAL_ARGS}
        self.arrays = Arrays(self.core, self.parts, optional)
        # The hot path's decisions, made once: which parts hook which stage, whether the substep writes joint_f.
        self._hooks = {
            h: [p for p in self.parts if getattr(type(p), h) is not getattr(Part, h)]
            for h in ("before_set_action", "before_substep", "after_substep", "after_reset")
        }
        if "actuator_models" in self._by_name:  # an actuator network in the substep's launch, or its own (host only)
            self._by_name["actuator_models"].choose_launch(self)
        self.writes_joint_f = plan.writes_joint_f
        self.action_buffer = self.core.action_buffer  # (read by every set_action)
        self.block_dim = step_block_dim(self.device, self.num_envs)
        self.wrappers: dict = {}  # zero-copy wp.array views of torch actions, by (address, strides)
        # Elided substeps: the host's substep count since the last set_action, and the Control whose drive targets
        # hold the current targets (its joint_target_q/qd arrays, kept alive so that their addresses stay unique).
        self.host_substeps = 0
        self._known_control: tuple[wp.array, wp.array] | None = None
        self._launch_set_action: _Launch | None = None
        self._launch_substep: _Launch | None = None
        self._launch_targets: _Launch | None = None
        self._reset_count = 0
        self.mode_changed = False
        if write_model:
            for part in self.parts:
                part.build(self, model, solver)
            self.mode_changed = self._by_name["drive_properties"].mode_changed
            if solver is not None:
                solver.notify_model_changed(self.model_flags())
            # Targets start at the model's initial pose (the first reset() re-initialises every env from the state).
            self.reset(_ModelState(model), None, None, None, first=False)

    # -- parts ----------------------------------------------------------------------------------------------------

    def part(self, name: str):
        """The part ``name`` (a key of :data:`wpctrl.engine.parts.PARTS`: ``"drive_properties"``, ``"response"``,
        ``"coupled_drive"``, ``"delay"``, ``"effort_readout"``, ``"ee"``, ``"impedance"``, ...) when the mode has it,
        else None; a name that is no part raises ``KeyError``."""
        if name not in PARTS:
            raise KeyError(f"no engine part {name!r}; the parts: {list(PARTS)}")
        return self._by_name.get(name)

    @property
    def response_part(self):
        return self._by_name.get("response") or self._by_name.get("coupled_drive")

    @property
    def needs_response(self) -> bool:
        return self.plan.needs_response

    @property
    def response(self) -> wp.array:
        """(num_envs, rows) r = (H^-1)_ii, or the core's (1, rows) placeholder of ones."""
        part = self.response_part
        return self.core.response if part is None else part.response

    @property
    def coupled(self) -> bool:
        return self.plan.coupled

    def model_flags(self):
        """What the engine changed in the model, as ``newton.ModelFlags`` for ``notify_model_changed``."""
        flags = newton.ModelFlags.JOINT_DOF_FORCE_PROPERTIES
        if "gravity" in self._by_name:
            flags |= newton.ModelFlags.BODY_INERTIAL_PROPERTIES
        return flags

    def attach_solver(self, solver) -> None:
        gravity = self._by_name.get("gravity")
        if gravity is not None:
            from .parts.gravity import check_solver

            check_solver(solver)
        self.solver = solver
        solver.notify_model_changed(self.model_flags())

    def notify_solver(self) -> None:
        """Tell the attached solver that per-DOF drive properties changed (MuJoCo, Steel and Kamino copy them into
        their own model; XPBD, Featherstone and SemiImplicit read Newton's arrays at every step)."""
        if self.solver is not None:
            self.solver.notify_model_changed(newton.ModelFlags.JOINT_DOF_FORCE_PROPERTIES)

    def update_response(self, state) -> None:
        """Recompute r = (H^-1)_ii for ``state`` now (the response part's update)."""
        part = self.response_part
        if part is not None:
            part.update(self, state)

    def _launch(self, kernel, dim, per_call: dict, block_dim=None) -> _Launch:
        """A recorded launch of ``kernel`` with every parameter looked up by name (``per_call`` first)."""
        params = {
            a.label: per_call[a.label] if a.label in per_call else self.arrays.lookup(a.label) for a in kernel.adj.args
        }
        return _Launch(kernel, dim, params, self.device, block_dim=block_dim)

    # -- stages ---------------------------------------------------------------------------------------------------

    def set_action(self, action: wp.array, state) -> None:
        for part in self._hooks["before_set_action"]:  # EE rows' targets (the joint launch leaves them), response
            part.before_set_action(self, action, state)
        if self._launch_set_action is None:
            per_call = {
                "host_substeps": 0,
                "action_in": action,
                "joint_q_in": state.joint_q,
                "joint_target_q_out": None,
                "joint_target_qd_out": None,
            }
            kernel = pd_step.set_action_kernel(self.layout)
            self._launch_set_action = self._launch(kernel, self.num_envs, per_call, self.block_dim)
        ln = self._launch_set_action
        ln.bind("action_in", action)
        ln.bind("joint_q_in", state.joint_q)
        if not self.per_substep:
            # An env whose action is rejected keeps counting: it carries the substeps since the previous set_action.
            # A captured graph does not know how many substeps preceded it at replay: it assumes a full control step.
            carry = self.num_substeps if self.device.is_capturing else self.host_substeps
            ln.bind("host_substeps", carry)
            known = self._known_control
            ln.bind("joint_target_q_out", None if known is None else known[0])
            ln.bind("joint_target_qd_out", None if known is None else known[1])
            self.host_substeps = 0
        ln.launch()

    def substep(self, state: newton.State, control: newton.Control) -> None:
        if not self.per_substep:
            # The drive targets are constant over the control step: written by set_action into the known Control.
            self.host_substeps += 1
            if not self._is_known_control(control):
                self.write_targets(control)
            return
        for part in self._hooks["before_substep"]:
            part.before_substep(self, state, control)
        joint_f = control.joint_f if self.writes_joint_f else None
        if self._launch_substep is None:
            per_call = {
                "joint_q_in": state.joint_q,
                "joint_qd_in": state.joint_qd,
                "joint_target_q_out": control.joint_target_q,
                "joint_target_qd_out": control.joint_target_qd,
                "joint_f_out": joint_f,
            }
            models = self.part("actuator_models")
            fused = None if models is None else models.substep_launch(self)
            if fused is None:  # (the kernel's network parameters unused)
                kernel, dim, block_dim = pd_step.substep_kernel(self.layout), self.num_envs, self.block_dim
                per_call.update(row0=0, io=NetIO(), hist_out=None)
            else:  # an actuator network's rows in the same launch (ActuatorModels.choose_launch)
                kernel, dim, block_dim, extra = fused
                per_call.update(extra)
            self._launch_substep = self._launch(kernel, dim, per_call, block_dim)
        ln = self._launch_substep
        ln.bind("joint_q_in", state.joint_q)
        ln.bind("joint_qd_in", state.joint_qd)
        ln.bind("joint_target_q_out", control.joint_target_q)
        ln.bind("joint_target_qd_out", control.joint_target_qd)
        ln.bind("joint_f_out", joint_f)
        ln.launch()
        for part in self._hooks["after_substep"]:
            part.after_substep(self, state, control)

    # -- the Control that holds the drive targets (no per-substep work) ----------------------------------------------

    def _is_known_control(self, control) -> bool:
        known = self._known_control
        return (
            known is not None
            and known[0].ptr == control.joint_target_q.ptr
            and known[1].ptr == control.joint_target_qd.ptr
        )

    def write_targets(self, control: newton.Control) -> None:
        """Write every env's current drive targets into ``control`` (one launch) and make it the known Control."""
        if self._launch_targets is None:
            per_call = {"joint_target_q_out": control.joint_target_q, "joint_target_qd_out": control.joint_target_qd}
            self._launch_targets = self._launch(_targets_kernel, (self.num_envs, self.num_rows), per_call)
        ln = self._launch_targets
        ln.bind("joint_target_q_out", control.joint_target_q)
        ln.bind("joint_target_qd_out", control.joint_target_qd)
        ln.launch()
        self._known_control = (control.joint_target_q, control.joint_target_qd)

    def forget_control(self) -> None:
        """The known Control no longer holds the current targets (they were edited on the host, or the user overwrote
        the Control): the next substep writes them again."""
        self._known_control = None

    def step_counter(self) -> wp.array:
        """(num_envs,) ManiSkill's ``_step``: the live device counter, or (elided substeps) a view refreshed now."""
        c = self.core
        if self.per_substep:
            return c.step
        wp.launch(
            _step_view_kernel, dim=self.num_envs, inputs=[self.host_substeps, c.step, c.step_view], device=self.device
        )
        return c.step_view

    def reset(self, state, env_ids, env_mask, control, first: bool) -> None:
        write_all = False
        if not self.per_substep:
            if control is None:
                # The reset envs' targets go into the known Control (if any), which then still holds every env's.
                control = None if self._known_control is None else _Targets(*self._known_control)
            elif not self._is_known_control(control):
                write_all = True  # a new Control: it gets every env's targets, not only the reset envs'
        n = 0 if env_ids is None else env_ids.shape[0]
        if (env_ids is not None and n == 0) or self.num_rows == 0:
            if write_all:
                self.write_targets(control)
            return
        per_call = {
            "first": int(first),
            "explicit_on": int(self.explicit),
            "host_substeps": 0 if self.per_substep else self.host_substeps,
            "env_ids_in": env_ids,
            "env_mask_in": env_mask,
            "joint_q_in": state.joint_q,
            "joint_qd_in": state.joint_qd,
            "joint_target_q_out": None if control is None else control.joint_target_q,
            "joint_target_qd_out": None if control is None else control.joint_target_qd,
            "joint_f_out": None if (control is None or not self.writes_joint_f) else control.joint_f,
        }
        effort = self._by_name.get("effort_readout")
        if effort is not None:  # (the coupled drive sets the substep kernel's effort outputs aside, not the reset's)
            per_call["computed_effort_out"] = effort.computed_effort
            per_call["applied_effort_out"] = effort.applied_effort
            per_call["saturation_count_out"] = effort.saturation_count
        names = [a.label for a in _reset_kernel.adj.args]
        inputs = [per_call[n] if n in per_call else self.arrays.lookup(n) for n in names]
        dim = (self.num_envs if env_ids is None else n, self.num_rows)
        wp.launch(_reset_kernel, dim=dim, inputs=inputs, device=self.device)
        for part in self._hooks["after_reset"]:
            part.after_reset(self, state, env_ids, env_mask)
        if write_all:
            self.write_targets(control)
