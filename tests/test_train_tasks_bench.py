"""The bench stage that trains several tasks for a time budget each (``python -m bench train-tasks``,
``bench/training/train_tasks.py``): the stage's command, its refusal of an unknown task, the per-task record it keeps
of a ``train.json`` (timings from the process's start, success once and at the end per evaluation, the first
evaluation past each success level), and a short CPU session of two tasks at once."""

from __future__ import annotations

import json

import pytest

from bench.__main__ import main as bench_main
from bench.training import train_tasks
from wpctrl.tasks.names import TASK_MODULES


def test_the_stage_runs_the_tasks_module_with_its_parameters(tmp_path, capsys):
    from bench import stages

    if not stages._has_assets():
        pytest.skip("the stage needs ManiSkill's Panda asset (mani-skill or .gpu/assets)")
    argv = ["train-tasks", "--dry-run", "--device", "cpu", "--set", "tasks=PullCube-v1,StackCube-v1", "--set",
            "time_limit=120", "--set", "parallel=0", "--set", "commit=abc1234", "--out", str(tmp_path)]  # fmt: skip
    assert bench_main(argv) == 0
    out = capsys.readouterr().out
    (line,) = [ln for ln in out.splitlines() if "-m bench.training.train_tasks" in ln]
    for part in ("--tasks PullCube-v1,StackCube-v1", "--time-limit 120.0", "--parallel 0", "--warmup 1",
                 "--control-mode pd_joint_delta_pos", "--commit abc1234", "--device cpu"):  # fmt: skip
        assert part in line, (part, line)
    assert "no stage read --set" not in out


def test_an_unknown_task_is_refused_listing_the_known_ones():
    with pytest.raises(SystemExit) as e:
        train_tasks.check_tasks("PullCube-v1,PlugCharger-v1")
    assert "unknown task(s) ['PlugCharger-v1']" in str(e.value)
    assert str(list(TASK_MODULES)) in str(e.value)
    assert train_tasks.check_tasks(" PullCube-v1, StackCube-v1 ") == ["PullCube-v1", "StackCube-v1"]


def _summary() -> dict:
    evals = [(-1, 0.0, 0.0, 1.0), (9, 0.55, 0.3, 12.0), (19, 0.95, 0.7, 24.0), (24, 0.85, 0.6, 30.0)]
    return {
        "task": "PullCube-v1", "control_mode": "pd_joint_delta_pos", "envs": 64, "steps_per_env": 4,
        "iterations": 25, "env_steps": 25 * 64 * 4, "substeps": 8, "seed": 0, "device": "cpu", "device_name": "cpu",
        "graph": True, "ppo_update": "rsl-rl", "action_sampling": "sync-free", "partial_reset": True, "eval_envs": 16,
        "max_episode_steps": 50, "obs_dim": 35, "recipe": {"steps_per_env": 4}, "stopped_by": "time_limit",
        "import_s": 4.0, "setup_s": 6.0, "train_start_s": 10.5, "train_wall_s": 30.0, "total_s": 42.0,
        "collection_env_steps_per_s_median": 500.0,
        "ppo": {"algorithm": {"num_learning_epochs": 8, "num_mini_batches": 32}},
        "evaluations": [{"iteration": it, "env_steps": (it + 1) * 256, "wall_s": w, "success_rate": once,
                         "success_at_end_rate": end, "mean_episode_reward": 1.0, "episodes": 16}
                        for it, once, end, w in evals],
    }  # fmt: skip


def test_the_record_times_each_evaluation_from_the_process_start():
    args = train_tasks.parser().parse_args(["--time-limit", "40", "--envs", "64", "--eval-every-steps", "2560"])
    r = train_tasks.task_record(_summary(), args, ["PullCube-v1", "StackCube-v1"])
    assert r["task"] == "PullCube-v1" and r["time_limit_s"] == 40.0 and r["eval_every_iterations"] == 10
    assert [e["wall_s_from_start"] for e in r["evaluations"]] == [11.5, 22.5, 34.5, 40.5]
    assert [(e["success_once"], e["success_at_end"]) for e in r["evaluations"]][1:] == [(0.55, 0.3), (0.95, 0.7),
                                                                                         (0.85, 0.6)]  # fmt: skip
    assert r["evaluations"][0]["env_steps"] == 0  # the untrained policy
    assert r["final"]["iteration"] == 24 and r["best"]["iteration"] == 19
    assert r["first_reached"]["0.5"] == {"iteration": 9, "env_steps": 2560, "wall_s_from_start": 22.5}
    assert r["first_reached"]["0.9"]["iteration"] == 19
    assert r["concurrent_tasks"] == ["PullCube-v1", "StackCube-v1"] and r["versions"]["torch"]
    assert r["commit"] and (r["epochs"], r["minibatches"]) == (8, 32)
    md = train_tasks.markdown([r], parallel=True)
    row = "| PullCube-v1 | pd_joint_delta_pos | 64 × 4 | 25 | 6,400 | time_limit | 85.0 % (60.0 %) | 95.0 % (34 s) |"
    assert row in md, md


@pytest.mark.slow  # two short PPO runs in two processes (CI runs it)
def test_a_cpu_session_trains_two_tasks_at_once_and_writes_a_record_each(tmp_path):
    pytest.importorskip("rsl_rl", reason="the train extra (rsl-rl-lib) is not installed")
    argv = ["--tasks", "PullCube-v1,LiftPegUpright-v1", "--device", "cpu", "--envs", "16", "--substeps", "2",
            "--time-limit", "1", "--eval-every", "1", "--eval-envs", "2", "--warmup", "0",
            "--out", str(tmp_path)]  # fmt: skip
    assert train_tasks.main(argv) == 0
    combined = json.loads((tmp_path / "train_tasks.json").read_text())
    assert combined["parallel"] is True and combined["exit_codes"] == {"PullCube-v1": 0, "LiftPegUpright-v1": 0}
    for task in ("PullCube-v1", "LiftPegUpright-v1"):
        r = json.loads((tmp_path / f"train_tasks_{task}.json").read_text())
        assert (r["task"], r["envs"], r["stopped_by"], r["iterations"]) == (task, 16, "time_limit", 1)
        assert r["concurrent_tasks"] == ["PullCube-v1", "LiftPegUpright-v1"]
        assert [e["iteration"] for e in r["evaluations"]] == [-1, 0]
        assert (tmp_path / task / "policy.ts").is_file()
    assert (tmp_path / "train_tasks.md").read_text().count("| pd_joint_delta_pos |") == 2
    assert (tmp_path / "train_tasks_runs.tar.gz").stat().st_size > 1000
