"""What a training run writes for its user besides the checkpoint: TensorBoard event files whose scalars are the ones
``train.json`` records (read back with TensorBoard's own reader), ``--resume`` (the checkpoint's weights, normaliser
and optimizer state at the resumed run's first update, the iteration count continuing, conflicting flags refused), the
learning curve's smoothing against a numpy re-derivation and its note where no episode has finished, and the skip
message of ``wpctrl evaluate --video`` where no renderer works."""

from __future__ import annotations

import copy
import json
import math
import shutil

import numpy as np
import pytest

pytest.importorskip("rsl_rl", reason="the train extra (rsl-rl-lib) is not installed")  # a dev dependency
torch = pytest.importorskip("torch", reason="torch is not installed")  # a dev dependency

from wpctrl.train.outputs import NO_EPISODE, figure, smoothed  # noqa: E402

REACH = ["--envs", "16", "--iterations", "2", "--seed", "0", "--eval-every", "1", "--eval-episodes", "16"]
"""Two reach iterations of 16 envs x 24 steps: the envs start at random steps of their 50-step episodes, so episodes
finish in both iterations; an evaluation after the first and after the last."""
PUSH = ["--task", "PushCube-v1", "--envs", "8", "--iterations", "2", "--steps-per-env", "4", "--minibatches", "2",
        "--substeps", "2", "--seed", "0", "--eval-envs", "4", "--eval-every", "1"]  # fmt: skip
"""Two PushCube iterations of 8 envs x 4 steps: no 50-step episode can end by time-out in 8 steps (and seed 0's
random pushes reach no goal), so none finishes; evaluations of the untrained policy, after the first iteration and
after the last."""


def _summary(run):
    return json.loads((run / "train.json").read_text())


@pytest.fixture(scope="module")
def reach_run(tmp_path_factory):
    from wpctrl.train.cli import main

    out = tmp_path_factory.mktemp("reach") / "run"
    assert main(REACH + ["--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def push_run(tmp_path_factory):
    from wpctrl.train.cli import main

    out = tmp_path_factory.mktemp("push") / "run"
    assert main(PUSH + ["--out", str(out)]) == 0
    return out


def _scalars(run) -> dict[str, list[tuple[int, float]]]:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(run), size_guidance={"scalars": 0})
    acc.Reload()
    return {tag: [(e.step, e.value) for e in acc.Scalars(tag)] for tag in acc.Tags()["scalars"]}


def _close(got, want):
    """TensorBoard stores float32: (step, value) pairs against train.json's float64 values."""
    assert [s for s, _ in got] == [s for s, _ in want], (got, want)
    np.testing.assert_allclose([v for _, v in got], [v for _, v in want], rtol=1e-6, atol=1e-7)


def test_reach_run_writes_tensorboard_scalars_equal_to_its_metrics_file(reach_run):
    assert list(reach_run.glob("events.out.tfevents.*"))
    sc, summary = _scalars(reach_run), _summary(reach_run)
    h, evals = summary["history"], summary["evaluations"]
    assert all(r["episodes"] > 0 for r in h)  # the Train/ episode scalars exist in both iterations
    its = [r["iteration"] for r in h]
    assert its == [0, 1]
    for key in ("value", "surrogate", "entropy"):  # rsl-rl's loss names
        _close(sc[f"Loss/{key}"], [(r["iteration"], r["losses"][key]) for r in h])
    _close(sc["Train/mean_reward"], [(i, r["mean_episode_reward"]) for i, r in zip(its, h)])
    _close(sc["Train/success_rate"], [(i, r["success_rate"]) for i, r in zip(its, h)])
    _close(sc["Train/episodes"], [(i, r["episodes"]) for i, r in zip(its, h)])
    _close(sc["Train/mean_step_reward"], [(i, r["mean_step_reward"]) for i, r in zip(its, h)])
    _close(sc["Perf/collection_fps"], [(i, r["collection_env_steps_per_s"]) for i, r in zip(its, h)])
    _close(sc["Perf/collection_time"], [(i, r["collect_s"]) for i, r in zip(its, h)])
    _close(sc["Policy/mean_std"], [(i, r["action_std"]) for i, r in zip(its, h)])
    _close(sc["Train/mean_reward/env_steps"], [(16 * 24 * (i + 1), r["mean_episode_reward"]) for i, r in zip(its, h)])
    assert [r["env_steps"] for r in h] == [16 * 24, 2 * 16 * 24]
    assert [e["iteration"] for e in evals] == [0, 1]
    _close(sc["Eval/success_rate"], [(e["iteration"], e["success_rate"]) for e in evals])
    _close(sc["Eval/mean_episode_reward"], [(e["iteration"], e["mean_episode_reward"]) for e in evals])
    _close(sc["Eval/success_rate/env_steps"], [(e["env_steps"], e["success_rate"]) for e in evals])
    assert "Train/mean_episode_length" not in sc  # the reach's episodes all last 50 steps: not recorded


def test_task_run_logs_its_evaluations_and_no_episode_scalars_before_an_episode_ends(push_run):
    sc, summary = _scalars(push_run), _summary(push_run)
    h, evals = summary["history"], summary["evaluations"]
    assert [r["episodes"] for r in h] == [0, 0]
    assert not any(t.startswith(("Train/mean_reward", "Train/success")) for t in sc)  # nothing to average
    _close(sc["Train/mean_step_reward"], [(r["iteration"], r["mean_step_reward"]) for r in h])
    _close(sc["Loss/value"], [(r["iteration"], r["losses"]["value"]) for r in h])
    assert [e["iteration"] for e in evals] == [-1, 0, 1]  # the untrained policy, then after each iteration
    _close(sc["Eval/success_at_end_rate"], [(e["iteration"], e["success_at_end_rate"]) for e in evals])
    _close(sc["Eval/mean_episode_reward"], [(e["iteration"], e["mean_episode_reward"]) for e in evals])


def test_logger_none_writes_no_event_file_and_wandb_is_refused_with_its_install_line(tmp_path, capsys):
    from wpctrl.__main__ import main

    out = tmp_path / "quiet"
    assert main(["train", "--envs", "8", "--iterations", "1", "--logger", "none", "--out", str(out)]) == 0
    assert (out / "train.json").exists() and not list(out.glob("events.out.tfevents.*"))
    printed = capsys.readouterr().out.splitlines()  # the set-up says what it builds before it builds it
    assert printed[0] == "wpctrl train: building 8 reach envs on cpu ...", printed[:3]
    assert any(line.startswith("wpctrl train: 8 envs on cpu") and "set up in" in line for line in printed), printed
    try:
        import wandb  # noqa: F401
    except ImportError:
        assert main(["train", "--logger", "wandb", "--out", str(tmp_path / "w")]) == 2
        assert "--logger wandb: the wandb package is not installed (pip install wandb)" in capsys.readouterr().err


# -- --resume ----------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("fixture", ["reach_run", "push_run"])
def test_resume_continues_from_the_checkpoint(fixture, request, tmp_path, monkeypatch):
    """A copy of the 2-iteration run resumed for 1 more: at the resumed run's first PPO update the actor (the reach's
    with its observation normaliser), the critic and Adam's state are the checkpoint's (not the fresh networks'
    initialisation); the iteration count, the history and the TensorBoard steps continue to 3."""
    from rsl_rl.algorithms import PPO

    from wpctrl.train.cli import main

    run = tmp_path / "run"
    shutil.copytree(request.getfixturevalue(fixture), run)
    saved = torch.load(run / "policy.pt", weights_only=False)
    before = _summary(run)
    alg_cfg = before["ppo"]["algorithm"]
    assert saved["iter"] == 2
    seen = []
    update = PPO.update

    def first_update(self):
        if not seen:
            seen.append({"actor": copy.deepcopy(self._raw_actor.state_dict()),
                         "critic": copy.deepcopy(self._raw_critic.state_dict()),
                         "optimizer": copy.deepcopy(self.optimizer.state_dict())})  # fmt: skip
        return update(self)

    monkeypatch.setattr(PPO, "update", first_update)
    assert main(["--resume", str(run), "--iterations", "1"]) == 0
    for name in ("actor", "critic"):
        want = saved[f"{name}_state_dict"]
        assert set(seen[0][name]) == set(want)
        for k, v in want.items():
            torch.testing.assert_close(seen[0][name][k], v, rtol=0, atol=0, msg=f"{name} {k}")
    assert any("normalizer" in k for k in saved["actor_state_dict"]) == (fixture == "reach_run")
    opt, want = seen[0]["optimizer"], saved["optimizer_state_dict"]
    assert opt["param_groups"] == want["param_groups"] and set(opt["state"]) == set(want["state"])
    steps = 2 * alg_cfg["num_learning_epochs"] * alg_cfg["num_mini_batches"]  # 2 iterations' mini-batch steps
    for i, st in want["state"].items():
        assert float(st["step"]) == float(opt["state"][i]["step"]) == steps
        for k in ("exp_avg", "exp_avg_sq"):
            torch.testing.assert_close(opt["state"][i][k], st[k], rtol=0, atol=0)
    summary = _summary(run)
    assert summary["iterations"] == 3 and [r["iteration"] for r in summary["history"]] == [0, 1, 2]
    assert summary["history"][:2] == before["history"] and summary["resumed_from"]["iteration"] == 2
    assert summary["env_steps"] == 3 * before["envs"] * before["steps_per_env"]
    assert summary["history"][2]["wall_s"] > before["evaluations"][-1]["wall_s"]  # after the run's last evaluation
    assert torch.load(run / "policy.pt", weights_only=False)["iter"] == 3
    assert [s for s, _ in _scalars(run)["Loss/value"]] == [0, 1, 2]


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--envs", "32"], "--envs 32: the resumed run was trained with --envs 16"),
        (["--task", "PushCube-v1"], "--task PushCube-v1: the resumed run was trained with --task reach"),
        (["--control-mode", "pd_joint_delta_pos"],
         "--control-mode pd_joint_delta_pos: the resumed run was trained with --control-mode pd_ee_delta_pos"),
    ],
)  # fmt: skip
def test_resume_refuses_flags_that_contradict_the_run(reach_run, argv, message, capsys):
    from wpctrl.__main__ import main

    assert main(["train", "--resume", str(reach_run)] + argv) == 2
    assert message in capsys.readouterr().err


def test_resume_refuses_a_folder_without_a_run(tmp_path, capsys):
    from wpctrl.__main__ import main

    assert main(["train", "--resume", str(tmp_path)]) == 2
    assert f"--resume: no train.json in {str(tmp_path)!r}" in capsys.readouterr().err


# -- the learning curve ------------------------------------------------------------------------------------------------


def _numpy_window(values, counts, window):
    """Every finished episode as its iteration's mean, in order; per iteration the mean of the last ``window``."""
    out = []
    for i in range(len(values)):
        eps = np.concatenate([np.full(n, v, float) for v, n in zip(values[: i + 1], counts[: i + 1]) if n] + [[]])
        out.append(eps[-window:].mean() if len(eps) else math.nan)
    return out


@pytest.mark.parametrize("window", [1, 3, 7, 50])
def test_success_smoothing_weighs_iterations_by_their_finished_episodes(window):
    rng = np.random.default_rng(window)
    counts = rng.integers(0, 6, 40)
    counts[:3] = 0  # no episode finished yet: NaN
    counts[20:23] = 0
    values = [None if n == 0 else float(rng.integers(0, n + 1) / n) for n in counts]
    got = smoothed(values, counts.tolist(), window)
    want = _numpy_window(values, counts, window)
    np.testing.assert_allclose(got, want, rtol=1e-12, equal_nan=True)
    assert math.isnan(got[0]) and not math.isnan(got[3])


def test_learning_curve_notes_where_no_episode_has_finished(reach_run, push_run):
    import matplotlib.pyplot as plt

    def texts(fig):
        return [t.get_text() for ax in fig.axes for t in ax.texts]

    push = _summary(push_run)
    assert sum(r["episodes"] for r in push["history"]) == 0
    fig = figure(push["history"], push["evaluations"], "push", "success", window=8)
    assert texts(fig).count(NO_EPISODE) == 4  # success and episode reward, against env steps and wall time
    plt.close(fig)
    reach = _summary(reach_run)
    fig = figure(reach["history"], reach["evaluations"], "reach", "success", window=16)
    assert NO_EPISODE not in texts(fig)
    h = reach["history"]
    line = next(ln for ln in fig.axes[0].lines if ln.get_label().startswith("training episodes, last 16"))
    np.testing.assert_allclose(line.get_ydata(), smoothed([r["success_rate"] for r in h], [r["episodes"] for r in h],
                                                          16))  # fmt: skip
    np.testing.assert_allclose(line.get_xdata(), [r["env_steps"] for r in h])
    plt.close(fig)
    for run in (reach_run, push_run):
        assert (run / "learning_curve.png").stat().st_size > 1000


# -- wpctrl evaluate --video --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def push_policy(push_run):
    from wpctrl.train.export import export

    return export(push_run, onnx=False)["policy.ts"]


def test_video_is_skipped_saying_why_where_no_renderer_works(push_policy, tmp_path, monkeypatch, capsys):
    """The evaluation runs and reports as without --video; one line on stderr says why there is no video: here an
    OpenGL context that cannot be made (MuJoCo's renderer probe patched to fail as EGL does without a driver), or a
    missing video writer."""
    from wpctrl.__main__ import main
    from wpctrl.train import video

    def no_context():
        raise RuntimeError("eglInitialize failed")

    monkeypatch.setattr(video, "_probe", no_context)
    film = tmp_path / "eval.mp4"
    argv = ["evaluate", "--policy", push_policy, "--sim", "newton", "--episodes", "2", "--video", str(film)]
    assert main(argv) == 0
    out, err = capsys.readouterr()
    skipped = [ln for ln in err.splitlines() if "--video skipped" in ln]
    assert len(skipped) == 1 and "no renderer" in skipped[0] and "RuntimeError: eglInitialize failed" in skipped[0]
    assert "PushCube-v1 on newton: success" in out and not film.exists()
    monkeypatch.setitem(__import__("sys").modules, "imageio", None)
    assert video.unavailable() == "no video writer: imageio is not installed (pip install imageio imageio-ffmpeg)"
    assert main(argv) == 0
    assert "--video skipped: no video writer: imageio is not installed" in capsys.readouterr().err


def test_video_frames_show_env_0_after_each_step(push_policy, tmp_path, capsys):
    """Where MuJoCo's offscreen renderer works (EGL, Mesa's software driver on a CPU machine): 2 episodes of 50 steps
    give 100 frames, and frame k is env 0 after step k of the first episode: an independent render of the same policy
    rolled by hand on a fresh env from the same seed matches it within the codec's loss and is far from other steps."""
    from wpctrl.train import video

    why = video.unavailable()
    if why:
        pytest.skip(why)
    import imageio.v2 as imageio
    import mujoco

    import wpctrl.tasks as T
    from wpctrl.__main__ import main

    film = tmp_path / "eval.mp4"
    argv = ["evaluate", "--policy", push_policy, "--sim", "newton", "--episodes", "2", "--envs", "1", "--seed", "3",
            "--video", str(film)]  # fmt: skip
    assert main(argv) == 0
    assert f"wrote {film} (100 frames" in capsys.readouterr().out
    frames = np.asarray(imageio.mimread(str(film), memtest=False), np.float32)
    assert frames.shape == (100, video.HEIGHT, video.WIDTH, 3)
    policy = torch.jit.load(push_policy)
    env = T.make("PushCube-v1", num_envs=1, seed=3, auto_reset=False, ignore_terminations=True,
                 physics=T.TaskPhysics(substeps=2))  # fmt: skip
    obs, _ = env.reset(seed=3)
    model = env.solver.mj_model  # the test's own render of the state: ManiSkill's camera, the same light
    renderer = mujoco.Renderer(model, video.HEIGHT, video.WIDTH)
    cam = mujoco.MjvCamera()
    eye, target = np.array(video.CAMERA_EYE), np.array(video.CAMERA_TARGET)
    cam.lookat[:], cam.distance = target, np.linalg.norm(target - eye)
    cam.azimuth = np.degrees(np.arctan2(*(target - eye)[[1, 0]]))
    cam.elevation = np.degrees(np.arcsin((target - eye)[2] / cam.distance))
    model.vis.headlight.ambient[:], model.vis.headlight.diffuse[:] = 0.35, 0.6
    refs = {}
    with torch.inference_mode():
        for k in range(40):
            obs, *_ = env.step(policy(obs))
            if k in (4, 5, 6, 35):
                data = mujoco.MjData(model)
                data.qpos[:] = env.solver.mjw_data.qpos.numpy()[0]
                mujoco.mj_forward(model, data)
                renderer.update_scene(data, camera=cam)
                refs[k] = renderer.render().astype(np.float32)
    renderer.close()
    diff = {k: float(np.abs(frames[5] - ref).mean()) for k, ref in refs.items()}
    assert diff[5] < 3.0 and diff[35] > 3 * diff[5], diff  # within the codec's loss; far from a later state
    assert diff[5] < min(diff[4], diff[6]), diff  # the state after step 5, not the one before or after
