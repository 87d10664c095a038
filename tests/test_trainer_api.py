"""Training from Python and the command line's one rule for unused options: :class:`wpctrl.train.TrainConfig`
refuses a field that cannot work before anything is built (naming the field, what it expects and what it got),
importing ``wpctrl.train`` loads neither torch nor rsl-rl, the evaluation and export modules import no rsl-rl, no
tensordict and no trainer, and an option a command or mode does not use is refused, naming it and why."""

from __future__ import annotations

import argparse
import subprocess
import sys

import pytest

from wpctrl.tasks.names import TASK_MODULES
from wpctrl.train import TrainConfig, TrainConfigError
from wpctrl.train.command_args import given_flags, refuse_unused


def _python(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)


def test_importing_the_train_package_loads_neither_torch_nor_rsl_rl():
    done = _python("import sys\nfrom wpctrl.train import Trainer, TrainConfig\nTrainConfig(envs=8)\n"
                   "print(sorted(m for m in ('torch', 'rsl_rl', 'warp', 'newton') if m in sys.modules))")  # fmt: skip
    assert done.returncode == 0 and done.stdout.strip() == "[]", (done.stdout, done.stderr)


def test_evaluation_and_export_modules_import_neither_rsl_rl_nor_the_trainer():
    code = (
        "import sys\n"
        "blocked = ('rsl_rl', 'tensordict', 'wpctrl.train.trainer', 'wpctrl.train.task_ppo', 'wpctrl.train.task_env')\n"
        "for name in blocked:\n"
        "    sys.modules[name] = None\n"
        "import wpctrl.train.evaluate, wpctrl.train.export, wpctrl.train.actor, wpctrl.train.policy_eval\n"
        "import wpctrl.train.commands\n"
        "print('ok')\n"
    )
    done = _python(code)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"envs": 0}, "TrainConfig.envs: expected a positive number, got 0"),
        ({"envs": "64"}, "TrainConfig.envs: expected an integer, got '64' (str)"),
        ({"task": "PushCube"}, f"TrainConfig.task: expected one of {['reach', *TASK_MODULES]}, got"),
        ({"epochs": 4}, "TrainConfig.epochs: only for the ManiSkill tasks"),
        ({"no_partial_reset": True}, "TrainConfig.no_partial_reset: only for the ManiSkill tasks"),
        ({"target_success": 0.9}, "TrainConfig.target_success: needs eval_every N"),
        ({"target_success": "high", "eval_every": 1}, "TrainConfig.target_success: expected a number, got 'high'"),
        ({"control_mode": "pd_joint_pos"}, "TrainConfig.control_mode: expected one of"),
        ({"task": "PushCube-v1", "device": "cpu", "ppo_update": "captured"},
         "TrainConfig.ppo_update: 'captured' needs a CUDA device, got device cpu"),
        ({"task": "PushCube-v1", "device": "cpu", "envs": 8}, "envs 8 x steps_per_env 4 = a batch of 32 samples"),
        ({"task": "PushCube-v1", "hide_obs": "fingers"},
         "TrainConfig.hide_obs: expected one of ['finger_qvel', 'none'], got 'fingers'"),
        ({"hide_obs": "none"}, "TrainConfig.hide_obs: only for the ManiSkill tasks"),
        ({"task": "PushCube-v1", "randomize": "mass=2:1"},
         "TrainConfig.randomize: TaskRandomization.mass: expected a range (low, high) of scale factors with 0 < low "
         "<= high, got (2.0, 1.0)"),
        ({"task": "PushCube-v1", "randomize": "gravity=1:2"},
         "TrainConfig.randomize: expected 'off', 'on' or name=low:high,... with names ['friction', 'contact_time', "
         "'mass'], got 'gravity=1:2'"),
        ({"task": "PushCube-v1", "randomize": 1}, "TrainConfig.randomize: expected 'off', 'on' or name=low:high"),
        ({"task": "PushCube-v1", "randomize": "contact_time=0.4:1", "substeps": 8},
         "TrainConfig.randomize: TaskRandomization.contact_time: expected low >= 0.5 (MuJoCo raises a time constant "
         "under two of its steps, 2.5 ms, to two steps, so a shorter one would not be drawn; the scene's shortest is "
         "5 ms), got (0.4, 1.0) (with substeps 8)"),
    ],
)  # fmt: skip
def test_train_config_names_the_field_that_cannot_work(kwargs, message):
    from wpctrl.train import Trainer

    with pytest.raises(TrainConfigError) as e:
        Trainer(TrainConfig(**kwargs))
    assert message in str(e.value), str(e.value)


def test_the_trained_tasks_are_the_registrys():
    """``wpctrl train`` trains every task of the registry (its host-only names), and its command line offers them."""
    from wpctrl.train.cli import parser
    from wpctrl.train.train_config import MANISKILL_TASKS, TASKS

    assert MANISKILL_TASKS == tuple(TASK_MODULES) and TASKS == ("reach", *TASK_MODULES)
    (task,) = [a for a in parser()._actions if a.dest == "task"]
    assert tuple(task.choices) == TASKS
    assert all(name in parser().description for name in TASK_MODULES)


def test_each_task_takes_maniskills_recipe_and_its_departures_are_data():
    """One recipe for every task (ManiSkill's ppo_fast: 4 steps per env, 8 epochs of 32 mini-batches), StackCube-v1's
    16 steps per env ManiSkill's own departure from it, read from TASK_RECIPES; a flag still wins."""
    from wpctrl.train.ppo_config import TASK_RECIPES, task_recipe

    for name in TASK_MODULES:
        cfg = TrainConfig(task=name, device="cpu").resolved()
        want = task_recipe(name)
        assert (cfg.steps_per_env, cfg.epochs, cfg.minibatches) == (
            want["steps_per_env"], want["epochs"], want["minibatches"])  # fmt: skip
        assert want["steps_per_env"] == TASK_RECIPES.get(name, {}).get("steps_per_env", 4)
    assert task_recipe("StackCube-v1")["steps_per_env"] == 16 and task_recipe("PullCube-v1")["steps_per_env"] == 4
    assert TrainConfig(task="StackCube-v1", device="cpu", steps_per_env=2).resolved().steps_per_env == 2
    assert set(TASK_RECIPES) <= set(TASK_MODULES)  # no recipe for a task the registry does not have
    # the batch check uses the task's default: 2 envs x 16 steps = 32 samples fill StackCube's 32 mini-batches by 1
    with pytest.raises(TrainConfigError, match="envs 2 x steps_per_env 16 = a batch of 32 samples"):
        TrainConfig(task="StackCube-v1", device="cpu", envs=2).check()


def test_train_config_mirrors_the_command_lines_options_and_defaults():
    from wpctrl.train.cli import parser

    args = parser().parse_args([])
    assert TrainConfig.from_args(args) == TrainConfig()
    cfg = TrainConfig(task="PushCube-v1", device="cpu").resolved()
    assert (cfg.envs, cfg.iterations, cfg.steps_per_env, cfg.eval_envs, cfg.eval_episodes) == (64, 20, 4, 64, 64)
    assert (cfg.control_mode, cfg.ppo_update, cfg.obs_normalization, cfg.action_sampling) == (
        "pd_joint_delta_pos", "rsl-rl", "off", "sync-free")  # fmt: skip
    assert (cfg.hide_obs, cfg.randomize) == ("finger_qvel", "off")
    reach = TrainConfig(device="cpu", envs=16).resolved()
    assert (reach.control_mode, reach.iterations, reach.steps_per_env, reach.eval_episodes) == (
        "pd_ee_delta_pos", 20, 24, 16)  # fmt: skip


def test_resume_from_python_refuses_a_changed_field_that_contradicts_the_run(tmp_path):
    import json

    from wpctrl.train import Trainer

    run = tmp_path / "run"
    run.mkdir()
    summary = {"task": "reach", "control_mode": "pd_ee_delta_pos", "envs": 16, "steps_per_env": 24, "seed": 3,
               "history": [], "evaluations": [], "iterations": 2}  # fmt: skip
    (run / "train.json").write_text(json.dumps(summary))
    (run / "policy.pt").write_text("")
    with pytest.raises(TrainConfigError, match="envs 32: the resumed run was trained with --envs 16"):
        Trainer(TrainConfig(resume=str(run), envs=32))
    t = Trainer(TrainConfig(resume=str(run), device="cpu"))
    assert (t.cfg.envs, t.cfg.seed, t.run_dir) == (16, 3, run)  # the run's configuration, its folder


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="wpctrl probe")
    p.add_argument("--device", default="cpu")
    p.add_argument("--envs", type=int, default=None)
    p.add_argument("--seed", type=int, default=0)
    return p


def test_refuse_unused_names_the_first_given_option_even_at_its_default(capsys):
    p = _parser()
    assert given_flags(p, ["--device", "cpu", "--seed", "1"]) == {"device", "seed"}
    refuse_unused(p, given_flags(p, ["--seed", "1"]), ("device", "envs"), "not used here")  # nothing refused
    with pytest.raises(SystemExit) as e:
        refuse_unused(p, given_flags(p, ["--envs", "4", "--device", "cpu"]), ("device", "envs"), "not used here")
    assert e.value.code == 2
    assert capsys.readouterr().err.splitlines()[-1] == "wpctrl probe: error: --device: not used here"


@pytest.mark.parametrize("option", [["--device", "cpu"], ["--envs", "4"], ["--substeps", "8"]])
def test_evaluate_on_maniskill_refuses_the_newton_only_options(option, tmp_path, capsys):
    from wpctrl.__main__ import main

    policy = tmp_path / "policy.ts"
    policy.write_text("not read: the option is refused first")
    assert main(["evaluate", "--policy", str(policy), "--sim", "maniskill", *option]) == 2
    err = capsys.readouterr().err.splitlines()[-1]
    assert err.startswith(f"wpctrl evaluate: error: {option[0]}: not used with --sim maniskill (ManiSkill runs"), err


def test_evaluate_on_maniskill_refuses_a_video(tmp_path, capsys):
    """Only ``--sim newton`` is filmed: ``--video`` with ``--sim maniskill`` is refused, not skipped after the run."""
    from wpctrl.__main__ import main

    policy = tmp_path / "policy.ts"
    policy.write_text("not read: the option is refused first")
    assert main(["evaluate", "--policy", str(policy), "--sim", "maniskill", "--video", str(tmp_path / "e.mp4")]) == 2
    err = capsys.readouterr().err.splitlines()[-1]
    assert err.startswith("wpctrl evaluate: error: --video: only --sim newton is recorded"), err
    assert not (tmp_path / "e.mp4").exists()


def test_evaluate_from_python_refuses_a_video_of_maniskill(tmp_path):
    pytest.importorskip("torch", reason="torch is not installed")
    from wpctrl.train.evaluate import evaluate

    with pytest.raises(ValueError, match="video: only sim='newton' is recorded, got sim='maniskill'"):
        evaluate(tmp_path / "policy.ts", sim="maniskill", video=tmp_path / "e.mp4")


def test_the_top_level_command_line_refuses_an_unknown_command(capsys):
    from wpctrl.__main__ import main

    assert main(["fly"]) == 2
    err = capsys.readouterr().err
    assert "wpctrl: error: argument <command>: invalid choice: 'fly'" in err and "'train'" in err
    assert main([]) == 2 and "train" in capsys.readouterr().out


@pytest.mark.slow  # a short PPO run (CI runs it)
def test_trainer_runs_from_python_and_returns_its_run_directory(tmp_path):
    pytest.importorskip("rsl_rl", reason="the train extra (rsl-rl-lib) is not installed")
    import json

    from wpctrl.train import Trainer

    cfg = TrainConfig(envs=8, iterations=1, device="cpu", logger="none", eval_episodes=8, out=tmp_path / "run")
    run = Trainer(cfg).run()
    assert run == tmp_path / "run" and (run / "policy.pt").is_file() and (run / "learning_curve.png").is_file()
    summary = json.loads((run / "train.json").read_text())
    got = (summary["task"], summary["envs"], summary["iterations"], summary["stopped_by"])
    assert got == ("reach", 8, 1, "iterations")
    assert summary["evaluation"]["episodes"] >= 8
