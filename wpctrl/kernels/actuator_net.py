"""Learned actuators in Warp: an MLP over a history of position errors and velocities, or an LSTM, per env and joint.

Private module. One thread per (env, joint of the network's rows); the network's shape (layer widths, activations,
the history taps or the LSTM's layers) is compiled into the kernel: a layer's outputs in a run-time loop, each
output's dot product unrolled over the layer's inputs, which stay in registers. Weights are one flat float32 array
read uniformly by all threads. The kernel runs after the substep kernel has written the drive targets into the
Control (the network's position target is that substep's, interpolated and delayed as the targets of any other row):
it reads ``joint_q``/``joint_qd`` and ``joint_target_q``, advances the history (or the recurrent state), evaluates
the network, applies the DC-motor envelope and the force limit, and writes ``joint_f`` and the effort readout.

Activation codes: 0 identity, 1 ReLU, 2 ELU(a), 3 tanh, 4 sigmoid, 5 softsign, 6 LeakyReLU(a).
"""

from __future__ import annotations

from typing import NamedTuple

import warp as wp

from .actuator_models import dc_motor_clamp
from .pd import _at

wp.set_module_options({"enable_backward": False})

ACT_IDENTITY, ACT_RELU, ACT_ELU, ACT_TANH, ACT_SIGMOID, ACT_SOFTSIGN, ACT_LEAKY = range(7)


class NetLayout(NamedTuple):
    """What a network kernel is compiled for. ``dense``: ``(in, out, activation code, activation parameter, weight
    offset, bias offset)`` per Linear layer after the input (MLP) or after the LSTM (its head). ``lstm``: ``(in,
    hidden, W_ih offset, W_hh offset, b_ih offset, b_hh offset)`` per LSTM layer (empty for an MLP). ``taps``: the MLP
    history indices (``input_idx``); ``history``: its length; ``pos_first``: input order ``pos_vel``; ``rows``: the
    joints it drives."""

    dense: tuple
    lstm: tuple
    taps: tuple
    history: int
    pos_first: bool
    rows: int


_KERNELS: dict[NetLayout, wp.Kernel] = {}


def net_kernel(layout: NetLayout) -> wp.Kernel:
    k = _KERNELS.get(layout)
    if k is None:
        k = _KERNELS[layout] = _make_net_kernel(layout)
    return k


@wp.func
def _activate(x: float, code: int, a: float):
    if code == ACT_RELU:
        return wp.max(x, 0.0)
    if code == ACT_ELU:
        if x > 0.0:
            return x
        return a * (wp.exp(x) - 1.0)
    if code == ACT_TANH:
        return wp.tanh(x)
    if code == ACT_SIGMOID:
        return 1.0 / (1.0 + wp.exp(-x))
    if code == ACT_SOFTSIGN:
        return x / (1.0 + wp.abs(x))
    if code == ACT_LEAKY:
        if x > 0.0:
            return x
        return a * x
    return x


@wp.func
def _sigmoid(x: float):
    return 1.0 / (1.0 + wp.exp(-x))


def _make_net_kernel(L: NetLayout) -> wp.Kernel:
    DENSE, LSTM, TAPS, HIST, POS_FIRST, N = L.dense, L.lstm, L.taps, L.history, bool(L.pos_first), L.rows
    MLP = not LSTM
    T = len(TAPS)
    widths = [2 * T if MLP else 2] + [d[1] for d in DENSE] + [s[1] for s in LSTM]
    W = max(widths)
    H = LSTM[0][1] if LSTM else 1
    vec_w = wp.types.vector(length=W, dtype=wp.float32)
    vec_g = wp.types.vector(length=4 * H, dtype=wp.float32)
    vec_h = wp.types.vector(length=H, dtype=wp.float32)
    vec_t = wp.types.vector(length=max(HIST, 1), dtype=wp.float32)
    POS_AT = tuple((t if POS_FIRST else T + t) for t in range(T))
    VEL_AT = tuple((T + t if POS_FIRST else t) for t in range(T))
    NL = len(LSTM)
    ND = len(DENSE)

    def net(
        # Rows of the network (row0 .. row0 + n in the mode's tables):
        row0: int,
        q_idx: wp.array2d[wp.int32],
        qd_idx: wp.array2d[wp.int32],
        q_stride: int,
        qd_stride: int,
        weights: wp.array[float],  # every layer's weights and biases, flat
        layer_out: wp.array[wp.int32],  # outputs per dense layer, then 4 x hidden per LSTM layer (a run-time bound)
        pos_scale: float,
        vel_scale: float,
        torque_scale: float,
        # Per env x row of the mode (num_envs, rows):
        force_limit: wp.array2d[float],  # [N·m or N]
        sat_effort: wp.array2d[float],  # DC-motor envelope [N·m or N] (inf: none)
        vel_limit: wp.array2d[float],  # [rad/s or m/s] (inf: none)
        # In:
        joint_q_in: wp.array[float],
        joint_qd_in: wp.array[float],
        joint_target_q_in: wp.array[float],  # this substep's (interpolated, delayed) target
        # In/out: MLP history (history, num_envs * n) or LSTM state (layers, num_envs * n, hidden):
        hist_pos_out: wp.array2d[float],
        hist_vel_out: wp.array2d[float],
        lstm_h_out: wp.array3d[float],
        lstm_c_out: wp.array3d[float],
        # Out:
        joint_f_out: wp.array[float],
        computed_effort_out: wp.array2d[float],  # optional (effort readout)
        applied_effort_out: wp.array2d[float],
        saturation_count_out: wp.array2d[wp.int32],
    ):
        env, j = wp.tid()
        r = row0 + j
        s = env * wp.static(N) + j
        qi = _at(q_idx, q_stride, env, r)
        di = _at(qd_idx, qd_stride, env, r)
        q = joint_q_in[qi]
        qd = joint_qd_in[di]
        err = joint_target_q_in[qi] - q
        lim = force_limit[env, r]
        sat = sat_effort[env, r]
        vl = vel_limit[env, r]
        x = vec_w()
        if wp.static(MLP):
            # The history, newest first (Isaac Lab rolls it and writes the current sample at index 0).
            hp = vec_t()
            hv = vec_t()
            hp[0] = err
            hv[0] = qd
            for k in range(wp.static(HIST)):
                if wp.static(k >= 1):
                    hp[k] = hist_pos_out[k - 1, s]
                    hv[k] = hist_vel_out[k - 1, s]
            for k in range(wp.static(HIST)):
                hist_pos_out[k, s] = hp[k]
                hist_vel_out[k, s] = hv[k]
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
            for li in range(wp.static(NL)):
                h = vec_h()
                c = vec_h()
                for k in range(wp.static(H)):
                    h[k] = lstm_h_out[li, s, k]
                    c[k] = lstm_c_out[li, s, k]
                g = vec_g()
                for o in range(layer_out[wp.static(ND + li)]):  # a run-time loop over the gates (see the dense layers)
                    acc = weights[wp.static(LSTM[li][4]) + o] + weights[wp.static(LSTM[li][5]) + o]
                    wi = wp.static(LSTM[li][2]) + o * wp.static(LSTM[li][0])
                    for i in range(wp.static(LSTM[li][0])):
                        acc += weights[wi + i] * x[i]
                    wh = wp.static(LSTM[li][3]) + o * wp.static(H)
                    for k in range(wp.static(H)):
                        acc += weights[wh + k] * h[k]
                    g[o] = acc
                # PyTorch's gate order: input, forget, cell, output.
                for k in range(wp.static(H)):
                    ig = _sigmoid(g[k])
                    fg = _sigmoid(g[wp.static(H) + k])
                    cg = wp.tanh(g[wp.static(2 * H) + k])
                    og = _sigmoid(g[wp.static(3 * H) + k])
                    c[k] = fg * c[k] + ig * cg
                    h[k] = og * wp.tanh(c[k])
                for k in range(wp.static(H)):
                    lstm_h_out[li, s, k] = h[k]
                    lstm_c_out[li, s, k] = c[k]
                for k in range(wp.static(H)):
                    x[k] = h[k]
        for li in range(wp.static(ND)):
            # Outputs in a run-time loop (its bound is read from an array, so neither Warp nor the CUDA compiler can
            # unroll it), each output's dot product unrolled with the inputs in registers: a fully unrolled layer lets
            # the compiler hoist every weight load at once and spill.
            y = vec_w()
            for o in range(layer_out[wp.static(li)]):
                acc = weights[wp.static(DENSE[li][5]) + o]
                wr = wp.static(DENSE[li][4]) + o * wp.static(DENSE[li][0])
                for i in range(wp.static(DENSE[li][0])):
                    acc += weights[wr + i] * x[i]
                y[o] = _activate(acc, wp.static(DENSE[li][2]), wp.static(DENSE[li][3]))
            x = y
        u = x[0] * torque_scale
        f = dc_motor_clamp(u, qd, sat, vl, lim)
        joint_f_out[di] = f
        if computed_effort_out:
            computed_effort_out[env, r] = u
            applied_effort_out[env, r] = f
            if f != u:
                saturation_count_out[env, r] = saturation_count_out[env, r] + 1

    return wp.kernel(net, name="wpctrl_actuator_net", enable_backward=False, module="unique")


@wp.kernel
def _reset_state_kernel(
    num_envs: int,
    n: int,  # the network's rows
    env_ids_in: wp.array[wp.int32],  # optional: thread row i resets env env_ids_in[i]
    env_mask_in: wp.array[wp.bool],  # optional
    # Out:
    hist_pos_out: wp.array2d[float],  # (history, num_envs * n)
    hist_vel_out: wp.array2d[float],
    lstm_h_out: wp.array3d[float],  # (layers, num_envs * n, hidden)
    lstm_c_out: wp.array3d[float],
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
    for k in range(hist_pos_out.shape[0]):
        hist_pos_out[k, s] = 0.0
        hist_vel_out[k, s] = 0.0
    for li in range(lstm_h_out.shape[0]):
        for k in range(lstm_h_out.shape[2]):
            lstm_h_out[li, s, k] = 0.0
            lstm_c_out[li, s, k] = 0.0
