"""The torch baseline of an actuator network: the network's substep written in torch, on the same rows and arrays.

What a user would write without wpctrl's network kernel, following Isaac Lab's ``ActuatorNetMLP`` /
``ActuatorNetLSTM.compute``: gather the rows' ``joint_q`` / ``joint_qd`` / ``joint_target_q``, roll the histories (or
run ``nn.LSTM`` on the stored hidden and cell state), evaluate the same ``torch.nn`` module (cuBLAS, cuDNN for the
LSTM), clip by the DC-motor envelope and the force limit, and scatter into ``joint_f``. Everything is written in
place into buffers allocated once, so the step can be captured in a CUDA graph together with wpctrl's own
``set_action`` / substep launches (``capture_joint``; ``capture_apart`` when one graph of both fails): the same
control step as wpctrl's network variant, with the network kernel's launch replaced by these torch ops.

Bench-only: it reads wpctrl internals (the engine's network group, binding and per-env arrays).
"""

from __future__ import annotations

import copy

import numpy as np
import torch
import warp as wp


class TorchActuatorNet:
    """The network rows of ``ctrl`` (its first ``ActuatorNet``) evaluated with torch each substep."""

    def __init__(self, ctrl, state, control, lstm_cells: bool = False):
        """``lstm_cells``: run the LSTM as its cell equations with ``torch.addmm`` (cuBLAS) instead of ``nn.LSTM``
        (cuDNN), for batches cuDNN refuses."""
        eng = ctrl._engine
        group = eng.part("actuator_models").nets[0]
        dev = torch.device("cuda", wp.get_device(eng.device).ordinal) if wp.get_device(eng.device).is_cuda else "cpu"
        r0, n = group.row0, group.n
        b = eng.binding
        rows = slice(r0, r0 + n)
        self.qi = torch.from_numpy(np.ascontiguousarray(b.coord_index[:, rows]).reshape(-1).astype(np.int64)).to(dev)
        self.di = torch.from_numpy(np.ascontiguousarray(b.dof_index[:, rows]).reshape(-1).astype(np.int64)).to(dev)

        def per_env(name):  # the (num_envs, rows) parameter, as a contiguous (num_envs * n,) tensor (read once)
            a = eng.arrays.lookup(name).numpy()[:, rows]
            return torch.from_numpy(np.ascontiguousarray(a).reshape(-1)).to(dev)

        self.lim, self.sat, self.vlim = per_env("force_limit"), per_env("sat_effort"), per_env("vel_limit")
        # float32 throughout, as the network kernels (no TF32 in cuBLAS or cuDNN)
        torch.backends.cuda.matmul.allow_tf32 = False
        torch.backends.cudnn.allow_tf32 = False
        s = group.spec
        self.ps, self.vs, self.ts = float(s.pos_scale), float(s.vel_scale), float(s.torque_scale)
        self.pos_first = s.input_order == "pos_vel"
        module = copy.deepcopy(s.network).to(dev).eval()
        self.lstm = next((m for m in module.modules() if isinstance(m, torch.nn.LSTM)), None)
        rows_total = b.num_envs * n
        if self.lstm is None:
            self.net = module
            taps = [int(i) for i in s.input_idx]
            self.taps = torch.tensor(taps, dtype=torch.int64, device=dev)  # on the device: no copy in the capture
            h = max(taps) + 1
            self.he = torch.zeros(h, rows_total, device=dev)
            self.hv = torch.zeros(h, rows_total, device=dev)
        else:
            self.head = torch.nn.Sequential(*[m for m in module.children() if not isinstance(m, torch.nn.LSTM)])
            self.cells = lstm_cells
            p = dict(self.lstm.named_parameters())
            self.cell_weights = [
                (p[f"weight_ih_l{k}"].T.contiguous(), p[f"weight_hh_l{k}"].T.contiguous(),
                 (p[f"bias_ih_l{k}"] + p[f"bias_hh_l{k}"]).detach())
                for k in range(self.lstm.num_layers)
            ]  # fmt: skip
            shape = (self.lstm.num_layers, rows_total, self.lstm.hidden_size)
            self.h = torch.zeros(shape, device=dev)
            self.c = torch.zeros(shape, device=dev)
        self.bind(state, control)

    def bind(self, state, control) -> None:
        self.jq = wp.to_torch(state.joint_q)
        self.jqd = wp.to_torch(state.joint_qd)
        self.jtq = wp.to_torch(control.joint_target_q)
        self.jf = wp.to_torch(control.joint_f)

    @torch.no_grad()
    def substep(self) -> None:
        q = self.jq[self.qi]
        qd = self.jqd[self.di]
        err = self.jtq[self.qi] - q
        if self.lstm is None:
            self.he.copy_(self.he.roll(1, 0))
            self.hv.copy_(self.hv.roll(1, 0))
            self.he[0] = err
            self.hv[0] = qd
            pos = self.he.index_select(0, self.taps).T * self.ps
            vel = self.hv.index_select(0, self.taps).T * self.vs
            u = self.net(torch.cat([pos, vel] if self.pos_first else [vel, pos], dim=1))[:, 0]
        else:
            pv = [err * self.ps, qd * self.vs]
            x = torch.stack(pv if self.pos_first else pv[::-1], dim=1)
            if self.cells:
                for k, (w_ih, w_hh, b) in enumerate(self.cell_weights):
                    g = torch.addmm(torch.addmm(b, x, w_ih), self.h[k], w_hh)
                    i, f, gg, o = g.chunk(4, dim=1)
                    self.c[k].mul_(torch.sigmoid(f)).add_(torch.sigmoid(i) * torch.tanh(gg))
                    self.h[k].copy_(torch.sigmoid(o) * torch.tanh(self.c[k]))
                    x = self.h[k]
                u = self.head(x)[:, 0]
            else:
                out, (h, c) = self.lstm(x[:, None, :], (self.h, self.c))
                self.h.copy_(h)
                self.c.copy_(c)
                u = self.head(out[:, 0])[:, 0]
        u = u * self.ts
        s = qd / self.vlim
        hi = torch.clamp(self.sat * (1.0 - s), min=-self.lim, max=self.lim)
        lo = torch.clamp(self.sat * (-1.0 - s), min=-self.lim, max=self.lim)
        self.jf.index_copy_(0, self.di, torch.minimum(torch.maximum(u, lo), hi))

    def reset(self) -> None:
        """Zero the histories (MLP) or the hidden and cell state (LSTM), as at construction."""
        for t in (self.he, self.hv) if self.lstm is None else (self.h, self.c):
            t.zero_()


# ----------------------------------------------------------------------------------------------------------------------
# Capture. Warp and torch must put their work on one stream, and that stream must stay known to Warp for as long as
# it is used: Warp keeps one record per CUDA stream handle, created by every ``wp.Stream`` that wraps the handle
# (``wp.stream_from_torch``) and erased when any such wrapper is garbage-collected. A temporary wrapper of the capture
# stream therefore makes the capture's own wrapper unknown ("Warp error: unknown stream"), and torch hands out its
# streams from a small pool, so a stream made later can be a handle an earlier wrapper still names. Hence one torch
# stream per device and its one Warp wrapper, made once and kept for the process.

_STREAMS: dict[int, tuple] = {}


def shared_stream(device):
    """``(torch stream, Warp stream)``: the one CUDA stream that the torch baseline's eager steps, warm-ups, captures
    and replays all run on, as torch's and as Warp's stream object (the same handle)."""
    ordinal = wp.get_device(device).ordinal
    if ordinal not in _STREAMS:
        ts = torch.cuda.Stream(device=torch.device("cuda", ordinal))
        _STREAMS[ordinal] = (ts, wp.stream_from_torch(ts))
    return _STREAMS[ordinal]


def run_on_shared_stream(fn, device) -> None:
    """Call ``fn`` with Warp's launches and torch's ops both on :func:`shared_stream`, after the work queued on Warp's
    current stream."""
    ts, ws = shared_stream(device)
    with wp.ScopedStream(ws), torch.cuda.stream(ts):
        fn()


def capture_joint(step, device):
    """One CUDA graph of ``step``, wpctrl's launches and torch's ops together: returns its replay function.

    As Warp's torch-interop tests capture: the step is warmed up twice on the shared stream (modules loaded, cuBLAS
    and cuDNN workspaces and the caching allocator's blocks made for that stream), torch opens the capture on that
    stream (its graph's private memory pool takes torch's allocations) and Warp joins it as an external capture, so
    that its own allocations and frees are graph-aware. Warp's stream is entered before the capture opens: entering
    it during the capture would make the capturing stream wait on uncaptured work (CUDA error 905)."""
    ts, ws = shared_stream(device)
    dev = torch.device("cuda", wp.get_device(device).ordinal)
    torch.cuda.synchronize(dev)
    with wp.ScopedStream(ws), torch.cuda.stream(ts):
        for _ in range(2):
            step()
    torch.cuda.synchronize(dev)
    graph = torch.cuda.CUDAGraph()
    with wp.ScopedStream(ws), torch.cuda.graph(graph, stream=ts, capture_error_mode="thread_local"):
        wp.capture_begin(stream=ws, force_module_load=False, external=True, capture_mode=wp.CaptureMode.THREAD_LOCAL)
        try:
            step()
        except BaseException:
            try:  # Warp's record of the capture goes; the step's error is the one reported
                wp.capture_end(stream=ws)
            except Exception:  # noqa: BLE001, S110
                pass
            raise
        wp.capture_end(stream=ws)

    def replay(graph=graph, ts=ts):
        with torch.cuda.stream(ts):
            graph.replay()

    return replay


def capture_apart(ctrl_step, tnet, substeps: int, device):
    """The fallback when one graph of both cannot be captured: two graphs replayed back to back on Warp's stream.

    wpctrl's step (its network launch made a no-op by the caller) is captured by Warp on its own stream, as every
    other variant of the bench; the torch network's ``substeps`` substeps by torch alone on the shared stream (after
    two warm-up substeps there), in a private memory pool. Each replay launches the Warp graph, then the torch graph
    on Warp's stream. The network's substeps then run after the step's instead of between them: the same work, and
    the same ``joint_f`` while the state does not change within a control step (no physics runs in the bench)."""
    ts, _ = shared_stream(device)
    dev = torch.device("cuda", wp.get_device(device).ordinal)
    with wp.ScopedCapture(device=device) as cap:
        ctrl_step()
    torch.cuda.synchronize(dev)
    with torch.cuda.stream(ts):
        for _ in range(2):
            tnet.substep()
    torch.cuda.synchronize(dev)
    graph = torch.cuda.CUDAGraph()
    with torch.cuda.graph(graph, stream=ts, capture_error_mode="thread_local"):
        for _ in range(substeps):
            tnet.substep()
    on_warp = wp.stream_to_torch(wp.get_stream(device))

    def replay(graph=graph, wgraph=cap.graph, on_warp=on_warp, device=device):
        wp.capture_launch(wgraph, stream=wp.get_stream(device))
        with torch.cuda.stream(on_warp):
            graph.replay()

    return replay
