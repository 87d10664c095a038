"""The demo's entry point with tiny settings: real MuJoCo-Warp / Featherstone rollouts of Pandas through wpctrl.

Every summary.json is parsed strictly (NaN / Infinity tokens raise). Every solver x actuation (x explicit PD law)
combination the CLI offers either tracks or is refused up front with exit 2 and a one-line reason.
"""

from __future__ import annotations

import json
import math

import pytest

from wpctrl import demo
from wpctrl.__main__ import main as cli_main
from wpctrl.demo import arguments as demo_arguments
from wpctrl.demo import main

TINY = ["--envs", "2", "--seconds", "0.75", "--no-progress"]


def _no_constant(name):
    raise ValueError(f"summary.json holds a bare {name} token (not strict JSON)")


def load_summary(out) -> dict:
    return json.loads((out / "summary.json").read_text(), parse_constant=_no_constant)


def test_demo_tracks_and_writes_files(tmp_path, capsys):
    out = tmp_path / "demo"
    rc = main(["--envs", "4", "--seconds", "1.5", "--out", str(out), "--no-progress", "--seed", "1"])
    assert rc == 0
    s = load_summary(out)
    assert (out / "tracking.png").stat().st_size > 10_000
    assert s["all_finite"] and s["envs"] == 4 and s["control_steps"] == 30 and s["world_size"] == 1
    assert s["nonfinite_envs"] == 0 and s["bad_actions"] == 0 and s["diverged_at_s"] is None
    assert "per_rank" not in s  # a plain run's summary is a single process's
    # A working controller keeps the arm within a few centi-radians of the sinusoid; a broken one (no targets,
    # wrong sign, wrong joints) leaves errors of the trajectory's amplitude (0.1-0.3 rad) or more.
    assert s["tracking_rms"]["arm"] < 0.06
    assert s["tracking_rms"]["gripper"] < 0.015
    assert s["tracking_rms"]["arm"] <= s["tracking_max"]["arm"] < 0.3
    assert s["env_steps_per_s"] > 0 and 0 < s["controller_share"] < 1
    assert s["compile_seconds"] <= s["setup_seconds"]
    printed = capsys.readouterr().out
    lines = printed.splitlines()
    # What runs comes first; the compile notice only when Warp compiled a module (test_compile_notice_* show it
    # appears on a cold cache and stays away on a warm one), then the time it took, then the table.
    assert lines[0] == "wpctrl demo: 4 Pandas, pd_joint_delta_pos, implicit actuation, MuJoCo-Warp at 100 Hz on cpu"
    ready = next(i for i, line in enumerate(lines) if line.startswith("kernels ready in "))
    compiled = int(lines[ready].split("(")[1].split(" kernel modules compiled")[0])
    notices = [line for line in lines if line.startswith("compiling Warp kernels for cpu: ")]
    assert len(notices) == (1 if compiled else 0) and ready == 1 + len(notices)
    for label in ("env-steps/s", "controller / control step", "solver / control step", "bad actions (NaN/Inf)"):
        assert label in printed
    assert "vs the policy's desired trajectory" in printed


def _combinations():
    for solver in demo.SOLVERS:
        for actuation in demo.ACTUATIONS:
            for pd in demo.explicit_pd_choices() if actuation == "explicit" else (None,):
                yield solver, actuation, pd


@pytest.mark.slow  # every solver x actuation x law the demo offers (CI runs it)
@pytest.mark.parametrize("solver, actuation, pd", list(_combinations()))
def test_every_offered_combination_tracks_or_is_refused(solver, actuation, pd, tmp_path, capsys):
    out = tmp_path / "demo"
    argv = [*TINY, "--solver", solver, "--actuation", actuation, "--out", str(out)]
    if pd is not None:
        argv += ["--explicit-pd", pd]
    why = demo.unsupported(solver, actuation, pd, demo.default_sim_freq(solver, actuation, pd))
    if why is not None:
        with pytest.raises(SystemExit) as e:
            main(argv)
        assert e.value.code == 2
        captured = capsys.readouterr()
        err = captured.err.strip().splitlines()
        assert err[-1] == f"wpctrl demo: error: {why}"  # one line, the reason, before anything was built
        assert "use " in why and not out.exists() and captured.out == ""
        return
    assert main(argv) == 0
    s = load_summary(out)
    assert s["all_finite"] and s["solver"] == solver and s["actuation"] == actuation
    assert s["explicit_pd"] == (pd if actuation == "explicit" else None)
    assert s["tracking_rms"]["arm"] < 0.06 and s["tracking_max"]["arm"] < 0.3


def test_explicit_defaults_and_rates_that_do_not_track_are_refused(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main([*TINY, "--actuation", "explicit", "--out", str(out)]) == 0
    s = load_summary(out)
    assert s["explicit_pd"] == "coupled" and s["sim_freq"] == 100
    for argv, fragment in [
        (
            ["--actuation", "explicit", "--explicit-pd", "stable", "--sim-freq", "100"],
            "--explicit-pd stable at --sim-freq 100",
        ),
        (["--solver", "featherstone", "--actuation", "explicit", "--sim-freq", "500"], "--solver featherstone at"),
        (["--actuation", "explicit", "--explicit-pd", "naive", "--sim-freq", "1000"], "--explicit-pd naive"),
    ]:
        with pytest.raises(SystemExit) as e:
            main([*TINY, *argv, "--out", str(out)])
        assert e.value.code == 2 and fragment in capsys.readouterr().err


def test_divergence_is_reported_as_null_with_the_cause(tmp_path, capsys, monkeypatch):
    """Force a refused combination through (Featherstone's explicit built-in drive at the Panda's gains): the run
    stops at the first non-finite step, RMS and max are both null, and the message names the options that hold."""
    monkeypatch.setattr(demo_arguments, "unsupported", lambda *a: None)
    out = tmp_path / "demo"
    rc = main([*TINY, "--solver", "featherstone", "--actuation", "implicit", "--sim-freq", "100", "--out", str(out)])
    assert rc == 1
    text = (out / "summary.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    s = load_summary(out)
    assert not s["all_finite"] and s["nonfinite_envs"] >= 1
    assert s["tracking_rms"] == {"arm": None, "gripper": None}
    assert s["tracking_max"] == {"arm": None, "gripper": None}
    assert s["diverged_at_s"] is not None and s["diverged_at_s"] < 0.75
    captured = capsys.readouterr()
    assert "RMS n/a rad, max n/a rad" in captured.out and "NO (" in captured.out
    assert "went non-finite" in captured.err and demo.supported_combinations() in captured.err


def test_strict_json_replaces_non_finite_numbers():
    from wpctrl.demo.report import strict_json

    text = strict_json({"a": math.nan, "b": [1.0, math.inf, -math.inf], "c": {"d": 2}})
    assert json.loads(text, parse_constant=_no_constant) == {"a": None, "b": [1.0, None, None], "c": {"d": 2}}


@pytest.mark.parametrize(
    "module, label",
    [("matplotlib", "matplotlib"), ("tqdm", "tqdm"), ("mujoco_warp", "MuJoCo-Warp"), ("mujoco", "MuJoCo")],
)
def test_missing_extra_is_one_line_before_any_simulation(module, label, tmp_path, capsys, monkeypatch):
    # None in sys.modules makes `import module` raise ImportError: the path a base install (no [demo] extra) takes.
    monkeypatch.setitem(__import__("sys").modules, module, None)
    out = tmp_path / "demo"
    rc = cli_main(["demo", "--envs", "2", "--seconds", "0.75", "--out", str(out)])  # the console script's entry
    assert rc == 2
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len([line for line in err if "wpctrl demo" in line]) == 1 and "Traceback" not in captured.err
    assert label in err[-1] and 'pip install -e ".[demo]"' in err[-1] and "wpctrl[demo]" in err[-1]
    assert captured.out == "" and not out.exists()


def test_missing_progress_bar_is_fine_without_progress(tmp_path, monkeypatch):
    monkeypatch.setitem(__import__("sys").modules, "tqdm", None)
    ns = demo._parser().parse_args(["--no-progress"])
    demo._check_extras(ns)  # no SystemExit: tqdm is only needed for the progress bar


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--control-mode", "pd_ee_delta_pose_nope"], "--control-mode"),
        (["--envs", "0"], "--envs"),
        (["--solver", "physx"], "--solver"),
        (["--sim-freq", "90"], "--sim-freq"),
        (["--seconds", "0.3"], "--seconds: expected at least 0.55 s"),
        (["--seconds", "0.5", "--control-freq", "10"], "--seconds: expected at least 0.6 s"),
        (["--control-freq", "0"], "--control-freq"),
        (["--device", "cuda:0"], "--device"),
        (["--device", "gpu"], "--device"),
        (["--explicit-pd", "stable"], "--explicit-pd stable: applies to --actuation explicit only"),
        (["--actuation", "explicit", "--explicit-pd", "nope"], "--explicit-pd"),
    ],
)
def test_demo_bad_arguments_exit_2(argv, message, capsys):
    import warp as wp

    if argv[0] == "--device" and argv[1] == "cuda:0" and wp.is_cuda_available():
        pytest.skip("cuda:0 exists on this machine: the no-GPU refusal cannot be shown")
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    captured = capsys.readouterr()
    assert message in captured.err
    assert captured.out == ""  # refused before anything is announced, built or compiled


def test_help_lists_every_control_mode_and_solver(capsys):
    from wpctrl.config.options import EXPLICIT_PD_LAWS
    from wpctrl.robots import PANDA_CONTROL_MODES

    assert list(demo.PANDA_MODES) == list(PANDA_CONTROL_MODES)  # the light copy --help reads is the real list
    assert sorted(demo.explicit_pd_choices()) == sorted(EXPLICIT_PD_LAWS)
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    text = capsys.readouterr().out
    for name in [*PANDA_CONTROL_MODES, *demo.SOLVERS, *demo.explicit_pd_choices()]:
        assert name in text
    for option in ("--envs", "--control-freq", "--seconds", "--seed", "--out", "--graph", "--progress"):
        line = text[text.index(option) :].split("\n--")[0]
        assert "(default " in " ".join(line.split()), option  # every option shows its default


def test_top_level_help_lists_the_commands(capsys):
    from wpctrl.__main__ import COMMANDS

    assert cli_main(["--help"]) == 0
    text = capsys.readouterr().out
    for name, (_, summary) in COMMANDS.items():
        assert f"  {name:8s} {summary}" in text


_NOTICE_SCRIPT = """
import sys, warp as wp
wp.config.log_level = wp.LOG_WARNING
wp.config.kernel_cache_dir = sys.argv[1]
from wpctrl.demo.notice import CompileNotice

@wp.kernel
def affine(x: wp.array(dtype=float)):
    i = wp.tid()
    x[i] = 2.0 * x[i] + 1.0

with CompileNotice(lambda msg: print("NOTICE", msg), "a test kernel") as notice:
    x = wp.ones(3, dtype=float, device="cpu")
    wp.launch(affine, 3, inputs=[x], device="cpu")
print(notice.summary(), x.numpy().tolist())
"""


def test_compile_notice_on_a_cold_cache_only(tmp_path):
    """Two processes share an empty kernel cache: the first compiles (one notice, before the compile), the second
    loads the module from the cache (no notice)."""
    import subprocess
    import sys

    script = tmp_path / "notice_probe.py"
    script.write_text(_NOTICE_SCRIPT)
    cache = tmp_path / "cache"

    def probe():
        r = subprocess.run([sys.executable, str(script), str(cache)], capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr
        return r.stdout.splitlines()

    cold = probe()
    assert cold[0].startswith("NOTICE compiling a test kernel (first run only")
    assert cold[1] == "1 kernel modules compiled, 0 loaded from the cache [3.0, 3.0, 3.0]"
    warm = probe()
    assert warm == ["0 kernel modules compiled, 1 loaded from the cache [3.0, 3.0, 3.0]"]


def test_default_output_is_git_ignored():
    from conftest import ROOT

    ignored = (ROOT / ".gitignore").read_text().split()
    assert demo.DEFAULT_OUT + "/" in ignored


# ----------------------------------------------------------------------------------------------------------------------
# --robot: ManiSkill agents loaded by uid (the maniskill extra is in the test dependencies)


def test_robot_modes_table_is_maniskills():
    from wpctrl.maniskill import load_robot

    for robot, modes in demo.ROBOT_MODES.items():
        if robot != "panda":
            refused = [m for (r, m) in demo.ROBOT_MODES_REFUSED if r == robot]
            assert sorted([*modes, *refused]) == sorted(load_robot(robot).control_modes), robot


@pytest.mark.slow  # ManiSkill's robots in MuJoCo-Warp (CI runs it)
@pytest.mark.parametrize(
    "robot, groups",
    [
        ("fetch", {"arm", "gripper", "body [rad]", "body [m]", "base [m/s]", "base [rad/s]"}),
        ("allegro_hand_right", {"robot"}),
        ("unitree_g1_simplified_legs", {"body"}),
    ],
)
def test_maniskill_robot_follows_its_drive_targets(robot, groups, tmp_path, capsys):
    """Every controlled joint of a ManiSkill robot follows wpctrl's drive targets inside MuJoCo-Warp: a base's
    velocity rows its velocity targets, the rest their position targets. Broken targets (wrong joints, wrong rows,
    a base command in the wrong frame) leave errors of the actions' own size (0.1-1 rad, 0.2 m/s)."""
    out = tmp_path / "demo"
    argv = ["--robot", robot, "--envs", "2", "--seconds", "1", "--no-progress", "--out", str(out)]
    assert main(argv) == 0
    s = load_summary(out)
    assert s["all_finite"] and s["robot"] == robot and set(s["tracking_rms"]) == groups
    assert capsys.readouterr().out.startswith(f"wpctrl demo: 2 {robot} robots, pd_joint_delta_pos")
    limits = {"rad": 0.05, "m": 0.04, "m/s": 0.1, "rad/s": 0.05}
    if robot == "unitree_g1_simplified_legs":  # floating, gravity on, no balance policy: it falls and its joints
        limits["rad"] = 0.2  # press on the ground: 0.08-0.12 rad measured
    for group, rms in s["tracking_rms"].items():
        assert rms < limits[s["units"][group]], (group, rms)
    assert (out / "tracking.png").stat().st_size > 10_000


def test_robot_refusals_name_the_reason(capsys, monkeypatch):
    for argv, fragment in [
        (["--robot", "fetch", "--control-mode", "pd_ee_pose"], "--control-mode: expected one of pd_joint_delta_pos"),
        (["--robot", "allegro_hand_right", "--solver", "steel"], "--solver mujoco only"),
        (["--robot", "fetch", "--control-mode", "pd_joint_pos_vel"], "refused, it normalises actions over the"),
    ]:
        with pytest.raises(SystemExit) as e:
            main(argv)
        captured = capsys.readouterr()
        assert e.value.code == 2 and fragment in captured.err and captured.out == ""
    monkeypatch.setitem(__import__("sys").modules, "mani_skill", None)  # a base install without the extra
    with pytest.raises(SystemExit) as e:
        main(["--robot", "fetch", "--no-progress"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "ManiSkill not installed; --robot fetch needs the [demo,maniskill] extra" in err
