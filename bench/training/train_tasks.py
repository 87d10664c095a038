"""PPO on several ManiSkill tasks for a time budget each, with periodic evaluations: success and time per task.

Each task trains in its own process (``python -m wpctrl train``'s :class:`~wpctrl.train.Trainer`, ManiSkill's PPO
recipe of the task: :func:`wpctrl.train.ppo_config.task_recipe`), in ``pd_joint_delta_pos`` (ManiSkill's baseline
mode) unless ``--control-mode`` says otherwise, until ``--time-limit`` seconds have passed since that process started
(imports, env build and kernel loading included, as ``wpctrl train --time-limit`` counts), then evaluates, saves and
exports its policy. ``--eval-every-steps`` (or ``--eval-every`` iterations) sets the periodic evaluations of the
deterministic policy on fresh episodes (``--eval-envs`` at a time, one round each): the same env-step spacing for
every task, whatever its steps per iteration.

``--parallel 1`` (the default) runs the tasks at the same time, one process each, on the one device: they share the
GPU by time-slicing, so each task's wall times are those of a GPU shared with the others (the JSON says which ran
alongside); ``--parallel 0`` runs them one after another, each with the GPU to itself, in ``n x`` the time. With
``--warmup 1`` (the default) every task first runs one iteration (all at once), to fill Warp's kernel cache (minutes
when cold), so that the measured runs start warm.

Per task, ``<out>/train_tasks_<task>.json``: task, control mode, envs, steps per env, iterations, env steps, the
recipe, the timings (imports, setup, the training's start, total), every evaluation (iteration, env steps, wall time
from the process's start and from the training's, success once and at the end, mean return, episodes), the final
one, the device, versions and commit; the run folder ``<out>/<task>/`` (``train.json``, ``learning_curve.png``,
``policy.pt``, ``policy.ts``, ``policy.json``) and its log ``<out>/<task>.log``. For all of them:
``<out>/train_tasks.json``, ``<out>/train_tasks.md`` and ``<out>/train_tasks_runs.tar.gz`` (the run folders without
their event files: the policies to evaluate elsewhere, e.g. ``python -m wpctrl evaluate --sim maniskill``).

    python -m bench.training.train_tasks --tasks PullCube-v1,LiftPegUpright-v1,StackCube-v1 --device cuda:0 \
        --time-limit 300 --out /tmp/train_tasks
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import subprocess
import sys
import tarfile
import time
from importlib import metadata
from pathlib import Path

T0 = time.perf_counter()  # a worker's clock starts here, before torch, Warp or the task load

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from wpctrl.train.train_config import MANISKILL_TASKS  # noqa: E402  (host-only names: no Warp, no torch)

DEFAULT_TASKS = "PullCube-v1,LiftPegUpright-v1,StackCube-v1"
VERSIONED = ("warp-lang", "newton", "mujoco-warp", "mujoco", "torch", "rsl-rl-lib", "tensordict", "numpy",
             "mani-skill")  # fmt: skip
SLACK_S = 150.0
"""A measured process's limit past ``--time-limit``: the iteration that crosses it, the final evaluation, the
checkpoint and the export."""
THRESHOLDS = (0.5, 0.8, 0.9)
"""Success rates (success once) whose first evaluation reaching them each record names (``first_reached``)."""
WARMUP_LIMIT_S = 420.0
"""A warm-up process's limit (a cold kernel cache: Warp and MuJoCo-Warp compile every kernel)."""


def _sh(argv: list[str]) -> str:
    try:
        return subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, timeout=10).stdout.strip()
    except Exception:  # noqa: BLE001  (no git: a copy of the tree)
        return ""


def versions() -> dict:
    out = {"python": sys.version.split()[0]}
    for name in VERSIONED:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def commit(given: str | None) -> dict:
    """The tree's commit: ``given`` where the caller names it (a device machine's copy of the tree may carry a stale
    ``.git``), else git's, else ``unknown``."""
    if given:
        return {"commit": given, "dirty": None, "commit_from": "--commit"}
    sha = _sh(["git", "rev-parse", "--short", "HEAD"])
    if sha:
        return {"commit": sha, "dirty": bool(_sh(["git", "status", "--porcelain", "wpctrl", "bench"])),
                "commit_from": "git"}  # fmt: skip
    return {"commit": "unknown", "dirty": None, "commit_from": None}


def _finite(value):
    """``value`` with every NaN / infinity as None (JSON has none; a diverged run still leaves its record)."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value


def check_tasks(text: str) -> list[str]:
    tasks = [t.strip() for t in text.split(",") if t.strip()]
    unknown = [t for t in tasks if t not in MANISKILL_TASKS]
    if unknown or not tasks:
        raise SystemExit(f"--tasks: unknown task(s) {unknown or [text]}; the known ones are {list(MANISKILL_TASKS)}")
    if len(set(tasks)) != len(tasks):
        raise SystemExit(f"--tasks: a task named twice in {tasks}")
    return tasks


# -- one task (a worker process) -----------------------------------------------------------------------------------


def _eval_every(args, task: str) -> int:
    """Iterations between evaluations: ``--eval-every``, else ``--eval-every-steps`` over the task's iteration."""
    if args.eval_every:
        return args.eval_every
    if not args.eval_every_steps:
        return 0
    from wpctrl.train.ppo_config import task_recipe

    steps = args.steps_per_env or task_recipe(task)["steps_per_env"]
    return max(1, math.ceil(args.eval_every_steps / (args.envs * steps)))


def run_task(args, task: str, out: Path, concurrent: list[str]) -> dict:
    """Train ``task`` in this process, export its policy and return (and write) its record."""
    from wpctrl.train import TrainConfig, Trainer

    run_dir = out / task
    warmup = args.warmup_only
    if warmup:
        run_dir = out / "warmup" / task
    cfg = TrainConfig(
        task=task, device=args.device, envs=args.envs, control_mode=args.control_mode, substeps=args.substeps,
        seed=args.seed, steps_per_env=args.steps_per_env, iterations=1 if warmup else args.iterations,
        eval_every=0 if warmup else _eval_every(args, task), eval_envs=min(args.eval_envs, 16) if warmup
        else args.eval_envs, time_limit=None if warmup else args.time_limit,
        target_success=None if warmup else args.target_success, logger="none", out=str(run_dir),
        hide_obs=args.hide_obs, randomize=args.randomize,
    )  # fmt: skip
    trainer = Trainer(cfg, started=T0)
    trainer.run()
    if warmup:
        return {}
    summary = trainer.summary()
    t = time.perf_counter()
    exported = trainer.export(onnx=False)
    export_s = time.perf_counter() - t
    record = task_record(summary, args, concurrent)
    record["export"] = {"policy.ts": str(Path(exported["policy.ts"]).relative_to(out)), "seconds": export_s}
    if args.newton_episodes:
        r = trainer.evaluate(sim="newton", episodes=args.newton_episodes, seed=args.seed + 1, device=args.device,
                             envs=min(args.newton_episodes, 1024), progress=False)  # fmt: skip
        record["newton_eval"] = {k: r[k] for k in ("episodes", "success_rate", "success_at_end_rate",
                                                   "mean_episode_reward", "eval_s")}  # fmt: skip
    if args.maniskill_episodes:
        record["maniskill_eval"] = _maniskill_eval(trainer, args)
    record["process_s"] = time.perf_counter() - T0
    path = out / f"train_tasks_{task}.json"
    path.write_text(json.dumps(_finite(record), indent=1))
    print(f"wrote {path}", flush=True)
    return record


def _maniskill_eval(trainer, args) -> dict:
    import importlib.util

    if importlib.util.find_spec("mani_skill") is None:
        return {"skipped": "mani-skill is not installed here (evaluate policy.ts elsewhere: wpctrl evaluate --sim "
                           "maniskill)"}  # fmt: skip
    r = trainer.evaluate(sim="maniskill", episodes=args.maniskill_episodes, seed=args.seed + 1, progress=False)
    return {k: r[k] for k in ("episodes", "success_rate", "success_at_end_rate", "mean_episode_reward", "eval_s")}


def task_record(summary: dict, args, concurrent: list[str]) -> dict:
    """What the bench keeps of a ``train.json``: the run's settings, timings and evaluations (each also timed from
    the process's start)."""
    start = summary.get("train_start_s", summary["import_s"] + summary["setup_s"])
    evaluations = [
        {
            "iteration": e["iteration"],
            "env_steps": max(0, e["env_steps"]),
            "wall_s_from_start": start + e["wall_s"],
            "wall_s_training": e["wall_s"],
            "success_once": e["success_rate"],
            "success_at_end": e["success_at_end_rate"],
            "mean_return": e["mean_episode_reward"],
            "mean_first_success_step": e.get("mean_first_success_step"),
            "episodes": e["episodes"],
            "eval_s": e.get("eval_s"),
        }
        for e in summary["evaluations"]
    ]
    final = evaluations[-1] if evaluations else None
    best = max(evaluations, key=lambda e: e["success_once"]) if evaluations else None  # the first of the best
    reached = {}
    for level in THRESHOLDS:
        first = next((e for e in evaluations if e["success_once"] >= level), None)
        reached[str(level)] = {k: first[k] for k in ("iteration", "env_steps", "wall_s_from_start")} if first else None
    keys = ("task", "control_mode", "envs", "steps_per_env", "iterations", "env_steps", "substeps", "seed", "device",
            "device_name", "graph", "ppo_update", "action_sampling", "partial_reset", "eval_envs", "max_episode_steps",
            "obs_dim", "recipe", "stopped_by", "import_s", "setup_s", "train_start_s", "train_wall_s", "total_s",
            "collection_env_steps_per_s_median", "hide_obs", "hidden_obs", "randomize")  # fmt: skip
    return {
        "format": "wpctrl-bench-train-tasks-1",
        **{k: summary.get(k) for k in keys},
        "epochs": summary["ppo"]["algorithm"]["num_learning_epochs"],
        "minibatches": summary["ppo"]["algorithm"]["num_mini_batches"],
        "time_limit_s": args.time_limit,
        "eval_every_iterations": _eval_every(args, summary["task"]),
        "concurrent_tasks": concurrent,
        "evaluations": evaluations,
        "final": final,
        "best": best,
        "first_reached": reached,
        "versions": versions(),
        **commit(args.commit),
        "date_utc": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
        "run_dir": summary["task"],
    }


# -- the session (the parent process) ------------------------------------------------------------------------------


def _worker_argv(args, task: str, warmup: bool) -> list[str]:
    argv = [sys.executable, "-m", "bench.training.train_tasks", "--worker", task, "--device", args.device,
            "--envs", str(args.envs), "--control-mode", args.control_mode, "--seed", str(args.seed),
            "--time-limit", str(args.time_limit), "--eval-envs", str(args.eval_envs), "--iterations",
            str(args.iterations), "--eval-every", str(args.eval_every), "--eval-every-steps",
            str(args.eval_every_steps), "--newton-episodes", str(args.newton_episodes), "--maniskill-episodes",
            str(args.maniskill_episodes), "--concurrent", args.concurrent_label, "--out", str(args.out)]  # fmt: skip
    for flag, v in (("--substeps", args.substeps), ("--steps-per-env", args.steps_per_env),
                    ("--target-success", args.target_success), ("--commit", args.commit),
                    ("--hide-obs", args.hide_obs), ("--randomize", args.randomize)):  # fmt: skip
        if v is not None:
            argv += [flag, str(v)]
    return argv + (["--warmup-only"] if warmup else [])


RUNNING: list[subprocess.Popen] = []
"""The workers started, stopped with this process (:func:`_stop_all`)."""


def _stop(p: subprocess.Popen) -> None:
    if p.poll() is None:
        p.terminate()
        try:
            p.wait(timeout=15)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def _stop_all(signum, frame) -> None:
    for p in RUNNING:
        _stop(p)
    raise SystemExit(128 + signum)


def _last_line(path: Path) -> str:
    try:
        lines = [ln for ln in path.read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        return ""
    return lines[-1][:160] if lines else ""


def _run_batch(args, tasks: list[str], warmup: bool, limit: float) -> dict[str, int]:
    """Start one worker per task, wait for all (each cut at ``limit`` seconds); their exit codes (124: cut)."""
    procs = {}
    for task in tasks:
        log = args.out / ("warmup" if warmup else "") / f"{task}.log"
        log.parent.mkdir(parents=True, exist_ok=True)
        sink = open(log, "w")  # noqa: SIM115
        # the workers stay in this process's group: a runner that stops this process's group stops them too
        procs[task] = (subprocess.Popen(_worker_argv(args, task, warmup), cwd=ROOT, stdout=sink,
                                        stderr=subprocess.STDOUT), sink, log, time.monotonic())  # fmt: skip
        RUNNING.append(procs[task][0])
        print(f"[train_tasks] {'warm-up' if warmup else 'training'} {task}: pid {procs[task][0].pid}, log {log}",
              flush=True)  # fmt: skip
    codes: dict[str, int] = {}
    last_report = time.monotonic()
    while len(codes) < len(procs):
        time.sleep(1.0)
        for task, (p, sink, log, t0) in procs.items():
            if task in codes:
                continue
            rc = p.poll()
            if rc is None and time.monotonic() - t0 > limit:
                _stop(p)
                rc = 124
            if rc is not None:
                codes[task] = rc
                sink.close()
                what = "cut" if rc == 124 else ("done" if rc == 0 else f"exit {rc}")
                print(f"[train_tasks] {task}: {what} after {time.monotonic() - t0:.0f} s; {_last_line(log)}",
                      flush=True)  # fmt: skip
                if rc != 0:
                    tail = log.read_text(errors="replace").splitlines()[-15:]
                    print("\n".join(f"    {ln}" for ln in tail), flush=True)
        if time.monotonic() - last_report >= args.report_every and len(codes) < len(procs):
            last_report = time.monotonic()
            for task, (_, _, log, t0) in procs.items():
                if task not in codes:
                    print(f"[train_tasks] {task} +{time.monotonic() - t0:.0f} s: {_last_line(log)}", flush=True)
    return codes


def _pct(x) -> str:
    return "–" if x is None else f"{100 * x:.1f} %"


def markdown(records: list[dict], parallel: bool) -> str:
    if not records:
        return "# PPO per task\n\nNo task finished.\n"
    r0 = records[0]
    lines = [
        f"# PPO per task, {'at the same time' if parallel else 'one after another'} on {r0['device_name']}\n",
        f"{r0['date_utc']}; commit {r0['commit']}{' (dirty)' if r0['dirty'] else ''}; "
        + ", ".join(f"{k} {v}" for k, v in r0["versions"].items() if v)
        + "\n",
        "| task | mode | envs × steps | iterations | env steps | stopped by | final success (at end) | best success "
        "(at s from start) | setup s | total s | collection env-steps/s |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in records:
        f, b = r["final"] or {}, r["best"] or {}
        lines.append(
            f"| {r['task']} | {r['control_mode']} | {r['envs']} × {r['steps_per_env']} | {r['iterations']} | "
            f"{r['env_steps']:,} | {r['stopped_by']} | {_pct(f.get('success_once'))} ({_pct(f.get('success_at_end'))})"
            f" | {_pct(b.get('success_once'))} ({b.get('wall_s_from_start', 0):.0f} s) | {r['setup_s']:.1f} | "
            f"{r['total_s']:.0f} | {r['collection_env_steps_per_s_median']:,.0f} |"
        )
    lines.append("\nEvaluations (success once / at the end, wall time from the process's start):\n")
    for r in records:
        evs = "; ".join(
            f"it {e['iteration']} ({e['env_steps'] / 1e6:.2f}M, {e['wall_s_from_start']:.0f} s): "
            f"{_pct(e['success_once'])} / {_pct(e['success_at_end'])}"
            for e in r["evaluations"]
        )
        lines.append(f"- {r['task']}: {evs}")
    return "\n".join(lines) + "\n"


def bundle(out: Path, tasks: list[str]) -> Path:
    """The run folders (without event files) in one archive: ``train_tasks_runs.tar.gz``."""
    path = out / "train_tasks_runs.tar.gz"
    keep = ("train.json", "learning_curve.png", "policy.pt", "policy.ts", "policy.json")
    with tarfile.open(path, "w:gz") as tar:
        for task in tasks:
            for name in keep:
                f = out / task / name
                if f.is_file():
                    tar.add(f, arcname=f"{task}/{name}")
            f = out / f"train_tasks_{task}.json"
            if f.is_file():
                tar.add(f, arcname=f.name)
    return path


def session(args) -> int:
    tasks = check_tasks(args.tasks)
    signal.signal(signal.SIGTERM, _stop_all)
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    for task in tasks:
        (out / f"train_tasks_{task}.json").unlink(missing_ok=True)
    t0 = time.monotonic()
    groups = [tasks] if args.parallel else [[t] for t in tasks]
    if args.warmup:  # all at once, whatever --parallel says: it fills the kernel cache and measures nothing
        args.concurrent_label = ",".join(tasks)
        _run_batch(args, tasks, warmup=True, limit=WARMUP_LIMIT_S)
        print(f"[train_tasks] warm-up done in {time.monotonic() - t0:.0f} s", flush=True)
    codes = {}
    for group in groups:
        args.concurrent_label = ",".join(group)
        codes.update(_run_batch(args, group, warmup=False, limit=args.time_limit + SLACK_S))
    records = []
    for task in tasks:
        path = out / f"train_tasks_{task}.json"
        if path.is_file():
            records.append(json.loads(path.read_text()))
    (out / "train_tasks.json").write_text(json.dumps({"parallel": bool(args.parallel), "tasks": tasks,
                                                      "exit_codes": codes, "records": records}, indent=1))  # fmt: skip
    md = markdown(records, bool(args.parallel))
    (out / "train_tasks.md").write_text(md)
    archive = bundle(out, tasks)
    print(md, flush=True)
    print(f"wrote {out / 'train_tasks.json'}, {out / 'train_tasks.md'}, {archive} in {time.monotonic() - t0:.0f} s",
          flush=True)  # fmt: skip
    missing = [t for t in tasks if not (out / f"train_tasks_{t}.json").is_file()]
    if missing:
        print(f"[train_tasks] no record for {missing} (see their logs in {out})", flush=True)
    return 0 if not missing else 1


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m bench.training.train_tasks", description=__doc__.split("\n\n")[0])
    p.add_argument("--tasks", default=DEFAULT_TASKS, help=f"comma-separated tasks (default {DEFAULT_TASKS}); any of "
                   f"{', '.join(MANISKILL_TASKS)}")  # fmt: skip
    p.add_argument("--device", default="cuda:0")
    p.add_argument("--envs", type=int, default=4096)
    p.add_argument("--control-mode", default="pd_joint_delta_pos", help="ManiSkill's PPO baseline mode by default")
    p.add_argument("--substeps", type=int, default=None, help="MuJoCo-Warp steps per physics step (default 16; the "
                   "GPU recipe of docs/training.md uses 8)")  # fmt: skip
    p.add_argument("--steps-per-env", type=int, default=None, help="default: the task's recipe (4; StackCube 16)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--hide-obs", default=None, help="wpctrl train's --hide-obs (default: finger_qvel)")
    p.add_argument("--randomize", default=None, help="wpctrl train's --randomize (default: off)")
    p.add_argument("--time-limit", type=float, default=300.0, help="seconds per task from its process's start")
    p.add_argument("--iterations", type=int, default=100_000, help="an iteration cap (the time limit stops first)")
    p.add_argument("--eval-every", type=int, default=0, help="iterations between evaluations (overrides "
                   "--eval-every-steps)")  # fmt: skip
    p.add_argument("--eval-every-steps", type=int, default=1_000_000, help="env steps between evaluations "
                   "(rounded up to whole iterations of each task; 0: only the final evaluation)")  # fmt: skip
    p.add_argument("--eval-envs", type=int, default=512, help="envs (and episodes) of each evaluation")
    p.add_argument("--target-success", type=float, default=None, help="stop a task once an evaluation reaches this")
    p.add_argument("--newton-episodes", type=int, default=0, help="after training: the exported policy on this many "
                   "fresh Newton episodes (0: none)")  # fmt: skip
    p.add_argument("--maniskill-episodes", type=int, default=0, help="after training: the exported policy on this "
                   "many real ManiSkill episodes, where mani-skill is installed (0: none)")  # fmt: skip
    p.add_argument("--parallel", type=int, choices=(0, 1), default=1, help="1: the tasks at the same time, one "
                   "process each; 0: one after another")  # fmt: skip
    p.add_argument("--warmup", type=int, choices=(0, 1), default=1, help="1: one iteration of each task first (fills "
                   "the kernel cache)")  # fmt: skip
    p.add_argument("--report-every", type=float, default=60.0, help="seconds between progress lines")
    p.add_argument("--commit", default=None, help="the tree's commit, where it has no .git (a device machine's copy)")
    p.add_argument("--out", type=Path, default=ROOT / "out" / "train_tasks")
    p.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    p.add_argument("--warmup-only", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--concurrent", default="", help=argparse.SUPPRESS)
    return p


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    args.out = Path(args.out).resolve()
    if args.worker:
        from wpctrl.console import cli_output

        cli_output(False)
        run_task(args, args.worker, args.out, [t for t in args.concurrent.split(",") if t])
        return 0
    return session(args)


if __name__ == "__main__":
    raise SystemExit(main())
