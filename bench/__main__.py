"""``python -m bench``: run named benchmark stages in one session, within a time budget; see bench/README.md.

Examples: ``python -m bench --list`` (the stages and groups); ``python -m bench step-explicit step-implicit --out
$OUT`` (two stages, results in ``$OUT/<stage>/``); ``python -m bench ab --baseline-tree .gpu/ab_base --out $OUT``
(the A/B of two trees).
"""

from __future__ import annotations

import argparse
import os
import sys
import textwrap
from pathlib import Path

from bench.session import ROOT, Session
from bench.stages import GROUPS, STAGES, expand


def _list() -> str:
    lines = []
    for group, names in GROUPS.items():
        lines.append(f"{group}: {' '.join(names)}")
    lines.append("")
    for st in STAGES:
        head = f"{st.name} [{st.group}, ~{st.expected_s} s] -> {st.outputs}"
        lines.append(head)
        lines += textwrap.wrap(st.what, 110, initial_indent="    ", subsequent_indent="    ")
        if st.needs:
            lines.append(f"    needs: {', '.join(st.needs)}")
        for k, v in st.params.items():
            lines.append(f"    --set {k}=...  ({v})")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m bench",
        description="Run benchmark stages (or groups of them) one after another within a time budget.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="groups: " + "; ".join(f"{g} = {' '.join(n)}" for g, n in GROUPS.items()),
    )
    p.add_argument("stages", nargs="*", help="stage or group names, in order")
    p.add_argument("--list", action="store_true", help="list the stages, their times, outputs and parameters")
    p.add_argument("--out", default=None, help="results folder (default: $OUT, else out/bench, git-ignored)")
    p.add_argument("--budget", type=float, default=570, help="seconds for the whole session; 0: none (default 570)")
    p.add_argument("--device", default="cuda:0", help="the device of every benchmark (default cuda:0)")
    p.add_argument("--envs", default=None, help="env counts for every stage that takes them, e.g. 1k,4k")
    p.add_argument("--repeats", type=int, default=None, help="timed samples per row for every benchmark")
    p.add_argument("--baseline-tree", type=Path, default=None, help="the old tree of the A/B stages (holds wpctrl/)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="a stage parameter (--list)")
    p.add_argument("--dry-run", action="store_true", help="print the commands without running them")
    args = p.parse_args(argv)
    if args.list or not args.stages:
        print(_list())
        return 0
    try:
        stages = expand(args.stages)
    except KeyError as e:
        p.error(f"unknown stage or group {e}; see --list")
    params = {}
    for kv in args.set:
        key, sep, value = kv.partition("=")
        if not sep:
            p.error(f"--set {kv}: expected KEY=VALUE")
        params[key] = value
    out = Path(args.out or os.environ.get("OUT") or ROOT / "out" / "bench")
    session = Session(out, budget_s=args.budget or None, device=args.device, envs=args.envs, repeats=args.repeats,
                      params=params, baseline_tree=args.baseline_tree, dry_run=args.dry_run)  # fmt: skip
    results = session.run_stages(stages)
    unused = set(params) - session.used_params
    if unused:
        print(f"[bench] note: no stage read --set {', '.join(sorted(unused))}", flush=True)
    return 0 if all(r.status in ("ok", "skipped") for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
