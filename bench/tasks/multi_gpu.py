"""Weak scaling over GPUs: graph-captured MuJoCo-Warp Panda rollouts with wpctrl, one process per GPU (torchrun).

Every rank builds ``--envs`` Pandas (default 4096) on ``cuda:{LOCAL_RANK}`` (``wpctrl.distributed.init``), a wpctrl
controller (``--mode``, implicit actuation, 20 Hz / 100 Hz: K = 5 substeps) and ``SolverMuJoCo``, and captures one
control step (``set_action`` + K x (``before_simulation_step`` + ``solver.step``)) in a graph. Then, with the same
graphs in the same processes:

* ``solo``: rank 0 replays its graph alone while the other ranks wait at a barrier (the 1-GPU figure);
* ``all``: every rank replays at once (the N-GPU figure); aggregate env-steps/s = N x envs / the slowest rank's
  seconds per control step (synchronous training waits for the slowest rank);
* ``+allreduce`` variants of both: after every control step, one ``torch.distributed.all_reduce`` of a
  policy-sized float32 tensor (``--allreduce-numel``, default 1M parameters = 4 MB; the solo variant reduces over a
  1-rank group), ordered after the step on the same CUDA stream, as a gradient all-reduce follows a rollout.

Weak-scaling efficiency = solo seconds per step / slowest rank's seconds per step (1.0 = perfect). Timing: median of
``--repeats`` samples of ``--steps`` control steps between two device syncs.

Run (2 GPUs; where NCCL's NVLink multicast misbehaves, export NCCL_NVLS_ENABLE=0 first)::

    torchrun --standalone --nproc-per-node=2 bench/tasks/multi_gpu.py --out bench/results/multi_gpu

CPU check with tiny sizes (gloo)::

    torchrun --standalone --nproc-per-node=2 bench/tasks/multi_gpu.py --device cpu --envs 4 --steps 2 --repeats 2

Results (rank 0): ``<out>/multi_gpu_<tag>.{json,md}``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

from bench.common import (  # noqa: E402
    DEFAULT_OUT,
    build_panda_model,
    fmt_envs,
    machine_info,
    md_table,
    meta_markdown,
    panda_mode,
    write_results,
)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--device", default="cuda", help="cuda (each rank: cuda:LOCAL_RANK) or cpu (gloo)")
    p.add_argument("--envs", type=int, default=4096, help="Pandas per rank (default 4096)")
    p.add_argument("--steps", type=int, default=50, help="control steps per timed sample")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--allreduce-numel", type=int, default=1 << 20, help="float32 elements all-reduced per step")
    p.add_argument("--mode", default="pd_joint_delta_pos")
    p.add_argument("--control-freq", type=int, default=20)
    p.add_argument("--sim-freq", type=int, default=100)
    p.add_argument("--out", default=str(DEFAULT_OUT))
    p.add_argument("--tag", default=None)
    args = p.parse_args(argv)

    wp.config.log_level = wp.LOG_WARNING
    wp.init()
    import newton
    import torch
    import torch.distributed as dist

    import wpctrl
    from wpctrl import distributed

    ctx = distributed.init(device=args.device, seed=0)
    if not ctx.distributed:
        p.error("run under torchrun (torchrun --standalone --nproc-per-node=N bench/tasks/multi_gpu.py ...)")
    device = wp.get_device(ctx.device)
    cuda = device.is_cuda
    tdev = torch.device("cuda", device.ordinal) if cuda else torch.device("cpu")

    def log(msg):
        if ctx.is_main:
            print(msg, flush=True)

    log(f"world {ctx.world_size}, backend {ctx.backend}, {args.envs} Pandas per rank on {ctx.device} "
        f"(NCCL_NVLS_ENABLE={os.environ.get('NCCL_NVLS_ENABLE')})")  # fmt: skip
    t0 = time.perf_counter()
    model = build_panda_model(args.envs, device, gravity=False)
    ctrl = wpctrl.build_controller(panda_mode(args.mode), model, args.control_freq, args.sim_freq)
    solver = newton.solvers.SolverMuJoCo(model, disable_contacts=True)
    K = ctrl.num_substeps
    dt = 1.0 / args.sim_freq
    s = [model.state(), model.state()]
    control = model.control()
    newton.eval_fk(model, s[0].joint_q, s[0].joint_qd, s[0])
    ctrl.reset(s[0], control=control)
    rng = np.random.default_rng(ctx.seed)
    action = wp.array(rng.uniform(-0.3, 0.3, (args.envs, ctrl.action_dim)).astype(np.float32), device=device)
    grad = torch.ones(args.allreduce_numel, dtype=torch.float32, device=tdev)
    solo_group = dist.new_group([0])  # every rank takes part in creating it
    build_s = time.perf_counter() - t0

    # Warp runs on a torch stream, so the all-reduce queued after a replay waits for it (and capture is off the
    # legacy default stream).
    stream_cm = None
    if cuda:
        tstream = torch.cuda.Stream(device=tdev)
        torch.cuda.set_stream(tstream)
        stream_cm = wp.ScopedStream(wp.stream_from_torch(tstream))
        stream_cm.__enter__()

    def control_step():
        ctrl.set_action(action, s[0])
        a, b = s[0], s[1]
        for _ in range(K):
            ctrl.before_simulation_step(a, control)
            solver.step(a, b, control, None, dt)
            a, b = b, a
        if a is not s[0]:
            s[0].assign(a)

    def sync():
        wp.synchronize_device(device)
        if cuda:
            torch.cuda.synchronize(tdev)

    t0 = time.perf_counter()
    control_step()  # first use: kernels compile or load
    sync()
    first_s = time.perf_counter() - t0
    with wp.ScopedCapture(device=device) as cap:
        control_step()
    graph = cap.graph
    sync()

    def timed(allreduce, group) -> float:
        samples = []
        for _ in range(args.repeats + 1):  # the first sample warms up
            sync()
            t = time.perf_counter()
            for _ in range(args.steps):
                wp.capture_launch(graph)
                if allreduce:
                    dist.all_reduce(grad, group=group)
            sync()
            samples.append((time.perf_counter() - t) / args.steps)
        return float(np.median(samples[1:]))

    res = {}
    for name, ar in (("step", False), ("step+allreduce", True)):
        ctx.barrier()
        solo = timed(ar, solo_group) if ctx.is_main else float("nan")
        ctx.barrier()
        every = timed(ar, None)
        ctx.barrier()
        rows = ctx.all_gather([solo, every])
        solo_s = float(rows[0, 0])
        slowest = float(rows[:, 1].max())
        res[name] = {
            "solo_s_per_step": solo_s,
            "all_s_per_step": [float(x) for x in rows[:, 1]],
            "solo_env_steps_per_s": args.envs / solo_s,
            "aggregate_env_steps_per_s": ctx.world_size * args.envs / slowest,
            "efficiency": solo_s / slowest,
        }
    if stream_cm is not None:
        stream_cm.__exit__(None, None, None)
    q = s[0].joint_q.numpy()
    bad = ctx.all_reduce_sum([float((~np.isfinite(q)).sum())])[0]
    firsts = ctx.all_gather([first_s, build_s])

    if ctx.is_main:
        meta = machine_info(device)
        meta.update(
            {
                "args": vars(args),
                "world_size": ctx.world_size,
                "backend": ctx.backend,
                "nccl_nvls_enable": os.environ.get("NCCL_NVLS_ENABLE"),
                "first_step_s_per_rank": [float(x) for x in firsts[:, 0]],
                "build_s_per_rank": [float(x) for x in firsts[:, 1]],
                "nonfinite_joint_q": int(bad),
                "torch_distributed": {"nccl": getattr(torch.cuda.nccl, "version", lambda: None)() if cuda else None},
            }
        )
        body = []
        for name, r in res.items():
            body.append(
                [
                    name,
                    fmt_envs(args.envs),
                    f"{r['solo_s_per_step'] * 1e6:,.0f}",
                    f"{r['solo_env_steps_per_s']:,.0f}",
                    ", ".join(f"{x * 1e6:,.0f}" for x in r["all_s_per_step"]),
                    f"{r['aggregate_env_steps_per_s']:,.0f}",
                    f"{100 * r['efficiency']:.1f} %",
                ]
            )
        md = (
            f"# Weak scaling: {ctx.world_size} ranks x {fmt_envs(args.envs)} Pandas, graph-captured MuJoCo-Warp + "
            f"wpctrl\n\n{meta_markdown(meta)}\n\nMode `{args.mode}`, implicit, K = {K}; all-reduce of "
            f"{args.allreduce_numel:,} float32 per control step in the `+allreduce` rows; {args.steps} steps x "
            f"median of {args.repeats}. Non-finite joint_q at the end: {int(bad)}.\n\n"
            + md_table(
                [
                    "per control step",
                    "envs/rank",
                    "1 rank µs",
                    "1 rank env-steps/s",
                    "all ranks µs (per rank)",
                    f"{ctx.world_size} ranks env-steps/s",
                    "weak-scaling efficiency",
                ],
                body,
            )
        )
        tag = args.tag or f"{'cuda' if cuda else 'cpu'}_x{ctx.world_size}"
        j, m = write_results(args.out, f"multi_gpu_{tag}", meta, [{"variant": k, **v} for k, v in res.items()], md)
        print(md, flush=True)
        print(f"wrote {j} and {m}", flush=True)
    ctx.shutdown()


if __name__ == "__main__":
    main()
