"""Actuator models (explicit actuation) as an engine part, with the kernels that set and randomise their per-env
parameters.

:class:`ActuatorModels` holds the per-env DC-motor parameters (``saturation_effort`` / ``velocity_limit``, randomisable
like the drive properties) and the actuator networks: each network's rows get one launch after the substep kernel
(:mod:`wpctrl.kernels.actuator_net`), and a reset zeroes their history / hidden state. Position tables need no part:
they are compiled into the substep kernel (:mod:`wpctrl.kernels.actuator_models`).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from ...config.actuator_models import ActuatorNet
from ...config.networks import read_network
from ...kernels import actuator_net
from ...kernels.env_selection import MODE_SCALE, _bump_counter_kernel, _select
from ..launch import _Launch
from .part import Part

wp.set_module_options({"enable_backward": False})

ACTUATOR_FIELDS = ("saturation_effort", "velocity_limit")
"""The per-env actuator-model parameters, in the order of their RNG streams."""


@wp.kernel
def _set_rows_kernel(
    row0: int,
    num_rows: int,
    env_ids_in: wp.array[wp.int32],  # optional
    env_mask_in: wp.array[wp.bool],  # optional
    values_in: wp.array2d[float],  # (1 | len(env_ids) | num_envs, num_rows): row 0 broadcasts
    # Out:
    param_out: wp.array2d[float],  # (num_envs, rows) a per-env parameter without a model mirror
):
    """Copy given values into a per-env parameter (an actuator model's) for the selected envs."""
    tid = wp.tid()
    env, rl, i = _select(tid, num_rows, env_ids_in, env_mask_in, param_out.shape[0])
    if env < 0:
        return
    b = 0
    if values_in.shape[0] > 1:
        b = i
        if env_mask_in:
            b = env
    param_out[env, row0 + rl] = values_in[b, rl]


@wp.kernel
def _randomize_rows_kernel(
    row0: int,
    num_rows: int,
    seed: int,
    stream: int,  # a stream per parameter: its draws do not depend on which others are drawn
    mode: int,
    lo: float,
    hi: float,
    env_ids_in: wp.array[wp.int32],  # optional
    env_mask_in: wp.array[wp.bool],  # optional
    nominal_in: wp.array[float],  # (rows,) the config's values
    rng_counter_in: wp.array[wp.int32],  # (1,)
    # Out:
    param_out: wp.array2d[float],  # (num_envs, rows)
):
    """value = nominal * U(lo, hi) ("scale") or U(lo, hi) ("abs"), as
    :func:`wpctrl.engine.parts.drive_properties._randomize_drive_kernel`."""
    tid = wp.tid()
    env, rl, i = _select(tid, num_rows, env_ids_in, env_mask_in, param_out.shape[0])
    if env < 0:
        return
    r = row0 + rl
    key = wp.randi(wp.rand_init(seed, rng_counter_in[0]))
    state = wp.rand_init(key + stream * 7919, env * param_out.shape[1] + r)
    x = lo + (hi - lo) * wp.randf(state)
    if mode == MODE_SCALE:
        x = nominal_in[r] * x
    param_out[env, r] = x


class ActuatorModels(Part):
    name = "actuator_models"
    OPTIONAL_ARGS = ("sat_effort", "vel_limit")

    @staticmethod
    def wanted(plan) -> bool:
        return plan.has_actuator_models

    def __init__(self, plan, alloc):
        rows = plan.rows
        R = plan.num_rows
        self.sat_effort = alloc.per_env(R, fill=rows.sat_effort)
        self.vel_limit = alloc.per_env(R, fill=rows.vel_limit)
        self.nominal = alloc.up(np.stack([rows.sat_effort, rows.vel_limit]).reshape(2, R), wp.float32)
        self.nets = [
            _NetGroup(plan, alloc, r0, n, spec) for r0, n, spec in rows.extras if isinstance(spec, ActuatorNet)
        ]

    def kernel_args(self) -> dict:
        return {
            "sat_effort": self.sat_effort,
            "vel_limit": self.vel_limit,
        }

    def after_substep(self, engine, state, control) -> None:
        for net in self.nets:
            net.launch(engine, state, control)

    def after_reset(self, engine, state, env_ids, env_mask) -> None:
        for net in self.nets:
            net.reset(engine, env_ids, env_mask)

    # -- per-env parameters ------------------------------------------------------------------------------------------

    def set(self, engine, values: np.ndarray, enabled, env_ids, env_mask, row0: int, num_rows: int) -> None:
        """Copy ``values`` (2, 1 | selected | num_envs, num_rows) into the enabled parameters' rows."""
        dev_values = wp.array(values.astype(np.float32), dtype=wp.float32, device=engine.device)
        dim = (engine.num_envs if env_ids is None else env_ids.shape[0]) * num_rows
        for p, arr in enumerate((self.sat_effort, self.vel_limit)):
            if enabled[p] and dim:
                wp.launch(
                    _set_rows_kernel,
                    dim=dim,
                    inputs=[row0, num_rows, env_ids, env_mask, dev_values[p], arr],
                    device=engine.device,
                )

    def randomize(self, engine, lo, hi, enabled, mode_abs: bool, seed: int, env_ids, env_mask, row0, num_rows) -> None:
        """Draw the enabled parameters on the device (the drive properties' RNG scheme, streams of their own)."""
        c = engine.core
        dim = (engine.num_envs if env_ids is None else env_ids.shape[0]) * num_rows
        if not dim:
            return
        for p, arr in enumerate((self.sat_effort, self.vel_limit)):
            if enabled[p]:
                wp.launch(
                    _randomize_rows_kernel,
                    dim=dim,
                    inputs=[row0, num_rows, int(seed), 4 + p, int(mode_abs), float(lo[p]), float(hi[p]), env_ids,
                            env_mask, self.nominal[p], c.rng_counter, arr],
                    device=engine.device,
                )  # fmt: skip
        wp.launch(_bump_counter_kernel, dim=1, inputs=[c.rng_counter], device=engine.device)


class _NetGroup:
    """One ActuatorNet's rows: its weights, its per-env state and its launch."""

    def __init__(self, plan, alloc, row0: int, n: int, spec: ActuatorNet):
        self.row0, self.n, self.spec = row0, n, spec
        net = read_network(spec)
        E, dev = plan.num_envs, alloc.device
        taps = tuple(int(i) for i in spec.input_idx) if net.kind == "mlp" else ()
        history = (max(taps) + 1) if taps else 0
        self.layout = actuator_net.NetLayout(
            dense=net.dense, lstm=net.lstm, taps=taps, history=history, pos_first=spec.input_order == "pos_vel", rows=n
        )
        self.weights = wp.array(net.weights, dtype=wp.float32, device=dev)
        widths = [d[1] for d in net.dense] + [4 * s[1] for s in net.lstm]
        self.layer_out = wp.array(np.asarray(widths, np.int32), dtype=wp.int32, device=dev)
        self.hist_pos = wp.zeros((max(history, 1), E * n), dtype=wp.float32, device=dev)
        self.hist_vel = wp.zeros((max(history, 1), E * n), dtype=wp.float32, device=dev)
        layers, hidden = (len(net.lstm), net.lstm[0][1]) if net.lstm else (1, 1)
        self.lstm_h = wp.zeros((layers, E * n, hidden), dtype=wp.float32, device=dev)
        self.lstm_c = wp.zeros((layers, E * n, hidden), dtype=wp.float32, device=dev)
        self._launch: _Launch | None = None

    def launch(self, engine, state, control) -> None:
        if self._launch is None:
            s = self.spec
            effort = engine.part("effort_readout")
            per_call = {
                "row0": self.row0,
                "weights": self.weights,
                "layer_out": self.layer_out,
                "pos_scale": float(s.pos_scale),
                "vel_scale": float(s.vel_scale),
                "torque_scale": float(s.torque_scale),
                "joint_q_in": state.joint_q,
                "joint_qd_in": state.joint_qd,
                "joint_target_q_in": control.joint_target_q,
                "hist_pos_out": self.hist_pos,
                "hist_vel_out": self.hist_vel,
                "lstm_h_out": self.lstm_h,
                "lstm_c_out": self.lstm_c,
                "joint_f_out": control.joint_f,
                "computed_effort_out": None if effort is None else effort.computed_effort,
                "applied_effort_out": None if effort is None else effort.applied_effort,
                "saturation_count_out": None if effort is None else effort.saturation_count,
            }
            self._launch = engine._launch(actuator_net.net_kernel(self.layout), (engine.num_envs, self.n), per_call)
        ln = self._launch
        ln.bind("joint_q_in", state.joint_q)
        ln.bind("joint_qd_in", state.joint_qd)
        ln.bind("joint_target_q_in", control.joint_target_q)
        ln.bind("joint_f_out", control.joint_f)
        ln.launch()

    def reset(self, engine, env_ids, env_mask) -> None:
        dim = engine.num_envs if env_ids is None else env_ids.shape[0]
        if dim == 0:
            return
        wp.launch(
            actuator_net._reset_state_kernel,
            dim=(dim, self.n),
            inputs=[engine.num_envs, self.n, env_ids, env_mask, self.hist_pos, self.hist_vel, self.lstm_h, self.lstm_c],
            device=engine.device,
        )
