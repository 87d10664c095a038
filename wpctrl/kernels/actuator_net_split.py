"""The actuator-network kernel with the weights compiled in and each row split over ``lanes`` warps.

Private module (see :mod:`.actuator_net`). When the rows are few (a few thousand robots), one thread per row leaves
the GPU nearly empty and each launch waits on one long chain of dependent instructions per thread. This kernel
spreads a row over ``lanes`` (2 or 4) threads in different warps of one block: a block of ``32 * lanes`` threads
takes 32 rows, and warp ``w`` computes the ``w``-th slice of every layer's units (``ceil(units / lanes)`` each). Each
warp runs its own copy of the layer code with its slice's weights as immediate operands (the slice is uniform over a
warp, so there is no divergence), so a thread issues about ``1 / lanes`` of the multiply-adds, and ``lanes`` times as
many warps share the GPU's schedulers.

The slices meet in shared memory (Warp tiles of ``(lanes, 32)`` vectors): after a hidden layer each warp stores its
units and reads the others' (one block synchronisation), and the output layer (one unit) is a partial sum over each
warp's slice of its inputs, added up in a fixed order (every warp holds the same total). The LSTM's layers split the
same way: a warp computes its units' four gates and cell, reads the layer's whole previous ``h`` and only its own
units' ``c``, and writes its units' ``h`` and ``c``. Every warp gathers the row's inputs (the same lines, from the
cache); warp 0 alone writes the history, ``joint_f`` and the effort readout. Threads past the last row compute the
last row again and store nothing (they still take part in the block's synchronisations).

On the CPU the kernel needs Warp's cooperative CPU blocks (``wp.config.enable_cpu_blocks``); without them the
engine runs the unrolled kernel instead (the same results).

Measured on an H200 (4,096 Pandas, 28,672 rows; Nsight Compute, one substep's launch) it is slower than the unrolled
kernel: 6.4 / 6.8 us (MLP / LSTM, 4 lanes) and 6.7 / 7.1 us (2 lanes) against 5.3 / 6.4 us. It does fill the GPU
better (achieved occupancy 40 % at 4 lanes against 10 %), but each warp spends 7-12 cycles per issued instruction
against 4-5, and the SMs execute 1.2-1.75x the instructions (every warp gathers the inputs, the slices are stored and
read back, the output is summed over the warps). Stall reasons were not sampled; what the split adds to the code is
the block synchronisations and the shared-memory exchange. At 1M envs (2 lanes) it is 1.4x (MLP) and 1.2x (LSTM)
slower. ``kernel="auto"`` therefore never picks it; it stays selectable for other GPUs and networks.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .actuator_net import NetIO, NetLayout, activate, dense_matrices, lstm_cell, lstm_matrices, row_input, write_effort
from .actuator_net_unrolled import _floats, _scaled, mlp_input

wp.set_module_options({"enable_backward": False})

WARP = 32
"""Rows per block: one per thread of a warp."""

LANES = (2, 4)
"""The split factors the kernel is built for."""

SPLIT_THREADS_PER_SM = 1024
"""``kernel="split"`` splits a network's rows over 4 threads while ``lanes x rows`` stays within this many threads per
SM (8 warps per scheduler), else over 2."""

_KERNELS: dict[tuple, wp.Kernel] = {}


def split_lanes(rows: int, sm_count: int) -> int:
    """Threads per row for ``rows`` rows on a GPU of ``sm_count`` SMs (the rule of :data:`SPLIT_THREADS_PER_SM`): 4, 2,
    or 1 (not even 2 fit; ``kernel="split"`` then splits over 2)."""
    for lanes in sorted(LANES, reverse=True):
        if rows * lanes <= SPLIT_THREADS_PER_SM * sm_count:
            return lanes
    return 1


def split_kernel(layout: NetLayout, weights: np.ndarray, scales: tuple[float, float, float], lanes: int) -> wp.Kernel:
    """The kernel of ``layout`` with ``weights`` and ``scales`` compiled in (as
    :func:`.actuator_net_unrolled.unrolled_kernel`), each row split over ``lanes`` warps. Launched over ``blocks * 32 *
    lanes`` threads with ``block_dim = 32 * lanes``, ``blocks = ceil(num_rows / 32)``."""
    if lanes not in LANES:
        raise ValueError(f"lanes: expected one of {LANES}, got {lanes}")
    w = np.ascontiguousarray(weights, dtype=np.float32)
    scales = tuple(float(np.float32(x)) for x in scales)
    key = (layout, w.tobytes(), scales, lanes)
    k = _KERNELS.get(key)
    if k is None:
        k = _KERNELS[key] = _make(layout, w, scales, lanes)
    return k


def _chunk(n: int, lanes: int) -> int:
    """Units per warp of a layer of ``n`` units: warp ``l`` owns ``l * m .. min(n, (l + 1) * m) - 1``."""
    return -(-n // lanes)


def _make(L: NetLayout, weights: np.ndarray, scales: tuple[float, float, float], S: int) -> wp.Kernel:
    N, POS_FIRST, PAST = L.rows, bool(L.pos_first), L.past
    PS, VS, TS = scales
    MLP = not L.lstm
    T = len(L.taps)
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
    M = max([_chunk(H, S) if NL else 1, *(_chunk(d, S) for d in DOUT)])  # the widest slice
    MH = _chunk(H, S)
    # The output layer's inputs: the previous layer's slices (a hidden layer or the LSTM), else the row's inputs.
    LAST_IN = DIN[ND - 1]
    LAST_FROM_SLICE = ND > 1 or NL > 0
    vec_w = wp.types.vector(length=width, dtype=wp.float32)
    vec_m = wp.types.vector(length=M, dtype=wp.float32)
    vec_s = wp.types.vector(length=max(NL * H, 1), dtype=wp.float32)
    vec_o = wp.types.vector(length=max(NL * MH, 1), dtype=wp.float32)
    vec_p = wp.types.vector(length=max(2 * PAST, 1), dtype=wp.float32)
    mlp_x = mlp_input(L, (PS, VS), vec_w)
    # units of warp l in a layer of n units: (first, count); UH: each warp's first LSTM unit
    SLICE = {n: tuple((lo * _chunk(n, S), max(0, min(n, (lo + 1) * _chunk(n, S)) - lo * _chunk(n, S))) for lo in
                      range(S)) for n in {H, *DOUT, *DIN}}  # fmt: skip
    UH = tuple(f for f, _ in SLICE[H])

    @wp.func
    def total(part: float, lane: int, t: int):
        """The sum of the warps' partial sums, in warp order (the same value in every warp)."""
        sh = wp.tile_empty(shape=(wp.static(S), wp.static(WARP)), dtype=float, storage="shared")
        sh[lane, t] = part  # synchronises the block
        acc = sh[0, t]
        for q in range(1, wp.static(S)):
            acc = acc + sh[q, t]
        return acc

    def net(
        row0: int,  # the network's rows: row0 .. row0 + n in the mode's tables
        num_rows: int,  # num_envs * n
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
        i = wp.tid()
        blk = i // wp.static(WARP * S)
        tl = i - blk * wp.static(WARP * S)  # the thread in its block
        lane = tl // wp.static(WARP)  # the slice: uniform over a warp
        t = tl - lane * wp.static(WARP)
        s = blk * wp.static(WARP) + t  # (env, joint) row, joint fastest
        live = s < num_rows
        if not live:
            s = num_rows - 1  # computed again, stored by no one: every thread reaches the synchronisations
        first = live and lane == 0  # the thread that stores the row's results
        env = s // wp.static(N)
        j = s - env * wp.static(N)
        r = row0 + j
        di, err, qd, lim, sat, vl = row_input(io, wp.static(L.q_lin), wp.static(L.qd_lin), env, r, j, joint_q_in,
                                              joint_qd_in, joint_target_q_in)  # fmt: skip
        x = vec_w()
        own = vec_m()
        new = vec_p()  # the MLP's history after this sample
        hs = vec_s()  # the LSTM's previous h (every layer's), and this warp's units' c and new (h, c)
        cs = vec_o()
        ho = vec_o()
        co = vec_o()
        # All state is read here and written at the end, after the last block synchronisation: another warp of the
        # block may still be reading a row's state when this one has its results.
        if wp.static(MLP):
            old = vec_p()
            if wp.static(PAST > 0):
                old = hist_out[s]
            x, new = mlp_x(err, qd, old)
        else:
            if wp.static(POS_FIRST):
                x[0] = _scaled(err, wp.static(PS))
                x[1] = _scaled(qd, wp.static(VS))
            else:
                x[0] = _scaled(qd, wp.static(VS))
                x[1] = _scaled(err, wp.static(PS))
            for k in range(wp.static(NL * H)):
                hs[k] = io.lstm_h[k, s]
            for li in range(wp.static(NL)):
                for k in range(wp.static(MH)):
                    if lane * wp.static(MH) + k < wp.static(H):
                        cs[wp.static(li * MH) + k] = io.lstm_c[wp.static(li * H) + lane * wp.static(MH) + k, s]
            for li in range(wp.static(NL)):
                for lo in range(wp.static(S)):
                    if lane == lo:
                        for k in range(wp.static(SLICE[H][lo][1])):
                            # PyTorch's gate order: input, forget, cell, output; rows u, H + u, 2H + u, 3H + u
                            g = wp.vec4()
                            for q in range(4):
                                acc = float(wp.static(LB[li][q * H + UH[lo] + k]))
                                for i in range(wp.static(LIN[li])):
                                    acc = acc + wp.static(LWI[li][q * H + UH[lo] + k][i]) * x[i]
                                for i in range(wp.static(H)):
                                    acc = acc + wp.static(LWH[li][q * H + UH[lo] + k][i]) * hs[wp.static(li * H) + i]
                                g[q] = acc
                            hk, ck = lstm_cell(g[0], g[1], g[2], g[3], cs[wp.static(li * MH) + k])
                            own[k] = hk
                            ho[wp.static(li * MH) + k] = hk
                            co[wp.static(li * MH) + k] = ck
                # the next layer takes all units (the head's output layer takes this warp's slice)
                if wp.static(li < NL - 1 or ND > 1):
                    sh = wp.tile_empty(shape=(wp.static(S), wp.static(WARP)), dtype=vec_m, storage="shared")
                    sh[lane, t] = own  # synchronises the block
                    for q in range(wp.static(S)):
                        v = sh[q, t]
                        for k in range(wp.static(SLICE[H][q][1])):
                            x[wp.static(SLICE[H][q][0]) + k] = v[k]
        u = float(0.0)
        for li in range(wp.static(ND)):
            if wp.static(li < ND - 1):
                y = vec_m()
                for lo in range(wp.static(S)):
                    if lane == lo:
                        for k in range(wp.static(SLICE[DOUT[li]][lo][1])):
                            acc = float(wp.static(DB[li][SLICE[DOUT[li]][lo][0] + k]))
                            for i in range(wp.static(DIN[li])):
                                acc = acc + wp.static(DW[li][SLICE[DOUT[li]][lo][0] + k][i]) * x[i]
                            y[k] = activate(acc, wp.static(DACT[li][0]), wp.static(DACT[li][1]))
                own = y
                if wp.static(li < ND - 2):  # the next layer is a hidden one: every warp needs all units
                    sh = wp.tile_empty(shape=(wp.static(S), wp.static(WARP)), dtype=vec_m, storage="shared")
                    sh[lane, t] = own  # synchronises the block
                    for q in range(wp.static(S)):
                        v = sh[q, t]
                        for k in range(wp.static(SLICE[DOUT[li]][q][1])):
                            x[wp.static(SLICE[DOUT[li]][q][0]) + k] = v[k]
            else:
                # the output unit: each warp's partial sum over its slice of the inputs, then their total
                part = float(0.0)
                for lo in range(wp.static(S)):
                    if lane == lo:
                        for k in range(wp.static(SLICE[LAST_IN][lo][1])):
                            if wp.static(LAST_FROM_SLICE):
                                part = part + wp.static(DW[li][0][SLICE[LAST_IN][lo][0] + k]) * own[k]
                            else:
                                xi = x[wp.static(SLICE[LAST_IN][lo][0]) + k]
                                part = part + wp.static(DW[li][0][SLICE[LAST_IN][lo][0] + k]) * xi
                acc = total(part, lane, t) + wp.static(DB[li][0])
                u = activate(acc, wp.static(DACT[li][0]), wp.static(DACT[li][1]))
        if wp.static(NL > 0):
            if live:
                for li in range(wp.static(NL)):
                    for k in range(wp.static(MH)):
                        if lane * wp.static(MH) + k < wp.static(H):
                            io.lstm_h[wp.static(li * H) + lane * wp.static(MH) + k, s] = ho[wp.static(li * MH) + k]
                            io.lstm_c[wp.static(li * H) + lane * wp.static(MH) + k, s] = co[wp.static(li * MH) + k]
        if first:
            if wp.static(PAST > 0):
                hist_out[s] = new
            write_effort(_scaled(u, wp.static(TS)), qd, env, r, di, lim, sat, vl, joint_f_out, io)

    return wp.kernel(
        net,
        name="wpctrl_actuator_net_split",
        enable_backward=False,
        grid_stride=False,
        module="unique",
        module_options={"fast_math": True},
    )
