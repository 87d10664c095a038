"""Actuator models (explicit actuation) as an engine part, with the kernels that set and randomise their per-env
parameters.

:class:`ActuatorModels` holds the per-env DC-motor parameters (``saturation_effort`` / ``velocity_limit``, randomisable
like the drive properties) and the actuator networks: each network's rows get one launch after the substep kernel
(:mod:`wpctrl.kernels.actuator_net`), or run in the substep kernel's launch where their ``launch`` setting and the mode
allow it (:meth:`ActuatorModels.choose_launch`); a reset zeroes their history / hidden state. Position tables need no
part: they are compiled into the substep kernel (:mod:`wpctrl.kernels.actuator_models`).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from ...config import ConfigError
from ...config.actuator_models import ActuatorNet
from ...config.networks import read_network
from ...kernels import actuator_net, actuator_net_fused, actuator_net_mma, actuator_net_tiled, actuator_net_unrolled
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
        self.fused: _NetGroup | None = None  # the network run in the substep's launch (choose_launch)

    def kernel_args(self) -> dict:
        return {
            "sat_effort": self.sat_effort,
            "vel_limit": self.vel_limit,
        }

    def after_substep(self, engine, state, control) -> None:
        for net in self.nets:
            if net is not self.fused:
                net.launch(engine, state, control)

    def choose_launch(self, engine) -> None:
        """Decide, once the engine knows its hooks, whether the network runs in the substep kernel's launch
        (:mod:`wpctrl.kernels.actuator_net_fused`; ``ActuatorNet.launch``): ``"auto"`` where :meth:`fuse_reason` finds
        nothing against it, ``"fused"`` or a :class:`~wpctrl.config.ConfigError` with that reason, ``"separate"``
        never."""
        asked = [g.spec.launch for g in self.nets]
        if "separate" in asked or not asked:
            if "fused" in asked:
                raise ConfigError(
                    "actuator.launch: expected 'auto' or 'separate' (the mode's other network runs in a launch of "
                    "its own), got 'fused'"
                )
            return
        why = self.fuse_reason(engine)
        if why is None:
            self.fused = self.nets[0]
        elif "fused" in asked:
            raise ConfigError(f"actuator.launch: expected 'auto' or 'separate' for this network ({why}), got 'fused'")

    def fuse_reason(self, engine) -> str | None:
        """Why the mode's network cannot run in the substep kernel's launch, or None when it can: one network, with
        the unrolled kernel, the only launch after the substep's, its rows' targets neither interpolated nor
        delayed."""
        if len(self.nets) != 1:
            return f"the substep's launch takes one network, this mode has {len(self.nets)}"
        if self.nets[0].kernel_kind != "unrolled":
            return f"the substep's launch takes the unrolled kernel, this network runs the {self.nets[0].kernel_kind}"
        others = [p.name for p in engine._hooks["after_substep"] if p.name != self.name]
        if others:
            return f"the mode launches {', '.join(others)} after the substep"
        reason = actuator_net_fused.fusable(engine.layout, self.nets[0].row0, self.nets[0].n)
        return None if reason is None else f"not with {reason}"

    def substep_launch(self, engine) -> tuple | None:
        """``(kernel, dim, block_dim, parameters)`` of the substep's launch with the network in it, or None."""
        g = self.fused
        if g is None:
            return None
        kernel = actuator_net_fused.fused_kernel(engine.layout, g.layout, g.weights, g.scales)
        per_call = {"row0": g.row0, "io": g.io(engine), "hist_out": g._extra["hist_out"]}
        return kernel, engine.num_envs * (1 + g.n), actuator_net_fused.BLOCK_DIM, per_call

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
    """One ActuatorNet's rows: its kernel (weights compiled in, or staged per block in shared memory; see
    :mod:`wpctrl.kernels.actuator_net`), its per-env state and its launch."""

    def __init__(self, plan, alloc, row0: int, n: int, spec: ActuatorNet):
        self.row0, self.n, self.spec = row0, n, spec
        net = read_network(spec)
        E, dev = plan.num_envs, alloc.device
        taps = tuple(int(i) for i in spec.input_idx) if net.kind == "mlp" else ()
        self.layout = actuator_net.NetLayout(
            dense=net.dense,
            lstm=net.lstm,
            taps=taps,
            history=(max(taps) + 1) if taps else 0,
            pos_first=spec.input_order == "pos_vel",
            rows=n,
            q_lin=_consecutive(plan.q_idx, plan.strided, row0, n),
            qd_lin=_consecutive(plan.qd_idx, plan.strided, row0, n),
        )
        cpu = wp.get_device(dev).is_cpu
        arch = 0 if cpu else wp.get_device(dev).arch
        self.kernel_kind = actuator_net.choose_kernel(self.layout, spec.kernel, arch)
        extra = {}
        if self.kernel_kind == "tiled":
            wmat, bias = actuator_net_tiled.pack(self.layout, net.weights)
            if wmat.size + bias.size > actuator_net.TILED_MAX_WEIGHTS:
                most = actuator_net.TILED_MAX_WEIGHTS
                raise ConfigError(
                    f"actuator.network: {net.weights.size} weights and biases; the tiled kernel holds at most {most} "
                    f"(as {wmat.shape[0]} x {wmat.shape[1]} matrices and {bias.size} biases) in a block's shared memory"
                )
            # On the CPU a block is one thread (a tile one row), unless Warp's cooperative CPU blocks are on.
            self.block_dim = 1 if cpu and not wp.config.enable_cpu_blocks else actuator_net_tiled.BLOCK_DIM
            tiles = -(-E * n // self.block_dim)
            sms = 1 if cpu else wp.get_device(dev).sm_count
            self.blocks = max(1, min(tiles, 8 * sms))
            extra = {
                "weight_tiles": wp.array(wmat, dtype=wp.float32, device=dev),
                "biases": wp.array(bias, dtype=wp.float32, device=dev),
                "num_rows": E * n,
                "num_tiles": tiles,
                "num_blocks": self.blocks,
            }
            self.kernel = actuator_net_tiled.tiled_kernel(self.layout, self.block_dim)
        hist_shape, state_shape = self.layout.state_shapes(E)
        self.hist = wp.zeros(hist_shape, dtype=wp.float32, device=dev)
        self.lstm_h = wp.zeros(state_shape, dtype=wp.float32, device=dev)
        self.lstm_c = wp.zeros(state_shape, dtype=wp.float32, device=dev)
        scales = (spec.pos_scale, spec.vel_scale, spec.torque_scale)
        self.weights, self.scales = net.weights, scales
        if self.kernel_kind == "unrolled":
            self.kernel = actuator_net_unrolled.unrolled_kernel(self.layout, net.weights, scales)
            extra = {"hist_out": actuator_net_unrolled.history_vectors(self.hist)}
        elif self.kernel_kind == "3xtf32":
            _check_mma(self.layout, dev)
            self.kernel = actuator_net_mma.mma_kernel(self.layout, scales)
            wfrag, bfrag = actuator_net_mma.pack(self.layout, net.weights)
            extra = {
                "hist_out": actuator_net_unrolled.history_vectors(self.hist),
                "wfrag": wp.array(wfrag.reshape(-1, 4), dtype=wp.vec4, device=dev),
                "bfrag": wp.array(bfrag.reshape(-1, 2), dtype=wp.vec2, device=dev),
                "num_rows": E * n,
            }
        else:
            extra["hist_out"] = self.hist
        self._extra = extra
        self._launch: _Launch | None = None

    def io(self, engine) -> actuator_net.NetIO:
        """The network kernels' ``io`` argument: the mode's index tables, the rows' limits, the LSTM state and the
        effort readout."""
        effort = engine.part("effort_readout")
        c, models = engine.core, engine.part("actuator_models")
        io = actuator_net.NetIO()
        io.q_idx, io.qd_idx, io.q_stride, io.qd_stride = c.q_idx, c.qd_idx, c.q_stride, c.qd_stride
        io.force_limit = engine.part("drive_properties").force_limit
        io.sat_effort, io.vel_limit = models.sat_effort, models.vel_limit
        io.lstm_h, io.lstm_c = self.lstm_h, self.lstm_c
        if effort is not None:
            io.computed_effort, io.applied_effort = effort.computed_effort, effort.applied_effort
            io.saturation_count = effort.saturation_count
        return io

    def launch(self, engine, state, control) -> None:
        if self._launch is None:
            s = self.spec
            per_call = {
                "row0": self.row0,
                "io": self.io(engine),
                "pos_scale": float(s.pos_scale),
                "vel_scale": float(s.vel_scale),
                "torque_scale": float(s.torque_scale),
                "joint_q_in": state.joint_q,
                "joint_qd_in": state.joint_qd,
                "joint_target_q_in": control.joint_target_q,
                "joint_f_out": control.joint_f,
                **self._extra,
            }
            if self.kernel_kind == "tiled":
                dim, block_dim = (self.blocks, self.block_dim), self.block_dim
            elif self.kernel_kind == "3xtf32":
                dim, block_dim = actuator_net_mma.launch_dim(engine.num_envs * self.n), actuator_net_mma.BLOCK_DIM
            else:
                dim, block_dim = engine.num_envs * self.n, actuator_net_unrolled.BLOCK_DIM
            self._launch = engine._launch(self.kernel, dim, per_call, block_dim)
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
            inputs=[engine.num_envs, self.n, env_ids, env_mask, self.hist, self.lstm_h, self.lstm_c],
            device=engine.device,
        )


def _check_mma(layout, device) -> None:
    """Refuse what the tensor-core kernel cannot run: an LSTM or too wide a layer, a GPU older than sm_80."""
    why = actuator_net.mma_unsupported(layout)
    if why is not None:
        raise ConfigError(f"actuator.kernel: expected another kernel than '3xtf32' for {why}, got '3xtf32'")
    d = wp.get_device(device)
    if d.is_cuda and d.arch < actuator_net.MMA_MIN_SM:
        raise ConfigError(
            f"actuator.kernel: '3xtf32' needs TF32 tensor cores (sm_{actuator_net.MMA_MIN_SM} or later), "
            f"got {d.name} (sm_{d.arch})"
        )


def _consecutive(idx: np.ndarray, strided: bool, row0: int, n: int) -> int:
    """Env 0's first index of the rows ``row0 .. row0 + n`` when the layout is replicated and they are consecutive
    (the network kernel then computes each row's index), else -1 (it reads the table)."""
    if not strided:
        return -1
    first = int(idx[0, row0])
    return first if np.array_equal(idx[0, row0 : row0 + n], first + np.arange(n)) else -1
