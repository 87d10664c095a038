"""Mutation check: does the test suite notice a small, deliberate bug in the kernels and the engine?

The mutations are data in ``tools/mutations/`` (one module per area of the code); this file runs them. Each mutation
is one exact text replacement in one file of ``wpctrl/`` (a sign flip, an off-by-one, a dropped
term, a check that skips a case). For each one this script copies the working tree to a temporary directory, applies
the replacement there, and runs the fast tests of the copy against the copy's ``wpctrl`` (the editable install's
import hook, which maps ``wpctrl`` to this checkout, is removed from the child interpreter, and the child checks that
the module it imported holds the mutated text). ``-x`` stops at the first failing test: that test *killed* the
mutation. A mutation that passes every test it ran *survived*: a blind spot of the suite.

Not part of CI: every mutation recompiles the kernels of the mutated module (Warp caches them by source, so the
mutated kernels land next to the real ones in Warp's kernel cache; ``--warp-cache DIR`` puts them elsewhere).

    python tools/mutate.py                    # every mutation, one at a time
    python tools/mutate.py --list             # names and what each one breaks
    python tools/mutate.py -k delay -k ema    # the mutations whose name contains "delay" or "ema"
    python tools/mutate.py --baseline         # the fast tests on an unmutated copy (must pass)
    python tools/mutate.py --markdown out.md  # also write the result table
    python tools/mutate.py --check            # only check that every mutation's text is still in its file, once
    python tools/mutate.py --changed-since main -j 8   # those in files changed since a revision, 8 at a time

Exit status: 0 when every mutation run was killed, 1 when one survived, 2 on a stale mutation (its text is no longer
in the file exactly once) or a baseline failure.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import os
import shutil
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

FAST_TESTS = (
    "tests/test_semantics.py",
    "tests/test_conformance.py",
    "tests/test_launches.py",
    "tests/test_actuation.py",
    "tests/test_base_controllers.py",
    "tests/test_errors.py",
    "tests/test_binding.py",
    "tests/test_plan.py",
    "tests/test_acceleration.py",
    "tests/test_coupled.py",
    "tests/test_ee.py",
    "tests/test_ee_conformance.py",
    "tests/test_actuator_models.py",
    "tests/test_actuator_net.py",
    "tests/test_actuator_net_fused.py",
    "tests/test_multi_axis.py",
    "tests/test_gravity.py",
    "tests/test_alloc_sync.py",
    "tests/test_properties.py",
    "tests/test_config_boundaries.py",
    "tests/test_actuator_setups.py",
    "tests/test_construction_orders.py",
    "tests/test_distributed_ranks.py",
    "tests/test_impedance.py",
    "tests/test_impedance_envs.py",
    "tests/test_second_controller.py",
)
"""The fast tests a mutation runs after its own targeted ones (a minute or less each on a 2-core CPU, warm cache)."""

PROPERTY_EXAMPLES = "60"
"""Hypothesis examples per property test in a mutant (``WPCTRL_PROPERTY_EXAMPLES``); the suite's default is larger."""


sys.path.insert(0, str(ROOT / "tools"))
from mutations import Mutation, all_mutations  # noqa: E402

MUTATIONS: list[Mutation] = all_mutations()


# ----------------------------------------------------------------------------------------------------------------------
# Running one mutation in a copy.

_CHILD = textwrap.dedent(
    """
    import importlib, json, sys, time
    root, out, mod, new = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4]
    # The editable install's finder maps 'wpctrl' to the original checkout: drop it, import the copy's.
    sys.meta_path[:] = [f for f in sys.meta_path if '__editable__' not in getattr(f, '__module__', '')]
    sys.path_hooks[:] = [h for h in sys.path_hooks if '__editable__' not in getattr(h, '__module__', '')]
    sys.path_importer_cache.clear()
    sys.path.insert(0, root)
    import wpctrl
    assert wpctrl.__file__.startswith(root), ('wpctrl imported from', wpctrl.__file__)
    if mod:
        m = importlib.import_module(mod)
        with open(m.__file__) as f:
            src = f.read()
        assert m.__file__.startswith(root) and new in src, ('mutation not active in', m.__file__)
    import pytest

    class Recorder:
        def __init__(self):
            self.failed, self.ran = [], 0

        def pytest_runtest_logreport(self, report):
            if report.when == 'call':
                self.ran += 1
            if report.failed and report.nodeid not in self.failed:
                self.failed.append(report.nodeid)

        def pytest_collectreport(self, report):
            if report.failed:
                self.failed.append(report.nodeid or 'collection')

    rec = Recorder()
    t0 = time.time()
    code = pytest.main(sys.argv[5:], plugins=[rec])
    with open(out, 'w') as f:
        json.dump({'exit': int(code), 'failed': rec.failed, 'ran': rec.ran, 'seconds': time.time() - t0}, f)
    """
)


def tree_files(root: Path) -> list[str]:
    """Tracked and untracked, not ignored files of the working tree."""
    out = subprocess.run(
        ["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=root, check=True, capture_output=True
    ).stdout.decode()
    return [p for p in out.split("\0") if p and (root / p).is_file()]


def make_copy(root: Path, files: list[str]) -> Path:
    dst = Path(tempfile.mkdtemp(prefix="wpctrl-mutant-"))
    for rel in files:
        target = dst / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(root / rel, target)
    return dst


def apply(copy: Path, m: Mutation) -> None:
    path = copy / m.file
    text = path.read_text()
    n = text.count(m.old)
    if n != 1:
        raise LookupError(f"{m.name}: its text occurs {n} times in {m.file} (expected once): update the mutation")
    path.write_text(text.replace(m.old, m.new))


def module_name(file: str) -> str:
    return file[:-3].replace("/", ".") if file.startswith("wpctrl/") and file.endswith(".py") else ""


def run_tests(copy: Path, tests: list[str], mod: str, marker: str, args) -> dict:
    out = copy / "mutate-result.json"
    env = dict(os.environ)
    env["PYTHONPATH"] = str(copy)
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    env.setdefault("WPCTRL_PROPERTY_EXAMPLES", PROPERTY_EXAMPLES)
    if args.warp_cache:
        env["WARP_CACHE_PATH"] = args.warp_cache
    cmd = [sys.executable, "-c", _CHILD, str(copy), str(out), mod, marker]
    cmd += ["-x", "-q", "-p", "no:cacheprovider", "--no-header", "--no-cov", "-m", "slow or not slow", *tests]
    # no coverage in a mutant; every test it names runs, the slow ones too
    t0 = time.time()
    try:
        proc = subprocess.run(cmd, cwd=copy, env=env, capture_output=True, text=True, timeout=args.timeout)
    except subprocess.TimeoutExpired:
        return {"exit": -1, "failed": [], "ran": 0, "seconds": time.time() - t0, "log": "timeout"}
    if not out.exists():
        log = proc.stderr[-3000:]
        return {"exit": proc.returncode, "failed": [], "ran": 0, "seconds": time.time() - t0, "log": log}
    res = json.loads(out.read_text())
    res["seconds"] = time.time() - t0
    res["log"] = (proc.stdout + proc.stderr)[-3000:]
    return res


def test_list(m: Mutation | None, copy: Path) -> list[str]:
    first = list(m.tests) if m else []
    # a file of FAST_TESTS that a targeted test id is in is left out: pytest would merge the id into that file's run,
    # at the file's place in the list, and the targeted test would no longer run first
    named = {t.split("::")[0] for t in first}
    rest = [t for t in FAST_TESTS if t not in first and t not in named]
    tests = [t for t in first + rest if (copy / t.split("::")[0]).exists()]
    if not tests:
        raise LookupError("no test to run (the listed test files are missing)")
    return tests


def run_one(m: Mutation | None, files: list[str], args) -> dict:
    copy = make_copy(ROOT, files)
    try:
        if m is not None:
            apply(copy, m)
        res = run_tests(copy, test_list(m, copy), module_name(m.file) if m else "", m.new if m else "", args)
    finally:
        if not args.keep:
            shutil.rmtree(copy, ignore_errors=True)
    if res["exit"] == -1:
        res["status"] = "timeout"
    elif res["failed"]:
        res["status"] = "killed"
    elif res["exit"] == 0:
        res["status"] = "survived"
    else:
        res["status"] = "error"
    return res


def markdown(rows: list[tuple[Mutation, dict]]) -> str:
    lines = ["| mutation | what it breaks | result | killed by | time [s] |", "|---|---|---|---|---|"]
    for m, r in rows:
        killer = r["failed"][0] if r["failed"] else "—"
        lines.append(f"| `{m.name}` | {m.what} | {r['status']} | `{killer}` | {r['seconds']:.0f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-k", action="append", default=[], help="run only mutations whose name contains this")
    ap.add_argument("--list", action="store_true", help="list the mutations and exit")
    ap.add_argument("--baseline", action="store_true", help="run the fast tests on an unmutated copy")
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per mutation")
    ap.add_argument("--warp-cache", default=None, help="Warp kernel cache for the mutants (default: Warp's own)")
    ap.add_argument("--keep", action="store_true", help="keep the temporary copies")
    ap.add_argument("--markdown", default=None, help="write the result table to this file")
    ap.add_argument("--json", default=None, help="write the raw results to this file")
    ap.add_argument("--check", action="store_true", help="only check that every chosen mutation still applies")
    ap.add_argument("--changed-since", default=None, help="only mutations of files changed since this git revision")
    ap.add_argument("-j", "--jobs", type=int, default=1, help="mutants run at once (each in its own copy)")
    args = ap.parse_args(argv)

    chosen = [m for m in MUTATIONS if not args.k or any(k in m.name for k in args.k)]
    if args.changed_since:
        diff = subprocess.run(
            ["git", "diff", "--name-only", args.changed_since], cwd=ROOT, check=True, capture_output=True, text=True
        ).stdout.split()
        chosen = [m for m in chosen if m.file in diff]
    if args.list:
        for m in chosen:
            print(f"{m.name:40s} {m.file:36s} {m.what}")
        return 0
    files = tree_files(ROOT)
    if args.baseline:
        r = run_one(None, files, args)
        print(f"baseline: {r['status']} ({r['ran']} tests, {r['seconds']:.0f} s) {r['failed'][:3]}")
        return 0 if r["status"] == "survived" else 2
    stale = []
    for m in chosen:
        text = (ROOT / m.file).read_text()
        if text.count(m.old) != 1:
            stale.append(m.name)
    if stale:
        print("stale mutations (their text is not in the file exactly once):", ", ".join(stale))
        return 2
    if args.check:
        print(f"{len(chosen)} mutations, each one's text in its file exactly once")
        return 0
    results: dict[str, dict] = {}

    def one(m: Mutation) -> None:
        r = run_one(m, files, args)
        results[m.name] = r
        killer = r["failed"][0] if r["failed"] else ""
        done = len(results)
        print(
            f"[{done}/{len(chosen)}] {m.name}: {r['status']} in {r['seconds']:.0f} s ({r['ran']} tests) {killer}",
            flush=True,
        )
        if r["status"] in ("error", "timeout"):
            print(textwrap.indent(r.get("log", ""), "    "))

    with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        list(pool.map(one, chosen))
    rows = [(m, results[m.name]) for m in chosen]
    table = markdown(rows)
    print()
    print(table)
    if args.markdown:
        Path(args.markdown).write_text(table + "\n")
    if args.json:
        Path(args.json).write_text(json.dumps([{"name": m.name, **r} for m, r in rows], indent=1))
    survived = [m.name for m, r in rows if r["status"] != "killed"]
    if survived:
        print("\nnot killed:", ", ".join(survived))
    return 1 if survived else 0


if __name__ == "__main__":
    sys.exit(main())
