"""Summarise bench/ab_step.sh: per (actuation, envs, variant), the median over rounds of A and of B, and B / A."""

from __future__ import annotations

import glob
import json
import os
import statistics
import sys


def main(work: str) -> None:
    runs: dict[tuple, dict[str, list[float]]] = {}
    commits = {}
    for path in sorted(glob.glob(os.path.join(work, "controller_step_ab_*.json"))):
        tag = os.path.basename(path)[len("controller_step_ab_") : -len(".json")]
        side, act, _round = tag.split("_")
        data = json.load(open(path))
        commits[side] = data.get("meta", {}).get("wpctrl_commit")
        for r in data["rows"]:
            key = (act, r["envs"], r["variant"])
            runs.setdefault(key, {}).setdefault(side, []).append(r["us_per_step"])
    print("# A/B: the captured and eager control step of two wpctrl trees, one GPU, alternating runs\n")
    print(f"A = {commits.get('A')}, B = {commits.get('B')} (median over rounds of each run's median, µs)\n")
    print("| actuation | envs | variant | A µs | B µs | B / A |")
    print("|---|---|---|---|---|---|")
    for (act, envs, variant), sides in sorted(runs.items()):
        a = statistics.median(sides.get("A", [float("nan")]))
        b = statistics.median(sides.get("B", [float("nan")]))
        print(f"| {act} | {envs} | {variant} | {a:.2f} | {b:.2f} | {b / a:.3f} |")


if __name__ == "__main__":
    main(sys.argv[1])
