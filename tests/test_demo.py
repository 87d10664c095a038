"""The demo's entry point with tiny settings: a real MuJoCo-Warp rollout of Pandas through wpctrl."""

from __future__ import annotations

import json

import pytest

from wpctrl.demo import main


def test_demo_tracks_and_writes_files(tmp_path, capsys):
    out = tmp_path / "demo"
    rc = main(["--envs", "4", "--seconds", "1.5", "--out", str(out), "--no-progress", "--seed", "1"])
    assert rc == 0
    s = json.loads((out / "summary.json").read_text())
    assert (out / "tracking.png").stat().st_size > 10_000
    assert s["all_finite"] and s["envs"] == 4 and s["control_steps"] == 30
    # A working controller keeps the arm within a few centi-radians of the sinusoid; a broken one (no targets,
    # wrong sign, wrong joints) leaves errors of the trajectory's amplitude (0.1-0.3 rad) or more.
    assert s["tracking_rms"]["arm"] < 0.06
    assert s["tracking_rms"]["gripper"] < 0.015
    assert s["env_steps_per_s"] > 0 and 0 < s["controller_share"] < 1
    printed = capsys.readouterr().out
    assert "env-steps/s" in printed and "arm tracking" in printed


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--control-mode", "pd_ee_delta_twist"], "--control-mode"),
        (["--envs", "0"], "--envs"),
        (["--solver", "physx"], "--solver"),
        (["--sim-freq", "90"], "--sim-freq"),
        (["--device", "cuda:0"], "--device"),
    ],
)
def test_demo_bad_arguments_exit_2(argv, message, capsys):
    import warp as wp

    if argv[0] == "--device" and wp.is_cuda_available():
        pytest.skip("a GPU is present")
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    assert message in capsys.readouterr().err
