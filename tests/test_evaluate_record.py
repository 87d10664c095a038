"""``wpctrl evaluate --sim maniskill --record FILE``: the ManiSkill episodes of an evaluation saved in the format
``wpctrl replay`` reads. A small exported policy (random weights, no training) runs two PickCube episodes; the file
is checked against ManiSkill itself (the state after ``reset(seed)``, and the recorded actions stepped from it in a
fresh env give the recorded success flags, poses and observations bit for bit), read unchanged by
:func:`wpctrl.tasks.replay.load_episodes`, and replayed on Newton by ``wpctrl replay``. Bad input: ``--record`` with
``--sim newton`` or a name it cannot write, an interrupted run (no file), and the recordings ``wpctrl replay``
refuses (an unknown task, another task than the env's, a control mode the Panda lacks, a file cut short). A task whose
ManiSkill default robot is another (StackCube-v1's ``panda_wristcam``) is evaluated on the robot the task builds."""

from __future__ import annotations

import gzip
import json

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="torch is not installed")  # a dev dependency
pytest.importorskip("mani_skill", reason="the maniskill extra is not installed")

from wpctrl.__main__ import main  # noqa: E402

TASK, MODE, ACTIONS = "PickCube-v1", "pd_ee_delta_pos", 4
SEED = 7
"""Episodes ``SEED`` and ``SEED + 1``."""


def _export_policy(folder, task: str = TASK, mode: str = MODE, actions: int = ACTIONS, robot: str | None = None):
    """A ``task`` policy as ``wpctrl export`` writes it, from a checkpoint with random weights (nothing trained);
    ``robot``: the checkpoint's ``robot_uids`` (None: none recorded, as before the robot was)."""
    from wpctrl.tasks import TASKS
    from wpctrl.train.actor import PolicyActor
    from wpctrl.train.export import export

    obs_dim = TASKS[task].obs_dim
    cfg = {"class_name": "MLPModel", "hidden_dims": [32, 32], "activation": "tanh", "obs_normalization": False,
           "distribution_cfg": {"class_name": "GaussianDistribution", "init_std": 1.0, "std_type": "log"}}  # fmt: skip
    torch.manual_seed(0)
    actor = PolicyActor(obs_dim, actions, cfg["hidden_dims"], cfg["activation"], False)
    weights = {**actor.state_dict(), "distribution.log_std_param": torch.zeros(actions)}
    infos = {"format": "wpctrl-task-policy-1", "task": task, "control_mode": mode, "obs_dim": obs_dim,
             "num_actions": actions, "action_low": [-1.0] * actions, "action_high": [1.0] * actions,
             "obs_fields": [["agent", "qpos", 9]], "substeps": 4, "partial_reset": True, "actor": cfg}  # fmt: skip
    if robot is not None:
        infos["robot_uids"] = robot
    folder.mkdir(parents=True)
    torch.save({"actor_state_dict": weights, "infos": infos}, folder / "policy.pt")
    return export(folder, onnx=False)["policy.ts"]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """The evaluation's result (``--out``) and its recording (``--record``), read back."""
    root = tmp_path_factory.mktemp("record")
    policy = _export_policy(root / "run")
    path, out = root / "x.json.gz", root / "result.json"
    argv = ["evaluate", "--policy", policy, "--sim", "maniskill", "--episodes", "2", "--seed", str(SEED),
            "--record", str(path), "--out", str(out), "--no-progress"]  # fmt: skip
    assert main(argv) == 0
    data = json.loads(gzip.decompress(path.read_bytes()))
    return {"path": path, "policy": policy, "data": data, "result": json.loads(out.read_text())}


def _f32(values) -> np.ndarray:
    return np.asarray(values, np.float32)


@pytest.mark.slow  # the real ManiSkill (about 10 s on a 2-core CPU)
def test_recording_holds_the_episodes_in_the_replay_format(recorded):
    from wpctrl.tasks.recording import load_episodes

    data, result = recorded["data"], recorded["result"]
    assert load_episodes(recorded["path"]) == data  # the replay's reader takes it as written
    assert sorted(p.name for p in recorded["path"].parent.iterdir()) == ["result.json", "run", "x.json.gz"]
    header = data["header"]
    assert (header["task"], header["control_mode"], header["max_episode_steps"]) == (TASK, MODE, 50)
    assert (header["sim_freq"], header["control_freq"], header["main_object"]) == (100, 20, "cube")
    assert header["env_kwargs"] == {"sim_backend": "physx_cpu", "render_backend": "none", "num_envs": 1,
                                    "obs_mode": "state", "control_mode": MODE, "reward_mode": "normalized_dense",
                                    "robot_uids": "panda"}  # fmt: skip
    assert header["policy"] == recorded["policy"] and header["policy_metadata"]["task"] == TASK
    assert header["versions"]["mani-skill"] == "3.0.1" and header["seeds"] == [SEED, SEED + 1]
    assert result["record"] == str(recorded["path"])
    for ep, rec in zip(data["episodes"], result["records"], strict=True):
        assert ep["seed"] == rec["seed"] and ep["n_steps"] == len(ep["actions"]) == 50
        assert {"success", "is_grasped", "is_robot_static", "is_obj_placed"} <= set(ep["info"])
        for key in ("cube_pose", "obs", *ep["info"]):
            series = ep[key] if key in ep else ep["info"][key]
            assert len(series) == 51, key  # t = 0 after the reset, then after every step
        assert sorted(ep["init_state_dict"]["actors"]) == ["cube", "goal_site", "table-workspace"]
        assert len(ep["init_state_dict"]["articulations"]["panda"]) == 31
        actions = _f32(ep["actions"])
        assert actions.shape == (50, ACTIONS)
        assert all(float(str(a)) == v for a, v in zip(actions.ravel(), np.ravel(ep["actions"]), strict=True))
        assert (ep["success_once"], ep["success_at_end"]) == (rec["success_once"], rec["success_at_end"])
        assert ep["success_once"] == any(ep["info"]["success"][1:])
        assert ep["success_at_end"] == ep["info"]["success"][-1]
        assert sum(ep["reward_normalized_dense"]) == pytest.approx(rec["return"], rel=1e-6)


def _replay_in_maniskill(env, ep, reload: bool) -> tuple[list, np.ndarray, np.ndarray]:
    """``ep``'s actions stepped in ManiSkill after ``reset(seed)`` (and, ``reload``, its ``init_state_dict`` loaded,
    as a replay on another simulator starts): the info flags, cube poses and observations after every step."""
    u = env.unwrapped
    flags, poses, observations = [], [], []
    with torch.inference_mode():  # as the evaluation runs ManiSkill
        env.reset(seed=ep["seed"])
        if reload:
            init = ep["init_state_dict"]
            u.set_state_dict({g: {k: torch.tensor(_f32([v])) for k, v in init[g].items()} for g in init})
        for action in ep["actions"]:
            obs, _, _, _, info = env.step(torch.tensor(_f32([action])))
            flags.append({key: bool(info[key][0]) for key in ep["info"]})
            poses.append(u.get_state_dict()["actors"]["cube"][0, :7].numpy().copy())
            observations.append(obs[0].numpy().copy())
    return flags, np.asarray(poses), np.asarray(observations)


@pytest.mark.slow  # the real ManiSkill
def test_recording_is_maniskills_own_episode(recorded):
    """The state after ``reset(seed)`` is the recorded ``init_state_dict``, and the recorded actions, stepped from
    there in a fresh env, give the recorded flags, cube poses and observations bit for bit (ManiSkill's CPU PhysX is
    deterministic). Loading the state dict into the reset env instead (``set_state_dict``, as a replay starts) gives
    the same episode to float32 rounding: setting the Panda's root pose, even to its own value, resets state PhysX
    keeps for the articulation, which moves the last bits of the next steps (about 1e-5 over 50 steps here)."""
    from wpctrl.tasks.maniskill_side import make_maniskill

    env = make_maniskill(TASK, MODE, reward_mode="normalized_dense")
    for ep in recorded["data"]["episodes"]:
        with torch.inference_mode():
            obs, _ = env.reset(seed=ep["seed"])
            state = env.unwrapped.get_state_dict()
        init = ep["init_state_dict"]
        for group in ("actors", "articulations"):
            assert sorted(state[group]) == sorted(init[group])
            for name, v in state[group].items():
                assert np.array_equal(v[0].numpy(), _f32(init[group][name])), (ep["seed"], name)
        assert np.array_equal(obs[0].numpy(), _f32(ep["obs"][0]))
        want_flags = [{key: ep["info"][key][t] for key in ep["info"]} for t in range(1, 51)]
        flags, poses, observations = _replay_in_maniskill(env, ep, reload=False)
        assert flags == want_flags
        assert np.array_equal(poses, _f32(ep["cube_pose"][1:])) and np.array_equal(observations, _f32(ep["obs"][1:]))
        flags, poses, observations = _replay_in_maniskill(env, ep, reload=True)
        assert flags == want_flags
        np.testing.assert_allclose(poses, _f32(ep["cube_pose"][1:]), rtol=0, atol=1e-4)
        np.testing.assert_allclose(observations, _f32(ep["obs"][1:]), rtol=0, atol=1e-3)
    env.close()


@pytest.mark.slow  # builds the Newton env (Warp kernels) and replays 50 steps on the CPU
def test_wpctrl_replay_runs_the_recording_on_newton(recorded, tmp_path, capsys):
    from wpctrl.config import ConfigError
    from wpctrl.tasks import make
    from wpctrl.tasks.replay import replay

    report = tmp_path / "replay.json"
    assert main(["replay", str(recorded["path"]), "--no-progress", "--out", str(report)]) == 0
    assert f"{TASK} {MODE}: 2 episodes replayed on Newton" in capsys.readouterr().out
    (rep,) = json.loads(report.read_text())
    episodes = recorded["data"]["episodes"]
    assert rep["summary"]["episodes"] == 2
    for got, ep in zip(rep["episodes"], episodes, strict=True):
        assert got["seed"] == ep["seed"] and got["success_recorded"] == ep["info"]["success"][1:]
        assert len(got["cube_error"]) == 50 and all(np.isfinite(got["cube_error"]))
    # a recording of another task than the env the replay was given
    env = make(TASK, num_envs=3, control_mode=MODE, auto_reset=False, ignore_terminations=True)
    other = {**recorded["data"], "header": {**recorded["data"]["header"], "task": "PushCube-v1"}}
    with pytest.raises(ConfigError, match=r"init_state_dict\.actors\['goal_site'\] is not part of PushCube-v1"):
        replay(other, env=env)
    refusal = f"env is {TASK} / panda / {MODE} / 3 envs, the file {TASK} / panda / {MODE} / 2 episodes"
    with pytest.raises(ConfigError, match=refusal):
        replay(recorded["data"], env=env)
    env.close()


# -- bad input ---------------------------------------------------------------------------------------------------------


def _replay_refusal(path, capsys) -> str:
    assert main(["replay", str(path), "--no-progress"]) == 2
    return capsys.readouterr().err


@pytest.mark.slow  # needs the recording (the real ManiSkill)
def test_replay_refuses_a_recording_of_a_task_or_mode_it_cannot_build(recorded, tmp_path, capsys):
    data = recorded["data"]
    for field, value, message in [
        ("task", "PushCube-v9", "task 'PushCube-v9' is not one wpctrl builds"),
        ("control_mode", "pd_ee_pos", "control mode 'pd_ee_pos' is not one of the Panda's"),
    ]:
        path = tmp_path / f"{field}.json.gz"
        path.write_bytes(gzip.compress(json.dumps({**data, "header": {**data["header"], field: value}}).encode()))
        err = _replay_refusal(path, capsys)
        assert message in err and str(path) in err, err


@pytest.mark.slow  # needs the recording (the real ManiSkill)
def test_replay_refuses_a_recording_cut_short(recorded, tmp_path, capsys):
    packed = recorded["path"].read_bytes()
    half_gz = tmp_path / "half.json.gz"
    half_gz.write_bytes(packed[: len(packed) // 2])
    err = _replay_refusal(half_gz, capsys)
    assert f"'{half_gz}' is not a recording (not a readable gzip file)" in err, err
    text = gzip.decompress(packed)
    half_json = tmp_path / "half.json"
    half_json.write_bytes(text[: len(text) // 2])
    err = _replay_refusal(half_json, capsys)
    assert f"'{half_json}' is not a recording (not JSON text)" in err, err


def test_record_is_refused_with_sim_newton_and_for_a_name_it_cannot_write(tmp_path, capsys):
    """Checked before torch or ManiSkill loads (any file passes as the policy here)."""
    policy = tmp_path / "policy.ts"
    policy.write_text("checked later")

    def refused(*argv) -> str:
        assert main(["evaluate", "--policy", str(policy), "--episodes", "1", *argv]) == 2
        return capsys.readouterr().err

    err = refused("--sim", "newton", "--record", str(tmp_path / "x.json"))
    assert "--record: only --sim maniskill is recorded for `wpctrl replay`" in err
    err = refused("--sim", "maniskill", "--record", str(tmp_path / "x.h5"))
    assert f"--record: expected a file name ending in .json or .json.gz, got '{tmp_path / 'x.h5'}'" in err
    err = refused("--sim", "maniskill", "--record", str(tmp_path / "none" / "x.json"))
    assert f"--record: no folder '{tmp_path / 'none'}'" in err
    (tmp_path / "d.json").mkdir()
    assert "is a folder, expected a file name" in refused("--sim", "maniskill", "--record", str(tmp_path / "d.json"))
    assert not (tmp_path / "x.json").exists()
    from wpctrl.train.evaluate import evaluate  # the Python API refuses the same, before loading the policy

    with pytest.raises(ValueError, match="record: only sim='maniskill' is saved for replay, got sim='newton'"):
        evaluate(policy, sim="newton", record=tmp_path / "x.json")
    with pytest.raises(ValueError, match="record: expected a file name ending in .json or .json.gz"):
        evaluate(policy, sim="maniskill", record=tmp_path / "x.txt")


@pytest.mark.slow  # the real ManiSkill and Newton replays
@pytest.mark.parametrize("robot", [None, "panda_wristcam"])
def test_a_policy_is_evaluated_on_the_robot_it_learned_on(tmp_path, capsys, robot):
    """ManiSkill's StackCube-v1 defaults to ``panda_wristcam`` (``panda_v3.urdf``: a 0.56 kg camera and its collision
    box on the hand). ``wpctrl evaluate --sim maniskill`` asks ManiSkill for the robot the policy's ``policy.json``
    names (``panda`` where it names none: every policy exported before the robot was recorded learned on ``panda``;
    measured with such a StackCube policy: cube A grasped in 75 % of the steps on ManiSkill's ``panda``, 20 % on
    ``panda_wristcam``, 82 % on Newton), records it, and ``wpctrl replay`` builds it to replay the recording."""
    want = robot or "panda"
    policy = _export_policy(tmp_path / "run", "StackCube-v1", "pd_joint_delta_pos", 8, robot)
    assert json.loads((tmp_path / "run" / "policy.json").read_text())["robot_uids"] == want
    path, out = tmp_path / "stack.json.gz", tmp_path / "result.json"
    argv = ["evaluate", "--policy", policy, "--sim", "maniskill", "--episodes", "1", "--seed", str(SEED),
            "--record", str(path), "--out", str(out), "--no-progress"]  # fmt: skip
    assert main(argv) == 0
    assert json.loads(out.read_text())["robot_uids"] == want
    data = json.loads(gzip.decompress(path.read_bytes()))
    assert data["header"]["env_kwargs"]["robot_uids"] == want
    assert list(data["episodes"][0]["init_state_dict"]["articulations"]) == [want]
    capsys.readouterr()
    assert main(["replay", str(path), "--no-progress"]) == 0
    assert "StackCube-v1" in capsys.readouterr().out


@pytest.mark.slow  # the real ManiSkill
def test_an_interrupted_evaluation_leaves_no_recording(tmp_path):
    from wpctrl.train.evaluate import evaluate_maniskill
    from wpctrl.train.record import EpisodeRecorder

    class StopsInEpisodeTwo:
        calls = 0

        def __call__(self, obs):
            self.calls += 1
            if self.calls == 60:
                raise KeyboardInterrupt
            return torch.zeros(1, ACTIONS)

    path = tmp_path / "x.json.gz"
    with pytest.raises(KeyboardInterrupt):
        evaluate_maniskill(StopsInEpisodeTwo(), TASK, MODE, 2, recorder=EpisodeRecorder(path, "p.ts", {}))
    assert list(tmp_path.iterdir()) == []
