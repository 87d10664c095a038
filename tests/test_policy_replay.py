"""ManiSkill episodes driven by policies trained on Newton (``<Task>__<control_mode>__policy.npz``: numpy arrays,
:mod:`wpctrl.tasks.policy_episodes`), replayed open-loop on Newton and run closed-loop from the same states.

- The conversion: the replay's episode dict holds the file's arrays where the replay reads them (the state dict's
  actors in ManiSkill's order, the table's fixed state, success for t = 0 .. T with False at the reset), read on the
  host only; Newton's observation right after loading an episode's initial state is ManiSkill's (the file's qpos,
  qvel, TCP, goal and cube at t = 0 within 1e-5, wpctrl's evaluate says no success there) and the exported policy
  answers it with the recorded first action (PickCube: the recorded first action of every episode after the first
  answers ``is_grasped`` = 1, stale contact flags of ManiSkill's previous episode).
- The refusals: a file name that does not parse, a task or control mode wpctrl does not build, a missing array,
  wrong shapes, non-finite values, bad seeds or success flags, another action width, a file that is not an npz:
  each a ConfigError naming the file and the array, before any env is built; the command line exits 2.
- The public files (``$WPCTRL_POLICY_EPISODES``, default ``/work/shared/tasks/policy``; skipped without them)
  replayed with the default physics: success once / at the end agrees with ManiSkill's on at least the measured
  number of episodes less one, and the target (90 % episode by episode) holds. The arm's first steps follow PhysX's
  within the measured bounds, 1-2 mrad, with the arm driven as PhysX's TGS solver drives it (``TaskPhysics.arm_drive``:
  its 15 iterations leave the coupled shoulder drives unconverged, docs/tasks.md); the 1e-3 rad target holds on
  PushCube and is a strict expected failure on PickCube, with the measured numbers in its reason.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import wpctrl  # noqa: E402
import wpctrl.tasks as T  # noqa: E402
from wpctrl.tasks.names import TASK_ACTORS  # noqa: E402
from wpctrl.tasks.policy_episodes import read_policy_episodes  # noqa: E402
from wpctrl.tasks.recording import load_episodes  # noqa: E402
from wpctrl.tasks.replay import main  # noqa: E402

POLICY = Path(os.environ.get("WPCTRL_POLICY_EPISODES", "/work/shared/tasks/policy"))
FILES = {
    "PushCube-v1": ("PushCube-v1__pd_joint_delta_pos__policy.npz", "push_policy"),
    "PickCube-v1": ("PickCube-v1__pd_ee_delta_pos__policy.npz", "pick_policy"),
}
REST = [0.0, np.pi / 8, 0.0, -5 * np.pi / 8, 0.0, 3 * np.pi / 4, np.pi / 4, 0.04, 0.04]

# measured 2026-11-28 with the default TaskPhysics (16 substeps), CPU: episodes whose success agrees with ManiSkill's
MEASURED_REPLAY = {  # task: (episodes, success once agrees, success at the end agrees); 2026-11-30, CPU
    "PushCube-v1": (10, 9, 6),
    "PickCube-v1": (6, 6, 5),
}
MEASURED_CLOSED_LOOP = {  # task: (Newton's successes once, success once agrees with ManiSkill's)
    "PushCube-v1": (7, 9),
    "PickCube-v1": (6, 5),
}


def _public(task: str) -> Path:
    path = POLICY / FILES[task][0]
    if not path.is_file():
        pytest.skip(f"no policy episodes at {path} (set $WPCTRL_POLICY_EPISODES)")
    return path


def _policy(task: str):
    """The exported policy that drove ``task``'s public episodes (``policy.ts``)."""
    from wpctrl.train.evaluate import load_policy

    path = POLICY / FILES[task][1] / "policy.ts"
    if not path.is_file():
        pytest.skip(f"no exported policy at {path}")
    return load_policy(path, task)[0]


# ---------------------------------------------------------------- a small valid file, and spoiled ones


def _arrays(e: int = 2, t: int = 3, width: int = 8) -> dict:
    """A valid PushCube file's arrays: the cube at rest, the goal 10 cm in front of it, the Panda at rest."""
    cube = [0.0, 0.0, 0.02, 1, 0, 0, 0] + [0.0] * 6
    goal = [0.1, 0.0, 0.001, 0.7071068, 0, 0.7071068, 0] + [0.0] * 6
    panda = [-0.615, 0, 0, 1, 0, 0, 0] + [0.0] * 6 + REST + [0.0] * 9
    pose = np.array(cube[:7], np.float32)
    return {
        "seeds": np.arange(e, dtype=np.int64) + 7,
        "init_state": np.tile(np.array(cube + goal + panda, np.float32), (e, 1)),
        "action": np.zeros((e, t, width), np.float32),
        "success": np.zeros((e, t), bool),
        "reward": np.zeros((e, t)),
        "cube": np.tile(pose, (e, t + 1, 1)),
        "qpos": np.tile(np.float32(REST), (e, t + 1, 1)),
        "contacts": np.zeros((e, t, 5, 15)),
    }


def _write(directory: Path, name: str = "PushCube-v1__pd_joint_delta_pos__policy.npz", edit=None, **kw) -> Path:
    arrays = _arrays(**kw)
    if edit is not None:
        edit(arrays)
    path = directory / name
    np.savez(path, **arrays)
    return path


def _set(key, value):
    return lambda a: a.__setitem__(key, value)


def _drop(key):
    return lambda a: a.pop(key)


def _poke(key, index, value):
    def edit(a):
        a[key] = a[key].astype(np.float32 if a[key].dtype == np.float32 else a[key].dtype)
        a[key][index] = value

    return edit


BAD_NAMES = {
    "one underscore": ("PushCube-v1_pd_joint_delta_pos_policy.npz", "the file name expected <Task>__<control_mode>"),
    "no policy suffix": ("PushCube-v1__pd_joint_delta_pos.npz", "the file name expected <Task>__<control_mode>"),
    "three parts": ("PushCube-v1__pd_joint_delta_pos__x__policy.npz", "the file name expected"),
    "unknown task": ("PushCube-v9__pd_joint_delta_pos__policy.npz", r"task 'PushCube-v9' \(from the file name\)"),
    "a task wpctrl does not build": ("PushT-v1__pd_joint_pos__policy.npz", r"task 'PushT-v1'"),
    "unknown control mode": ("PushCube-v1__pd_fast__policy.npz", r"control mode 'pd_fast' \(from the file name\)"),
}

BAD_ARRAYS = {
    "no actions": (_drop("action"), r"has no array 'action'"),
    "no seeds": (_drop("seeds"), r"has no array 'seeds'"),
    "no cube poses": (_drop("cube"), r"has no array 'cube'"),
    "init_state of another width": (_set("init_state", np.zeros((2, 56), np.float32)),
                                    r"'init_state' expected shape \(E, 57\) = \(2, 57\), got \(2, 56\)"),
    "init_state of another episode count": (_set("init_state", np.zeros((3, 57), np.float32)),
                                            r"'init_state' expected shape \(E, 57\) = \(2, 57\), got \(3, 57\)"),
    "actions without a width axis": (_set("action", np.zeros((2, 3), np.float32)),
                                     r"'action' expected shape \(E, T, A\) = \(E, T, A\), got \(2, 3\)"),
    "actions without steps": (_set("action", np.zeros((2, 0, 8), np.float32)), r"'action' holds no steps"),
    "success one short": (_set("success", np.zeros((2, 2), bool)),
                          r"'success' expected shape \(E, T\) = \(2, 3\), got \(2, 2\)"),
    "cube poses one short": (_set("cube", np.zeros((2, 3, 7), np.float32)),
                             r"'cube' expected shape \(E, T\+1, 7\) = \(2, 4, 7\), got \(2, 3, 7\)"),
    "qpos of another width": (_set("qpos", np.zeros((2, 4, 7), np.float32)), r"'qpos' expected shape"),
    "NaN action": (_poke("action", (1, 2, 3), np.nan), r"action\[1\]\[2\]\[3\] is nan, expected a finite number"),
    "infinite initial state": (_poke("init_state", (0, 2), np.inf), r"init_state\[0\]\[2\] is inf"),
    "NaN cube pose": (_poke("cube", (1, 3, 0), np.nan), r"cube\[1\]\[3\]\[0\] is nan"),
    "NaN contact force": (_poke("contacts", (0, 1, 2, 3), np.nan), r"contacts\[0\]\[1\]\[2\]\[3\] is nan"),
    "actions as text": (_set("action", np.full((2, 3, 8), "x")), r"'action' expected numbers, got dtype <U1"),
    "success flags of 2": (_set("success", np.full((2, 3), 2)), r"'success' expected booleans \(or 0/1\)"),
    "success as floats": (_set("success", np.zeros((2, 3))), r"'success' expected booleans \(or 0/1 integers\)"),
    "negative seed": (_set("seeds", np.array([3, -5])), r"seeds\[1\] is -5, expected a non-negative integer"),
    "seeds as floats": (_set("seeds", np.array([3.0, 4.0])), r"'seeds' expected integers, got dtype float64"),
    "no episodes": (lambda a: a.update({k: v[:0] for k, v in a.items()}), r"holds no episodes"),
    "another action width": (_set("action", np.zeros((2, 3, 7), np.float32)),
                             r"episodes\[0\]\.actions has 7 values per step, control mode 'pd_joint_delta_pos' "
                             r"takes 8"),
}  # fmt: skip


@pytest.fixture
def no_env(monkeypatch):
    """``make`` replaced by a function that fails the test: a refused file builds no env."""

    def make(*a, **k):
        raise AssertionError("an env was built for a file that should have been refused")

    monkeypatch.setattr("wpctrl.tasks.factory.make", make)


def test_a_valid_file_is_read_on_the_host_into_the_replays_format(tmp_path):
    """Reading a policy-episode file imports neither Warp, Newton nor torch; its episodes land where the replay reads
    them: the task's actors in ManiSkill's order (the table's fixed state first), the Panda, the actions, success
    for t = 0 .. T (False at the reset) and the cube's poses."""
    path = _write(tmp_path)
    code = ("import sys; from wpctrl.tasks.policy_episodes import read_policy_episodes as r; "
            f"r({str(path)!r}); print(sorted(m for m in ('warp', 'newton', 'torch') if m in sys.modules))")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
    data = read_policy_episodes(path)
    assert data["header"]["task"] == "PushCube-v1" and data["header"]["control_mode"] == "pd_joint_delta_pos"
    assert data["header"]["main_object"] == "cube"
    assert load_episodes(path) == data  # the replay's checks pass (the action width too)
    arrays = _arrays()
    from wpctrl.tasks.state_dict import table_state

    for i, ep in enumerate(data["episodes"]):
        assert ep["seed"] == arrays["seeds"][i]
        assert list(ep["init_state_dict"]["actors"]) == list(TASK_ACTORS["PushCube-v1"].state)
        np.testing.assert_array_equal(ep["init_state_dict"]["actors"]["table-workspace"], table_state())
        assert ep["info"]["success"] == [False] * 4
        assert np.asarray(ep["actions"]).shape == (3, 8) and np.asarray(ep["cube_pose"]).shape == (4, 7)
    # the npz's success[t] is after step t: the replay's t + 1 (t = 0 is the reset, never a success here)
    shifted = read_policy_episodes(_write(tmp_path, edit=_set("success", np.array([[0, 1, 0], [1, 1, 0]], bool))))
    assert [ep["info"]["success"] for ep in shifted["episodes"]] == [[False, False, True, False],
                                                                      [False, True, True, False]]


@pytest.mark.parametrize("case", sorted(BAD_NAMES))
def test_a_file_name_that_does_not_say_a_task_wpctrl_builds_is_refused(case, tmp_path, no_env):
    name, message = BAD_NAMES[case]
    path = _write(tmp_path, name)
    for fn in (load_episodes, T.replay):
        with pytest.raises(wpctrl.ConfigError, match=message) as e:
            fn(path)
        assert repr(str(path)) in str(e.value)


@pytest.mark.parametrize("case", sorted(BAD_ARRAYS))
def test_a_bad_array_is_refused_naming_the_file_and_the_array(case, tmp_path, no_env):
    edit, message = BAD_ARRAYS[case]
    path = _write(tmp_path, edit=edit)
    for fn in (load_episodes, T.replay):
        with pytest.raises(wpctrl.ConfigError, match=message) as e:
            fn(path)
        assert repr(str(path)) in str(e.value)


def test_a_file_that_is_not_an_npz_is_refused(tmp_path, no_env):
    path = tmp_path / "PushCube-v1__pd_joint_delta_pos__policy.npz"
    path.write_bytes(b"not a zip archive")
    with pytest.raises(wpctrl.ConfigError, match=r"is not a readable numpy .npz file of policy episodes"):
        load_episodes(path)
    np.savez(path, **dict(_arrays(), seeds=np.array([object(), object()])))  # needs pickle: refused as unreadable
    with pytest.raises(wpctrl.ConfigError, match=r"is not a readable numpy .npz file"):
        load_episodes(path)


def test_the_command_line_refuses_a_bad_file_with_exit_code_2(tmp_path, capsys, no_env):
    path = _write(tmp_path, edit=_poke("action", (0, 1, 2), np.nan))
    out = tmp_path / "report.json"
    assert main([str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and path.name in err and "action[0][1][2] is nan" in err
    assert not out.exists()


# ---------------------------------------------------------------- the public files on Newton


@pytest.fixture(scope="module")
def envs():
    """One env per public file (all its episodes), reused by the tests below (each resets and loads the states)."""
    made = {}

    def get(task: str):
        if task not in made:
            data = load_episodes(_public(task))
            made[task] = T.make(task, num_envs=len(data["episodes"]), control_mode=data["header"]["control_mode"],
                                auto_reset=False, ignore_terminations=True)  # fmt: skip
        return made[task]

    yield get
    for env in made.values():
        env.close()


def _load_states(env, data: dict):
    eps = data["episodes"]
    state = {g: {k: torch.tensor([ep["init_state_dict"][g][k] for ep in eps]) for k in eps[0]["init_state_dict"][g]}
             for g in ("actors", "articulations")}  # fmt: skip
    env.reset(seed=[ep["seed"] for ep in eps], options={"reconfigure": True})
    env.set_state_dict(state)


def _fields(env, obs: np.ndarray) -> dict:
    slices = env.task_spec.obs_slices()
    return {name: obs[:, s] for group in slices.values() for name, s in group.items()}


@pytest.mark.parametrize("task", FILES)
def test_newtons_observation_after_loading_the_initial_state_is_maniskills(task, envs):
    """Right after the state is loaded, Newton's observation is the one ManiSkill recorded (the file's qpos, qvel,
    TCP pose, goal and cube at t = 0, within 1e-5), wpctrl's evaluate finds no success there (the False the reader
    puts at t = 0), and the policy answers with the recorded first action (PickCube: every episode after the first
    answered ``is_grasped`` = 1 on ManiSkill, the previous episode's contacts, stale in its reused env)."""
    path = _public(task)
    arrays, data, env = np.load(path), load_episodes(path), envs(task)
    _load_states(env, data)
    obs = env.get_obs().cpu().numpy()
    f = _fields(env, obs)
    expected = {"qpos": arrays["qpos"][:, 0], "qvel": arrays["qvel"][:, 0], "tcp_pose": arrays["tcp"][:, 0],
                "goal_pos": arrays["goal_sd"][:, 0, :3], "obj_pose": arrays["cube"][:, 0]}  # fmt: skip
    for name, want in expected.items():
        np.testing.assert_allclose(f[name], want, atol=1e-5, rtol=0, err_msg=name)
    assert not env.evaluate()["success"].any()
    policy = _policy(task)
    if task == "PickCube-v1":
        k = env.task_spec.obs_slices()["extra"]["is_grasped"]
        assert not obs[:, k].any()
        obs[1:, k] = 1.0  # ManiSkill's stale flag (episode 0 followed a fresh env's reset)
    with torch.inference_mode():
        first = policy(torch.from_numpy(obs)).numpy()
    np.testing.assert_allclose(first, arrays["action"][:, 0], atol=1e-4, rtol=0)


def _first_steps(task, envs, steps: int) -> np.ndarray:
    """|Newton's arm qpos - ManiSkill's| after each of the first ``steps`` recorded actions, (steps, E, 7)."""
    path = _public(task)
    arrays, env = np.load(path), envs(task)
    _load_states(env, load_episodes(path))
    errors = []
    for t in range(steps):
        obs, *_ = env.step(torch.from_numpy(arrays["action"][:, t]))
        errors.append(np.abs(obs[:, :7].cpu().numpy() - arrays["qpos"][:, t + 1, :7]))
    return np.stack(errors)


@pytest.mark.parametrize("task, bound_j1, bound_rest", [("PushCube-v1", 0.0015, 0.0015),
                                                       ("PickCube-v1", 0.0015, 0.003)])
def test_the_arm_follows_physx_in_the_first_steps_within_the_measured_bounds(task, envs, bound_j1, bound_rest):
    """The first three recorded actions move the arm as on PhysX within what was measured, with a little slack
    (PushCube: every joint within 0.8 mrad; PickCube: panda_joint1 within 0.7, the others within 1.8 mrad). The arm's
    drive is PhysX's TGS pass (``TaskPhysics.arm_drive``): PhysX's 15 iterations leave the drives of the coupled
    shoulder joints unconverged, and MuJoCo's own drive, which converges, parts from PhysX by 8-9 mrad after the first
    action and up to 17 mrad by the third (docs/tasks.md)."""
    err = _first_steps(task, envs, 3)
    assert err[..., 0].max() <= bound_j1, err.max(axis=(0, 1))
    assert err[..., 1:].max() <= bound_rest, err.max(axis=(0, 1))


_PICK_SATURATED = pytest.mark.xfail(strict=True, reason=(
    "measured: PickCube's arm within 0.5 / 1.0 / 1.8 / 1.4 / 1.3 mrad of PhysX's after each of the first five steps: "
    "its pd_ee_delta_pos IK steps saturate the drives, where the solver step (16 MuJoCo steps against PhysX's 15 "
    "position iterations) and MuJoCo's integration of the clamped torque part"))


@pytest.mark.parametrize("task", [pytest.param(t, marks=[_PICK_SATURATED] if t == "PickCube-v1" else [])
                                  for t in FILES])  # fmt: skip
def test_target_the_arm_follows_physx_within_1_mrad_for_five_steps(task, envs):
    """The goal: every arm joint within 1 mrad of PhysX's over the first five steps (PushCube: 0.8 mrad measured)."""
    assert _first_steps(task, envs, 5).max() <= 1e-3


@pytest.mark.parametrize("task", FILES)
def test_replay_agrees_with_maniskill_on_the_measured_episodes(task, envs):
    """The public file replayed open-loop with the default physics: the success once and the success at the end of
    at least the measured number of episodes less one agree with ManiSkill's (ManiSkill: PushCube 6 / 10 once,
    0 / 10 at the end; PickCube 5 / 6 and 3 / 6). Measured: PushCube 9 / 10 and 6-8 / 10 agree, PickCube 6 / 6 and
    5 / 6 (with MuJoCo's own drive of the arm 9 / 10, 8 / 10 and 4 / 6, 5 / 6)."""
    report = T.replay(_public(task), env=envs(task))
    n, once, end = MEASURED_REPLAY[task]
    assert len(report.episodes) == n
    recorded = {"PushCube-v1": (6, 0), "PickCube-v1": (5, 3)}[task]
    assert (sum(e.success_once_recorded for e in report.episodes),
            sum(e.success_at_end_recorded for e in report.episodes)) == recorded  # fmt: skip
    assert report.once_agreement >= (once - 1) / n, report.format()
    assert report.outcome_agreement >= (end - 1) / n, report.format()


@pytest.mark.parametrize("task", FILES)
def test_target_replay_agrees_with_maniskill_episode_by_episode(task, envs):
    """The goal: success once agrees episode by episode in >= 90 % of the public file's episodes (measured: PushCube
    9 / 10, PickCube 6 / 6; with MuJoCo's own drive of the arm PickCube's were 4 / 6)."""
    assert T.replay(_public(task), env=envs(task)).once_agreement >= 0.9


@pytest.mark.parametrize("task", FILES)
def test_the_policy_closed_loop_on_newton_from_the_same_states(task, envs):
    """The exported policy run closed-loop on Newton from the files' initial states (``replay(..., policy=...)``)
    succeeds (once) in at least the measured number of episodes less one, and agrees with ManiSkill's run of the
    same policy on as many."""
    report = T.replay(_public(task), env=envs(task), policy=_policy(task))
    n = len(report.episodes)
    successes, agree = MEASURED_CLOSED_LOOP[task]
    assert sum(e.success_once for e in report.episodes) >= successes - 1, report.format()
    assert report.once_agreement >= (agree - 1) / n, report.format()


def test_a_closed_loop_replay_refuses_a_bad_policy_or_first_action(no_env):
    path = _public("PushCube-v1")
    with pytest.raises(wpctrl.ConfigError, match="first_action expected one of"):
        T.replay(path, policy=lambda obs: obs, first_action="zero")
    with pytest.raises(wpctrl.ConfigError, match="policy expected a callable"):
        T.replay(path, policy="policy.ts")


def test_the_command_line_replays_a_policy_file(tmp_path, capsys):
    """``python -m wpctrl replay FILE.npz --out OUT``: one line per episode, the summary with the success-once
    agreement, the report written."""
    import json

    path = _public("PickCube-v1")
    out = tmp_path / "report.json"
    assert main([str(path), "--out", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert text.count("  seed 2000") == 6 and "success once:" in text
    summary = json.loads(out.read_text())[0]["summary"]
    assert summary["task"] == "PickCube-v1" and summary["episodes"] == 6
    assert summary["once_agreement"] >= (MEASURED_REPLAY["PickCube-v1"][1] - 1) / 6
