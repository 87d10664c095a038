"""The impedance part of a control mode: operational-space and joint-impedance controllers (and the kernel that
randomises an OSC controller's task gains). Registered with the engine when this module is imported, which
``build_controller`` does for a mode with an impedance config (its family names this module).

Their joints are effort rows of the mode's engine (no action column of their own): the substep kernel delays,
clamps to ``force_limit``, reads out and writes ``Control.joint_f`` for them as for any effort row, and a reset zeroes
their command. This part adds, per controller, one launch before the joint ``set_action`` launch (the target and the
variable gains from the action) and one before every substep launch (the torque from the measured state, written as
the rows' commanded effort), plus the EE reset of an OSC controller (its target pose becomes the measured pose).

Per-env gains: a joint-impedance controller's stiffness / damping and an OSC controller's null-space gains are the
rows' per-env drive properties (``ctrl.stiffness`` / ``damping``: set and randomised as every row's); an OSC
controller's task gains are ``(num_envs, 6)`` arrays of this part (``task_stiffness`` / ``task_damping``).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from ..config.errors import ConfigError
from ..engine.launch import _Launch
from ..engine.parts import register_part
from ..engine.parts.ee import EEPart, ee_chain
from ..engine.parts.part import Part
from ..kernels import inertia
from ..kernels.dims import PER_ENV_BLOCK_DIM
from ..kernels.env_selection import MODE_SCALE, _bump_counter_kernel, _select
from ..kernels.spatial import Articulation
from . import warp_kernels
from .spec import DECOUPLE_NONE, ImpedanceSpec


def _specs(plan) -> dict:
    return {r0: v for r0, v in plan.ee_specs.items() if isinstance(v[2], ImpedanceSpec)}


@wp.kernel(enable_backward=False)
def _randomize_task_gains_kernel(
    seed: int,
    mode: int,  # env_selection.MODE_SCALE / MODE_ABS
    enabled: wp.vec2i,  # (stiffness, damping)
    lo: wp.vec2,
    hi: wp.vec2,
    # In:
    env_ids_in: wp.array[wp.int32],  # optional: thread block i draws for env env_ids_in[i]
    env_mask_in: wp.array[wp.bool],  # optional: only where True
    nominal_in: wp.array2d[float],  # (2, 6): the config's task stiffness and damping
    rng_counter_in: wp.array[wp.int32],  # (1,)
    # Out:
    task_kp_out: wp.array2d[float],  # (num_envs, 6)
    task_kd_out: wp.array2d[float],
):
    """An OSC controller's task gains: nominal * U(lo, hi) ("scale") or U(lo, hi) ("abs"), per env and axis, from a
    stream of their own (keyed by the seed, the draw counter and the env's axis)."""
    tid = wp.tid()
    env, k, i = _select(tid, 6, env_ids_in, env_mask_in, task_kp_out.shape[0])
    if env < 0:
        return
    key = wp.randi(wp.rand_init(seed, rng_counter_in[0]))
    state = wp.rand_init(key, 1000003 + env * 6 + k)
    for p in range(2):
        u = wp.randf(state)  # drawn for both, so that one's values do not depend on whether the other is drawn
        if enabled[p] != 0:
            x = lo[p] + (hi[p] - lo[p]) * u
            if mode == MODE_SCALE:
                x = nominal_in[p, k] * x
            if p == 0:
                task_kp_out[env, k] = x
            else:
                task_kd_out[env, k] = x


class _Unit:
    """The device side of one impedance controller (its rows ``row0 .. row0 + n``, action columns from ``col0``)."""

    def __init__(self, spec: ImpedanceSpec, engine, row0: int, col0: int, n: int):
        self.spec = spec
        self.engine = engine
        self.row0, self.col0, self.num_dof = row0, col0, n
        model, dev, E = engine.model, engine.device, engine.num_envs
        plan = engine.plan  # (a coupled drive is refused with effort rows when the plan is checked)
        b = engine.binding
        up = lambda a: wp.array(np.ascontiguousarray(a, np.int32), dtype=wp.int32, device=dev)  # noqa: E731
        self.row_q_off = up(b.q_off[row0 : row0 + n])
        self.row_qd_off = up(b.qd_off[row0 : row0 + n])
        self.gravity_on = bool(spec.gravity and not plan.options.balance_passive_force)
        needs_h = spec.decoupling != DECOUPLE_NONE or self.gravity_on
        layout, why = inertia.chain_layout(model, b.joint_index[:, row0 : row0 + n], b.dof_index[:, row0 : row0 + n])
        self.fused = None
        if layout is not None:
            self.fused = inertia.FusedChain(layout, model)
        elif needs_h:
            what = "inertial decoupling" if spec.decoupling != DECOUPLE_NONE else "gravity compensation"
            raise ConfigError(
                f"joint_names: {what} needs the mass matrix and gravity torque of a fixed-base articulation of "
                f"revolute / prismatic / fixed joints ({why}); turn it off for this robot"
            )
        f32 = lambda a: wp.array(np.asarray(a, np.float32), dtype=wp.float32, device=dev)  # noqa: E731
        self.target_lo = f32(spec.target_low)
        self.target_hi = f32(spec.target_high)
        self.damping_ratio = f32(spec.damping_ratio)
        self.posture = None if spec.nullspace_target is None else f32(spec.nullspace_target)
        if spec.osc:
            self.task_stiffness = wp.array(np.tile(spec.stiffness, (E, 1)), dtype=wp.float32, device=dev)
            self.task_damping = wp.array(np.tile(spec.damping, (E, 1)), dtype=wp.float32, device=dev)
        else:
            self.task_stiffness = self.task_damping = None
        gworld = model.gravity.shape[0]
        bworld = model.body_world.numpy()
        if self.fused is not None:
            w = bworld[model.joint_child.numpy()[self.fused.layout.env_joint_base]]
        else:
            w = np.zeros(E, np.int64)
        self.env_world = up(np.where(w < 0, gworld - 1, np.minimum(w, gworld - 1)))
        self._set_action = None
        self._torque = None

    # -- chain parameters (an OSC unit's EE chain; placeholders for joint impedance) ----------------------------------

    def chain_params(self) -> dict:
        return {"chain": ee_chain(self.engine.model)}

    def gain_arrays(self) -> tuple[wp.array, wp.array, int]:
        """Where the variable gains go: ``(kp, kd, first column)``."""
        drive = self.engine.part("drive_properties")
        return drive.kp, drive.kd, self.row0

    def _action_params(self) -> warp_kernels.ImpedanceAction:
        eng, s = self.engine, self.spec
        p = warp_kernels.ImpedanceAction()
        p.mode, p.use_delta, p.use_target = int(s.mode), int(s.use_delta), int(s.use_target)
        p.normalize, p.frame_bits, p.clip_targets = int(s.normalize), int(s.frame_bits), int(eng.plan.clip_targets)
        p.target_lo, p.target_hi, p.damping_ratio = self.target_lo, self.target_hi, self.damping_ratio
        p.rot_scale = wp.vec3(*(float(v) for v in s.rot_scale))
        p.kp_lo, p.kp_hi = (float(v) for v in s.stiffness_limits)
        p.ratio_lo, p.ratio_hi = (float(v) for v in s.damping_ratio_limits)
        p.row_qlo, p.row_qhi = eng.core.row_qlo, eng.core.row_qhi
        return p

    # -- stages ---------------------------------------------------------------------------------------------------

    def set_action(self, action: wp.array, state) -> None:
        eng, s = self.engine, self.spec
        if self._set_action is None:
            kp, kd, gain_off = self.gain_arrays()
            params = self.chain_params()
            params.update(
                row_q_off=self.row_q_off,
                env_q_base=eng.core.env_q_base,
                row0=self.row0,
                col0=self.col0,
                gain_col0=self.col0 + s.task_dim,
                gain_off=gain_off,
                p=self._action_params(),
                action_in=action,
                joint_q_in=state.joint_q,
                processed_action_out=eng.core.processed_action,
                target_pose_out=getattr(self, "target_pose", None),
                ee_pose_out=getattr(self, "ee_pose", None),
                target_qpos_out=eng.core.target_qpos,
                kp_out=kp,
                kd_out=kd,
            )
            kernel = warp_kernels.set_action_kernel(s.osc, self.num_dof)
            names = [a.label for a in kernel.adj.args]
            self._set_action = _Launch(
                kernel, eng.num_envs, {k: params[k] for k in names}, eng.device, block_dim=PER_ENV_BLOCK_DIM
            )
        self._set_action.bind("action_in", action)
        self._set_action.bind("joint_q_in", state.joint_q)
        self._set_action.launch()

    def torques(self, state) -> None:
        eng, s = self.engine, self.spec
        if self._torque is None:
            drive = eng.part("drive_properties")
            fused = self.fused
            params = self.chain_params()
            if fused is not None:
                params.update(fused.chain_args())
                row_dof = tuple(int(d) for d in fused.layout.row_dof)
                kernel = warp_kernels.torque_kernel(s.osc, self.num_dof, row_dof, fused.kernel_key())
            else:
                params["art"] = Articulation()  # no fused inertia pass: never read
                kernel = warp_kernels.torque_kernel(s.osc, self.num_dof, None, None)
            params.update(
                gravity_in=eng.model.gravity,
                env_world=self.env_world,
                row_q_off=self.row_q_off,
                row_qd_off=self.row_qd_off,
                env_q_base=eng.core.env_q_base,
                env_qd_base=eng.core.env_qd_base,
                row0=self.row0,
                decoupling=int(s.decoupling),
                gravity_on=int(self.gravity_on),
                nullspace_on=int(s.nullspace),
                singularity_damping=float(s.singularity_damping),
                task_kp=self.task_stiffness,
                task_kd=self.task_damping,
                kp=drive.kp,
                kd=drive.kd,
                posture=self.posture,
                joint_q_in=state.joint_q,
                joint_qd_in=state.joint_qd,
                target_pose_in=getattr(self, "target_pose", None),
                target_qpos_in=eng.core.target_qpos,
                target_effort_out=eng.part("effort_command").target_effort,
            )
            names = [a.label for a in kernel.adj.args]
            self._torque = _Launch(
                kernel, eng.num_envs, {k: params[k] for k in names}, eng.device, block_dim=PER_ENV_BLOCK_DIM
            )
        self._torque.bind("joint_q_in", state.joint_q)
        self._torque.bind("joint_qd_in", state.joint_qd)
        self._torque.launch()

    def reset(self, state, env_ids, env_mask) -> None:
        pass


class _OSCUnit(_Unit, EEPart):
    """An OSC controller: an :class:`EEPart` (its chain binding, ``target_pose``, ``ee_pose``, the EE reset) with the
    impedance launches."""

    def __init__(self, spec: ImpedanceSpec, engine, row0: int, col0: int, n: int):
        EEPart.__init__(self, spec, engine, row0, col0, n)
        _Unit.__init__(self, spec, engine, row0, col0, n)

    def chain_params(self) -> dict:
        return dict(self._chain_params)

    def gain_arrays(self) -> tuple[wp.array, wp.array, int]:
        return self.task_stiffness, self.task_damping, 0

    def set_action(self, action: wp.array, state) -> None:
        _Unit.set_action(self, action, state)

    def randomize_task(self, lo, hi, enabled, mode_abs: bool, seed: int, env_ids, env_mask) -> None:
        """Draw the task gains of the selected envs on the device (two launches: the draw, the counter bump)."""
        eng = self.engine
        dim = (eng.num_envs if env_ids is None else env_ids.shape[0]) * 6
        if dim == 0:
            return
        nominal = wp.array(np.stack([self.spec.stiffness, self.spec.damping]), dtype=wp.float32, device=eng.device)
        wp.launch(
            _randomize_task_gains_kernel,
            dim=dim,
            inputs=[
                int(seed),
                int(mode_abs),
                wp.vec2i(*enabled),
                wp.vec2(*lo),
                wp.vec2(*hi),
                env_ids,
                env_mask,
                nominal,
                eng.core.rng_counter,
                self.task_stiffness,
                self.task_damping,
            ],  # fmt: skip
            device=eng.device,
        )
        wp.launch(_bump_counter_kernel, dim=1, inputs=[eng.core.rng_counter], device=eng.device)

    def reset(self, state, env_ids, env_mask) -> None:
        """The measured EE pose becomes the target pose of the reset envs."""
        EEPart.reset(self, state, env_ids, env_mask, use_target=True)


class Impedance(Part):
    """The mode's impedance controllers (see the module docstring)."""

    name = "impedance"

    @staticmethod
    def wanted(plan) -> bool:
        return bool(_specs(plan))

    def __init__(self, plan, alloc):
        self.specs = _specs(plan)  # {first row: (first action column, rows, spec)}
        self.units: dict[int, _Unit] = {}

    def build(self, engine, model, solver) -> None:
        for row0, (col0, n, spec) in self.specs.items():
            cls = _OSCUnit if spec.osc else _Unit
            self.units[row0] = cls(spec, engine, row0, col0, n)

    def before_set_action(self, engine, action, state) -> None:
        for unit in self.units.values():
            unit.set_action(action, state)

    def before_substep(self, engine, state, control) -> None:
        for unit in self.units.values():
            unit.torques(state)

    def after_reset(self, engine, state, env_ids, env_mask) -> None:
        for unit in self.units.values():
            unit.reset(state, env_ids, env_mask)


register_part(Impedance)
