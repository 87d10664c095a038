"""Summarise an A/B of two wpctrl trees: per (bench, case, envs, variant), the old tree's and the new tree's time, the
ratio new / old, and how much it moves from round to round.

Reads the result files that the A/B stages of ``python -m bench`` (``ab-step``, ``ab-osc``, ``ab-task``) write, named
``<bench>_ab_<side>_<case>_<round>.json`` (side ``A`` = the old tree, ``B`` = the new one):

* ``controller_step`` and ``osc_step``: one row per (envs, variant) with ``us_per_step`` and ``samples_us``;
* ``task_step``: one row per (task, envs) with the seconds of ``env step``, ``controller``, ``task kernels`` and
  ``physics`` (the last is the bare MuJoCo-Warp step, the same code in both trees: a check of the machine's drift).

Columns: the median over rounds of each run's median (µs), their ratio, the smallest and largest per-round ratio
(the two trees' runs of one round are back to back, so a round's ratio is free of slower drift), and the spread of
the timed samples inside a run (largest minus smallest over the median, the median of that over runs).

    python -m bench.ab.summary RUN_DIR [--label-old A --label-new B] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
from pathlib import Path

NAME = re.compile(r"^(?P<bench>[a-z_]+?)_ab_(?P<side>[AB])_(?P<case>[A-Za-z0-9-]+)_(?P<round>\d+)\.json$")
TASK_PARTS = ("env step", "controller", "task kernels", "physics")


def _records(path: Path, bench: str, case: str):
    """(case, envs, variant, µs, samples in µs or None) of every timed row of one result file."""
    rows = json.loads(path.read_text()).get("rows", [])
    for r in rows:
        if bench == "task_step":
            for part in TASK_PARTS:
                if part in r:
                    yield r.get("task", case), r["envs"], part, r[part] * 1e6, None
        elif "us_per_step" in r and r.get("variant") != "mujoco_warp_step":
            variant = r["variant"] + (" interp" if r.get("interpolate") else "")
            yield case, r["envs"], variant, r["us_per_step"], r.get("samples_us")


def collect(run_dir) -> dict:
    """{(bench, case, envs, variant): {side: {round: (µs, relative sample spread or None)}}} and the commits."""
    table: dict = {}
    commits: dict = {}
    for path in sorted(Path(run_dir).glob("*_ab_*.json")):
        m = NAME.match(path.name)
        if not m:
            continue
        bench, side, rnd = m["bench"], m["side"], int(m["round"])
        commits.setdefault(side, json.loads(path.read_text()).get("meta", {}).get("wpctrl_commit"))
        for case, envs, variant, us, samples in _records(path, bench, m["case"]):
            spread = (max(samples) - min(samples)) / us if samples and us > 0 else None
            table.setdefault((bench, case, envs, variant), {}).setdefault(side, {})[rnd] = (us, spread)
    return {"table": table, "commits": commits}


def _envs(n: int) -> str:
    for div, suffix in ((1 << 20, "M"), (1 << 10, "k")):
        if n >= div and n % div == 0:
            return f"{n // div}{suffix}"
    return str(n)


def summarise(run_dir, label_old: str | None = None, label_new: str | None = None) -> tuple[str, list[dict]]:
    """The Markdown table and one record per row."""
    got = collect(run_dir)
    old = label_old or got["commits"].get("A") or "A"
    new = label_new or got["commits"].get("B") or "B"
    lines = [
        "# A/B: two wpctrl trees, one machine, alternating runs\n",
        f"old = {old}, new = {new}. µs per step: the median over rounds of each run's median; new / old of those; "
        "the smallest and largest ratio of one round's two runs; the spread of the timed samples in a run "
        "(max − min over the median, median over runs).\n",
        "| bench | case | envs | variant | old µs | new µs | new / old | per round | sample spread old / new |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    records = []
    for key in sorted(got["table"], key=lambda k: (k[0], k[1], k[3], k[2])):
        bench, case, envs, variant = key
        sides = got["table"][key]
        a, b = sides.get("A", {}), sides.get("B", {})
        if not a or not b:
            lines.append(f"| {bench} | {case} | {_envs(envs)} | {variant} | {'missing' if not a else ''} | "
                         f"{'missing' if not b else ''} | | | |")  # fmt: skip
            continue
        a_us = statistics.median(v[0] for v in a.values())
        b_us = statistics.median(v[0] for v in b.values())
        per_round = [b[r][0] / a[r][0] for r in sorted(set(a) & set(b))]
        spread = {}
        for side, runs in (("old", a), ("new", b)):
            s = [v[1] for v in runs.values() if v[1] is not None]
            spread[side] = statistics.median(s) if s else None
        rounds = f"{min(per_round):.3f}–{max(per_round):.3f}" if len(per_round) > 1 else "–"
        sp = " / ".join("–" if spread[k] is None else f"{100 * spread[k]:.1f} %" for k in ("old", "new"))
        lines.append(f"| {bench} | {case} | {_envs(envs)} | {variant} | {a_us:.2f} | {b_us:.2f} | "
                     f"{b_us / a_us:.3f} | {rounds} | {sp} |")  # fmt: skip
        records.append({"bench": bench, "case": case, "envs": envs, "variant": variant, "old_us": a_us,
                        "new_us": b_us, "new_over_old": b_us / a_us, "per_round_new_over_old": per_round,
                        "sample_spread_old": spread["old"], "sample_spread_new": spread["new"]})  # fmt: skip
    if not records:
        lines.append("\n(no pair of runs yet)")
    return "\n".join(lines) + "\n", records


def write(run_dir, md_path, label_old: str | None = None, label_new: str | None = None) -> str:
    """Write the Markdown table to ``md_path`` and its records beside it (``.json``); returns the Markdown."""
    text, records = summarise(run_dir, label_old, label_new)
    md_path = Path(md_path)
    md_path.write_text(text)
    md_path.with_suffix(".json").write_text(json.dumps({"old": label_old, "new": label_new, "rows": records}, indent=1))
    return text


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("run_dir")
    p.add_argument("--label-old", default=None)
    p.add_argument("--label-new", default=None)
    p.add_argument("--json", default=None, help="also write the rows as JSON here")
    args = p.parse_args(argv)
    text, records = summarise(args.run_dir, args.label_old, args.label_new)
    print(text)
    if args.json:
        Path(args.json).write_text(json.dumps(records, indent=1))


if __name__ == "__main__":
    main()
