"""What a kernel launch costs against its parameter count, and what a dependent index chain costs.

Three trivial kernels over ``envs x 9`` threads (a Panda's 9 rows), each writing one float per thread:

* ``p1``: 1 array parameter;
* ``p25``: 25 array parameters (wpctrl's substep kernel has ~25), of which it touches only the first;
* ``chain`` / ``flat`` / ``stride``: the same gather ``dst[i] = src[index(i)]`` through wpctrl's former index chain
  (``env_base[env] + row_off[row]``, a 1-D launch with an integer division), through one precomputed flat
  ``(envs, rows)`` index table on a 2-D launch (wpctrl, uneven worlds), or through env 0's ``(1, rows)`` table plus
  ``env * stride`` on a 2-D launch (wpctrl, replicated worlds).

For each: host time of a plain ``wp.launch``, of a recorded launch (``wp.launch(..., record_cmd=True)`` then
``Launch.launch()``, what wpctrl's engine does), and per node of a captured graph of ``--nodes`` back-to-back
launches (``wp.ScopedCapture`` / ``wp.capture_launch``: a CUDA graph on GPU, Warp's APIC replay on CPU).

    python bench/profiling/launch_params.py --device cuda:0 --envs 4k,1M --out OUT     # GPU, ~20 s
    python bench/profiling/launch_params.py --device cpu --envs 1,4k --clock thread    # CPU

Writes ``<out>/launch_params_<cpu|cuda>.{json,md}``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

from bench.common import (  # noqa: E402
    DEFAULT_OUT,
    Sync,
    fmt_envs,
    fmt_us,
    load_average,
    machine_info,
    md_table,
    measure_interleaved,
    meta_markdown,
    parse_envs,
    write_results,
)

ROWS = 9
A = wp.array[float]


@wp.kernel
def _p1(a0: A):
    i = wp.tid()
    a0[i] = a0[i] + 1.0


@wp.kernel
def _p25(
    a0: A, a1: A, a2: A, a3: A, a4: A, a5: A, a6: A, a7: A, a8: A, a9: A, a10: A, a11: A, a12: A,
    a13: A, a14: A, a15: A, a16: A, a17: A, a18: A, a19: A, a20: A, a21: A, a22: A, a23: A, a24: A,
):  # fmt: skip
    i = wp.tid()
    a0[i] = a0[i] + 1.0


@wp.kernel
def _chain(env_base: wp.array[wp.int32], row_off: wp.array[wp.int32], src: wp.array[float], dst: wp.array2d[float]):
    tid = wp.tid()
    rows = row_off.shape[0]
    env = tid // rows
    r = tid - env * rows
    dst[env, r] = src[env_base[env] + row_off[r]]


@wp.kernel
def _stride(idx0: wp.array2d[wp.int32], stride: int, src: wp.array[float], dst: wp.array2d[float]):
    env, r = wp.tid()
    dst[env, r] = src[idx0[0, r] + env * stride]


@wp.kernel
def _flat(idx: wp.array2d[wp.int32], src: wp.array[float], dst: wp.array2d[float]):
    env, r = wp.tid()
    dst[env, r] = src[idx[env, r]]


def launches(n_envs: int, device):
    """{name: (kernel, dim, inputs)}; the index tables follow a replicated Panda's layout (stride 9 coordinates)."""
    n = n_envs * ROWS
    arrays = [wp.zeros(n, dtype=float, device=device) for _ in range(25)]
    stride = 9
    base = np.arange(n_envs, dtype=np.int32) * stride
    off = np.arange(ROWS, dtype=np.int32)
    src = wp.array(np.arange(n_envs * stride, dtype=np.float32), dtype=float, device=device)
    dst = wp.zeros((n_envs, ROWS), dtype=float, device=device)
    return {
        "p1": (_p1, n, arrays[:1]),
        "p25": (_p25, n, arrays),
        "chain": (
            _chain,
            n,
            [wp.array(base, dtype=wp.int32, device=device), wp.array(off, dtype=wp.int32, device=device), src, dst],
        ),
        "flat": (
            _flat,
            (n_envs, ROWS),
            [wp.array(base[:, None] + off[None, :], dtype=wp.int32, device=device), src, dst],
        ),
        "stride": (_stride, (n_envs, ROWS), [wp.array(off[None, :], dtype=wp.int32, device=device), stride, src, dst]),
    }


def run(args, n_envs: int, device, sync) -> list[dict]:
    fns = {}
    specs = launches(n_envs, device)
    for name, (kernel, dim, inputs) in specs.items():
        wp.launch(kernel, dim=dim, inputs=inputs, device=device)  # compile and load
        cmd = wp.launch(kernel, dim=dim, inputs=inputs, device=device, record_cmd=True)
        fns[f"{name}/launch"] = lambda k=kernel, d=dim, i=inputs: wp.launch(k, dim=d, inputs=i, device=device)
        fns[f"{name}/recorded"] = cmd.launch
        sync()
        with wp.ScopedCapture(device=device) as cap:
            for _ in range(args.nodes):
                cmd.launch()
        fns[f"{name}/graph"] = lambda g=cap.graph: wp.capture_launch(g)
    times = measure_interleaved(
        fns, sync, repeats=args.repeats, min_time=args.min_time, warmup=args.warmup, clock=args.clock
    )
    rows = []
    for key, t in times.items():
        name, how = key.split("/")
        per = args.nodes if how == "graph" else 1
        rows.append(
            {
                "envs": n_envs,
                "threads": n_envs * ROWS,
                "kernel": name,
                "how": how,
                "nodes": per,
                "us_per_launch": t["median_s"] * 1e6 / per,
                "us_per_call": t["median_s"] * 1e6,
                "samples_us": [x * 1e6 for x in t["samples_s"]],
                "iters": t["iters"],
                "clock": args.clock,
            }
        )
    return rows


def markdown(meta: dict, rows: list[dict], nodes: int) -> str:
    out = [
        "# Launch cost against parameter count and index chains\n",
        meta_markdown(meta) + "\n",
        f"µs per launch (graph: per node of a {nodes}-node graph, replayed). p1 / p25: a trivial kernel with 1 / 25 "
        "array parameters; chain / flat / stride: a gather through base[env] + off[row] (1-D launch, integer "
        "division), through a flat (env, row) index table, or through env 0's row table + env * stride (2-D).\n",
    ]
    hows = ["launch", "recorded", "graph"]
    table = []
    for n in sorted({r["envs"] for r in rows}):
        for k in ["p1", "p25", "chain", "flat", "stride"]:
            got = {r["how"]: r for r in rows if r["envs"] == n and r["kernel"] == k}
            if got:
                table.append(
                    [fmt_envs(n), k] + [fmt_us(got[h]["us_per_launch"] * 1e-6) if h in got else "–" for h in hows]
                )
    out.append(md_table(["envs", "kernel", "wp.launch", "recorded launch", "graph node"], table))
    return "\n".join(out)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--device", default="cuda:0" if wp.is_cuda_available() else "cpu")
    p.add_argument("--envs", default="4k,1M", help="comma list, k/M suffixes")
    p.add_argument("--nodes", type=int, default=6, help="launches per captured graph (a control step: 1 + K = 6)")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--min-time", type=float, default=None, help="seconds per sample (default cpu 0.05, cuda 0.02)")
    p.add_argument("--warmup", type=int, default=3)
    p.add_argument("--clock", default="wall", choices=["wall", "thread"])
    p.add_argument("--out", default=str(DEFAULT_OUT))
    p.add_argument("--tag", default=None, help="file-name suffix (default: the device kind)")
    args = p.parse_args(argv)
    wp.init()
    device = wp.get_device(args.device)
    if args.clock == "thread" and device.is_cuda:
        p.error("--clock thread only makes sense on the CPU device")
    if args.min_time is None:
        args.min_time = 0.02 if device.is_cuda else 0.05
    sync = Sync(device)
    meta = machine_info(device)
    meta.update({"args": vars(args), "loadavg_start": load_average()})
    print(meta_markdown(meta), flush=True)
    rows = []
    t0 = time.perf_counter()
    for n in parse_envs(args.envs):
        got = run(args, n, device, sync)
        for r in got:
            print(f"[{fmt_envs(n)}] {r['kernel']:>5} {r['how']:>8}: {r['us_per_launch']:9.2f} us/launch", flush=True)
        rows += got
    meta["wall_s"] = time.perf_counter() - t0
    tag = args.tag or ("cuda" if device.is_cuda else "cpu")
    j, m = write_results(args.out, f"launch_params_{tag}", meta, rows, markdown(meta, rows, args.nodes))
    print(f"wrote {j} and {m}", flush=True)


if __name__ == "__main__":
    main()
