"""The stages of ``python -m bench``: what each runs, how long it takes, what it writes.

Times (``expected_s``) are for one H100 / H200 with a warm Warp kernel cache; an empty cache adds the compilation
(noted per stage). Every stage fits one 10-minute device call; the runner starts a stage only if its expected time
still fits the budget. Parameters (``--set key=value``) are listed per stage; ``--envs``, ``--repeats`` and
``--device`` apply to every stage that times something.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from bench.session import ROOT, Cmd, Session, Step

ASSETS = ROOT / ".gpu" / "assets"
BASELINE = ROOT / ".gpu" / "ab_base"


@dataclass(frozen=True)
class Stage:
    name: str
    group: str
    what: str
    expected_s: int
    outputs: str
    steps: Callable[[Session], list[Step]]
    needs: tuple[str, ...] = ()  # cuda, ncu, assets, baseline, git, mani_skill
    params: dict[str, str] = field(default_factory=dict)  # --set key: what it sets (default)
    modules: tuple[str, ...] = ()  # the benchmark modules and test files it runs (checked by the tests)

    def unfit(self, s: Session) -> str | None:
        """Why this stage cannot run in this session, or None."""
        if "cuda" in self.needs and not s.cuda:
            return "needs a CUDA device"
        if "ncu" in self.needs and not shutil.which(os.environ.get("NCU", "ncu")):
            return "no ncu (Nsight Compute) on the PATH"
        if "assets" in self.needs and not _has_assets():
            return f"no ManiSkill Panda asset: run `python -m bench assets` where mani-skill is installed ({ASSETS})"
        tree = s.baseline_tree
        if "baseline" in self.needs and not (tree and (tree / "wpctrl" / "__init__.py").is_file()):
            return f"needs --baseline-tree DIR holding the old wpctrl/ (e.g. {BASELINE.relative_to(ROOT)})"
        if "git" in self.needs and not (ROOT / ".git").exists():
            return "needs the git checkout"
        return None


def _assets() -> Path | None:
    root = Path(os.environ.get("WPCTRL_MANISKILL_ASSETS") or ASSETS)
    return root if (root / "robots" / "panda" / "panda_v2.urdf").is_file() else None


def _has_assets() -> bool:
    """The tasks find ManiSkill's Panda: a copy (``WPCTRL_MANISKILL_ASSETS`` or .gpu/assets) or mani-skill itself."""
    import importlib.util

    return _assets() is not None or importlib.util.find_spec("mani_skill") is not None


def _env_assets() -> dict:
    root = _assets()
    return {"WPCTRL_MANISKILL_ASSETS": root} if root else {}


def bench(label: str, module: str, s: Session, *args, limit: float, envs: str | None = None, **kw) -> Cmd:
    """A benchmark module on the session's device, writing into the stage's folder."""
    argv = ["python", "-m", module, "--device", s.device, "--out", s.dir(), *map(str, args)]
    if envs is not None:
        argv += ["--envs", s.sizes(envs)]
    return Cmd(label, argv, limit, **kw)


def pytest(label: str, *targets: str, limit: float, k: str | None = None) -> Cmd:
    argv = ["python", "-m", "pytest", "-q", "-p", "no:cacheprovider", "--no-cov", *targets]
    return Cmd(label, argv + (["-k", k] if k else []), limit, env=_env_assets())


def _machine(s: Session) -> None:
    """The GPU, the driver and the library versions, into the stage folder."""
    code = (
        "import importlib.metadata as m\n"
        "for p in ('warp-lang', 'newton', 'mujoco-warp', 'torch', 'rsl-rl-lib', 'tensordict'):\n"
        "    try: print(p, m.version(p))\n"
        "    except Exception: print(p, '-')"
    )
    lines = [subprocess.run([s.python, "-c", code], capture_output=True, text=True).stdout]
    if shutil.which("nvidia-smi"):
        q = ["nvidia-smi", "--query-gpu=name,driver_version,memory.total,clocks.max.sm", "--format=csv,noheader"]
        lines.append(subprocess.run(q, capture_output=True, text=True).stdout)
    (s.dir() / "machine.txt").write_text("".join(lines))


# ----------------------------------------------------------------------------------------------------------------------
# setup (on the development machine)


def _assets_steps(s: Session) -> list[Step]:
    def copy(s: Session) -> None:
        import importlib.util

        spec = importlib.util.find_spec("mani_skill")
        if spec is None:
            raise RuntimeError("mani-skill is not importable here (use the Python that has it: .venv/bin/python)")
        src = Path(spec.origin).parent / "assets" / "robots" / "panda"
        dst = ASSETS / "robots" / "panda"
        shutil.rmtree(ASSETS, ignore_errors=True)
        (dst / "franka_description" / "meshes").mkdir(parents=True)
        for f in ("panda_v2.urdf", "panda_v2.srdf"):
            shutil.copy2(src / f, dst / f)
        shutil.copytree(src / "franka_description" / "meshes" / "collision",
                        dst / "franka_description" / "meshes" / "collision")  # fmt: skip
        size = sum(f.stat().st_size for f in ASSETS.rglob("*") if f.is_file())
        s.say(f"ManiSkill's Panda asset in {ASSETS} ({size / 1e6:.1f} MB): carry .gpu/assets with the device call")

    return [copy]


def _baseline_steps(s: Session) -> list[Step]:
    rev = s.param("rev", "HEAD")

    def prepare(s: Session) -> None:
        shutil.rmtree(BASELINE, ignore_errors=True)
        BASELINE.mkdir(parents=True)
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev, "wpctrl"], capture_output=True, check=True)
        subprocess.run(["tar", "-x", "-C", str(BASELINE)], input=archive.stdout, check=True)
        git = ["git", "-C", str(ROOT)]
        old = subprocess.run([*git, "rev-parse", "--short", rev], capture_output=True, text=True).stdout.strip()
        new = subprocess.run([*git, "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
        dirty = subprocess.run([*git, "status", "--porcelain", "wpctrl"], capture_output=True, text=True).stdout
        (BASELINE / "COMMIT").write_text(old + "\n")
        (BASELINE / "NEW_COMMIT").write_text(new + ("+changes" if dirty.strip() else "") + "\n")
        s.say(f"baseline {old} in {BASELINE}; this tree {new}: carry .gpu/ab_base with the device call")

    return [prepare]


# ----------------------------------------------------------------------------------------------------------------------
# tests on CUDA


def _tests(*targets: str, limit: float, k: str | None = None):
    return lambda s: [_machine, pytest("pytest", *targets, limit=limit, k=k)]


# ----------------------------------------------------------------------------------------------------------------------
# the control step

CTRL_ENVS = "1,64,1k,4k,16k,64k,256k,1M"


def _step_explicit(s: Session) -> list[Step]:
    return [_machine, bench("explicit", "bench.step.controller_step", s, "--repeats", s.reps(), limit=240,
                            envs=CTRL_ENVS)]  # fmt: skip


def _step_implicit(s: Session) -> list[Step]:
    args = ("--repeats", s.reps(), "--actuation", "implicit", "--interpolate", "off", "--tag",
            "cuda_implicit" if s.cuda else "cpu_implicit")  # fmt: skip
    return [_machine, bench("implicit", "bench.step.controller_step", s, *args, limit=180, envs=CTRL_ENVS)]


def _step_block_dim(s: Session) -> list[Step]:
    out = []
    for b in s.param("blocks", "32,64,128,256").split(","):
        args = ("--repeats", s.reps(), "--actuation", "implicit", "--interpolate", "off", "--variants",
                "wpctrl_graph,floor", "--block-dim", b, "--tag", f"block{b}")  # fmt: skip
        out.append(bench(f"block {b}", "bench.step.controller_step", s, *args, limit=90, envs="4k,1M"))
    return out


def _step_osc(s: Session) -> list[Step]:
    args = ("--repeats", s.reps(), "--physics-envs", s.param("physics_envs", 4096))
    return [_machine, bench("osc_step", "bench.step.osc_step", s, *args, limit=320, envs="1k,16k,4k")]


# ----------------------------------------------------------------------------------------------------------------------
# actuators

NET_VARIANTS = (
    "plain,dc_motor,position_limit,mlp_unrolled,lstm_unrolled,mlp,lstm,mlp_tiled,lstm_tiled,torch_mlp,torch_lstm"
)


def _act_models(s: Session) -> list[Step]:
    out = [_machine]
    for v in s.param("models", "dc_motor,position_limit,newton_dc").split(","):  # each against plain, own process
        args = ("--repeats", s.reps(), "--variants", f"plain,{v}", "--tag", v)
        out.append(bench(v, "bench.actuators.actuator_cost", s, *args, limit=100, envs="1,4k,64k,1M"))
    return out


def _act_nets(s: Session) -> list[Step]:
    args = ["--repeats", s.reps(), "--variants", s.param("variants", NET_VARIANTS)]
    if not s.cuda:
        args.append("--cpu-blocks")  # the tiled kernels run their GPU blocks on the CPU
    return [_machine, bench("actuator_cost", "bench.actuators.actuator_cost", s, *args, limit=300, envs="4k,64k,1M")]


# ----------------------------------------------------------------------------------------------------------------------
# training


def _train_args(s: Session, task: str, out: Path) -> list[str]:
    return ["python", "-m", "wpctrl", "train", "--task", task, "--device", s.device, "--envs",
            str(_one_size(s, 4096)), "--substeps", str(s.param("substeps", 8)), "--seed", str(s.param("seed", 0)),
            "--control-mode", s.param("control_mode", "pd_joint_delta_pos"), "--out", str(out)]  # fmt: skip


def _one_size(s: Session, default: int) -> int:
    from bench.common import parse_envs

    return parse_envs(s.envs)[0] if s.envs else default


def _task_warmup(s: Session) -> Cmd:
    return Cmd("warm-up (one PushCube iteration)", _train_args(s, "PushCube-v1", s.dir() / "warmup") +
               ["--iterations", "1"], 240, env=_env_assets())  # fmt: skip


def _export_and_evaluate(s: Session, run: Path) -> list[Step]:
    episodes = str(s.param("eval_episodes", 1000))
    return [
        Cmd("export", ["python", "-m", "wpctrl", "export", str(run)], 60),
        Cmd(
            "evaluate on Newton",
            [
                "python",
                "-m",
                "wpctrl",
                "evaluate",
                "--policy",
                str(run / "policy.ts"),
                "--sim",
                "newton",
                "--device",
                s.device,
                "--episodes",
                episodes,
                "--envs",
                episodes,
                "--seed",
                "1",
                "--out",
                str(run / "newton_eval.json"),
            ],
            60,
            env=_env_assets(),
        ),  # fmt: skip
    ]


def _train_reach(s: Session) -> list[Step]:
    n = str(_one_size(s, 4096))
    return [
        _machine,
        Cmd(
            "warm-up (one iteration)",
            [
                "python",
                "-m",
                "wpctrl",
                "train",
                "--envs",
                n,
                "--iterations",
                "1",
                "--seed",
                str(s.param("seed", 0)),
                "--out",
                str(s.dir() / "warmup"),
            ],
            300,
        ),  # fmt: skip
        Cmd(
            "train",
            [
                "python",
                "-m",
                "wpctrl",
                "train",
                "--envs",
                n,
                "--iterations",
                str(s.param("iterations", 300)),
                "--seed",
                str(s.param("seed", 0)),
                "--eval-every",
                "5",
                "--target-success",
                str(s.param("target", 0.95)),
                "--out",
                str(s.dir()),
            ],
            300,
        ),  # fmt: skip
    ]


def _train_reach_rate(s: Session) -> list[Step]:
    args = ["--envs", str(_one_size(s, 4096))]
    train_json = s.find("train-reach", "train.json")
    if train_json:
        args += ["--train-json", str(train_json)]
    return [_machine, bench("train_rate", "bench.training.train_rate", s, *args, limit=150)]


def _train_push(s: Session) -> list[Step]:
    run = s.dir()
    args = ["--eval-every", "5", "--target-success", str(s.param("target", 0.9)), "--time-limit",
            str(s.param("cap", 150))]  # fmt: skip
    train = Cmd("train PushCube-v1", _train_args(s, "PushCube-v1", run) + args, 200, env=_env_assets())
    return [_machine, _task_warmup(s), train, *_export_and_evaluate(s, run)]


def _train_pick(s: Session) -> list[Step]:
    train = Cmd("train PickCube-v1", _train_args(s, "PickCube-v1", s.dir()) + ["--eval-every",
                str(s.param("eval_every", 25)), "--target-success", str(s.param("target", 0.8)), "--time-limit",
                str(s.param("cap", 540))], 585, env=_env_assets())  # fmt: skip
    return [_machine, train]


def _train_pick_eval(s: Session) -> list[Step]:
    run = s.find("train-pick", "policy.pt")
    if run is None:
        raise RuntimeError("no train-pick/policy.pt in this session's output or in .gpu/bench-last: run train-pick")
    dst = s.dir() / "pick"
    shutil.copytree(run.parent, dst, dirs_exist_ok=True)
    return _export_and_evaluate(s, dst)


def _task_rate(s: Session, label: str, *args, limit: float) -> Cmd:
    return bench(label, "bench.training.task_train_rate", s, "--task", "PushCube-v1", "--envs",
                 str(_one_size(s, 4096)), "--substeps", str(s.param("substeps", 8)), *args, limit=limit,
                 env=_env_assets())  # fmt: skip


def _train_sampling_rate(s: Session) -> list[Step]:
    return [_machine, _task_warmup(s), _task_rate(s, "rsl-rl sampling", "--action-sampling", "rsl-rl", limit=120),
            _task_rate(s, "sync-free sampling", "--action-sampling", "sync-free", limit=120)]  # fmt: skip


TRAIN_TASKS = "PullCube-v1,LiftPegUpright-v1,StackCube-v1"


def _train_tasks(s: Session) -> list[Step]:
    """Every task of ``tasks`` trained for ``time_limit`` s (``bench/training/train_tasks.py``): at the same time, one
    process each (``parallel=1``), or one after another (``parallel=0``), after a one-iteration warm-up of each."""
    tasks = s.param("tasks", TRAIN_TASKS)
    time_limit = s.param("time_limit", 300.0)
    parallel, warmup = s.param("parallel", 1), s.param("warmup", 1)
    n = 1 if parallel else len(tasks.split(","))
    limit = n * (time_limit + 150) + (420 if warmup else 0) + 60
    args = ["--tasks", tasks, "--envs", str(_one_size(s, 4096)), "--substeps", str(s.param("substeps", 8)),
            "--seed", str(s.param("seed", 0)), "--control-mode", s.param("control_mode", "pd_joint_delta_pos"),
            "--time-limit", str(time_limit), "--eval-every-steps", str(s.param("eval_every_steps", 1_000_000)),
            "--eval-every", str(s.param("eval_every", 0)), "--eval-envs", str(s.param("eval_envs", 512)),
            "--parallel", str(parallel), "--warmup", str(warmup),
            "--newton-episodes", str(s.param("newton_episodes", 0)),
            "--maniskill-episodes", str(s.param("maniskill_episodes", 0))]  # fmt: skip
    if s.param("commit", ""):
        args += ["--commit", s.param("commit", "")]
    return [_machine, bench("train_tasks", "bench.training.train_tasks", s, *args, limit=limit, env=_env_assets())]


def _train_push_rate(s: Session) -> list[Step]:
    train_json = s.find("train-push", "train.json")
    extra = ("--train-json", str(train_json)) if train_json else ()
    return [_machine, _task_rate(s, "collection rate", *extra, limit=240)]


# ----------------------------------------------------------------------------------------------------------------------
# profiling (Nsight Compute wraps the benchmark's process)

NCU_STEP_METRICS = (
    "gpu__time_duration.sum,dram__throughput.avg.pct_of_peak_sustained_elapsed,"
    "gpu__compute_memory_throughput.avg.pct_of_peak_sustained_elapsed,dram__bytes.sum.per_second,dram__bytes_read.sum,"
    "dram__bytes_write.sum,sm__warps_active.avg.pct_of_peak_sustained_active,sm__maximum_warps_per_active_cycle_pct,"
    "smsp__average_warps_issue_stalled_long_scoreboard_per_issue_active.ratio,"
    "smsp__average_warps_issue_stalled_lg_throttle_per_issue_active.ratio,"
    "smsp__average_warps_issue_stalled_wait_per_issue_active.ratio,smsp__inst_executed.sum,"
    "launch__registers_per_thread,launch__grid_size,launch__block_size"
)


def _ncu(*args: str) -> list[str]:
    return [os.environ.get("NCU", "ncu"), *args]


def _sections(*names: str) -> list[str]:
    return [x for n in names for x in ("--section", n)]


def _prof_ncu_step(s: Session) -> list[Step]:
    """Four modes of one eager control step at 1M envs: the sections (details page) and the raw metrics (CSV)."""
    d, envs = s.dir(), s.sizes("1M")
    kernels = "regex:wpctrl_set_action|wpctrl_substep|_targets_kernel"
    sections = _sections("SpeedOfLight", "MemoryWorkloadAnalysis", "Occupancy", "WarpStateStats", "LaunchStats",
                         "SchedulerStats")  # fmt: skip
    out: list[Step] = [_machine]
    for act, interp in (("implicit", "off"), ("implicit", "on"), ("explicit", "off"), ("explicit", "on")):
        target = ["python", "-m", "bench.profiling.ncu_target", "--device", "cuda:0", "--envs", envs, "--actuation",
                  act, "--interpolate", interp, "--steps", "1"]  # fmt: skip
        tag = f"{act}_{interp}"
        out.append(Cmd(f"ncu sections {tag}", _ncu("--profile-from-start", "off", "--kernel-name", kernels, *sections,
                       "--page", "details", *target), 300, log_to=d / f"ncu_report_{tag}.txt"))  # fmt: skip
        out.append(Cmd(f"ncu metrics {tag}", _ncu("--profile-from-start", "off", "--kernel-name", kernels, "--metrics",
                       NCU_STEP_METRICS, "--csv", "--page", "raw", *target), 300,
                       log_to=d / f"ncu_raw_{tag}.txt"))  # fmt: skip

    def collect(s: Session) -> None:  # one CSV (the rows of every mode) and one report
        with open(d / "ncu_metrics.csv", "w") as csv, open(d / "ncu_report.txt", "w") as rep:
            for f in sorted(d.glob("ncu_raw_*.txt")):
                csv.write(f"# {f.stem.removeprefix('ncu_raw_')}\n")
                csv.writelines(x for x in open(f) if x.startswith('"'))
                f.unlink()
            for f in sorted(d.glob("ncu_report_*.txt")):
                rep.write(f"=== {f.stem.removeprefix('ncu_report_')}\n" + f.read_text())
                f.unlink()
        key = re.compile(r"^  [a-zA-Z_]+.*_kernel|DRAM Throughput|Achieved Occupancy|Duration|Long Scoreboard")
        for line in open(d / "ncu_report.txt"):
            if key.search(line):
                s.say(line.rstrip())

    return [*out, collect]


def _prof_ncu_nets(s: Session) -> list[Step]:
    kernels = s.param("kernels", "wpctrl_actuator_net")
    variants = s.param("variants", "mlp,lstm,mlp_tiled,lstm_tiled")
    sections = _sections("SpeedOfLight", "ComputeWorkloadAnalysis", "MemoryWorkloadAnalysis", "Occupancy",
                         "WarpStateStats", "SchedulerStats", "LaunchStats")  # fmt: skip
    out: list[Step] = [_machine]
    for n in s.sizes("4k,1M").split(","):
        argv = _ncu("--profile-from-start", "off", "--clock-control", "none", "--kernel-name", f"regex:{kernels}",
                    *sections, "--page", "details", "python", "-m", "bench.profiling.ncu_net", "--envs", n,
                    "--variants", variants)  # fmt: skip
        out.append(Cmd(f"ncu {n}", argv, 90, log_to=s.dir() / f"ncu_net_{n}.txt"))
    return out


def _prof_ncu_coupled(s: Session) -> list[Step]:
    """One graph-replayed coupled-drive launch at 4k envs (the bench's warm-up launches skipped)."""
    target = ["python", "-m", "bench.step.inertia_update", "--device", "cuda:0", "--envs", "4k", "--variants",
              "coupled, H per substep", "--repeats", "1", "--out", str(s.dir() / "bench")]  # fmt: skip
    pick = ["--kernel-name", "regex:coupled_drive", "--launch-skip", "20", "--launch-count", "1"]
    out: list[Step] = [_machine, Cmd("ncu coupled", _ncu(*pick, *_sections("SpeedOfLight", "LaunchStats", "Occupancy",
                       "WarpStateStats", "MemoryWorkloadAnalysis", "InstructionStats"), *target), 200,
                       log_to=s.dir() / "ncu_coupled.txt")]  # fmt: skip
    if s.param("source", 0):  # per-source-line instruction counts and stall samples, the kernel built with lineinfo
        code = ("import runpy, sys, warp as wp\nwp.config.lineinfo = True\nsys.argv = ['inertia_update'] + "
                f"{target[3:]!r}\nrunpy.run_module('bench.step.inertia_update', run_name='__main__')")  # fmt: skip
        rep = s.dir() / "coupled_src"
        out.append(Cmd("ncu coupled source", _ncu(*pick, *_sections("SourceCounters", "WarpStateStats"),
                       "--import-source", "yes", "-f", "-o", str(rep), "python", "-c", code), 240))  # fmt: skip
        out.append(Cmd("ncu source page", _ncu("-i", f"{rep}.ncu-rep", "--page", "source", "--csv", "--print-source",
                       "cuda"), 60, log_to=s.dir() / "ncu_coupled_source.csv"))  # fmt: skip
    return out


def _prof_ncu_substep(s: Session) -> list[Step]:
    """One graph-replayed substep launch at 4k envs per actuator model."""
    out: list[Step] = [_machine]
    for v in ("plain", "dc_motor", "position_limit"):
        target = ["python", "-m", "bench.actuators.actuator_cost", "--envs", "4k", "--repeats", "1", "--variants", v,
                  "--tag", "ncu", "--out", str(s.dir() / "bench")]  # fmt: skip
        argv = _ncu("--kernel-name", "regex:wpctrl_substep", "--launch-skip", "20", "--launch-count", "1",
                    *_sections("SpeedOfLight", "LaunchStats", "WarpStateStats"), *target)  # fmt: skip
        out.append(Cmd(f"ncu substep {v}", argv, 100, log_to=s.dir() / f"ncu_substep_{v}.txt"))
    return out


# ----------------------------------------------------------------------------------------------------------------------
# A/B of two trees

AB_ENVS = "1k,4k,16k"


def _ab(stem: str, module: str, cases: dict, limit: float):
    def steps(s: Session) -> list[Step]:
        from bench.ab.trees import alternate

        return [_machine, lambda s: alternate(s, stem=stem, module=module, cases=cases(s), envs=s.sizes(AB_ENVS),
                                              per_run_limit_s=limit)]  # fmt: skip

    return steps


def _ab_step_cases(s: Session) -> dict:
    # real Pandas up to the largest size: only the public API, so that an older tree runs the same code path
    common = ["--repeats", s.reps(), "--interpolate", "off", "--variants", "wpctrl_graph,wpctrl_eager",
              "--max-real-envs", str(1 << 20)]  # fmt: skip
    return {act: [*common, "--actuation", act] for act in s.param("actuation", "explicit,implicit").split(",")}


def _ab_osc_cases(s: Session) -> dict:
    return {"osc": ["--repeats", s.reps(), "--variants", "osc_graph,osc_eager,ji_graph,ee_graph", "--physics-envs",
                    "-1"]}  # fmt: skip


def _ab_task_cases(s: Session) -> dict:
    return {"task": ["--tasks", s.param("tasks", "PushCube-v1"), "--substeps", str(s.param("substeps", 8))]}


def _ab_kernels(s: Session) -> list[Step]:
    def run(s: Session) -> None:
        from bench.ab import kernels_summary
        from bench.ab.trees import this_label, tree_label

        old, work = s.baseline_tree.resolve(), s.dir() / "runs"
        work.mkdir(parents=True, exist_ok=True)
        longest = 0.0
        for rnd in range(1, s.param("rounds", 2) + 1):
            for side, tree in (("A", old), ("B", ROOT)):
                if s.left() < 1.2 * longest + 5:
                    s.say(f"ab-kernels: stopping before round {rnd} {side} ({s.left():.0f} s left)")
                    s.status = "cut"
                    break
                argv = ["python", "-m", "bench.ab.kernels", "--device", s.device, "--repeats", s.reps(7), "--out",
                        work, "--tag", f"{side}_{rnd}"]  # fmt: skip
                if s.param("cases", ""):
                    argv += ["--cases", s.param("cases", "")]
                if s.envs:
                    argv += ["--envs", s.envs]
                if rnd == 1:
                    argv += ["--outputs", work / f"{side}.npz"]
                if s.param("quick", 1):
                    argv.append("--quick")
                t0 = time.monotonic()
                s.run(Cmd(f"kernels {side} round {rnd}", argv, 400, env={"BENCH_WPCTRL_TREE": tree}))
                longest = max(longest, time.monotonic() - t0)
        text = "\n".join(kernels_summary.timing(str(work), {"A": tree_label(old), "B": this_label(old)}) +
                         kernels_summary.outputs(str(work)))  # fmt: skip
        (s.dir() / "ab_kernels.md").write_text(text + "\n")
        s.say("\n" + text)

    return [_machine, run]


# ----------------------------------------------------------------------------------------------------------------------
# The table

_S = Stage
STAGES: list[Stage] = [
    # setup: on the development machine, before a GPU session
    _S(
        "assets",
        "setup",
        "copy ManiSkill's Panda asset (URDF, SRDF, collision meshes; ~0.6 MB) to .gpu/assets for "
        "the task and training stages (run with a Python that has mani-skill)",
        5,
        ".gpu/assets/",
        _assets_steps,
    ),
    _S(
        "ab-baseline",
        "setup",
        "write a commit's wpctrl/ and both trees' commits to .gpu/ab_base, the baseline tree of "
        "the A/B stages on a machine without git",
        5,
        ".gpu/ab_base/",
        _baseline_steps,
        needs=("git",),
        params={"rev": "the baseline commit (HEAD)"},
    ),
    # CUDA tests
    _S(
        "tests-step",
        "tests",
        "CUDA tests of the control step: parity with the CPU, graph replay, launch counts, the "
        "captured randomisation reaching MuJoCo-Warp",
        200,
        "tests-step.log",
        _tests(
            "tests/test_cuda.py",
            "tests/test_semantics.py",
            "tests/test_launches.py",
            "tests/test_actuation.py::test_cuda_captured_randomisation_reaches_mujoco",
            limit=420,
        ),
        needs=("cuda",),
        modules=("tests/test_cuda.py", "tests/test_semantics.py", "tests/test_launches.py", "tests/test_actuation.py"),
    ),
    _S(
        "tests-features",
        "tests",
        "CUDA tests of the features (delays, effort tracking, drive randomisation) and of "
        "the EE step; ~5 min with a cold kernel cache",
        150,
        "tests-features.log",
        _tests("tests/test_cuda_features.py", "tests/test_ee_cuda.py", limit=560),
        needs=("cuda",),
        modules=("tests/test_cuda_features.py", "tests/test_ee_cuda.py"),
    ),
    _S(
        "tests-osc",
        "tests",
        "CUDA tests of the impedance controllers (CPU / CUDA parity, graph replay)",
        120,
        "tests-osc.log",
        _tests("tests/test_impedance_cuda.py", limit=250),
        needs=("cuda",),
        modules=("tests/test_impedance_cuda.py",),
    ),
    _S(
        "tests-nets",
        "tests",
        "CUDA tests of the actuator networks",
        60,
        "tests-nets.log",
        _tests("tests/test_actuator_net.py", "tests/test_actuator_net_fused.py", k="cuda", limit=200),
        needs=("cuda",),
        modules=("tests/test_actuator_net.py", "tests/test_actuator_net_fused.py"),
    ),
    _S(
        "tests-tasks",
        "tests",
        "CUDA tests of the tasks, the sync-free sampler and the captured PPO update",
        120,
        "tests-tasks.log",
        _tests("tests/test_sampling.py", "tests/test_tasks_cuda.py", "tests/test_ppo_update.py", k="cuda", limit=300),
        needs=("cuda", "assets"),
        modules=("tests/test_sampling.py", "tests/test_tasks_cuda.py", "tests/test_ppo_update.py"),
    ),
    # the control step
    _S(
        "step-explicit",
        "step",
        "the explicit control step (set_action + 5 substeps): wpctrl eager and graph, torch "
        "eager and CUDA graph, the copy floor; interpolation off and on; 1 to 1M envs",
        150,
        "controller_step_cuda.{json,md}",
        _step_explicit,
        modules=("bench/step/controller_step.py",),
    ),
    _S(
        "step-implicit",
        "step",
        "the implicit control step without interpolation (one launch), 1 to 1M envs",
        90,
        "controller_step_cuda_implicit.{json,md}",
        _step_implicit,
        modules=("bench/step/controller_step.py",),
    ),
    _S(
        "step-block-dim",
        "step",
        "the step kernels' CUDA block size (32 / 64 / 128 / 256) at 4k and 1M envs",
        150,
        "controller_step_block<B>.{json,md}",
        _step_block_dim,
        needs=("cuda",),
        params={"blocks": "32,64,128,256"},
        modules=("bench/step/controller_step.py",),
    ),
    _S(
        "step-ee",
        "step",
        "the pd_ee_delta_pose step against a torch port of ManiSkill's GPU path, and one MuJoCo-Warp step",
        150,
        "ee_step_cuda.{json,md}",
        lambda s: [_machine, bench("ee_step", "bench.step.ee_step", s, "--repeats", s.reps(), limit=300, envs=None)],
        modules=("bench/step/ee_step.py",),
    ),
    _S(
        "step-osc",
        "step",
        "the osc_ee_delta_pose step next to joint impedance, the EE step and Newton's "
        "ControllerOperationalSpace; one MuJoCo-Warp step at 4k; ~5 min with a cold kernel cache",
        150,
        "osc_step_cuda.{json,md}",
        _step_osc,
        params={"physics_envs": "MuJoCo-Warp step at this N (4096)"},
        modules=("bench/step/osc_step.py",),
    ),
    _S(
        "step-actuation",
        "step",
        "each actuation option (delay, effort tracking, clipped targets, shared gains) on one "
        "control step, graph and eager",
        90,
        "actuation_cost_cuda.{json,md}",
        lambda s: [
            _machine,
            bench(
                "actuation_cost",
                "bench.step.actuation_cost",
                s,
                "--repeats",
                s.reps(),
                "--eager",
                limit=150,
                envs="1,4k,64k,1M",
            ),
        ],
        modules=("bench/step/actuation_cost.py",),
    ),
    _S(
        "step-inertia",
        "step",
        "the joint-space response update and the force / acceleration / stable drives, against "
        "Newton's JointSpaceResponse",
        100,
        "inertia_update_cuda.{json,md}",
        lambda s: [
            _machine,
            bench("inertia_update", "bench.step.inertia_update", s, "--repeats", s.reps(), limit=150, envs="1,4k,64k"),
        ],
        modules=("bench/step/inertia_update.py",),
    ),
    _S(
        "step-coupled",
        "step",
        "the coupled drive's control step against the MuJoCo-Warp step of the same run",
        150,
        "inertia_update_cuda.{json,md}",
        lambda s: [
            _machine,
            bench(
                "coupled",
                "bench.step.inertia_update",
                s,
                "--variants",
                "coupled",
                "--mujoco",
                "--repeats",
                s.reps(),
                limit=300,
                envs="1,4k,64k",
            ),
        ],
        modules=("bench/step/inertia_update.py",),
    ),
    # actuators
    _S(
        "act-models",
        "actuators",
        "each actuator model (DC motor, position table, Newton's ClampingDCMotor) against "
        "the plain explicit step of the same process, 1 to 1M envs",
        240,
        "actuator_cost_<model>.{json,md}",
        _act_models,
        params={"models": "dc_motor,position_limit,newton_dc"},
        modules=("bench/actuators/actuator_cost.py",),
    ),
    _S(
        "act-nets",
        "actuators",
        "the actuator networks (MLP, LSTM; unrolled, fused and tiled kernels) and their torch "
        "baseline in one CUDA graph, against the plain step, 4k / 64k / 1M envs",
        150,
        "actuator_cost_cuda.{json,md}",
        _act_nets,
        params={"variants": NET_VARIANTS},
        modules=("bench/actuators/actuator_cost.py",),
    ),
    _S(
        "act-fidelity",
        "actuators",
        "replay of ManiSkill's PhysX traces through each actuation option on MuJoCo-Warp: one-step error and drift",
        120,
        "fidelity_cuda.{json,md}",
        lambda s: [_machine, bench("fidelity", "bench.actuators.fidelity", s, limit=200)],
        modules=("bench/actuators/fidelity.py",),
    ),
    # tasks
    _S(
        "task-step",
        "tasks",
        "PushCube / PickCube env step (graph replay) against the bare MuJoCo-Warp step, the "
        "controller's and the task kernels' shares, 16 / 8 / 4 MuJoCo steps per physics step",
        150,
        "task_step_cuda.{json,md}",
        lambda s: [
            _machine,
            bench(
                "task_step",
                "bench.tasks.task_step",
                s,
                "--substeps",
                s.param("substeps", "16,8,4"),
                limit=300,
                envs="4k",
                env=_env_assets(),
            ),
        ],
        needs=("assets",),
        params={"substeps": "16,8,4"},
        modules=("bench/tasks/task_step.py",),
    ),
    _S(
        "task-rollout",
        "tasks",
        "full control steps with SolverMuJoCo and SolverXPBD: env-steps/s and the controller's share, eager and graph",
        150,
        "rollout_cuda.{json,md}",
        lambda s: [
            _machine,
            bench(
                "rollout",
                "bench.tasks.rollout",
                s,
                "--solver",
                s.param("solvers", "mujoco,xpbd"),
                "--steps",
                "20",
                "--repeats",
                s.reps(3),
                limit=240,
                envs="1k,4k",
            ),
        ],
        params={"solvers": "mujoco,xpbd"},
        modules=("bench/tasks/rollout.py",),
    ),
    # training
    _S(
        "train-reach",
        "training",
        "PPO on 4,096 reach envs: a one-iteration warm-up, then training to 95 % "
        "evaluation success (~3-5 min; cold kernel cache +2 min)",
        300,
        "train.json, learning_curve.png, policy.pt",
        _train_reach,
        params={"iterations": "300", "target": "0.95", "seed": "0"},
    ),
    _S(
        "train-reach-rate",
        "training",
        "the reach env's step by part (rollout, controller, env step, rsl-rl, PPO's "
        "collection) and, after train-reach, the training run's collection rate",
        60,
        "train_rate_cuda.{json,md}",
        _train_reach_rate,
        modules=("bench/training/train_rate.py",),
    ),
    _S(
        "train-push",
        "training",
        "PushCube-v1 PPO, 4,096 envs: warm-up, training to 90 % (cap 150 s), export, "
        "evaluation on Newton over 1,000 episodes (~4-7 min)",
        330,
        "train.json, policy.{pt,ts,json}, newton_eval.json",
        _train_push,
        needs=("assets",),
        params={
            "target": "0.9",
            "cap": "150",
            "substeps": "8",
            "seed": "0",
            "control_mode": "pd_joint_delta_pos",
            "eval_episodes": "1000",
        },
    ),
    _S(
        "train-pick",
        "training",
        "PickCube-v1 PPO, 4,096 envs, to 80 % (cap 540 s from the start)",
        570,
        "train.json, policy.pt",
        _train_pick,
        needs=("assets",),
        params={"target": "0.8", "cap": "540", "eval_every": "25", "substeps": "8", "seed": "0"},
    ),
    _S(
        "train-pick-eval",
        "training",
        "export and Newton evaluation of train-pick's policy",
        90,
        "pick/policy.{ts,json}, pick/newton_eval.json",
        _train_pick_eval,
        needs=("assets",),
    ),
    _S(
        "train-sampling",
        "training",
        "PushCube's collection step with rsl-rl's action sampling and with the sync-free sampler (after a warm-up)",
        200,
        "task_train_rate_PushCube-v1_cuda.{json,md}",
        _train_sampling_rate,
        needs=("assets",),
        modules=("bench/training/task_train_rate.py",),
    ),
    _S(
        "train-push-rate",
        "training",
        "PushCube's step by part (bare rollout, controller, env step, rsl-rl, "
        "collection) and, after train-push, the training run's collection rate",
        150,
        "task_train_rate_PushCube-v1_cuda.{json,md}",
        _train_push_rate,
        needs=("assets",),
        modules=("bench/training/task_train_rate.py",),
    ),
    _S(
        "train-tasks",
        "training",
        "PPO on several ManiSkill tasks (default PullCube, LiftPegUpright, StackCube; pd_joint_delta_pos, "
        "4,096 envs each, ManiSkill's recipe per task), at the same time as separate processes (parallel=0: one "
        "after another), each for time_limit s after a one-iteration warm-up, evaluated every eval_every_steps env "
        "steps; a JSON per task (~6.5 min with the defaults; cold kernel cache +2.5 min)",
        540,
        "train_tasks_<task>.json, train_tasks.{json,md}, train_tasks_runs.tar.gz, <task>/",
        _train_tasks,
        needs=("assets",),
        params={
            "tasks": TRAIN_TASKS,
            "time_limit": "300 (s per task, from its process's start)",
            "eval_every_steps": "1000000",
            "eval_every": "0 (iterations; overrides eval_every_steps)",
            "eval_envs": "512",
            "parallel": "1",
            "warmup": "1",
            "substeps": "8",
            "seed": "0",
            "control_mode": "pd_joint_delta_pos",
            "newton_episodes": "0",
            "maniskill_episodes": "0 (needs mani-skill on the machine)",
            "commit": "the tree's commit where it has no .git",
        },
        modules=("bench/training/train_tasks.py",),
    ),
    # profiling
    _S(
        "prof-overhead",
        "profiling",
        "where an eager step's host time goes: each public call and its pieces, a cProfile listing",
        40,
        "profile_overhead_cuda.{json,md}",
        lambda s: [
            _machine,
            bench(
                "profile_overhead",
                "bench.profiling.profile_overhead",
                s,
                "--repeats",
                s.reps(),
                "--profile-steps",
                "1000",
                limit=90,
                envs="1,4k",
            ),
        ],
        modules=("bench/profiling/profile_overhead.py",),
    ),
    _S(
        "prof-launch",
        "profiling",
        "launch cost against parameter count and index chains: per wp.launch, recorded launch and graph node",
        40,
        "launch_params_cuda.{json,md}",
        lambda s: [
            _machine,
            bench("launch_params", "bench.profiling.launch_params", s, "--repeats", s.reps(), limit=90, envs="4k,1M"),
        ],
        modules=("bench/profiling/launch_params.py",),
    ),
    _S(
        "prof-ncu-step",
        "profiling",
        "Nsight Compute of the step kernels at 1M envs in four modes (implicit / "
        "explicit, interpolation off / on): DRAM throughput, occupancy, stalls",
        150,
        "ncu_report.txt, ncu_metrics.csv",
        _prof_ncu_step,
        needs=("cuda", "ncu"),
        modules=("bench/profiling/ncu_target.py",),
    ),
    _S(
        "prof-ncu-nets",
        "profiling",
        "Nsight Compute of one launch of each actuator-network kernel at 4k and 1M",
        90,
        "ncu_net_<envs>.txt",
        _prof_ncu_nets,
        needs=("cuda", "ncu"),
        params={"variants": "mlp,lstm,mlp_tiled,lstm_tiled", "kernels": "wpctrl_actuator_net"},
        modules=("bench/profiling/ncu_net.py",),
    ),
    _S(
        "prof-ncu-coupled",
        "profiling",
        "Nsight Compute of one coupled-drive launch at 4k envs (source=1: per source line)",
        90,
        "ncu_coupled.txt [, ncu_coupled_source.csv]",
        _prof_ncu_coupled,
        needs=("cuda", "ncu"),
        params={"source": "0"},
        modules=("bench/step/inertia_update.py",),
    ),
    _S(
        "prof-ncu-substep",
        "profiling",
        "Nsight Compute of one substep launch at 4k envs per actuator model (plain, DC motor, position table)",
        120,
        "ncu_substep_<model>.txt",
        _prof_ncu_substep,
        needs=("cuda", "ncu"),
        modules=("bench/actuators/actuator_cost.py",),
    ),
    # A/B of two trees
    _S(
        "ab-step",
        "ab",
        "the control step (explicit and implicit, no interpolation; graph and eager) of the baseline "
        "tree and this one, alternating, 1k / 4k / 16k envs, 3 rounds: new / old and its spread",
        300,
        "ab_step.{md,json}, runs/",
        _ab("controller_step", "bench.step.controller_step", _ab_step_cases, 240),
        needs=("baseline",),
        params={"rounds": "3", "actuation": "explicit,implicit"},
        modules=("bench/step/controller_step.py",),
    ),
    _S(
        "ab-osc",
        "ab",
        "the OSC step (osc_ee_delta_pose graph and eager; joint impedance and the EE step, graph) of "
        "both trees, alternating, 1k / 4k / 16k envs, 3 rounds (cold kernel cache: +3 min)",
        300,
        "ab_osc.{md,json}, runs/",
        _ab("osc_step", "bench.step.osc_step", _ab_osc_cases, 320),
        needs=("baseline",),
        params={"rounds": "3"},
        modules=("bench/step/osc_step.py",),
    ),
    _S(
        "ab-task",
        "ab",
        "the PushCube env step (graph replay) and its controller / task-kernel / physics parts of "
        "both trees, alternating, 1k / 4k / 16k envs, 3 rounds",
        400,
        "ab_task.{md,json}, runs/",
        _ab("task_step", "bench.tasks.task_step", _ab_task_cases, 400),
        needs=("baseline", "assets"),
        params={"rounds": "3", "tasks": "PushCube-v1", "substeps": "8"},
        modules=("bench/tasks/task_step.py",),
    ),
    _S(
        "ab-kernels",
        "ab",
        "every kernel family's captured step (joint, inertia, coupled, EE, OSC, networks) of both "
        "trees, 2 rounds, and whether both write the same bits on a fixed sequence",
        400,
        "ab_kernels.md, runs/",
        _ab_kernels,
        needs=("baseline",),
        params={"rounds": "2", "cases": "every case", "quick": "1"},
        modules=("bench/ab/kernels.py", "bench/ab/kernels_summary.py"),
    ),
]

BY_NAME = {s.name: s for s in STAGES}
GROUPS: dict[str, list[str]] = {}
for _stage in STAGES:
    GROUPS.setdefault(_stage.group, []).append(_stage.name)
GROUPS["ab"] = ["ab-step", "ab-osc", "ab-task"]  # the three A/B tables; ab-kernels by name


def expand(names: list[str]) -> list[Stage]:
    """Stage and group names to stages, in the order given, each once."""
    out: list[Stage] = []
    for name in names:
        if name in BY_NAME:
            picked = [name]
        elif name in GROUPS:
            picked = GROUPS[name]
        else:
            raise KeyError(name)
        out += [BY_NAME[n] for n in picked if BY_NAME[n] not in out]
    return out
