"""The actuator-network kernel as tiled matrix products: weights in shared memory, rows batched into tiles.

Private module (see :mod:`.actuator_net`). A block of ``B`` threads stages every weight matrix once in shared memory
(one ``wp.tile_load`` of the packed matrices, :func:`pack`) and then walks tiles of ``B`` rows (one row per thread):
the threads gather their rows' inputs, ``wp.tile`` makes them the columns of an ``(in, B)`` tile, each layer is a
``wp.tile_matmul`` of a view of its weights with that tile (the LSTM's two per layer accumulate into one gate tile),
``wp.untile`` hands every thread its column for the bias, the activation or the LSTM cell, and the last layer's
column is the row's torque, clamped and written as in the unrolled kernel. Intermediate activations stay in the
block's shared memory. The kernel is compiled for the network's shape; the weights are data. On the CPU a block is
one thread and a tile one row.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from . import actuator_net
from .actuator_net import NetIO, NetLayout, activate, dense_matrices, lstm_cell, lstm_matrices, read_row, write_effort

wp.set_module_options({"enable_backward": False})

BLOCK_DIM = 64
"""CUDA threads per block (and rows per tile)."""

_KERNELS: dict[tuple, wp.Kernel] = {}


def tiled_kernel(layout: NetLayout, block_dim: int) -> wp.Kernel:
    """The kernel of ``layout`` for blocks of ``block_dim`` threads (``BLOCK_DIM`` on CUDA; 1 on the CPU, or
    ``BLOCK_DIM`` with Warp's cooperative CPU blocks): launched over ``(blocks, block_dim)`` with the packed weights
    of :func:`pack`. One kernel object per block size (its tiles' shapes follow it)."""
    k = _KERNELS.get((layout, block_dim))
    if k is None:
        k = _KERNELS[(layout, block_dim)] = _make(layout, block_dim)
    return k


def _placement(L: NetLayout):
    """Row offsets of each matrix in the packed weights and of each bias vector: ``(lstm [(W_ih row, W_hh row,
    bias)], dense [(W row, bias)], rows, cols, biases)``."""
    row = bias = 0
    lstm, dense = [], []
    cols = 1
    for n_in, h, *_ in L.lstm:
        lstm.append((row, row + 4 * h, bias))
        row += 8 * h
        bias += 4 * h
        cols = max(cols, n_in, h)
    for n_in, n_out, *_ in L.dense:
        dense.append((row, bias))
        row += n_out
        bias += n_out
        cols = max(cols, n_in)
    return tuple(lstm), tuple(dense), row, cols, bias


def pack(layout: NetLayout, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The weight matrices stacked into one ``(rows, cols)`` float32 array (each at its placement, zero-padded to the
    widest input) and the biases (the LSTM's two per gate added in float32) into one vector."""
    lstm_p, dense_p, rows, cols, nb = _placement(layout)
    w = np.zeros((rows, cols), np.float32)
    b = np.zeros(max(nb, 1), np.float32)
    for (ri, rh, bo), (w_ih, w_hh, bsum) in zip(lstm_p, lstm_matrices(layout, weights)):
        w[ri : ri + w_ih.shape[0], : w_ih.shape[1]] = w_ih
        w[rh : rh + w_hh.shape[0], : w_hh.shape[1]] = w_hh
        b[bo : bo + bsum.size] = bsum
    for (ro, bo), (wd, bd, _, _) in zip(dense_p, dense_matrices(layout, weights)):
        w[ro : ro + wd.shape[0], : wd.shape[1]] = wd
        b[bo : bo + bd.size] = bd
    return w, b


def _make(L: NetLayout, block_dim: int) -> wp.Kernel:
    N, TAPS, POS_FIRST, PAST = L.rows, L.taps, bool(L.pos_first), L.past
    MLP = not L.lstm
    T = len(TAPS)
    LP, DP, WROWS, WCOLS, NB = _placement(L)
    LIN = tuple(int(s[0]) for s in L.lstm)
    H = int(L.lstm[0][1]) if L.lstm else 1
    DIN = tuple(int(d[0]) for d in L.dense)
    DOUT = tuple(int(d[1]) for d in L.dense)
    DACT = tuple((int(d[2]), float(d[3])) for d in L.dense)
    NL, ND = len(L.lstm), len(L.dense)
    vec_in = wp.types.vector(length=2 * T if MLP else 2, dtype=wp.float32)
    vec_h = wp.types.vector(length=H, dtype=wp.float32)
    vec_t = wp.types.vector(length=max(L.history, 1), dtype=wp.float32)
    POS_AT = tuple((t if POS_FIRST else T + t) for t in range(T))
    VEL_AT = tuple((T + t if POS_FIRST else t) for t in range(T))

    # The layers as a chain of functions, each calling the next with its output tile: a layer's tiles differ in shape
    # from the next one's, and one symbol keeps one type within a function.
    def dense_stage(li: int, nxt):
        W_AT, W_ROWS, W_COLS = DP[li][0], DOUT[li], DIN[li]

        @wp.func(module="unique")
        def stage(wts: Any, bs: Any, xt: Any, s: int, live: bool, io: NetIO):
            w = wp.tile_view(wts, offset=(wp.static(W_AT), 0), shape=(wp.static(W_ROWS), wp.static(W_COLS)))
            z = wp.untile(wp.tile_matmul(w, xt))
            for o in range(wp.static(DOUT[li])):
                z[o] = activate(z[o] + bs[wp.static(DP[li][1]) + o], wp.static(DACT[li][0]),
                                     wp.static(DACT[li][1]))  # fmt: skip
            if wp.static(nxt is None):
                return z[0]
            else:
                return nxt(wts, bs, wp.tile(z), s, live, io)

        return stage

    def lstm_stage(li: int, nxt):
        IH_AT, HH_AT, BO = LP[li]
        G, IH_COLS = 4 * H, LIN[li]

        @wp.func(module="unique")
        def stage(wts: Any, bs: Any, xt: Any, s: int, live: bool, io: NetIO):
            h = vec_h()
            c = vec_h()
            if live:
                for k in range(wp.static(H)):
                    h[k] = io.lstm_h[wp.static(li * H) + k, s]
                    c[k] = io.lstm_c[wp.static(li * H) + k, s]
            w_ih = wp.tile_view(wts, offset=(wp.static(IH_AT), 0), shape=(wp.static(G), wp.static(IH_COLS)))
            w_hh = wp.tile_view(wts, offset=(wp.static(HH_AT), 0), shape=(wp.static(G), wp.static(H)))
            gates = wp.tile_matmul(w_ih, xt)
            wp.tile_matmul(w_hh, wp.tile(h), gates)  # accumulates: W_ih x + W_hh h
            g = wp.untile(gates)
            for k in range(wp.static(H)):
                # PyTorch's gate order: input, forget, cell, output.
                hk, ck = lstm_cell(g[k] + bs[wp.static(BO) + k], g[wp.static(H) + k] + bs[wp.static(BO + H) + k],
                                        g[wp.static(2 * H) + k] + bs[wp.static(BO + 2 * H) + k],
                                        g[wp.static(3 * H) + k] + bs[wp.static(BO + 3 * H) + k], c[k])  # fmt: skip
                h[k] = hk
                c[k] = ck
            if live:
                for k in range(wp.static(H)):
                    io.lstm_h[wp.static(li * H) + k, s] = h[k]
                    io.lstm_c[wp.static(li * H) + k, s] = c[k]
            return nxt(wts, bs, wp.tile(h), s, live, io)

        return stage

    stage0 = None
    for li in reversed(range(ND)):
        stage0 = dense_stage(li, stage0)
    for li in reversed(range(NL)):
        stage0 = lstm_stage(li, stage0)

    @wp.func(module="unique")
    def rows(
        wts: Any,
        bs: Any,
        tile: int,
        lane: int,
        row0: int,
        io: NetIO,
        pos_scale: float,
        vel_scale: float,
        torque_scale: float,
        num_rows: int,
        joint_q_in: wp.array[float],
        joint_qd_in: wp.array[float],
        joint_target_q_in: wp.array[float],
        hist_out: wp.array2d[float],
        joint_f_out: wp.array[float],
    ):
        """One tile of rows (a block's pass): a function of its own so that each layer's tiles may differ in shape
        (a symbol inside a run-time loop keeps one type)."""
        # Every thread takes part in the tile operations; a thread past the last row computes on zeros.
        s = tile * wp.block_dim() + lane
        live = s < num_rows
        env = s // wp.static(N)
        j = s - env * wp.static(N)
        r = row0 + j
        di = int(0)
        err = float(0.0)
        qd = float(0.0)
        lim = float(0.0)
        sat = float(0.0)
        vl = float(0.0)
        if live:
            qi, di, q, qd, lim, sat, vl = read_row(io, wp.static(L.q_lin), wp.static(L.qd_lin), env, r, j,
                                                     joint_q_in, joint_qd_in)  # fmt: skip
            err = joint_target_q_in[qi] - q
        x = vec_in()
        if wp.static(MLP):
            hp = vec_t()
            hv = vec_t()
            hp[0] = err
            hv[0] = qd
            if live:
                for k in range(wp.static(PAST)):
                    hp[k + 1] = hist_out[s, k]
                    hv[k + 1] = hist_out[s, wp.static(PAST) + k]
                for k in range(wp.static(PAST)):
                    hist_out[s, k] = hp[k]
                    hist_out[s, wp.static(PAST) + k] = hv[k]
            for t in range(wp.static(T)):
                x[wp.static(POS_AT[t])] = hp[wp.static(TAPS[t])] * pos_scale
                x[wp.static(VEL_AT[t])] = hv[wp.static(TAPS[t])] * vel_scale
        else:
            if wp.static(POS_FIRST):
                x[0] = err * pos_scale
                x[1] = qd * vel_scale
            else:
                x[0] = qd * vel_scale
                x[1] = err * pos_scale
        u = stage0(wts, bs, wp.tile(x), s, live, io)
        if live:
            write_effort(u * torque_scale, qd, env, r, di, lim, sat, vl, joint_f_out, io)

    def net(
        row0: int,  # the network's rows: row0 .. row0 + n in the mode's tables
        io: NetIO,  # index tables, per-env limits, the LSTM state, the effort readout
        pos_scale: float,
        vel_scale: float,
        torque_scale: float,
        weight_tiles: wp.array2d[float],  # the packed matrices (pack)
        biases: wp.array[float],
        num_rows: int,  # num_envs * n
        num_tiles: int,  # ceil(num_rows / block_dim)
        num_blocks: int,  # the launch's blocks: each walks tiles blk, blk + num_blocks, ...
        # In:
        joint_q_in: wp.array[float],
        joint_qd_in: wp.array[float],
        joint_target_q_in: wp.array[float],
        # In/out: the MLP's past samples (num_envs * n, 2 * past):
        hist_out: wp.array2d[float],
        # Out:
        joint_f_out: wp.array[float],
    ):
        blk, lane = wp.tid()
        wts = wp.tile_load(weight_tiles, shape=(wp.static(WROWS), wp.static(WCOLS)), storage="shared")  # once per block
        bs = wp.tile_load(biases, shape=(wp.static(max(NB, 1)),), storage="shared")
        for tile in range(blk, num_tiles, num_blocks):
            rows(wts, bs, tile, lane, row0, io, pos_scale, vel_scale, torque_scale, num_rows, joint_q_in, joint_qd_in,
                 joint_target_q_in, hist_out, joint_f_out)  # fmt: skip

    # The block size is a module option from the start: the tiles' shapes (and the layer functions built for them)
    # follow it, and a build for another size would reuse those functions.
    return actuator_net.net_kernel(net, "wpctrl_actuator_net_tiled", enable_mathdx_gemm=False, block_dim=block_dim)
