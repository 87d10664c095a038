"""Bad input to the replay and to ``set_state_dict`` is refused before anything is built or written, each refusal a
:class:`wpctrl.ConfigError` naming the file, the field, what was expected and what came.

Replay (``wpctrl.tasks.replay``): a recording of the public sample (tests/data/tasks, real ManiSkill 3.0.1 episodes)
with one field spoiled is refused by ``load_episodes`` and by ``replay`` (no env is made: ``make`` is replaced by a
function that fails the test), and ``wpctrl replay FILE --out OUT`` exits 2 with the file's name in its one line and
writes no report. The action width a recording must have is the control mode's, read from its controller configs;
here it is checked against the action space ManiSkill's own env has in every mode.

``set_state_dict``: a state dict of another task, one with an actor or the Panda missing, wrong widths, a wrong
batch, non-numbers, non-finite values, a moved table or robot root, or a bad ``"controller"`` entry is refused
naming ``state[group][name]``, and the env is exactly as before (joint coordinates and velocities, goal markers, the
controller's targets, the state dict it reports).
"""

from __future__ import annotations

import copy
import json
import re
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import wpctrl  # noqa: E402
import wpctrl.tasks as T  # noqa: E402
from wpctrl.tasks.names import CONTROL_MODES  # noqa: E402
from wpctrl.tasks.recording import action_width  # noqa: E402
from wpctrl.tasks.replay import main  # noqa: E402

DATA = Path(__file__).parent / "data" / "tasks"
EE = "PushCube-v1__pd_ee_delta_pos.json"
JOINT = "PushCube-v1__pd_joint_delta_pos.json"
N = 2


def _recording(name: str) -> dict:
    return json.loads((DATA / name).read_text())


def _ep(edit):
    """An edit of episode 0."""
    return lambda d: edit(d["episodes"][0])


def _set(path: str, value):
    """Episode 0's ``path`` (dot-separated keys / indices) set to ``value``."""

    def edit(ep):
        *head, last = path.split(".")
        for k in head:
            ep = ep[int(k)] if isinstance(ep, list) else ep[k]
        ep[int(last) if isinstance(ep, list) else last] = value

    return _ep(edit)


def _actor(name: str, fn):
    return _ep(lambda ep: ep["init_state_dict"]["actors"].__setitem__(name, fn(ep["init_state_dict"]["actors"][name])))


def _header(**kw):
    return lambda d: d["header"].update(kw)


E0 = r"episodes\[0\]"
ISD = rf"{E0}\.init_state_dict"
REPLAY_BAD = {
    # the action width is the control mode's (its controllers' action space), every action finite
    "ee mode, joint-mode widths": (
        EE,
        _ep(lambda ep: ep.update(actions=[a + [0.0] * 4 for a in ep["actions"]])),
        rf"{E0}\.actions has 8 values per step, control mode 'pd_ee_delta_pos' takes 4",
    ),
    "joint mode, ee-mode widths": (
        JOINT,
        _ep(lambda ep: ep.update(actions=[a[:4] for a in ep["actions"]])),
        rf"{E0}\.actions has 4 values per step, control mode 'pd_joint_delta_pos' takes 8",
    ),
    "header names another mode": (
        EE,
        _header(control_mode="pd_joint_pos"),
        rf"{E0}\.actions has 4 values per step, control mode 'pd_joint_pos' takes 8",
    ),
    "pos_vel mode": (JOINT, _header(control_mode="pd_joint_pos_vel"), "'pd_joint_pos_vel' takes 15"),
    "nan action": (EE, _set("actions.3.1", float("nan")), rf"{E0}\.actions\[3\]\[1\] is nan, expected a finite"),
    "inf action": (JOINT, _set("actions.49.7", float("inf")), rf"{E0}\.actions\[49\]\[7\] is inf, expected a finite"),
    "ragged actions": (
        EE,
        _set("actions.2", [0.0, 0.0, 0.0]),
        rf"{E0}\.actions expected an array of numbers, got rows of different lengths",
    ),
    "text actions": (EE, _set("actions.2", ["a", "b", "c", "d"]), rf"{E0}\.actions expected an array of numbers"),
    "actions of one step": (EE, _set("actions", [0.0, 0.0, 0.0, 0.0]), rf"{E0}\.actions expected shape \(T, A\)"),
    # info: a flag for the reset and one per action, booleans
    "success one short": (
        EE,
        _ep(lambda ep: ep["info"]["success"].pop()),
        rf"{E0}\.info\.success expected n_steps \+ 1 = 51 flags .*, got 50 entries",
    ),
    "success one long": (EE, _ep(lambda ep: ep["info"]["success"].append(True)), r"= 51 flags .*, got 52 entries"),
    "no success": (EE, _ep(lambda ep: ep["info"].pop("success")), rf"{E0}\.info expected an object with 'success'"),
    "is_grasped short": (
        EE,
        _set("info.is_grasped", [False] * 3),
        rf"{E0}\.info\.is_grasped expected .* got 3 entries",
    ),
    "success not a flag": (EE, _set("info.success.5", 0.5), rf"{E0}\.info\.success\[5\] expected a boolean, got 0.5"),
    "n_steps": (EE, _set("n_steps", 49), rf"{E0}\.n_steps is 49, expected 50 \(the number of actions\)"),
    "seed": (EE, _set("seed", "3"), rf"{E0}\.seed expected a non-negative integer .*, got '3'"),
    # init_state_dict: the task's actors (TASK_ACTORS), the Panda, widths 13 / 31, finite
    "PushCube state on StackCube": (
        EE,
        _header(task="StackCube-v1"),
        rf"{ISD}\.actors\['cube'\] is not part of StackCube-v1 \(its actors: "
        r"\['table-workspace', 'cubeA', 'cubeB'\], got \['cube', 'goal_region', "
        r"'table-workspace'\]\)",
    ),
    "PushCube state on PickCube": (
        EE,
        _header(task="PickCube-v1"),
        rf"{ISD}\.actors\['goal_region'\] is not part of PickCube-v1",
    ),
    "actor missing": (
        EE,
        _ep(lambda ep: ep["init_state_dict"]["actors"].pop("goal_region")),
        rf"{ISD}\.actors has no 'goal_region' entry, which PushCube-v1 needs",
    ),
    "panda missing": (
        EE,
        _ep(lambda ep: ep["init_state_dict"]["articulations"].pop("panda")),
        rf"{ISD}\.articulations expected one robot of \['panda', 'panda_wristcam'\], got \[\]",
    ),
    "another robot": (
        EE,
        _ep(lambda ep: ep["init_state_dict"]["articulations"].__setitem__("fetch", [0.0] * 31)),
        rf"{ISD}\.articulations expected one robot of \['panda', 'panda_wristcam'\], got \['fetch', 'panda'\]",
    ),
    "robots of two episodes": (
        EE,
        lambda d: d["episodes"][1]["init_state_dict"].update(
            articulations={"panda_wristcam": d["episodes"][1]["init_state_dict"]["articulations"]["panda"]}),
        r"episodes\[1\]\.init_state_dict\.articulations\['panda_wristcam'\] is a state of the robot 'panda_wristcam', "
        r"expected 'panda'",
    ),
    "actor width": (
        EE,
        _actor("cube", lambda v: v[:7]),
        rf"{ISD}\.actors\['cube'\] expected shape \(13,\), got \(7,\)",
    ),
    "panda width": (
        EE,
        _ep(
            lambda ep: ep["init_state_dict"]["articulations"].__setitem__(
                "panda", ep["init_state_dict"]["articulations"]["panda"][:22]
            )
        ),
        rf"{ISD}\.articulations\['panda'\] expected shape \(31,\), got \(22,\)",
    ),  # fmt: skip
    "batched actor": (
        EE,
        _actor("cube", lambda v: [v]),
        rf"{ISD}\.actors\['cube'\] expected shape \(13,\), got \(1, 13\)",
    ),
    "nan in state": (
        EE,
        _actor("cube", lambda v: [float("nan")] + v[1:]),
        rf"{ISD}\.actors\['cube'\] holds non-finite",
    ),
    "text in state": (
        EE,
        _actor("cube", lambda v: ["x"] * 13),
        rf"{ISD}\.actors\['cube'\] expected an array of numbers",
    ),
    "no articulations": (
        EE,
        _set("init_state_dict", {"actors": {}}),
        rf"{ISD} expected a dict with 'actors' and 'articulations', got \['actors'\]",
    ),
    # the main object's poses and the episode itself
    "pose width": (
        EE,
        _ep(lambda ep: ep.update(cube_pose=[p[:3] for p in ep["cube_pose"]])),
        rf"{E0}\.cube_pose expected shape \(51, 7\), got \(51, 3\)",
    ),
    "nan pose": (EE, _set("cube_pose.7.2", float("nan")), rf"{E0}\.cube_pose\[7\]\[2\] is nan"),
    "episode not an object": (EE, lambda d: d["episodes"].__setitem__(0, []), rf"{E0} expected an object, got list"),
    "episodes not a list": (EE, lambda d: d.update(episodes={"0": d["episodes"][0]}), "episodes expected a list"),
}


@pytest.fixture
def no_env(monkeypatch):
    """``make`` replaced: a refused recording must never build an env."""
    import wpctrl.tasks.factory as factory

    def make(*args, **kwargs):
        raise AssertionError("an env was built for a refused recording")

    monkeypatch.setattr(factory, "make", make)


@pytest.mark.parametrize("case", list(REPLAY_BAD))
def test_a_bad_recording_is_refused_naming_the_field_before_an_env_is_built(case, tmp_path, capsys, no_env):
    name, edit, reason = REPLAY_BAD[case]
    data = _recording(name)
    assert T.load_episodes(copy.deepcopy(data)) is not None  # the sample itself passes
    edit(data)
    with pytest.raises(wpctrl.ConfigError, match=reason):
        T.load_episodes(data)
    with pytest.raises(wpctrl.ConfigError, match=reason):
        T.replay(data)
    path = tmp_path / name
    path.write_text(json.dumps(data))
    with pytest.raises(wpctrl.ConfigError, match=rf"^replay: {re.escape(repr(str(path)))}: .*{reason}"):
        T.load_episodes(path)
    out = tmp_path / "report.json"
    assert main([str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"wpctrl replay: error: {str(path)!r}: ") and len(err.splitlines()) == 1, err
    assert not out.exists()


def test_the_action_width_is_the_one_the_recordings_were_made_with():
    """``action_width`` (from the controller configs) against ManiSkill's action space as its recordings store it
    (``header.action_space``), for the modes of the sample."""
    for path in sorted(DATA.glob("*__*.json")):
        header = _recording(path.name)["header"]
        assert action_width(header["control_mode"]) == len(header["action_space"]["low"]), path.name


@pytest.mark.parametrize("mode", CONTROL_MODES)
def test_the_action_width_is_maniskills_in_every_mode(mode):
    """The width the replay checks is the action space of ManiSkill 3.0.1's own env in the same control mode."""
    pytest.importorskip("mani_skill")
    from maniskill_tasks_side import make_maniskill

    env = make_maniskill("PushCube-v1", mode)
    try:
        assert action_width(mode) == env.unwrapped.single_action_space.shape[0]
    finally:
        env.close()


# -- set_state_dict ----------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def env():
    """PushCube in a ``use_target`` mode (its state dict has a ``"controller"`` entry), a few steps into an episode."""
    e = T.make("PushCube-v1", num_envs=N, control_mode="pd_joint_target_delta_pos",
               physics=T.TaskPhysics(substeps=2))  # fmt: skip
    e.reset(seed=3)
    for _ in range(3):
        e.step(0.3 * torch.ones(N, 8))
    return e


def _state_edit(fn):
    def make(env):
        s = env.get_state_dict()
        fn(s)
        return s

    return make


def _put(group, name, fn):
    return _state_edit(lambda s: s[group].__setitem__(name, fn(s[group][name])))


def _pick_state(s):
    s["actors"]["goal_site"] = s["actors"].pop("goal_region")


SA = r"state\['actors'\]"
SR = r"state\['articulations'\]"
SC = r"state\['controller'\]"
STATE_BAD = {
    "PickCube's state": (
        _state_edit(_pick_state),
        None,
        rf"{SA}\['goal_site'\] is not part of PushCube-v1 \(its "
        r"actors: \['table-workspace', 'cube', 'goal_region'\], got \['cube', 'goal_site', "
        r"'table-workspace'\]\); a state dict of another task",
    ),
    "StackCube's state": (
        _state_edit(lambda s: s["actors"].update(cubeA=s["actors"].pop("cube"), cubeB=s["actors"].pop("goal_region"))),
        None,
        rf"{SA}\['cubeA'\] is not part of PushCube-v1",
    ),  # fmt: skip
    "actor missing": (
        _state_edit(lambda s: s["actors"].pop("cube")),
        None,
        rf"{SA} has no 'cube' entry, which PushCube-v1 needs \(expected \['table-workspace', 'cube', "
        r"'goal_region'\], got \['goal_region', 'table-workspace'\]\)",
    ),
    "panda missing": (_state_edit(lambda s: s["articulations"].pop("panda")), None, rf"{SR} has no 'panda' entry"),
    "the other robot's state": (
        _state_edit(lambda s: s["articulations"].__setitem__("panda_wristcam", s["articulations"].pop("panda"))),
        None,
        rf"{SR}\['panda_wristcam'\] is a state of the robot 'panda_wristcam', expected 'panda' \(PushCube-v1 on "
        r"'panda'; make\(\.\.\., robot_uids='panda_wristcam'\) builds the other\)",
    ),
    "another robot": (
        _state_edit(lambda s: s["articulations"].__setitem__("fetch", torch.zeros(N, 31))),
        None,
        rf"{SR}\['fetch'\] is not part of PushCube-v1",
    ),
    "actor width": (
        _put("actors", "cube", lambda v: v[:, :7]),
        None,
        rf"{SA}\['cube'\] expected shape \(2, 13\) \(2 envs set, 13 values each\) or \(13,\), got \(2, 7\)",
    ),
    "panda width": (
        _put("articulations", "panda", lambda v: v[:, :22]),
        None,
        rf"{SR}\['panda'\] expected shape \(2, 31\) .*, got \(2, 22\)",
    ),
    "batch too large": (
        _put("actors", "cube", lambda v: torch.cat([v, v])),
        None,
        rf"{SA}\['cube'\] expected shape \(2, 13\) .*, got \(4, 13\)",
    ),
    "batch of all for one env": (
        lambda env: env.get_state_dict(),
        [1],
        rf"{SA}\['table-workspace'\] expected "
        r"shape \(1, 13\) \(1 envs set, 13 values each\) or \(13,\), got \(2, 13\)",
    ),
    "3-d entry": (
        _put("actors", "cube", lambda v: v[None]),
        None,
        rf"{SA}\['cube'\] expected shape .*, got \(1, 2, 13\)",
    ),
    "bool entry": (
        _put("actors", "cube", lambda v: v > 0),
        None,
        rf"{SA}\['cube'\] expected an array of numbers, got dtype bool",
    ),
    "text entry": (
        _put("actors", "cube", lambda v: [["x"] * 13] * N),
        None,
        rf"{SA}\['cube'\] expected an array of numbers",
    ),
    "ragged entry": (
        _put("actors", "cube", lambda v: [[0.0] * 13, [0.0] * 7]),
        None,
        rf"{SA}\['cube'\] expected an array of numbers, got list",
    ),
    "nan": (
        _put("articulations", "panda", lambda v: v.index_fill(1, torch.tensor([15]), float("nan"))),
        None,
        rf"{SR}\['panda'\] holds non-finite values",
    ),
    "table moved": (
        _put("actors", "table-workspace", lambda v: v + 0.1),
        None,
        rf"{SA}\['table-workspace'\] has the pose .*; the table is fixed on Newton at",
    ),
    "root moved": (
        _put("articulations", "panda", lambda v: v.index_fill(1, torch.tensor([0]), -0.5)),
        None,
        rf"{SR}\['panda'\] has the root pose \[-0.5, .*; the Panda's root is fixed at \[-0.61",
    ),
    "not a dict": (lambda env: [1, 2], None, "state expected a dict with 'actors' and 'articulations', got list"),
    "no articulations": (
        _state_edit(lambda s: s.pop("articulations")),
        None,
        r"state expected a dict with 'actors' and 'articulations', got \['actors', 'controller'\]",
    ),
    "actors not a dict": (
        _state_edit(lambda s: s.__setitem__("actors", [1])),
        None,
        rf"{SA} expected a dict of actors by name, got list",
    ),
    "controller of another mode": (
        _state_edit(lambda s: s["controller"].__setitem__("gripper", {})),
        None,
        rf"{SC}\['gripper'\] is not a stateful controller of pd_joint_target_delta_pos "
        r"\(expected one of \['arm'\]\)",
    ),
    "controller key": (
        _state_edit(lambda s: s["controller"]["arm"].__setitem__("target_pose", torch.zeros(N, 7))),
        None,
        rf"{SC}\['arm'\]\['target_pose'\] is not part of the controller's state \(expected "
        r"\['target_qpos'\]\)",
    ),
    "controller width": (
        _state_edit(lambda s: s["controller"]["arm"].__setitem__("target_qpos", torch.zeros(N, 9))),
        None,
        rf"{SC}\['arm'\]\['target_qpos'\] expected shape \(2, 7\) or \(7,\), got \(2, 9\)",
    ),
    "controller nan": (
        _state_edit(lambda s: s["controller"]["arm"]["target_qpos"].fill_(float("nan"))),
        None,
        rf"{SC}\['arm'\]\['target_qpos'\] holds non-finite",
    ),
    "controller not a dict": (_state_edit(lambda s: s.__setitem__("controller", [1])), None, rf"{SC} expected a dict"),
}


def _snapshot(env) -> dict:
    """Everything a state write touches, as host copies."""
    out = {"joint_q": env.state.joint_q.numpy().copy(), "joint_qd": env.state.joint_qd.numpy().copy(),
           "marker_pos": env.marker_pos.numpy().copy(), "marker_quat": env.marker_quat.numpy().copy()}  # fmt: skip
    for uid, entry in env.ctrl.get_state().items():
        for k, v in entry.items():
            out[f"controller/{uid}/{k}"] = v.numpy().copy()
    for group in ("actors", "articulations"):
        for name, v in env.get_state_dict()[group].items():
            out[f"{group}/{name}"] = v.numpy().copy()
    return out


@pytest.mark.parametrize("case", list(STATE_BAD))
def test_a_bad_state_dict_is_refused_naming_the_entry_and_nothing_is_written(env, case):
    make, env_idx, reason = STATE_BAD[case]
    state = make(env)
    before = _snapshot(env)
    with pytest.raises(wpctrl.ConfigError, match=r"^set_state_dict: " + reason):
        env.set_state_dict(state, env_idx=env_idx)
    after = _snapshot(env)
    assert after.keys() == before.keys()
    for key in before:
        np.testing.assert_array_equal(after[key], before[key], err_msg=key)


def test_a_controller_entry_is_restored_for_the_envs_set_only(env):
    """The ``"controller"`` entry checked on the host is the one written: env 1's targets from the state, env 0's
    as they were."""
    state = env.get_state_dict()
    before = state["controller"]["arm"]["target_qpos"].clone()
    new = {g: {k: v[1:] for k, v in state[g].items()} for g in ("actors", "articulations")}
    new["controller"] = {"arm": {"target_qpos": before[1:] + 0.01}}
    env.set_state_dict(new, env_idx=[1])
    after = env.get_state_dict()["controller"]["arm"]["target_qpos"]
    torch.testing.assert_close(after[0], before[0], rtol=0, atol=0)
    torch.testing.assert_close(after[1], before[1] + 0.01, rtol=0, atol=0)
