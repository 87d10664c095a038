"""The machinery of ``python -m bench``: run named stages one after another, each command under its own time limit
and all of them inside one time budget, every output under one folder.

A stage (``bench/stages.py``) is a list of steps: a :class:`Cmd` (a process: a benchmark module, pytest, ncu) or a
Python callable given the :class:`Session`. Each stage writes into ``<out>/<stage>/`` (its log there as
``<stage>.log``) and is mirrored to ``.gpu/bench-last/<stage>/`` in the repository, where a later call on the same
machine finds what an earlier one left (a policy to evaluate, a ``train.json`` to compare against) even when each
call has a fresh output folder. The session writes ``<out>/session.md`` and ``session.json``: each stage's status
and seconds, and the stages that did not run.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LAST = ROOT / ".gpu" / "bench-last"  # git-ignored; kept between calls on a warm device machine


@dataclass
class Cmd:
    """One process. ``argv[0] == "python"`` means this interpreter; ``log_to``: a file that takes the process's
    output instead of the stage log (then only its last lines are echoed)."""

    label: str
    argv: list[str]
    limit_s: float
    env: dict = field(default_factory=dict)
    cwd: Path | None = None
    log_to: Path | None = None


@dataclass
class Result:
    stage: str
    status: str  # ok, failed, cut (a command hit its limit or the budget), not run, skipped
    seconds: float = 0.0
    note: str = ""


class Session:
    def __init__(self, out: Path, *, budget_s: float | None, device: str, envs: str | None, repeats: int | None,
                 params: dict[str, str], baseline_tree: Path | None = None, python: str = sys.executable,
                 dry_run: bool = False):  # fmt: skip
        self.out = Path(out).resolve()
        self.t0 = time.monotonic()
        self.deadline = self.t0 + budget_s if budget_s else None
        self.device = device
        self.envs = envs
        self.repeats = repeats
        self.params = params
        self.used_params: set[str] = set()
        self.baseline_tree = baseline_tree
        self.python = python
        self.dry_run = dry_run
        self.stage = None  # the stage being run
        self.status = "ok"
        self._log = None

    # -- what stages read --------------------------------------------------------------------------------------------

    @property
    def cuda(self) -> bool:
        return self.device.startswith("cuda")

    def dir(self, stage: str | None = None) -> Path:
        """The output folder of ``stage`` (default: the running one)."""
        return self.out / (stage or self.stage.name)

    def param(self, key: str, default):
        """A stage parameter: ``--set key=value`` if given, else ``default`` (same type)."""
        self.used_params.add(key)
        if key not in self.params:
            return default
        value = self.params[key]
        return type(default)(value) if default is not None and not isinstance(default, str) else value

    def sizes(self, default: str) -> str:
        """The env counts of a benchmark: ``--envs`` if given, else the stage's default."""
        return self.envs or default

    def reps(self, default: int = 5) -> str:
        return str(self.repeats or default)

    def find(self, stage: str, rel: str) -> Path | None:
        """A file an earlier stage wrote: in this session's output, else in the last run's mirror."""
        for base in (self.out, LAST):
            path = base / stage / rel
            if path.exists():
                return path
        return None

    def left(self) -> float:
        """Seconds left of the budget (infinite without one)."""
        return float("inf") if self.deadline is None else self.deadline - time.monotonic()

    def say(self, text: str) -> None:
        line = f"[bench +{time.monotonic() - self.t0:5.0f}s] {text}"
        print(line, flush=True)
        if self._log:
            self._log.write(line + "\n")
            self._log.flush()

    # -- running -----------------------------------------------------------------------------------------------------

    def run(self, cmd: Cmd) -> int:
        """Run one command under ``min(its limit, the budget left)``; returns its exit status (124: cut)."""
        argv = [self.python if a == "python" else str(a) for a in cmd.argv]
        limit = min(cmd.limit_s, self.left())
        self.say(f"{cmd.label}: {' '.join(argv)} (limit {limit:.0f} s)")
        if self.dry_run:
            return 0
        if limit < 5:
            self.say(f"{cmd.label}: not started, {limit:.0f} s left")
            self.status = "cut"
            return 124
        env = dict(os.environ, PYTHONUNBUFFERED="1", **{k: str(v) for k, v in cmd.env.items()})
        sink = open(cmd.log_to, "w") if cmd.log_to else None  # noqa: SIM115
        t0 = time.monotonic()
        proc = subprocess.Popen(argv, cwd=cmd.cwd or ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                text=True, errors="replace", start_new_session=True)  # fmt: skip
        tail: list[str] = []

        def pump():
            for line in proc.stdout:
                if sink:
                    sink.write(line)
                    tail.append(line)
                    del tail[:-5]
                else:
                    sys.stdout.write(line)
                    sys.stdout.flush()
                    if self._log:
                        self._log.write(line)

        reader = threading.Thread(target=pump, daemon=True)
        reader.start()
        try:
            rc = proc.wait(timeout=limit)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGTERM)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
            rc = 124
        reader.join(timeout=10)
        if sink:
            sink.close()
            for line in tail:
                self.say(f"  {line.rstrip()}")
        dt = time.monotonic() - t0
        if rc == 124:
            self.say(f"{cmd.label}: cut after {dt:.0f} s")
            self.status = "cut"
        elif rc != 0:
            self.say(f"{cmd.label}: exit {rc} after {dt:.0f} s")
            if self.status == "ok":
                self.status = "failed"
        else:
            self.say(f"{cmd.label}: done in {dt:.0f} s")
        return rc

    def run_stages(self, stages: list) -> list[Result]:
        """Run ``stages`` in order; stop at the first whose expected time no longer fits the budget."""
        self.out.mkdir(parents=True, exist_ok=True)
        results: list[Result] = []
        self._log = open(self.out / "session.log", "a")  # noqa: SIM115
        self.say(f"session: {', '.join(s.name for s in stages)}; device {self.device}; out {self.out}; "
                 f"budget {'none' if self.deadline is None else f'{self.left():.0f} s'}")  # fmt: skip
        stopped = False
        for stage in stages:
            if stopped:
                results.append(Result(stage.name, "not run", note="the budget ran out before it"))
                continue
            why = stage.unfit(self)
            if why:
                self.say(f"{stage.name}: skipped ({why})")
                results.append(Result(stage.name, "skipped", note=why))
                continue
            if self.left() < stage.expected_s:
                self.say(f"{stage.name}: not run: expects ~{stage.expected_s} s, {self.left():.0f} s left; stopping")
                results.append(Result(stage.name, "not run", note=f"expects ~{stage.expected_s} s"))
                stopped = True
                continue
            results.append(self._run_stage(stage))
        self._write_summary(results)
        self._log.close()
        self._log = None
        return results

    def _run_stage(self, stage) -> Result:
        self.stage = stage
        self.status = "ok"
        d = self.dir()
        d.mkdir(parents=True, exist_ok=True)
        session_log, self._log = self._log, open(d / f"{stage.name}.log", "a")  # noqa: SIM115
        t0 = time.monotonic()
        self.say(f"=== {stage.name}: {stage.what} (expected ~{stage.expected_s} s)")
        note = ""
        try:
            for step in stage.steps(self):
                if self.left() < 5:
                    self.say(f"{stage.name}: budget spent, the rest of the stage skipped")
                    self.status = "cut"
                    break
                if isinstance(step, Cmd):
                    self.run(step)
                elif not self.dry_run:
                    step(self)
        except Exception as e:  # noqa: BLE001  a broken stage must not take the session down
            self.say(f"{stage.name}: {type(e).__name__}: {e}")
            self.status, note = "failed", f"{type(e).__name__}: {e}"
        dt = time.monotonic() - t0
        self.say(f"=== {stage.name}: {self.status} in {dt:.0f} s")
        self._log.close()
        self._log = session_log
        with open(d / f"{stage.name}.log") as f:
            self._log.write(f.read())
        if not self.dry_run and d.resolve() != (LAST / stage.name).resolve():
            shutil.rmtree(LAST / stage.name, ignore_errors=True)
            shutil.copytree(d, LAST / stage.name)
        return Result(stage.name, self.status, dt, note)

    def _write_summary(self, results: list[Result]) -> None:
        lines = ["| stage | status | seconds | note |", "|---|---|---|---|"]
        lines += [f"| {r.stage} | {r.status} | {r.seconds:.0f} | {r.note} |" for r in results]
        not_run = [r.stage for r in results if r.status == "not run"]
        text = "\n".join(lines) + "\n" + (f"\nNot run: {', '.join(not_run)}\n" if not_run else "")
        self.say("summary\n" + text)
        if not self.dry_run:
            (self.out / "session.md").write_text(text)
            (self.out / "session.json").write_text(json.dumps([r.__dict__ for r in results], indent=1))


Step = Cmd | Callable[[Session], None]
