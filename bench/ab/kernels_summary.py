"""Summarise ``python -m bench ab-kernels``: per case and size, the median over rounds of A and of B (graph replay and
eager µs) and B / A; and whether the two trees' outputs on the fixed sequence are the same bits.

    python -m bench.ab.kernels_summary WORK_DIR [--label-a A --label-b B]   # reads ab_kernels_{A,B}_<round>.json,
                                                                            # A.npz / B.npz

The labels name the trees where their recorded commit cannot (a tree without git metadata reads its parent's).
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import statistics

import numpy as np


def timing(work: str, labels: dict[str, str] | None = None) -> list[str]:
    runs: dict[tuple, dict[str, dict[str, list[float]]]] = {}
    commits = {}
    for path in sorted(glob.glob(os.path.join(work, "ab_kernels_*.json"))):
        side = os.path.basename(path)[len("ab_kernels_") :].split("_")[0]
        data = json.load(open(path))
        commits[side] = (labels or {}).get(side) or data.get("meta", {}).get("wpctrl_commit")
        for r in data["rows"]:
            by = runs.setdefault((r["case"], r["envs"]), {}).setdefault(side, {"graph_us": [], "eager_us": []})
            by["graph_us"].append(r["graph_us"])
            by["eager_us"].append(r["eager_us"])
    out = [
        "# A/B: the captured control step of every kernel family, two wpctrl trees, one GPU, alternating runs\n",
        f"A = {commits.get('A')}, B = {commits.get('B')}; median over rounds of each run's median (µs); "
        "set_action + 5 substeps\n",
        "| case | envs | A graph | B graph | B / A graph | A eager | B eager | B / A eager |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for (case, envs), sides in sorted(runs.items()):
        med = {s: {k: statistics.median(v) for k, v in d.items()} for s, d in sides.items()}
        a, b = med.get("A"), med.get("B")
        if a is None or b is None:
            out.append(f"| {case} | {envs} | missing side | | | | | |")
            continue
        out.append(
            f"| {case} | {envs} | {a['graph_us']:.2f} | {b['graph_us']:.2f} | {b['graph_us'] / a['graph_us']:.3f} | "
            f"{a['eager_us']:.1f} | {b['eager_us']:.1f} | {b['eager_us'] / a['eager_us']:.3f} |"
        )
    return out


def outputs(work: str) -> list[str]:
    a_path, b_path = os.path.join(work, "A.npz"), os.path.join(work, "B.npz")
    if not (os.path.exists(a_path) and os.path.exists(b_path)):
        return ["\n(no outputs to compare)"]
    a, b = np.load(a_path), np.load(b_path)
    keys = sorted(set(a.files) | set(b.files))
    differ, missing = [], [k for k in keys if k not in a.files or k not in b.files]
    for k in keys:
        if k in missing:
            continue
        x, y = a[k], b[k]
        same = x.shape == y.shape and x.dtype == y.dtype
        if not same or not np.array_equal(
            np.ascontiguousarray(x).view(np.uint8), np.ascontiguousarray(y).view(np.uint8)
        ):
            d = float(np.nanmax(np.abs(x.astype(np.float64) - y.astype(np.float64)))) if x.shape == y.shape else None
            differ.append(f"{k.replace('__', '/')}: max |B - A| = {d}")
    head = f"\nOutputs of the fixed sequence (64 envs, 3 control steps per case): {len(keys)} arrays compared, "
    if not differ and not missing:
        return [head + "all bitwise equal."]
    return [head + f"{len(differ)} differ, {len(missing)} missing:"] + [f"- {d}" for d in differ + missing]


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("work")
    p.add_argument("--label-a", default=None)
    p.add_argument("--label-b", default=None)
    args = p.parse_args(argv)
    print("\n".join(timing(args.work, {"A": args.label_a, "B": args.label_b}) + outputs(args.work)))


if __name__ == "__main__":
    main()
