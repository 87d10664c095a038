"""Write the test suite's counts and times into docs/testing.md from real runs: the page never states them by hand.

Run the suite with a JUnit report, then this script with each report and what the run was:

    python -m pytest -q --junitxml=/tmp/fast.xml                          # the README's command (the fast tests)
    python -m pytest -q -m slow --junitxml=/tmp/slow.xml                  # the slow tests
    python tools/test_report.py --run "fast, warm cache" /tmp/fast.xml --run "slow, warm cache" /tmp/slow.xml

It replaces the table between the ``test-runs`` markers of docs/testing.md with one row per report: tests, passed,
skipped, failed, the run's wall time (the report's own ``time``), the machine (cores, CPU model), the date and the
commit. ``--wall SECONDS`` per run overrides the time with one measured around the whole command (collection and
start-up included).
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "testing.md"
BEGIN, END = "<!-- test-runs:begin -->", "<!-- test-runs:end -->"


def counts(path: Path) -> dict:
    """Tests, failures, errors, skips and the time of a pytest JUnit report."""
    root = ET.parse(path).getroot()
    suites = [root] if root.tag == "testsuite" else list(root.iter("testsuite"))
    total = {"tests": 0, "failures": 0, "errors": 0, "skipped": 0, "time": 0.0}
    for s in suites:
        for k in ("tests", "failures", "errors", "skipped"):
            total[k] += int(s.get(k, 0))
        total["time"] += float(s.get("time", 0.0))
    total["passed"] = total["tests"] - total["failures"] - total["errors"] - total["skipped"]
    return total


def machine() -> str:
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{os.cpu_count()}-core {model}, Python {platform.python_version()}"


def commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()  # fmt: skip
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def minutes(seconds: float) -> str:
    return f"{seconds / 60:.1f} min"


def table(rows: list[tuple[str, dict, float | None]]) -> str:
    lines = ["| run | tests | passed | skipped | failed | wall time | machine | date, commit |", "|---" * 8 + "|"]
    stamp = f"{datetime.date.today().isoformat()}, {commit()}"
    for label, c, wall in rows:
        t = minutes(wall if wall is not None else c["time"])
        lines.append(f"| {label} | {c['tests']:,} | {c['passed']:,} | {c['skipped']:,} | "
                     f"{c['failures'] + c['errors']:,} | {t} | {machine()} | {stamp} |")  # fmt: skip
    return "\n".join(lines)


def write(doc: Path, text: str) -> None:
    page = doc.read_text()
    if BEGIN not in page or END not in page:
        raise SystemExit(f"{doc}: expected the markers {BEGIN} and {END}")
    head, rest = page.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    doc.write_text(f"{head}{BEGIN}\n{text}\n{END}{tail}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", nargs=2, action="append", metavar=("LABEL", "JUNIT_XML"), required=True,
                    help="what the run was and its pytest --junitxml report")  # fmt: skip
    ap.add_argument(
        "--wall",
        type=float,
        action="append",
        default=[],
        help="the wall time [s] of each run, in the order of --run (default: the report's time)",
    )
    ap.add_argument("--doc", type=Path, default=DOC)
    args = ap.parse_args(argv)
    if args.wall and len(args.wall) != len(args.run):
        ap.error(f"--wall: expected one per --run ({len(args.run)}), got {len(args.wall)}")
    walls = args.wall or [None] * len(args.run)
    rows = [(label, counts(Path(path)), wall) for (label, path), wall in zip(args.run, walls)]
    text = table(rows)
    write(args.doc, text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
