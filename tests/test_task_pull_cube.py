"""PullCube-v1 (wpctrl/tasks/pull_cube.py) against ManiSkill 3.0.1's ``PullCubeEnv``
(mani_skill/envs/tasks/tabletop/pull_cube.py): a numpy re-derivation of its evaluation, dense reward and observation
(below, read from ManiSkill's source; nothing here imports wpctrl's definitions for it), the state dict round trip,
the reset distribution and the edges of the success radius and the "reached" radius; then, side by side with the
real ManiSkill (``-m slow``), its constants, the observation / reward / success of the same states, its reset
distribution, and its motion-planning demo replayed on Newton (tests/test_demo_replay.py's goals)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
scipy_stats = pytest.importorskip("scipy.stats")

import wpctrl.tasks as T  # noqa: E402
from wpctrl.tasks.definitions import PANDA_REST_QPOS  # noqa: E402

N = 4
FAST = T.TaskPhysics(substeps=2)
"""The definitions, not the physics' fidelity."""
TASK = "PullCube-v1"


# -- ManiSkill's PullCubeEnv in numpy ----------------------------------------------------------------------------------

HALF, RADIUS = 0.02, 0.1  # PullCubeEnv.cube_half_size, goal_radius


def ref_evaluate(cube_p, goal_p):
    return {"success": np.linalg.norm(cube_p[:, :2] - goal_p[:, :2], axis=1) < RADIUS}


def ref_dense(tcp_p, cube_p, goal_p, success):
    pull_pt = cube_p + np.array([HALF + 2 * 0.005, 0.0, 0.0])
    d = np.linalg.norm(pull_pt - tcp_p, axis=1)
    reward = 1 - np.tanh(5 * d)
    place = 1 - np.tanh(5 * np.linalg.norm(cube_p[:, :2] - goal_p[:, :2], axis=1))
    reward = reward + place * (d < 0.01)
    return np.where(success, 3.0, reward)


def ref_obs(state: dict, tcp_pose):
    """agent qpos, qvel; extra tcp_pose, goal_pos, obj_pose (``_get_obs_extra``'s order)."""
    robot = np.asarray(state["articulations"]["panda"], np.float64)
    cube = np.asarray(state["actors"]["cube"], np.float64)
    goal = np.asarray(state["actors"]["goal_region"], np.float64)
    return np.hstack([robot[:, 13:22], robot[:, 22:31], tcp_pose, goal[:, :3], cube[:, :7]])


@pytest.fixture(scope="module")
def env():
    return T.make(TASK, num_envs=N, control_mode="pd_joint_delta_pos", physics=FAST)


def _numpy(state: dict) -> dict:
    return {g: {k: v.numpy() for k, v in d.items()} for g, d in state.items() if g in ("actors", "articulations")}


def _check_against_reference(env, state: dict) -> None:
    """Newton's observation, evaluation and dense / normalised reward of ``state`` against the re-derivation."""
    obs = env.get_obs().numpy()
    s = _numpy(state)
    tcp_pose = obs[:, 18:25].astype(np.float64)  # Newton's FK of ManiSkill's URDF (checked in test_tasks_maniskill)
    np.testing.assert_allclose(obs, ref_obs(s, tcp_pose), atol=1e-6)
    cube_p, goal_p = s["actors"]["cube"][:, :3].astype(np.float64), s["actors"]["goal_region"][:, :3]
    success = ref_evaluate(cube_p, goal_p)["success"]
    np.testing.assert_array_equal(env.evaluate()["success"].numpy(), success)
    dense = ref_dense(tcp_pose[:, :3], cube_p, goal_p.astype(np.float64), success)
    np.testing.assert_allclose(env.reward_dense.numpy(), dense, atol=1e-5)


def _random_state(env, rng) -> dict:
    """A valid state: the Panda near rest, the cube anywhere on the table (any yaw, some velocity), the goal near."""
    qpos = np.asarray(PANDA_REST_QPOS) + rng.normal(0, 0.15, (N, 9))
    qpos[:, 7:] = rng.uniform(0.0, 0.04, (N, 2))
    yaw = rng.uniform(0, 2 * np.pi, N)
    cube = np.column_stack([rng.uniform(-0.25, 0.15, (N, 2)), np.full(N, 0.02), np.cos(yaw / 2), np.zeros((N, 2)),
                            np.sin(yaw / 2), rng.normal(0, 0.05, (N, 6))])  # fmt: skip
    goal = np.column_stack([cube[:, :2] - [0.2, 0.0] + rng.normal(0, 0.08, (N, 2)), np.full(N, 1e-3),
                            np.tile(env.task_spec.markers[0].quat, (N, 1)), np.zeros((N, 6))])  # fmt: skip
    state = env.get_state_dict()
    state["actors"]["cube"] = torch.tensor(cube, dtype=torch.float32)
    state["actors"]["goal_region"] = torch.tensor(goal, dtype=torch.float32)
    state["articulations"]["panda"][:, 13:22] = torch.tensor(qpos, dtype=torch.float32)
    state["articulations"]["panda"][:, 22:31] = torch.tensor(rng.normal(0, 0.3, (N, 9)), dtype=torch.float32)
    return state


def test_state_dict_round_trips_exactly_and_obs_reward_success_are_maniskills(env):
    rng = np.random.default_rng(5)
    for _ in range(4):
        state = _random_state(env, rng)
        env.set_state_dict(state)
        back = env.get_state_dict()
        for group in ("actors", "articulations"):
            for k, v in state[group].items():
                torch.testing.assert_close(back[group][k], v, rtol=0, atol=0)
        _check_against_reference(env, state)
    assert env.task_spec.obs_dim == 35 and env.task_spec.max_reward == 3.0


def _place(env, cube_xyz, goal_xy, tcp_offset=None) -> dict:
    """The current state with the cube at ``cube_xyz`` (or at the TCP's pull point + ``tcp_offset``), the goal at
    ``goal_xy``; set into the env and returned."""
    state = env.get_state_dict()
    cube = state["actors"]["cube"]
    if tcp_offset is not None:
        tcp = env.get_obs()[:, 18:21]
        cube_xyz = tcp - torch.tensor([HALF + 0.01, 0.0, 0.0]) + torch.as_tensor(tcp_offset, dtype=torch.float32)
    cube[:, :3] = torch.as_tensor(cube_xyz, dtype=torch.float32)
    cube[:, 3:] = torch.tensor([1.0, 0, 0, 0, 0, 0, 0, 0, 0, 0])
    state["actors"]["goal_region"][:, :2] = torch.as_tensor(goal_xy, dtype=torch.float32)
    env.set_state_dict(state)
    return state


def test_success_radius_edge_and_no_height_condition(env):
    """Success: the cube's xy strictly within 0.1 m of the goal's, at any height (PullCube checks no z, PushCube
    does): 9.99 cm in, 10.01 cm out, and lifted 10 cm still in. Success sets the dense reward to 3 (normalised 1)."""
    env.reset(seed=0)
    goal = torch.tensor([[-0.2, 0.0]] * N)
    cube = torch.tensor([[-0.1001, 0.0, 0.02], [-0.0999, 0.0, 0.02], [-0.2, 0.0999, 0.12], [-0.2 + 0.0707, -0.0708,
                         0.02]])  # fmt: skip
    state = _place(env, cube, goal)
    assert env.evaluate()["success"].tolist() == [True, False, True, False]
    np.testing.assert_allclose(env.reward_dense.numpy()[[0, 2]], 3.0)
    _check_against_reference(env, state)


def test_place_reward_waits_until_the_tcp_reaches_the_pull_point(env):
    """The place term counts only with the TCP within 1 cm of the pull point (1 cm beyond the cube's +x face): the
    cube placed so that the pull point is 0.95 cm (envs 0, 1) and 1.05 cm (envs 2, 3) from the TCP, the goal 11 cm
    behind it (place term about 0.5)."""
    env.reset(seed=1)
    offsets = [[0.0095, 0.0, 0.0], [0.0, 0.0, -0.0095], [0.0, 0.0105, 0.0], [0.0, 0.0, 0.0105]]
    tcp = env.get_obs()[:, 18:21]
    state = _place(env, None, tcp[:, :2] - torch.tensor([0.03 + 0.11, 0.0]), tcp_offset=offsets)  # 11 cm: no success
    _check_against_reference(env, state)
    r = env.reward_dense.numpy()
    assert (r[:2] > 1.0).all() and (r[2:] < 1.0).all(), r  # place term (up to 1) on top of reaching (at most 1)


def test_reset_draws_follow_maniskills_distribution(env):
    """``_initialize_episode``: cube xy ~ U[-0.1, 0.1]^2 flat on the table without yaw, the goal at the cube's xy -
    (0.2, 0), z = 1e-3, turned +90 degrees about y; the arm at rest + N(0, 0.02). 30 resets of 4 envs (KS tests
    against the uniform and normal laws)."""
    draws = []
    for seed in range(30):
        env.reset(seed=seed)
        s = env.get_state_dict()
        draws.append((s["articulations"]["panda"][:, 13:22].numpy(), s["actors"]["cube"].numpy(),
                      s["actors"]["goal_region"].numpy()))  # fmt: skip
    qpos, cube, goal = (np.concatenate([d[i] for d in draws]) for i in range(3))
    noise = (qpos[:, :7] - np.asarray(PANDA_REST_QPOS[:7])).ravel()
    assert scipy_stats.kstest(noise, "norm", args=(0.0, 0.02)).pvalue > 1e-3
    np.testing.assert_allclose(qpos[:, 7:], 0.04, atol=1e-7)
    for axis in (0, 1):
        assert scipy_stats.kstest(cube[:, axis], "uniform", args=(-0.1, 0.2)).pvalue > 1e-3
    np.testing.assert_allclose(cube[:, 2:7], np.broadcast_to([0.02, 1, 0, 0, 0], (len(cube), 5)), atol=1e-7)
    np.testing.assert_allclose(goal[:, :2], cube[:, :2] - [0.2, 0.0], atol=1e-6)
    np.testing.assert_allclose(goal[:, 2], 1e-3, atol=1e-7)
    half = math.sqrt(0.5)  # euler2quat(0, pi/2, 0)
    np.testing.assert_allclose(goal[:, 3:7], np.broadcast_to([half, 0, half, 0], (len(goal), 4)), atol=1e-6)


# -- side by side with the real ManiSkill ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def maniskill():
    pytest.importorskip("mani_skill")
    from maniskill_tasks_side import make_maniskill

    return make_maniskill(TASK, "pd_joint_delta_pos")


@pytest.mark.slow
def test_definitions_are_maniskills(maniskill):
    """The module's constants against PullCubeEnv's class, its source and a live env's state dict."""
    import inspect

    import gymnasium as gym
    from mani_skill.envs.tasks.tabletop.pull_cube import PullCubeEnv

    from wpctrl.tasks import pull_cube
    from wpctrl.tasks.names import TASK_ACTORS

    spec = T.TASKS[TASK]
    assert (spec.cube_half_size, spec.goal_radius) == (PullCubeEnv.cube_half_size, PullCubeEnv.goal_radius)
    assert gym.spec(TASK).max_episode_steps == spec.max_episode_steps == 50
    init = inspect.getsource(PullCubeEnv._initialize_episode)
    assert f"torch.rand((b, 2)) * {2 * pull_cube.SPAWN_HALF} - {pull_cube.SPAWN_HALF}" in init
    assert "xyz - torch.tensor([0.1 + self.goal_radius, 0, 0])" in init
    assert pull_cube.GOAL_OFFSET == pytest.approx(0.1 + PullCubeEnv.goal_radius)
    reward = inspect.getsource(PullCubeEnv.compute_dense_reward)
    assert "[self.cube_half_size + 2 * 0.005, 0, 0]" in reward and "tcp_to_pull_pose_dist < 0.01" in reward
    assert 'reward[info["success"]] = 3' in reward
    assert "max_reward = 3.0" in inspect.getsource(PullCubeEnv.compute_normalized_dense_reward)
    state = maniskill.unwrapped.get_state_dict()
    assert tuple(state["actors"]) == TASK_ACTORS[TASK].state
    goal = state["actors"]["goal_region"][0].numpy()
    np.testing.assert_allclose(goal[3:7], spec.markers[0].quat, atol=1e-6)


def _maniskill_states(ms, rng) -> list:
    """ManiSkill's states after resets and random actions, and the same with the cube moved next to the TCP's pull
    point (the place term on) and onto the goal (success)."""
    base = ms.unwrapped
    out = []
    for seed in range(4):
        ms.reset(seed=seed)
        for _ in range(6):
            out.append(base.get_state_dict())
            ms.step(torch.tensor(rng.uniform(-1, 1, (1, 8)), dtype=torch.float32))
        state = base.get_state_dict()
        tcp = base.agent.tcp.pose.p[0]
        for where in (tcp - torch.tensor([0.03 - 0.004 * seed, 0.0, 0.0]), state["actors"]["goal_region"][0, :3]):
            moved = {g: {k: v.clone() for k, v in d.items()} for g, d in state.items() if isinstance(d, dict)}
            moved["actors"]["cube"][0, :3] = where + torch.tensor([0.0, 0.0, 0.02 if seed % 2 else 0.0])
            out.append(moved)
    return out


@pytest.mark.slow
def test_same_state_gives_maniskills_obs_reward_and_success(maniskill):
    ms, base = maniskill, maniskill.unwrapped
    nw = T.make(TASK, num_envs=1, control_mode="pd_joint_delta_pos", physics=FAST)
    successes, reached = 0, 0
    for state in _maniskill_states(ms, np.random.default_rng(0)):
        base.set_state_dict(state)
        info = base.get_info()
        obs = base.get_obs(info)[0].numpy()
        dense = base.compute_dense_reward(obs=None, action=None, info=info)[0].item()
        normalized = base.compute_normalized_dense_reward(obs=None, action=None, info=info)[0].item()
        nw.set_state_dict(state)
        np.testing.assert_allclose(nw.get_obs()[0].numpy(), obs, atol=1e-5)
        assert bool(nw.evaluate()["success"][0]) == bool(info["success"][0])
        assert nw.reward_dense.numpy()[0] == pytest.approx(dense, abs=1e-5)
        assert nw.reward_dense.numpy()[0] / 3.0 == pytest.approx(normalized, abs=1e-5)
        back = nw.get_state_dict()
        for group in ("actors", "articulations"):
            for k, v in state[group].items():
                torch.testing.assert_close(back[group][k], v, rtol=0, atol=2e-7)
        successes += bool(info["success"][0])
        reached += 1.0 < dense < 3.0
    assert successes >= 4 and reached >= 2, (successes, reached)  # both branches of the reward were visited


@pytest.mark.slow
def test_reset_distribution_is_maniskills(maniskill):
    """30 seeded resets on each: two-sample KS tests of the cube's x and y and of the arm's init noise; the goal's
    offset from the cube exact on both."""
    ms = maniskill
    nw = T.make(TASK, num_envs=1, control_mode="pd_joint_delta_pos", physics=FAST)

    def draws(reset, get):
        noise, cube, goal = [], [], []
        for seed in range(30):
            reset(seed)
            s = get()
            noise.append(s["articulations"]["panda"][0, 13:20].numpy() - np.asarray(PANDA_REST_QPOS[:7]))
            cube.append(s["actors"]["cube"][0, :3].numpy())
            goal.append(s["actors"]["goal_region"][0, :3].numpy())
        return np.array(noise), np.array(cube), np.array(goal)

    theirs = draws(lambda s: ms.reset(seed=s), ms.unwrapped.get_state_dict)
    ours = draws(lambda s: nw.reset(seed=s), nw.get_state_dict)
    assert scipy_stats.ks_2samp(theirs[0].ravel(), ours[0].ravel()).pvalue > 1e-3
    for axis in (0, 1):
        assert scipy_stats.ks_2samp(theirs[1][:, axis], ours[1][:, axis]).pvalue > 1e-3
    for _, cube, goal in (theirs, ours):
        np.testing.assert_allclose(goal - cube, np.broadcast_to([-0.2, 0.0, 1e-3 - 0.02], cube.shape), atol=1e-6)


@pytest.mark.slow
def test_motion_planning_demo_replays_to_maniskills_outcome():
    """ManiSkill's motion-planning demo of PullCube (5 episodes, 62-79 steps in pd_joint_pos) replayed on Newton:
    >= 90 % of ManiSkill's successes kept, the cube's final position within 1 cm of PhysX's in the median."""
    from test_demo_replay import DEMOS, assert_demo_replays

    path = Path(DEMOS) / f"{TASK}__pd_joint_pos.json.gz"
    if not path.is_file():
        pytest.skip(f"no demo file {path}")
    assert_demo_replays(path)
