"""The actuator-network kernel with the weights compiled in: one thread per (env, joint) row, every layer unrolled.

Private module (see :mod:`.actuator_net`). Each weight is an immediate operand of its fused multiply-add and each
bias the start of its accumulator, so a layer of ``out x in`` weights is ``out x in`` instructions per row with no
load, and the row's inputs and activations stay in registers from the gather to the ``joint_f`` write (a 6-32-32-1
MLP compiles to 1,248 FFMA in 1,785 instructions and 80 registers on sm_90, no local memory). Only the row's own
state moves through device memory, all of it read before the network. The kernel is compiled for the network's
weights: a new network is a new kernel (a few seconds). Compiled with fast math on CUDA: ``exp`` and the
activations' divisions are the approximate ones (a few ulp).
"""

from __future__ import annotations

import hashlib

import numpy as np
import warp as wp

from . import actuator_net
from .actuator_net import NetIO, NetLayout, activate, dense_matrices, lstm_cell, lstm_matrices, read_row, write_effort

wp.set_module_options({"enable_backward": False})

BLOCK_DIM = 64
"""CUDA threads per block: at 4,096 Pandas (28,672 arm rows) 448 blocks spread over every SM."""

_KERNELS: dict[tuple, tuple[wp.Function, wp.Kernel]] = {}


def unrolled_kernel(layout: NetLayout, weights: np.ndarray, scales: tuple[float, float, float]) -> wp.Kernel:
    """The kernel of ``layout`` with ``weights`` (the flat float32 array of :func:`wpctrl.config.networks.read_network`)
    and ``scales`` (``pos_scale``, ``vel_scale``, ``torque_scale``, float32 values; a scale of 1 is no multiply)
    compiled in. Launched over ``num_envs * layout.rows`` threads; the history is a vector array aliasing the
    ``(num_envs * rows, 2 * past)`` one (:func:`history_vectors`)."""
    return _unrolled(layout, weights, scales)[1]


def unrolled_row(layout: NetLayout, weights: np.ndarray, scales: tuple[float, float, float]) -> wp.Function:
    """The unrolled kernel's network as a function of one row, forced inline: ``(s, env, r, di, err, qd, lim, sat,
    vl, io, hist_out, joint_f_out)``, the row's inputs as :func:`.actuator_net.read_row` reads them. For kernels
    that run the network's rows beside other work in one launch (:mod:`.actuator_net_fused`)."""
    return _unrolled(layout, weights, scales)[0]


def _unrolled(layout: NetLayout, weights: np.ndarray, scales: tuple[float, float, float]):
    w = np.ascontiguousarray(weights, dtype=np.float32)
    scales = tuple(float(np.float32(x)) for x in scales)
    key = (layout, w.tobytes(), scales)
    k = _KERNELS.get(key)
    if k is None:
        k = _KERNELS[key] = _make(layout, w, scales)
    return k


def history_vectors(hist: wp.array) -> wp.array:
    """The ``(num_envs * rows, 2 * past)`` history array as a ``(num_envs * rows,)`` array of vectors (the same memory:
    keep ``hist`` alive with it), so that a row's samples are one load with constant offsets."""
    vec = wp.types.vector(length=hist.shape[1], dtype=wp.float32)
    return wp.array(ptr=hist.ptr, dtype=vec, shape=(hist.shape[0],), device=hist.device)


@wp.func
def _scaled(x: float, scale: float):
    """``x * scale``; with a compile-time 1, no instruction."""
    if scale == 1.0:
        return x
    return x * scale


def _floats(a) -> tuple:
    """A float32 array as nested tuples of Python floats (each exactly the float32 value)."""
    a = np.asarray(a, np.float32)
    if a.ndim == 0:
        return float(a)
    return tuple(_floats(x) for x in a)


def mlp_row_input(L: NetLayout, scales: tuple[float, float], vec_x) -> wp.Function:
    """An MLP row's input vector, as a function ``(s, err, qd, hist_out) -> x`` of the row ``s``, its position error
    and velocity and the history (the vector array of :func:`history_vectors`): ``x`` (``vec_x``) holds the samples at
    the network's taps, scaled by ``scales`` (``pos_scale``, ``vel_scale``), in the network's order, zero past them;
    the row's history advances by one substep in place (the current sample becomes the newest past one)."""
    TAPS, POS_FIRST, PAST = L.taps, bool(L.pos_first), L.past
    PS, VS = (float(np.float32(x)) for x in scales)
    T = len(TAPS)
    vec_t = wp.types.vector(length=max(L.history, 1), dtype=wp.float32)
    vec_p = wp.types.vector(length=max(2 * PAST, 1), dtype=wp.float32)
    POS_AT = tuple((t if POS_FIRST else T + t) for t in range(T))
    VEL_AT = tuple((T + t if POS_FIRST else t) for t in range(T))

    def row_x(s: int, err: float, qd: float, hist_out: wp.array[vec_p]):
        x = vec_x()
        # The history, newest first (Isaac Lab rolls it and writes the current sample at index 0).
        hp = vec_t()
        hv = vec_t()
        hp[0] = err
        hv[0] = qd
        old = vec_p()
        if wp.static(PAST > 0):
            old = hist_out[s]
        new = vec_p()
        for k in range(wp.static(PAST)):
            hp[k + 1] = old[k]
            hv[k + 1] = old[wp.static(PAST) + k]
            new[k] = hp[k]
            new[wp.static(PAST) + k] = hv[k]
        for t in range(wp.static(T)):
            x[wp.static(POS_AT[t])] = _scaled(hp[wp.static(TAPS[t])], wp.static(PS))
            x[wp.static(VEL_AT[t])] = _scaled(hv[wp.static(TAPS[t])], wp.static(VS))
        if wp.static(PAST > 0):
            hist_out[s] = new
        return x

    row_x.__annotations__["hist_out"] = wp.array[vec_p]  # (the body does not name vec_p: no closure variable)
    digest = hashlib.sha256(repr((TAPS, POS_FIRST, PAST, PS, VS, vec_x._length_)).encode()).hexdigest()[:16]
    return wp.func(row_x, name="wpctrl_actuator_net_row_input_" + digest, module="unique", inline=True)


def _make(L: NetLayout, weights: np.ndarray, scales: tuple[float, float, float]) -> tuple[wp.Function, wp.Kernel]:
    N, TAPS, POS_FIRST, PAST = L.rows, L.taps, bool(L.pos_first), L.past
    PS, VS, TS = scales
    MLP = not L.lstm
    T = len(TAPS)
    dense = dense_matrices(L, weights)
    lstm = lstm_matrices(L, weights)
    DW = tuple(_floats(w) for w, _, _, _ in dense)
    DB = tuple(_floats(b) for _, b, _, _ in dense)
    DACT = tuple((c, a) for _, _, c, a in dense)
    DIN = tuple(int(d[0]) for d in L.dense)
    DOUT = tuple(int(d[1]) for d in L.dense)
    LWI = tuple(_floats(w) for w, _, _ in lstm)
    LWH = tuple(_floats(w) for _, w, _ in lstm)
    LB = tuple(_floats(b) for _, _, b in lstm)
    LIN = tuple(int(s[0]) for s in L.lstm)
    H = int(L.lstm[0][1]) if L.lstm else 1
    NL, ND = len(L.lstm), len(L.dense)
    width = max([2 * T if MLP else 2, H, *DOUT])
    vec_w = wp.types.vector(length=width, dtype=wp.float32)
    vec_g = wp.types.vector(length=4 * H, dtype=wp.float32)
    vec_s = wp.types.vector(length=max(len(L.lstm) * H, 1), dtype=wp.float32)
    vec_p = wp.types.vector(length=max(2 * PAST, 1), dtype=wp.float32)
    mlp_x = mlp_row_input(L, (PS, VS), vec_w)

    def net_row(
        s: int,  # (env, joint) row, joint fastest
        env: int,
        r: int,  # the row in the mode's tables
        # The row's inputs (read_row, and the position error):
        di: int,
        err: float,
        qd: float,
        lim: float,
        sat: float,
        vl: float,
        io: NetIO,
        hist_out: wp.array[vec_p],
        joint_f_out: wp.array[float],
    ):
        x = vec_w()
        if wp.static(MLP):
            x = mlp_x(s, err, qd, hist_out)
        else:
            if wp.static(POS_FIRST):
                x[0] = _scaled(err, wp.static(PS))
                x[1] = _scaled(qd, wp.static(VS))
            else:
                x[0] = _scaled(qd, wp.static(VS))
                x[1] = _scaled(err, wp.static(PS))
            hs = vec_s()
            cs = vec_s()
            for k in range(wp.static(NL * H)):
                hs[k] = io.lstm_h[k, s]
                cs[k] = io.lstm_c[k, s]
            for li in range(wp.static(NL)):
                g = vec_g()
                for o in range(wp.static(4 * H)):
                    acc = float(wp.static(LB[li][o]))
                    for i in range(wp.static(LIN[li])):
                        acc = acc + wp.static(LWI[li][o][i]) * x[i]
                    for k in range(wp.static(H)):
                        acc = acc + wp.static(LWH[li][o][k]) * hs[wp.static(li * H) + k]
                    g[o] = acc
                # PyTorch's gate order: input, forget, cell, output.
                for k in range(wp.static(H)):
                    hk, ck = lstm_cell(g[k], g[wp.static(H) + k], g[wp.static(2 * H) + k], g[wp.static(3 * H) + k],
                                            cs[wp.static(li * H) + k])  # fmt: skip
                    io.lstm_h[wp.static(li * H) + k, s] = hk
                    io.lstm_c[wp.static(li * H) + k, s] = ck
                    x[k] = hk
        for li in range(wp.static(ND)):
            y = vec_w()
            for o in range(wp.static(DOUT[li])):
                acc = float(wp.static(DB[li][o]))
                for i in range(wp.static(DIN[li])):
                    acc = acc + wp.static(DW[li][o][i]) * x[i]
                y[o] = activate(acc, wp.static(DACT[li][0]), wp.static(DACT[li][1]))
            x = y
        write_effort(_scaled(x[0], wp.static(TS)), qd, env, r, di, lim, sat, vl, joint_f_out, io)

    net_row.__annotations__["hist_out"] = wp.array[vec_p]  # (the body does not name vec_p: no closure variable)
    # The function's name carries the network: Warp's module hash does not see a function's wp.static() values that
    # are resolved only at code generation (the weights, under loops), so two networks' functions must differ by name.
    digest = hashlib.sha256(repr((L, scales)).encode() + weights.tobytes()).hexdigest()[:16]
    row = wp.func(net_row, name="wpctrl_actuator_net_row_" + digest, module="unique", inline=True)

    def net(
        row0: int,  # the network's rows: row0 .. row0 + n in the mode's tables
        io: NetIO,  # index tables, per-env limits, the LSTM state, the effort readout
        # In:
        joint_q_in: wp.array[float],
        joint_qd_in: wp.array[float],
        joint_target_q_in: wp.array[float],  # this substep's (interpolated, delayed) target
        # In/out: the MLP's past samples per row (position errors, then velocities, newest first):
        hist_out: wp.array[vec_p],
        # Out:
        joint_f_out: wp.array[float],
    ):
        s = wp.tid()  # (env, joint) row, joint fastest
        env = s // wp.static(N)
        j = s - env * wp.static(N)
        r = row0 + j
        # Every input is read here, before the network, so that all loads are in flight together.
        qi, di, q, qd, lim, sat, vl = read_row(io, wp.static(L.q_lin), wp.static(L.qd_lin), env, r, j, joint_q_in,
                                                 joint_qd_in)  # fmt: skip
        row(s, env, r, di, joint_target_q_in[qi] - q, qd, lim, sat, vl, io, hist_out, joint_f_out)

    net.__annotations__["hist_out"] = wp.array[vec_p]  # (the body does not name vec_p: no closure variable)
    return row, actuator_net.net_kernel(net, "wpctrl_actuator_net", grid_stride=False)
