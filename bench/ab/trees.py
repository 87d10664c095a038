"""Two wpctrl source trees timed by the same benchmark in one session: the A/B stages of ``python -m bench``.

The benchmark code is this tree's; the ``wpctrl`` it imports is chosen per process by ``BENCH_WPCTRL_TREE``
(``bench/common.py``): the old tree (side A, ``--baseline-tree``) or this one (side B). Runs alternate A, B, then B,
A, ... round after round on one machine, so that a change is measured free of machine-to-machine and run-to-run
drift; the summary (``bench/ab/summary.py``) is rewritten after every run, so a session cut short keeps what it
measured. A run starts only if the budget still holds the longest run so far.

A baseline tree is a directory holding the old ``wpctrl/`` package; a checkout (``git worktree add``) or what
``python -m bench ab-baseline --set rev=<commit>`` writes to ``.gpu/ab_base`` (the package, and the commits of both
trees in ``COMMIT`` / ``NEW_COMMIT``, for a machine whose copy of the repository has no git).
"""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

from bench.ab import summary
from bench.session import ROOT, Cmd, Session


def tree_label(tree: Path) -> str:
    """The old tree's name: its recorded commit, else its git HEAD, else its path."""
    f = tree / "COMMIT"
    if f.is_file():
        return f.read_text().strip()
    return _git(tree, "rev-parse", "--short", "HEAD") or str(tree)


def this_label(baseline: Path) -> str:
    """This tree's name: the commit recorded beside the baseline when it was prepared, else git HEAD (+changes)."""
    f = baseline / "NEW_COMMIT"
    if f.is_file():
        return f.read_text().strip()
    head = _git(ROOT, "rev-parse", "--short", "HEAD")
    if not head:
        return "this tree"
    return head + ("+changes" if _git(ROOT, "status", "--porcelain", "wpctrl") else "")


def _git(where: Path, *args: str) -> str:
    try:
        r = subprocess.run(["git", "-C", str(where), *args], capture_output=True, text=True, timeout=20)
        return r.stdout.strip() if r.returncode == 0 else ""
    except (OSError, subprocess.SubprocessError):
        return ""


def alternate(session: Session, *, stem: str, module: str, cases: dict[str, list[str]], envs: str,
              per_run_limit_s: float) -> None:  # fmt: skip
    """Run ``module`` in both trees for every case, ``rounds`` times, alternating; then summarise.

    ``cases``: {case name (no ``_``): the module's arguments}. Each run writes ``<stem>_ab_<side>_<case>_<round>``
    (``.json``, ``.md``) into ``<stage>/runs/``; the table goes to ``<stage>/<stage>.md`` (``ab_step.md`` ...).
    """
    old, new = session.baseline_tree.resolve(), ROOT
    labels = tree_label(old), this_label(old)
    runs = session.dir() / "runs"
    runs.mkdir(parents=True, exist_ok=True)
    table = session.dir() / (session.stage.name.replace("-", "_") + ".md")
    rounds = session.param("rounds", 3)
    session.say(f"A/B {stem}: old = {labels[0]} ({old}), new = {labels[1]} ({new}); {rounds} rounds, envs {envs}")
    longest = 0.0
    for rnd in range(1, rounds + 1):
        sides = (("A", old), ("B", new)) if rnd % 2 else (("B", new), ("A", old))
        for side, tree in sides:
            for case, args in cases.items():
                if session.left() < 1.2 * longest + 5:
                    session.say(f"A/B {stem}: stopping before round {rnd} {side} {case} ({session.left():.0f} s left)")
                    session.status = "cut"
                    session.say("\n" + summary.write(runs, table, *labels))
                    return
                t0 = time.monotonic()
                argv = ["python", "-m", module, "--device", session.device, "--envs", envs,
                        "--out", runs, "--tag", f"ab_{side}_{case}_{rnd}", *args]  # fmt: skip
                session.run(Cmd(f"{stem} {side} {case} round {rnd}", argv, per_run_limit_s,
                                env={"BENCH_WPCTRL_TREE": tree}))  # fmt: skip
                longest = max(longest, time.monotonic() - t0)
                summary.write(runs, table, *labels)
    session.say("\n" + summary.write(runs, table, *labels))
