"""wpctrl.tasks where envs, episodes and values differ: every env of a reset draws its own episode (checked env by
env against ManiSkill's distributions), a partial ``set_state_dict`` leaves the other envs exactly as they were (their
state, drive targets, observation and step count, and their next step against a twin env never touched), the final
info of an episode ended by success inside an auto-resetting step, and the edges of the tasks' ranges (every arm
joint of PickCube's "robot static" at the threshold, the grasp cone's angle and force limit, the goal radii) against
numpy re-derivations of ManiSkill's definitions (tests/reference_tasks.py); a task declared outside the package
(two bodies, a capsule, a marker) built from its declaration, and what a task refuses (unknown ids, another task's
state dict)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

torch = pytest.importorskip("torch")
scipy_stats = pytest.importorskip("scipy.stats")

import reference_tasks as R  # noqa: E402
import warp as wp  # noqa: E402

import wpctrl  # noqa: E402
import wpctrl.tasks as T  # noqa: E402
from wpctrl.tasks import funcs as F  # noqa: E402
from wpctrl.tasks.definitions import PANDA_REST_QPOS, Actor, Box, Capsule, Marker, ObsField  # noqa: E402

N = 4
FAST = T.TaskPhysics(substeps=2)
"""The API's bookkeeping, not the physics' fidelity: 2 MuJoCo steps per physics step."""
GOAL = {"PushCube-v1": "goal_region", "PickCube-v1": "goal_site"}


@pytest.fixture(scope="module")
def push_env():
    return T.make("PushCube-v1", num_envs=N, control_mode="pd_joint_delta_pos", physics=FAST)


@pytest.fixture(scope="module")
def pick_env():
    return T.make("PickCube-v1", num_envs=N, control_mode="pd_ee_delta_pos", physics=FAST)


def _draws(env, task, seeds):
    """(seeds, N, ...) arm qpos noise, cube pose and goal position right after ``reset(seed=s)``."""
    noise, cube, goal = [], [], []
    for s in seeds:
        env.reset(seed=s)
        st = env.get_state_dict()
        noise.append(st["articulations"]["panda"][:, 13:20].numpy() - np.asarray(PANDA_REST_QPOS[:7]))
        cube.append(st["actors"]["cube"].numpy())
        goal.append(st["actors"][GOAL[task]][:, :3].numpy())
    return np.stack(noise), np.stack(cube), np.stack(goal)


# -- every env its own episode ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("task", ["PushCube-v1", "PickCube-v1"])
def test_every_env_of_a_reset_draws_its_own_episode_from_maniskills_distribution(task, push_env, pick_env):
    """200 seeded resets of 4 envs. Within every reset the envs' episodes differ (cube, goal, arm noise). Each env on
    its own follows ManiSkill's _initialize_episode: arm noise N(0, 0.02), cube xy U[-0.1, 0.1], PickCube's goal xy
    U[-0.1, 0.1] and z = 0.02 + U[0, 0.3], each by a Kolmogorov-Smirnov test per env and axis (at most 48 tests: each
    at p > 1e-3, a family-wise false alarm of about 5 %; the draws are Warp's deterministic RNG, so the same on every
    machine). A partial reset of one env draws that env a new episode and leaves the others'."""
    env = push_env if task == "PushCube-v1" else pick_env
    noise, cube, goal = _draws(env, task, range(200))
    for s in range(200):
        for a in range(N):
            for b in range(a + 1, N):
                assert not np.allclose(cube[s, a, :2], cube[s, b, :2]), (s, a, b)
                assert not np.allclose(noise[s, a], noise[s, b]), (s, a, b)
                if task == "PickCube-v1":
                    assert not np.allclose(goal[s, a], goal[s, b]), (s, a, b)
    for e in range(N):
        p = scipy_stats.kstest(noise[:, e].ravel(), scipy_stats.norm(0.0, 0.02).cdf).pvalue
        assert p > 1e-3, (e, p)
        for axis in range(2):
            p = scipy_stats.kstest(cube[:, e, axis], scipy_stats.uniform(-0.1, 0.2).cdf).pvalue
            assert p > 1e-3, (e, axis, p)
        if task == "PickCube-v1":
            for axis, dist in ((0, scipy_stats.uniform(-0.1, 0.2)), (1, scipy_stats.uniform(-0.1, 0.2)),
                               (2, scipy_stats.uniform(0.02, 0.3))):  # fmt: skip
                p = scipy_stats.kstest(goal[:, e, axis], dist.cdf).pvalue
                assert p > 1e-3, (e, axis, p)
    # a partial reset: env 2 gets a new episode, unlike its last one and unlike the others' current ones
    env.reset(seed=5)
    before = env.get_state_dict()["actors"]["cube"].clone()
    env.reset(options={"env_idx": [2]})
    after = env.get_state_dict()["actors"]["cube"]
    torch.testing.assert_close(after[[0, 1, 3]], before[[0, 1, 3]], rtol=0, atol=0)
    assert not torch.allclose(after[2, :2], before[2, :2])
    for e in (0, 1, 3):
        assert not torch.allclose(after[2, :2], after[e, :2])


# -- a partial set_state_dict ------------------------------------------------------------------------------------------


def _control_targets(env) -> np.ndarray:
    return env.control.joint_target_q.numpy().reshape(env.num_envs, -1).copy()


def test_partial_set_state_dict_leaves_the_other_envs_exactly_as_they_were():
    """Two PushCube envs step through the same differing actions. One then gets a state dict for envs 1 and 3 only:
    those envs hold it (their drive targets at its qpos, their observation of it); envs 0 and 2 keep their state,
    drive targets, observation and step count bit for bit, and their next step equals the untouched twin's."""
    acts = torch.as_tensor(np.random.default_rng(3).uniform(-1, 1, (3, N, 8)).astype(np.float32))
    envs = [T.make("PushCube-v1", num_envs=N, control_mode="pd_joint_delta_pos", auto_reset=False, physics=FAST)
            for _ in range(2)]  # fmt: skip
    for env in envs:
        env.reset(seed=9)
        for k in range(2):
            env.step(acts[k])
    env, twin = envs
    before = env.get_state_dict()
    targets, obs = _control_targets(env), env.get_obs().clone()
    rng = np.random.default_rng(4)
    new = {g: {k: v[[1, 3]].clone() for k, v in before[g].items()} for g in ("actors", "articulations")}
    new["actors"]["cube"][:, :2] += torch.as_tensor(rng.uniform(-0.05, 0.05, (2, 2)), dtype=torch.float32)
    new["articulations"]["panda"][:, 13:20] += torch.as_tensor(rng.uniform(-0.1, 0.1, (2, 7)), dtype=torch.float32)
    env.set_state_dict(new, env_idx=[1, 3])

    after = env.get_state_dict()
    keep, moved = [0, 2], [1, 3]
    for group in ("actors", "articulations"):
        for name, v in before[group].items():
            torch.testing.assert_close(after[group][name][keep], v[keep], rtol=0, atol=0)
            torch.testing.assert_close(after[group][name][moved], new[group][name], rtol=0, atol=0)
    now = _control_targets(env)
    np.testing.assert_array_equal(now[keep], targets[keep])
    coords = env.scene.robot_coord0
    np.testing.assert_allclose(now[moved, coords : coords + 7], new["articulations"]["panda"][:, 13:20].numpy(),
                               atol=1e-6)  # fmt: skip
    obs_now = env.get_obs()
    torch.testing.assert_close(obs_now[keep], obs[keep], rtol=0, atol=0)
    np.testing.assert_allclose(obs_now[moved, :9].numpy(), new["articulations"]["panda"][:, 13:22].numpy(), atol=1e-6)
    assert env.elapsed_steps.tolist() == [2] * N
    o1, r1, *_ = env.step(acts[2])
    o2, r2, *_ = twin.step(acts[2])
    torch.testing.assert_close(o1[keep], o2[keep], rtol=0, atol=0)
    torch.testing.assert_close(r1[keep], r2[keep], rtol=0, atol=0)


# -- the final info of an episode ended by success ---------------------------------------------------------------------


def test_an_episode_ended_by_success_is_in_the_final_info_and_restarts_inside_the_step():
    """ManiSkillVectorEnv with auto reset: env 1's cube is put on its goal, the others are not. The step terminates
    env 1 only; ``_final_info`` marks env 1, whose final info reports the success and its one step and whose final
    observation shows the cube where it was set; env 1 starts a new episode (step 0, a new cube); envs 0, 2, 3 go
    on (step 1, no final info)."""
    env = T.make("PushCube-v1", num_envs=N, control_mode="pd_joint_delta_pos", physics=FAST)
    env.reset(seed=4)
    state = env.get_state_dict()
    goal = state["actors"]["goal_region"][1, :3]
    state["actors"]["cube"][1, :2] = goal[:2]
    env.set_state_dict(state)
    hold = torch.zeros(N, 8)
    hold[:, -1] = 1.0
    obs, reward, terminated, truncated, info = env.step(hold)
    mask = [False, True, False, False]
    assert terminated.tolist() == mask and not truncated.any()
    assert info["_final_info"].tolist() == mask and info["_final_observation"].tolist() == mask
    assert bool(info["final_info"]["success"][1]) and info["final_info"]["elapsed_steps"][1] == 1
    assert info["elapsed_steps"].tolist() == [1, 0, 1, 1]
    assert reward[1].item() == pytest.approx(1.0)
    cube = slice(18 + 10, 18 + 13)  # PushCube's obs: qpos, qvel, tcp pose (7), goal (3), cube pose
    np.testing.assert_allclose(info["final_observation"][1, cube][:2].numpy(), goal[:2].numpy(), atol=5e-3)
    assert not np.allclose(obs[1, cube][:2].numpy(), goal[:2].numpy(), atol=1e-2)  # a new episode's cube
    np.testing.assert_array_equal(info["final_observation"][[0, 2, 3]].numpy(), obs[[0, 2, 3]].numpy())


# -- the edges of the tasks' ranges ------------------------------------------------------------------------------------


def _at_goal(env) -> dict:
    state = env.get_state_dict()
    goal = torch.tensor([0.05, -0.02, 0.15])
    state["actors"]["goal_site"][:, :3] = goal
    cube = state["actors"]["cube"]
    cube[:, :3] = goal
    cube[:, 3:] = torch.tensor([1.0, 0, 0, 0, 0, 0, 0, 0, 0, 0])
    state["articulations"]["panda"][:, 22:31] = 0.0
    return state


@pytest.mark.parametrize("joint", range(9))
def test_pick_robot_static_checks_every_arm_joint_at_the_threshold(pick_env, joint):
    """ManiSkill's ``is_static(0.2)``: max |qvel| of the 7 arm joints <= 0.2 rad/s, the fingers not counted. One joint
    at a time at +0.2 (static: the edge is inside), +0.2005, -0.2005 and -0.2 rad/s, on the cube at its goal:
    ``is_robot_static`` and ``success`` against the numpy re-derivation."""
    pick_env.reset(seed=1)
    state = _at_goal(pick_env)
    speeds = torch.tensor([0.2, 0.2005, -0.2005, -0.2])
    state["articulations"]["panda"][:, 22 + joint] = speeds
    pick_env.set_state_dict(state)
    flags = pick_env.evaluate()
    parts = R.state_parts(pick_env.get_state_dict(), "goal_site")
    ref = R.pick_evaluate(parts["cube_p"], parts["goal_p"], parts["qvel"], np.zeros(N, bool))
    expect = [True] * N if joint >= 7 else [True, False, False, True]
    assert ref["is_robot_static"].tolist() == expect
    assert flags["is_robot_static"].tolist() == expect
    assert flags["success"].tolist() == ref["success"].tolist()


def _finger_axes(env) -> np.ndarray:
    """(N, 2, 3): each env's left finger's +y axis and its right finger's -y axis (``Panda.is_grasping``'s
    directions), from the bodies' world rotations (Newton's xyzw quaternions) by numpy."""
    from scipy.spatial.transform import Rotation

    sc = env.scene
    body_q = env.state.body_q.numpy().reshape(N, sc.bodies_per_env, 7)
    out = np.zeros((N, 2, 3))
    for i, (b, sign) in enumerate(zip(sc.finger_bodies0, (1.0, -1.0))):
        out[:, i] = sign * Rotation.from_quat(body_q[:, b, 3:7]).apply([0.0, 1.0, 0.0])
    return out


def _is_grasping(forces: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """ManiSkill's ``Panda.is_grasping(min_force=0.5, max_angle=85)``: both fingers' contact force >= 0.5 N and
    within 85 degrees of the finger's direction."""
    norm = np.linalg.norm(forces, axis=-1)
    cos = np.einsum("nij,nij->ni", forces, axes) / np.maximum(norm * np.linalg.norm(axes, axis=-1), 1e-12)
    angle = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return ((norm >= 0.5) & (angle <= 85.0)).all(axis=1)


def test_pick_grasp_cone_and_force_limit_at_their_edges(pick_env):
    """The contact forces the sensor reports, written per env and finger: at 84.9 and 85.1 degrees from the finger's
    direction (about the finger's own x axis), at 0.49 and 0.51 N along it, the other finger in each case well inside
    the cone. ``is_grasped`` against ManiSkill's ``is_grasping`` re-derived in numpy, env by env, for both fingers."""
    pick_env.reset(seed=2)
    pick_env.set_state_dict(_at_goal(pick_env))
    axes = _finger_axes(pick_env)
    sc = pick_env.scene
    body_q = pick_env.state.body_q.numpy().reshape(N, sc.bodies_per_env, 7)
    from scipy.spatial.transform import Rotation

    cases = [(84.9, 2.0), (85.1, 2.0), (0.0, 0.49), (30.0, 0.51)]
    seen = []
    for finger in (0, 1):
        forces = np.zeros((N, 2, 3))
        for e, (deg, mag) in enumerate(cases):
            side = Rotation.from_quat(body_q[e, sc.finger_bodies0[finger], 3:7]).apply([1.0, 0.0, 0.0])
            rad = math.radians(deg)
            forces[e, finger] = mag * (math.cos(rad) * axes[e, finger] + math.sin(rad) * side)
            other = 1 - finger
            forces[e, other] = 3.0 * axes[e, other]
        fm = pick_env._sensor.force_matrix
        values = fm.numpy()
        values[:, 0] = forces.reshape(2 * N, 3)
        fm.assign(wp.array(values, dtype=wp.vec3, device=fm.device))
        pick_env._sensor.force_matrix_friction.zero_()
        got = pick_env.evaluate()["is_grasped"].numpy()
        ref = _is_grasping(forces, axes)
        assert ref.tolist() == [True, False, False, True]
        assert got.tolist() == ref.tolist(), finger
        seen.append(got.tolist())
    assert seen[0] == seen[1]


@pytest.mark.parametrize("task", ["PushCube-v1", "PickCube-v1"])
def test_goal_radius_and_height_edges(task, push_env, pick_env):
    """The cube just inside and just outside the goal radius (PushCube: 0.1 m in xy, strictly; PickCube: 0.025 m in
    3-D, inclusive) and PushCube's height limit (z < 0.025): ``success`` against the numpy re-derivation."""
    env = push_env if task == "PushCube-v1" else pick_env
    env.reset(seed=3)
    state = env.get_state_dict() if task == "PushCube-v1" else _at_goal(env)
    goal = state["actors"][GOAL[task]][:, :3].clone()
    cube = state["actors"]["cube"]
    cube[:, 3:] = torch.tensor([1.0, 0, 0, 0, 0, 0, 0, 0, 0, 0])
    if task == "PushCube-v1":
        offsets = [(0.0995, 0.0, 0.02), (0.1005, 0.0, 0.02), (0.0, 0.0995, 0.0249), (0.0, 0.0, 0.0251)]
        for e, (dx, dy, z) in enumerate(offsets):
            cube[e, :3] = torch.tensor([goal[e, 0] + dx, goal[e, 1] + dy, z])
    else:
        offsets = [(0.0245, 0.0, 0.0), (0.0255, 0.0, 0.0), (0.0, 0.0, -0.0245), (0.015, 0.015, 0.015)]
        for e, d in enumerate(offsets):
            cube[e, :3] = goal[e] + torch.tensor(d)
    env.set_state_dict(state)
    got = env.evaluate()["success"].numpy()
    parts = R.state_parts(env.get_state_dict(), GOAL[task])
    if task == "PushCube-v1":
        ref = R.push_evaluate(parts["cube_p"], parts["goal_p"])["success"]
    else:
        ref = R.pick_evaluate(parts["cube_p"], parts["goal_p"], parts["qvel"], np.zeros(N, bool))["success"]
    assert ref.tolist() == [True, False, True, False]
    assert got.tolist() == ref.tolist()


# -- a task declared outside the package ------------------------------------------------------------------------------

BLOCK_HALF = (0.02, 0.03, 0.01)
BLOCK_HALF_Z = BLOCK_HALF[2]
PEG_RADIUS, PEG_HALF_LENGTH = 0.01, 0.04


@wp.func
def _blocks_initialize(s: F.Sim, e: int, rng: wp.uint32):
    x = (wp.randf(rng) * 2.0 - 1.0) * 0.05
    F.set_actor_pose(s, e, 0, wp.vec3(x, 0.1, BLOCK_HALF_Z), wp.quat_identity())
    F.set_actor_pose(s, e, 1, wp.vec3(0.0, -0.1, PEG_RADIUS), F.yaw_quat(wp.randf(rng) * 2.0 * wp.pi))
    F.set_marker_pos(s, e, 0, wp.vec3(x, 0.0, 0.1))


@wp.func
def _blocks_evaluate(s: F.Sim, e: int):
    s.info[e, 0] = F.actor_pos(s, e, 0)[2] > 0.05
    s.info[e, 1] = F.actor_pos(s, e, 1)[2] < PEG_RADIUS + 1.0e-3


@wp.func
def _blocks_reward(s: F.Sim, e: int) -> float:
    return -wp.length(F.actor_pos(s, e, 1) - F.tcp_pos(s, e))


@wp.func
def _blocks_box_pose(s: F.Sim, e: int) -> F.vec7:
    return F.actor_pose7(s, e, 0)


@wp.func
def _blocks_peg_pos(s: F.Sim, e: int) -> wp.vec3:
    return F.actor_pos(s, e, 1)


@wp.func
def _blocks_goal_pos(s: F.Sim, e: int) -> wp.vec3:
    return F.marker_pos(s, e, 0)


class _Blocks(T.Task):
    """Two free bodies (a box and a capsule lying along x), one goal marker, a flag besides success."""

    actors = (Actor("box", (Box(BLOCK_HALF),), build_height=BLOCK_HALF[2]),
              Actor("peg", (Capsule(PEG_RADIUS, PEG_HALF_LENGTH),), build_height=PEG_RADIUS),
              Marker("goal"))  # fmt: skip
    contact_actors = ("peg",)
    obs_extra = (ObsField("extra", "box_pose", 7, _blocks_box_pose), ObsField("extra", "peg_pos", 3, _blocks_peg_pos),
                 ObsField("extra", "goal_pos", 3, _blocks_goal_pos))  # fmt: skip
    info_keys = ("peg_on_table",)
    max_reward = 1.0
    initialize = _blocks_initialize
    evaluate = _blocks_evaluate
    dense_reward = _blocks_reward


def test_a_task_declared_outside_the_package_builds_from_its_declaration(monkeypatch):
    """A third task, registered from here: a box and a capsule (two free bodies), a goal marker, three observation
    fields, a flag besides success. The state dict lists its actors in the declared order, the observation packs its
    fields in the declared order (each equal to the state it reports), every env draws its own episode, the bodies
    weigh what their shapes and density give, the capsule lies along x (it rests at its radius), and a state dict of
    PushCube is refused naming the actor it lacks. The registry forgets the task afterwards."""
    from wpctrl.tasks import registry

    built_in = dict(T.TASKS)  # the built-in modules imported before the registry is patched
    monkeypatch.setattr(registry, "_REGISTERED", built_in)
    T.register_task("Blocks-test", max_episode_steps=10)(_Blocks)
    assert "Blocks-test" in T.TASKS and T.get_task("Blocks-test").obs_dim == 18 + 13
    env = T.make("Blocks-test", num_envs=3, physics=FAST, auto_reset=False)
    obs, info = env.reset(seed=5)
    assert sorted(info) == ["elapsed_steps", "fail", "peg_on_table", "success"]
    for _ in range(3):
        obs, *_ = env.step(torch.zeros(3, env.single_action_space.shape[0]))
    state = env.get_state_dict()
    assert list(state["actors"]) == ["table-workspace", "box", "peg", "goal"]
    s = env.task_spec.obs_slices()["extra"]
    np.testing.assert_array_equal(obs[:, s["box_pose"]].numpy(), state["actors"]["box"][:, :7].numpy())
    np.testing.assert_array_equal(obs[:, s["peg_pos"]].numpy(), state["actors"]["peg"][:, :3].numpy())
    np.testing.assert_array_equal(obs[:, s["goal_pos"]].numpy(), state["actors"]["goal"][:, :3].numpy())
    assert len(set(state["actors"]["box"][:, 0].tolist())) == 3  # each env its own draw
    np.testing.assert_allclose(state["actors"]["peg"][:, 2].numpy(), PEG_RADIUS, atol=5e-4)  # lying along x
    np.testing.assert_allclose(state["actors"]["box"][:, 2].numpy(), BLOCK_HALF[2], atol=5e-4)
    assert env.evaluate()["peg_on_table"].tolist() == [True] * 3
    mass = env.model.body_mass.numpy()
    box_mass = 1000.0 * 8 * np.prod(BLOCK_HALF)
    peg_mass = 1000.0 * math.pi * PEG_RADIUS**2 * (2 * PEG_HALF_LENGTH + 4 / 3 * PEG_RADIUS)
    assert mass[env.scene.actor_body0["box"]] == pytest.approx(box_mass, rel=1e-5)
    assert mass[env.scene.actor_body0["peg"]] == pytest.approx(peg_mass, rel=1e-5)
    push = T.make("PushCube-v1", num_envs=3, physics=FAST, graph=False)
    with pytest.raises(wpctrl.ConfigError, match=r"state\['actors'\]\['cube'\] is not part of Blocks-test"):
        env.set_state_dict(push.get_state_dict())
    monkeypatch.undo()
    assert "Blocks-test" not in T.TASKS


def test_unknown_task_ids_and_another_tasks_state_dict_are_refused_naming_them(push_env, pick_env):
    """An unknown task id lists the known ones (make, get_task, TASKS); PushCube's state dict on PickCube and back is
    refused naming the actor the other task has, before anything is written."""
    known = re.escape(str(sorted(T.TASKS)))
    for call in (lambda: T.make("PlugCharger-v1"), lambda: T.get_task("PlugCharger-v1")):
        with pytest.raises(wpctrl.ConfigError, match=rf"'PlugCharger-v1'.*{known}"):
            call()
    with pytest.raises(KeyError, match="PickCube-v1"):
        T.TASKS["PlugCharger-v1"]
    before = pick_env.get_state_dict()
    with pytest.raises(wpctrl.ConfigError, match=r"state\['actors'\]\['goal_region'\] is not part of PickCube-v1"):
        pick_env.set_state_dict(push_env.get_state_dict())
    for name, v in pick_env.get_state_dict()["actors"].items():
        torch.testing.assert_close(v, before["actors"][name], rtol=0, atol=0)
    with pytest.raises(wpctrl.ConfigError, match=r"state\['actors'\]\['goal_site'\] is not part of PushCube-v1"):
        push_env.set_state_dict(pick_env.get_state_dict())
    missing = push_env.get_state_dict()
    del missing["actors"]["goal_region"]
    with pytest.raises(wpctrl.ConfigError, match=r"no 'goal_region' entry, which PushCube-v1 needs"):
        push_env.set_state_dict(missing)


@pytest.mark.parametrize("name", ["PushCube-v1__pd_ee_delta_pos.json", "PickCube-v1__pd_ee_delta_pos.json"])
def test_the_observation_layout_generated_from_the_declared_fields_is_maniskills(name):
    """The flattened observation's fields, generated from each task module's declaration, against the layout
    ManiSkill's recordings carry (names, order, widths)."""
    import json
    from pathlib import Path

    header = json.loads((Path(__file__).parent / "data" / "tasks" / name).read_text())["header"]
    task = T.TASKS[header["task"]]
    ours = [(f"{g}/{n}", s.start, s.stop) for g, fields in task.obs_slices().items() for n, s in fields.items()]
    theirs = [(f["name"], f["start"], f["stop"]) for f in header["obs_layout"]["fields"]]
    assert ours == theirs and task.obs_dim == header["obs_layout"]["dim"]
    assert [f.boolean for f in task.obs_fields] == [f["dtype"] == "bool" for f in header["obs_layout"]["fields"]]
