"""Learned actuators in Warp: an MLP over a history of position errors and velocities, or an LSTM, per env and joint.

Private module. A network's rows run in one launch after the substep kernel (the network's position target is that
substep's, interpolated and delayed as the targets of any other row). Each thread of the launch is one (env, joint)
row: it gathers ``joint_q`` / ``joint_qd`` / ``joint_target_q``, advances the history (or the recurrent state),
evaluates the network, applies the DC-motor envelope and the force limit, and writes ``joint_f`` and the effort
readout; no intermediate row buffer leaves the thread (or, in the tiled and tensor-core kernels, the block's shared
memory and the warp's registers). Three kernels evaluate the network, all compiled for its shape:

- :mod:`.actuator_net_unrolled` (networks of up to :data:`UNROLLED_MAX_MACS` multiply-adds per row): the weights are
  compiled into the kernel as immediate operands, so each multiply-add is one fused multiply-add instruction with no
  load, no shared memory and no block synchronisation. The kernel is compiled per network (its weights are part of
  it).
- :mod:`.actuator_net_mma` (MLPs of layers up to :data:`MMA_MAX_WIDTH` wide, CUDA sm_80 or later): one warp per
  32 rows, each layer a warp-wide tensor-core product at float32 accuracy (3xTF32). The weights are data. What
  ``"auto"`` runs for an MLP past :data:`UNROLLED_MAX_MACS` on such a GPU.
- :mod:`.actuator_net_tiled` (any size up to :data:`TILED_MAX_WEIGHTS` weights): the weights are staged once per
  block in shared memory (``wp.tile_load``), each block evaluates tiles of rows as matrix products
  (``wp.tile_matmul``), one tile per block pass. Compiled per network shape; the weights are data. What ``"auto"``
  runs past :data:`UNROLLED_MAX_MACS` where the tensor-core kernel does not apply (an LSTM, a layer wider than
  :data:`MMA_MAX_WIDTH`, a GPU before sm_80, the CPU).

:func:`read_row` gathers a row's inputs and :func:`write_effort` writes its effort, for every kernel; the unrolled
kernel's MLP input code (:func:`.actuator_net_unrolled.mlp_row_input`) also feeds the tensor-core kernel.

The MLP's past samples are one ``(num_envs * rows, 2 * past)`` array, a row's position errors then velocities, newest
first (the unrolled kernel reads and writes a row's as one vector); the LSTM's ``h`` and ``c`` are ``(layers * hidden,
num_envs * rows)`` arrays, so that a warp's loads of one unit are one coalesced line.

Activation codes: 0 identity, 1 ReLU, 2 ELU(a), 3 tanh, 4 sigmoid, 5 softsign, 6 LeakyReLU(a).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import warp as wp

from .actuator_models import dc_motor_clamp
from .pd import _at

wp.set_module_options({"enable_backward": False})

ACT_IDENTITY, ACT_RELU, ACT_ELU, ACT_TANH, ACT_SIGMOID, ACT_SOFTSIGN, ACT_LEAKY = range(7)

UNROLLED_MAX_MACS = 4096
"""The largest network (multiply-adds per row) that ``kernel="auto"`` compiles with its weights in the code: each
multiply-add is a 16-byte instruction, and past ~64 KB of straight-line code the instruction caches stop holding the
kernel."""

TILED_MAX_WEIGHTS = 16384
"""The most weights and biases the tiled kernel stages in a block's shared memory (64 KB of float32)."""


class NetLayout(NamedTuple):
    """What a network kernel is compiled for. ``dense``: ``(in, out, activation code, activation parameter, weight
    offset, bias offset)`` per Linear layer after the input (MLP) or after the LSTM (its head). ``lstm``: ``(in,
    hidden, W_ih offset, W_hh offset, b_ih offset, b_hh offset)`` per LSTM layer (empty for an MLP). ``taps``: the MLP
    history indices (``input_idx``); ``history``: its length; ``pos_first``: input order ``pos_vel``; ``rows``: the
    joints it drives; ``q_lin`` / ``qd_lin``: in a replicated layout whose network rows are consecutive coordinates
    (DOFs) of each env, env 0's first one (the kernel then computes the index instead of reading a table), else -1."""

    dense: tuple
    lstm: tuple
    taps: tuple
    history: int
    pos_first: bool
    rows: int
    q_lin: int = -1
    qd_lin: int = -1

    @property
    def macs(self) -> int:
        """Multiply-adds per row."""
        n = sum(d[0] * d[1] for d in self.dense)
        return n + sum(4 * s[1] * (s[0] + s[1]) for s in self.lstm)

    @property
    def past(self) -> int:
        """MLP history slots kept between substeps (the current sample is not stored)."""
        return max(self.history - 1, 0)

    def state_shapes(self, num_envs: int) -> tuple[tuple[int, int], tuple[int, int]]:
        """Shapes of the history array ``(num_envs * rows, 2 * past)`` and of the LSTM state arrays (h and c)
        ``(layers * hidden, num_envs * rows)``, at least one slot each (Warp indexes no empty dimension)."""
        s = num_envs * self.rows
        units = sum(x[1] for x in self.lstm)
        return (s, max(2 * self.past, 1)), (max(units, 1), s)


MMA_MAX_WIDTH = 128
"""The widest layer (inputs or units, padded to a multiple of 8) the tensor-core kernel takes: its operand and
accumulator fragments live in registers."""

MMA_MIN_SM = 80
"""The oldest CUDA architecture with TF32 tensor cores (sm_80)."""


def mma_unsupported(layout: NetLayout) -> str | None:
    """Why ``layout`` cannot run on the tensor-core kernel (:mod:`.actuator_net_mma`), or None: it takes MLPs (no
    LSTM) of layers up to :data:`MMA_MAX_WIDTH` wide."""
    if layout.lstm:
        return "an LSTM (this kernel runs MLPs)"
    widest = max(-(-int(w) // 8) * 8 for d in layout.dense for w in d[:2])
    if widest > MMA_MAX_WIDTH:
        return f"a layer {widest} wide (padded to 8; at most {MMA_MAX_WIDTH})"
    return None


def choose_kernel(layout: NetLayout, kernel: str, cuda_arch: int = 0) -> str:
    """``"unrolled"``, ``"3xtf32"`` or ``"tiled"`` for ``kernel`` (``"auto"`` or a kernel's name) on a device of
    ``cuda_arch`` (0: the CPU). ``"auto"``: the unrolled kernel up to :data:`UNROLLED_MAX_MACS` multiply-adds per row
    (measured faster than the others there); past that the tensor-core kernel for an MLP it takes on sm_80 or later
    (measured 5-7x faster than the tiled kernel on an H100), else the tiled one."""
    if kernel == "auto":
        if layout.macs <= UNROLLED_MAX_MACS:
            return "unrolled"
        return "3xtf32" if cuda_arch >= MMA_MIN_SM and mma_unsupported(layout) is None else "tiled"
    return kernel


def dense_matrices(layout: NetLayout, weights: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, int, float]]:
    """``(W (out, in), b (out,), activation code, parameter)`` of each Linear layer, float32."""
    out = []
    for n_in, n_out, code, a, wo, bo in layout.dense:
        w = weights[wo : wo + n_in * n_out].reshape(n_out, n_in)
        out.append((w, weights[bo : bo + n_out], int(code), float(a)))
    return out


def lstm_matrices(layout: NetLayout, weights: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """``(W_ih (4H, in), W_hh (4H, H), b_ih + b_hh (4H,))`` of each LSTM layer, float32 (the biases added once, in
    float32)."""
    out = []
    for n_in, h, wih, whh, bih, bhh in layout.lstm:
        g = 4 * h
        w_ih = weights[wih : wih + g * n_in].reshape(g, n_in)
        w_hh = weights[whh : whh + g * h].reshape(g, h)
        out.append((w_ih, w_hh, (weights[bih : bih + g] + weights[bhh : bhh + g]).astype(np.float32)))
    return out


def net_kernel(f, name: str, grid_stride: bool | None = None, **module_options) -> wp.Kernel:
    """``f`` as a network kernel named ``name``: a module of its own (each kernel is compiled for one network or
    shape), no backward pass, fast math and ``module_options``; ``grid_stride=False`` for a launch of exactly one
    thread per row (or lane)."""
    return wp.kernel(f, name=name, enable_backward=False, grid_stride=grid_stride, module="unique",
                     module_options={"fast_math": True, **module_options})  # fmt: skip


# -- elementwise functions. The network kernels are compiled with fast math on CUDA, where exp is ``ex2.approx`` of a
# scaled argument and a division one reciprocal and one multiply (2 ulp each); exact on the CPU. --------------------


@wp.func
def sigmoid(x: float):
    return 1.0 / (1.0 + wp.exp(-x))


@wp.func
def tanh(x: float):
    """``1 - 2 / (exp(2x) + 1)``: five instructions with fast math instead of the library's tanh; within ~3e-7 of it
    (absolute), exactly +-1 at large |x|."""
    return 1.0 - 2.0 / (wp.exp(2.0 * x) + 1.0)


@wp.func
def activate(x: float, code: int, a: float):
    if code == ACT_RELU:
        return wp.max(x, 0.0)
    if code == ACT_ELU:
        if x > 0.0:
            return x
        return a * (wp.exp(x) - 1.0)
    if code == ACT_TANH:
        return tanh(x)
    if code == ACT_SIGMOID:
        return sigmoid(x)
    if code == ACT_SOFTSIGN:
        return x / (1.0 + wp.abs(x))
    if code == ACT_LEAKY:
        if x > 0.0:
            return x
        return a * x
    return x


@wp.func
def lstm_cell(ig: float, fg: float, cg: float, og: float, c: float):
    """PyTorch's LSTM cell from the gate pre-activations (input, forget, cell, output): ``(h, c)``."""
    c_new = sigmoid(fg) * c + sigmoid(ig) * tanh(cg)
    return sigmoid(og) * tanh(c_new), c_new


@wp.struct
class NetIO:
    """What a network's kernel reads and writes besides Newton's state and Control (one argument instead of twelve,
    shared by both kernels): where each row's coordinate and DOF are (the mode's index tables), the rows' force limit
    and DC-motor envelope (per env), the LSTM's state (in/out) and the effort readout (optional). Filled by the
    actuator-model part (:mod:`wpctrl.engine.parts.actuator_models`)."""

    q_idx: wp.array2d[wp.int32]  # (1 | num_envs, rows) the mode's coordinate index table
    qd_idx: wp.array2d[wp.int32]  # its DOF index table
    q_stride: int  # a replicated layout's coordinate stride per env (0: per-env tables)
    qd_stride: int
    force_limit: wp.array2d[float]  # (num_envs, rows) [N·m or N]
    sat_effort: wp.array2d[float]  # DC-motor envelope [N·m or N] (inf: none)
    vel_limit: wp.array2d[float]  # [rad/s or m/s] (inf: none)
    lstm_h: wp.array2d[float]  # in/out (layers * hidden, num_envs * n)
    lstm_c: wp.array2d[float]
    computed_effort: wp.array2d[float]  # optional (effort readout) [N·m or N]
    applied_effort: wp.array2d[float]
    saturation_count: wp.array2d[wp.int32]


@wp.func
def row_index(io: NetIO, q_lin: int, qd_lin: int, env: int, r: int, j: int):
    """Row ``r`` (the network's ``j``-th) of ``env``: its coordinate and DOF index. ``q_lin`` / ``qd_lin`` (>= 0): the
    network's rows are consecutive coordinates / DOFs of env 0 from there (the index is computed, no table read)."""
    qi = q_lin + j + env * io.q_stride
    if q_lin < 0:
        qi = _at(io.q_idx, io.q_stride, env, r)
    di = qd_lin + j + env * io.qd_stride
    if qd_lin < 0:
        di = _at(io.qd_idx, io.qd_stride, env, r)
    return qi, di


@wp.func
def read_row(
    io: NetIO,
    q_lin: int,
    qd_lin: int,
    env: int,
    r: int,
    j: int,
    joint_q_in: wp.array[float],
    joint_qd_in: wp.array[float],
):
    """What a network row reads besides its position target, all before the network so that the loads are in flight
    together: its coordinate and DOF index (:func:`row_index`'s), position and velocity, force limit and DC-motor
    envelope (saturation effort, velocity limit). The caller reads the target (at the coordinate index) and forms the
    position error ``q* - q``."""
    qi, di = row_index(io, q_lin, qd_lin, env, r, j)
    return qi, di, joint_q_in[qi], joint_qd_in[di], io.force_limit[env, r], io.sat_effort[env, r], io.vel_limit[env, r]


@wp.func
def write_effort(
    u: float,
    qd: float,
    env: int,
    r: int,
    di: int,
    lim: float,
    sat: float,
    vl: float,
    joint_f_out: wp.array[float],
    io: NetIO,
):
    """The computed effort ``u`` through the DC-motor envelope (``sat``, ``vl``) and the force limit ``lim`` into
    ``joint_f`` (and the effort readout when it is on). The kernels read the row's parameters with its other inputs,
    before the network: a load here would put one more memory round trip after it."""
    f = dc_motor_clamp(u, qd, sat, vl, lim)
    joint_f_out[di] = f
    if io.computed_effort:
        io.computed_effort[env, r] = u
        io.applied_effort[env, r] = f
        if f != u:
            io.saturation_count[env, r] = io.saturation_count[env, r] + 1


@wp.kernel
def _reset_state_kernel(
    num_envs: int,
    n: int,  # the network's rows
    env_ids_in: wp.array[wp.int32],  # optional: thread row i resets env env_ids_in[i]
    env_mask_in: wp.array[wp.bool],  # optional
    # Out:
    hist_out: wp.array2d[float],  # (num_envs * n, k)
    lstm_h_out: wp.array2d[float],  # (k, num_envs * n)
    lstm_c_out: wp.array2d[float],
):
    """Zero the reset envs' history and recurrent state (as Isaac Lab's actuator nets do). Launched over
    ``(selected envs, n)``."""
    i, j = wp.tid()
    env = i
    if env_ids_in:
        env = env_ids_in[i]
    if env < 0 or env >= num_envs:
        return
    if env_mask_in:
        if not env_mask_in[env]:
            return
    s = env * n + j
    for k in range(hist_out.shape[1]):
        hist_out[s, k] = 0.0
    for k in range(lstm_h_out.shape[0]):
        lstm_h_out[k, s] = 0.0
        lstm_c_out[k, s] = 0.0
