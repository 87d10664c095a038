"""PegInsertionSide-v1 (wpctrl/tasks/peg_insertion_side.py) against independent references: ManiSkill 3.0.1's
recorded motion-planning demos (their ``episode_geometry``, observations and rewards), a numpy re-derivation of its
``evaluate`` / ``compute_dense_reward`` (``mani_skill/envs/tasks/tabletop/peg_insertion_side.py``), Newton's solver
(the drawn geometry is what collides), and, marked slow, the real ManiSkill side by side (PhysX CPU, rendering
stubbed out): its live collision shapes, the same state giving the same observation, success and rewards, the reset
distribution.
"""

from __future__ import annotations

import gzip
import json
import math
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
scipy_stats = pytest.importorskip("scipy.stats")
Rotation = pytest.importorskip("scipy.spatial.transform").Rotation

from task_probes import finger_axes, write_finger_forces  # noqa: E402

import wpctrl.tasks as T  # noqa: E402
from wpctrl.config import ConfigError  # noqa: E402
from wpctrl.tasks import peg_insertion_side as P  # noqa: E402

ENV_ID = "PegInsertionSide-v1"
ROBOT = "panda"
"""The robot of ManiSkill's motion-planning demos (the public sample): ManiSkill's default for the task is
``panda_wristcam``, tested in ``tests/test_wristcam.py``."""
DEMOS = Path("/work/shared/tasks/PegInsertionSide-v1__pd_joint_pos.json.gz")
FAST = T.TaskPhysics(substeps=2)
"""The bookkeeping and definitions, not the physics' fidelity: 2 MuJoCo steps per physics step."""


def _demos() -> dict:
    if not DEMOS.is_file():
        pytest.skip(f"ManiSkill's PegInsertionSide demos are not at {DEMOS}")
    return json.loads(gzip.open(DEMOS).read())


def _state(ep: dict, k: int | None = None) -> dict:
    """The episode's initial state dict, or (``k``) the recorded state after k steps (peg, qpos, qvel)."""
    init = ep["init_state_dict"]
    st = {g: {n: torch.tensor([v], dtype=torch.float32) for n, v in d.items()} for g, d in init.items()}
    if k is not None:
        st["actors"]["peg"][0, :7] = torch.tensor(ep["actor_poses"]["peg"][k])
        st["actors"]["peg"][0, 7:] = 0.0
        st["articulations"][ROBOT][0, 13:22] = torch.tensor(ep["qpos"][k])
        st["articulations"][ROBOT][0, 22:31] = torch.tensor(ep["qvel"][k])
    return st


# -- numpy re-derivation of ManiSkill's PegInsertionSideEnv --------------------------------------------------------


def _rot(q_wxyz) -> Rotation:
    q = np.asarray(q_wxyz, float)
    return Rotation.from_quat([q[1], q[2], q[3], q[0]])


def ref_head_in_hole(peg7, box7, geometry) -> np.ndarray:
    """``(box_hole_pose.inv() * peg_head_pose).p``."""
    length = geometry["peg_half_size"][0]
    head = np.asarray(peg7[:3]) + _rot(peg7[3:]).apply([length, 0, 0])
    hole = np.asarray(box7[:3]) + _rot(box7[3:]).apply(geometry["box_hole_offset"])
    return _rot(box7[3:]).inv().apply(head - hole)


def ref_success(peg7, box7, geometry) -> bool:
    h = ref_head_in_hole(peg7, box7, geometry)
    r = geometry["box_hole_radius"]
    return bool(h[0] >= -0.015 and abs(h[1]) <= r and abs(h[2]) <= r)


def ref_dense(tcp_p, peg7, box7, geometry, grasped: bool) -> float:
    """``compute_dense_reward`` (10 on success)."""
    if ref_success(peg7, box7, geometry):
        return 10.0
    length = geometry["peg_half_size"][0]
    r_peg, r_box = _rot(peg7[3:]), _rot(box7[3:])
    tail = np.asarray(peg7[:3]) + r_peg.apply([-0.06, 0, 0])
    reward = 1 - math.tanh(4.0 * np.linalg.norm(np.asarray(tcp_p) - tail)) + grasped
    goal = np.asarray(box7[:3]) + r_box.apply(geometry["box_hole_offset"]) - r_box.apply([length, 0, 0])
    head = np.asarray(peg7[:3]) + r_peg.apply([length, 0, 0])
    a = np.linalg.norm(r_box.inv().apply(head - goal)[1:])
    b = np.linalg.norm(r_box.inv().apply(np.asarray(peg7[:3]) - goal)[1:])
    reward += 3 * (1 - math.tanh(0.5 * (a + b) + 4.5 * max(a, b))) * grasped
    pre = a < 0.01 and b < 0.01
    reward += 5 * (1 - math.tanh(5.0 * np.linalg.norm(ref_head_in_hole(peg7, box7, geometry)))) * (grasped and pre)
    return float(reward)


# -- the declaration and the scene drawn from the seed -------------------------------------------------------------


def test_the_observation_layout_is_the_recordings():
    header = _demos()["header"]
    layout = header["obs_layout"]
    layout = eval(layout) if isinstance(layout, str) else layout  # noqa: S307  (the file's repr of a dict)
    ours = [(f"{f.group}/{f.name}", f.size) for f in T.TASKS[ENV_ID].obs_fields]
    assert ours == [(f["name"], f["stop"] - f["start"]) for f in layout["fields"]]
    assert T.TASKS[ENV_ID].obs_dim == layout["dim"] == 43
    assert T.TASKS[ENV_ID].max_episode_steps == header["max_episode_steps"] == 100


def test_each_seed_draws_the_recorded_geometry():
    """The peg's half sizes, the hole's half width and its centre in the box, for every demo's seed, as ManiSkill's
    ``_batched_episode_rng`` drew them (the recordings' ``episode_geometry``), whichever env holds the seed."""
    eps = _demos()["episodes"]
    params = T.TASKS[ENV_ID].draw_episode_params(np.array([e["seed"] for e in eps][::-1]))[::-1]
    for ep, p in zip(eps, params):
        g = ep["episode_geometry"]
        np.testing.assert_allclose(p[[P.LENGTH, P.RADIUS, P.RADIUS]], g["peg_half_size"], rtol=1e-6)
        assert p[P.HOLE_RADIUS] == pytest.approx(g["box_hole_radius"], rel=1e-6)
        np.testing.assert_allclose(p[[P.CENTER_Y, P.CENTER_Z]], g["box_hole_offset"][1:], rtol=1e-5, atol=1e-9)


def test_the_drawn_geometry_is_what_collides():
    """Two envs reconfigured to two seeds: MuJoCo-Warp's boxes of each world are that seed's peg and box with a hole,
    the peg's mass is its box's at density 1000; after steps the peg rests on the table at its own half width and the
    kinematic box has not moved. Reconfigured to two other seeds, all of it follows (the solver was told)."""
    env = T.make(ENV_ID, robot_uids=ROBOT, num_envs=2, control_mode="pd_joint_pos", physics=FAST, auto_reset=False)
    assert env.reconfiguration_freq == 0
    task, sc = T.TASKS[ENV_ID], env.scene
    for seeds in ([100, 102], [103, 104]):
        env.reset(seed=seeds, options={"reconfigure": True})
        params = task.draw_episode_params(np.array(seeds))
        np.testing.assert_allclose(env.episode_params, params)
        mjm = env.solver.mjw_model
        shape_of_geom = env.solver.mjc_geom_to_newton_shape.numpy()
        size, pos = mjm.geom_size.numpy(), mjm.geom_pos.numpy()
        for e in range(2):
            shapes = task.episode_shapes(params[e])
            for name in ("peg", "box_with_hole"):
                for s0, box in zip(sc.actor_shapes0[name], shapes[name]):
                    geom = int(np.nonzero(shape_of_geom[e] == s0 + e * sc.shapes_per_env)[0][0])
                    np.testing.assert_allclose(size[e, geom], box.half_size, rtol=1e-6)
                    np.testing.assert_allclose(pos[e, geom], box.offset, atol=1e-7)
            length, radius = params[e, P.LENGTH], params[e, P.RADIUS]
            mass = env.model.body_mass.numpy()[sc.actor_body0["peg"] + e * sc.bodies_per_env]
            assert mass == pytest.approx(1000 * 8 * length * radius**2, rel=1e-5)
        start = env.get_state_dict()["actors"]
        hold = torch.cat([env.get_state_dict()["articulations"][ROBOT][:, 13:20], torch.ones(2, 1)], dim=1)
        for _ in range(10):
            env.step(hold)
        end = env.get_state_dict()["actors"]
        np.testing.assert_allclose(end["peg"][:, 2].numpy(), params[:, P.RADIUS], atol=3e-4)
        torch.testing.assert_close(end["box_with_hole"], start["box_with_hole"], rtol=0, atol=0)
        assert (end["box_with_hole"][:, 7:] == 0).all()


def test_reconfiguration_follows_maniskills_frequency():
    """One env: every reset draws its scene from the reset's seed (``reconfiguration_freq`` 1, ManiSkill's default
    there); several envs: only ``options["reconfigure"]``; a partial reset cannot reconfigure; a bad frequency is
    refused naming it."""
    one = T.make(ENV_ID, robot_uids=ROBOT, num_envs=1, physics=FAST, auto_reset=False)
    assert one.reconfiguration_freq == 1
    task = T.TASKS[ENV_ID]
    for seed in (100, 7):
        one.reset(seed=seed)
        np.testing.assert_allclose(one.episode_params, task.draw_episode_params(np.array([seed])))
        obs = one.get_obs()[0].numpy()
        assert obs[32:35] == pytest.approx(one.episode_params[0, [P.LENGTH, P.RADIUS, P.RADIUS]], rel=1e-6)
    two = T.make(ENV_ID, robot_uids=ROBOT, num_envs=2, physics=FAST, auto_reset=False, seed=5)
    before = two.episode_params.copy()
    two.reset(seed=[100, 102])
    np.testing.assert_array_equal(two.episode_params, before)
    with pytest.raises(ConfigError, match="reconfigure.*partial reset"):
        two.reset(seed=[100, 102], options={"reconfigure": True, "env_idx": [0]})
    np.testing.assert_array_equal(two.episode_params, before)
    with pytest.raises(ConfigError, match="reconfiguration_freq"):
        T.make(ENV_ID, robot_uids=ROBOT, num_envs=1, reconfiguration_freq=-1)


def test_recorded_states_give_the_recorded_observation_and_the_rederived_rewards():
    """States along two demos (their initial state dicts with the recorded peg pose, qpos and qvel of every 10th step)
    loaded into Newton: the observation is ManiSkill's recorded one (within its 6 significant digits), success and
    the dense / normalized reward are the numpy re-derivation's with the grasp set either way (the fingers' contact
    forces written along / against their opening directions), and the recorded reward is the re-derivation's for
    one of the two grasps. The state dict comes back as loaded."""
    eps = _demos()["episodes"][:2]
    env = T.make(ENV_ID, robot_uids=ROBOT, num_envs=1, control_mode="pd_joint_pos", physics=FAST, auto_reset=False)
    checked = {"success": 0, "grasp-dependent": 0}
    for ep in eps:
        env.reset(seed=ep["seed"])
        g = ep["episode_geometry"]
        box7 = ep["init_state_dict"]["actors"]["box_with_hole"][:7]
        for k in list(range(0, len(ep["actions"]) + 1, 10)) + [len(ep["actions"])]:
            state = _state(ep, k)
            env.set_state_dict(state)
            obs = env.get_obs()[0].numpy()
            np.testing.assert_allclose(obs, ep["obs"][k], rtol=2e-5, atol=2e-5)
            back = env.get_state_dict()
            for group in ("actors", "articulations"):
                for name, v in state[group].items():
                    torch.testing.assert_close(back[group][name], v, rtol=0, atol=2e-7)
            peg7 = ep["actor_poses"]["peg"][k]
            rewards = {}
            for grasp in (False, True):
                axes = finger_axes(env)
                write_finger_forces(env, 2.0 * axes if grasp else -2.0 * axes)
                ev = env.evaluate()
                assert bool(ev["success"][0]) == ref_success(peg7, box7, g) == bool(ep["info"]["success"][k])
                rewards[grasp] = ref_dense(obs[18:21], peg7, box7, g, grasp)
                assert env.reward_dense.numpy()[0] == pytest.approx(rewards[grasp], abs=2e-5)
            if k == 0:  # reward_dense[t] is the reward of step t, the state after it (obs[t + 1])
                continue
            recorded = ep["reward_dense"][k - 1]
            assert min(abs(recorded - r) for r in rewards.values()) < 1e-4 * max(1.0, abs(recorded)), (k, rewards)
            checked["success"] += bool(ep["info"]["success"][k])
            checked["grasp-dependent"] += abs(rewards[True] - rewards[False]) > 1e-3
    assert checked["success"] >= 2 and checked["grasp-dependent"] >= 10, checked


@pytest.mark.parametrize("axis, edge", [(0, "depth"), (1, "radius"), (2, "-radius")])
def test_success_flips_at_the_edges_of_the_hole(axis, edge):
    """A demo's inserted peg moved (in the hole's frame) so that its head sits 0.5 mm inside, then 0.5 mm outside, an
    edge of ``has_peg_inserted``: 1.5 cm before the hole's centre along its axis, the hole's half width sideways."""
    ep = _demos()["episodes"][0]
    env = T.make(ENV_ID, robot_uids=ROBOT, num_envs=1, control_mode="pd_joint_pos", physics=FAST, auto_reset=False)
    env.reset(seed=ep["seed"])
    g = ep["episode_geometry"]
    box7 = ep["init_state_dict"]["actors"]["box_with_hole"][:7]
    k = len(ep["actions"])
    assert ep["info"]["success"][k]
    peg7 = np.asarray(ep["actor_poses"]["peg"][k], float)
    head = ref_head_in_hole(peg7, box7, g)
    limit = {"depth": -0.015, "radius": g["box_hole_radius"], "-radius": -g["box_hole_radius"]}[edge]
    inward = 1.0 if axis == 0 else -np.sign(limit)
    for offset, inside in ((0.0005, True), (-0.0005, False)):
        target = head.copy()
        target[axis] = limit + inward * offset
        moved = peg7.copy()
        moved[:3] += _rot(box7[3:]).apply(target - head)
        assert ref_success(moved, box7, g) == inside
        state = _state(ep, k)
        state["actors"]["peg"][0, :7] = torch.tensor(moved, dtype=torch.float32)
        env.set_state_dict(state)
        assert bool(env.evaluate()["success"][0]) == inside, (axis, offset)


@pytest.fixture(scope="module")
def demo_replay():
    """The public demos replayed once with the task's physics, for the tests that read the report."""
    return T.replay(DEMOS if DEMOS.is_file() else _demos())


def test_maniskills_motion_planning_demos_replay_to_insertion(demo_replay):
    """Every public demo (``pd_joint_pos``, 134-200 steps) open-loop from its state dict, one env each, each env
    reconfigured from its episode's seed, with the task's physics (``T.task_physics``): success at the end in >= 90 %
    of ManiSkill's successes and the peg's final position within 2 cm of PhysX's in the median."""
    report = demo_replay
    ok = [e.success_at_end for e in report.episodes if e.success_at_end_recorded]
    err = [e.cube_error[-1] for e in report.episodes]
    assert np.mean(ok) >= 0.9 and np.median(err) <= 0.02, (ok, np.round(err, 4).tolist())


def test_the_demos_carry_the_peg_in_the_grip_as_physx_does_and_insert_it(demo_replay):
    """With the task's physics the grip holds the peg as PhysX's does: up to the grasp the peg follows PhysX's within
    1 mm (measured 0.34 mm at most), carried to the box within 1.5 cm until the insertion, the plan's last 25 steps
    (measured 5.6-11.0 mm: the pyramidal cone lets it slide along its axis in the grip), and all four demos insert it,
    ending within 2 cm of PhysX's peg (measured 6.1-15.7 mm; the hole's clearance is 3 mm across the peg, not along
    it)."""
    report = demo_replay
    for ep, res in zip(_demos()["episodes"], report.episodes):
        grasp = next(k for k, a in enumerate(ep["actions"]) if a[7] < 0)
        err = np.asarray(res.cube_error)
        assert err[: grasp + 1].max() < 1e-3, (ep["seed"], err[: grasp + 1].max())
        carried = len(ep["actions"]) - 25  # the plan's last 25 steps push the peg into the hole
        assert err[:carried].max() < 1.5e-2, (ep["seed"], err[:carried].max())
    inserted = [e for e in report.episodes if e.success_at_end and e.success_at_end_recorded]
    assert len(inserted) == len(report.episodes), [e.success_at_end for e in report.episodes]
    assert max(e.cube_error[-1] for e in inserted) < 2e-2, [e.cube_error[-1] for e in inserted]


def test_the_common_defaults_let_the_peg_turn_in_the_grip_and_miss_the_hole():
    """Why the task departs from :class:`~wpctrl.tasks.TaskPhysics`'s defaults (``PegInsertionSide.physics``):
    without the fingers' torsional friction the carried peg creeps and turns in the grip, reaches the box 1.5-2.9 cm
    off and no demo inserts (measured 2026-11-29: 0 / 4, the peg 7.5-8.2 cm off at the end). The task's physics must
    stay what makes the difference: the common defaults keep at most one of the four and leave the peg over 3 cm off
    in the median."""
    report = T.replay(DEMOS if DEMOS.is_file() else _demos(), physics=T.TaskPhysics())
    ok = [e.success_at_end for e in report.episodes if e.success_at_end_recorded]
    err = [e.cube_error[-1] for e in report.episodes]
    assert sum(ok) <= 1 and np.median(err) > 0.03, (ok, np.round(err, 4).tolist())


def test_the_tasks_physics_is_its_declared_departures():
    """``make`` without ``physics`` builds the task's own (``T.task_physics``): the defaults with the task's fields,
    a change on top keeps them; the task's departures are the fingers' grip (torsional friction, contacts stiffer
    than the defaults', the pyramidal cone) and MuJoCo's own drive of the arm."""
    from wpctrl.tasks.peg_insertion_side import PHYSICS

    own = T.task_physics(ENV_ID)
    assert own == T.TaskPhysics(**PHYSICS) and own != T.TaskPhysics()
    assert own.finger_torsion > 0.0 and own.finger_solimp[0] > T.TaskPhysics().finger_solimp[0]
    assert own.cone == "pyramidal" != T.TaskPhysics().cone
    assert own.arm_drive == "mujoco" != T.TaskPhysics().arm_drive
    assert own == T.TaskPhysics(finger_torsion=own.finger_torsion, finger_solimp=own.finger_solimp, cone=own.cone,
                                arm_drive=own.arm_drive)  # fmt: skip
    assert T.task_physics(ENV_ID, substeps=8) == T.TaskPhysics(**PHYSICS, substeps=8)
    assert T.task_physics("PushCube-v1") == T.TaskPhysics()
    env = T.make(ENV_ID, robot_uids=ROBOT, num_envs=1, auto_reset=False)
    assert env.physics == own


# -- side by side with the real ManiSkill (slow) -------------------------------------------------------------------


@pytest.fixture(scope="module")
def maniskill():
    pytest.importorskip("mani_skill")
    from maniskill_tasks_side import make_maniskill

    return make_maniskill(ENV_ID, "pd_joint_pos", robot_uids=ROBOT, max_episode_steps=500)


def _reset(ms, seed: int):
    """ManiSkill's reset of one env rebuilds its scene (rendering stubbed out while it does)."""
    from wpctrl.tasks.maniskill_side import no_visuals

    with no_visuals():
        return ms.reset(seed=seed)


@pytest.mark.slow
def test_the_scene_is_maniskills(maniskill):
    """For three seeds, ManiSkill's live PhysX shapes (the peg's box, the four boxes of the hole, their local poses),
    the peg's mass and material, and its ``peg_half_sizes`` / ``box_hole_radii`` / ``box_hole_offsets``, against the
    module's draws and shapes; ManiSkill's constants in its source."""
    import inspect

    import gymnasium as gym
    import sapien
    from mani_skill.envs.tasks.tabletop.peg_insertion_side import PegInsertionSideEnv

    assert gym.spec(ENV_ID).max_episode_steps == T.TASKS[ENV_ID].max_episode_steps
    assert PegInsertionSideEnv._clearance == P.CLEARANCE
    load = inspect.getsource(PegInsertionSideEnv._load_scene)
    for text in ("uniform(0.085, 0.125)", "uniform(0.015, 0.025)", "uniform(-1, 1, size=(2,))"):
        assert text in load, text
    init = inspect.getsource(PegInsertionSideEnv._initialize_episode)
    for text in ("low=torch.tensor([-0.1, -0.3]), high=torch.tensor([0.1, 0])", "np.pi / 2 - np.pi / 3",
                 "low=torch.tensor([-0.05, 0.2])", "high=torch.tensor([0.05, 0.4])", "np.pi / 2 - np.pi / 8",
                 "-np.pi / 4", "normal(0, 0.02"):  # fmt: skip
        assert text in init, text
    reward = inspect.getsource(PegInsertionSideEnv.compute_dense_reward)
    assert "max_angle=20" in reward and "[-0.06, 0, 0]" in reward and "reward[info[\"success\"]] = 10" in reward
    base, task = maniskill.unwrapped, T.TASKS[ENV_ID]
    for seed in (0, 100, 12345):
        _reset(maniskill, seed)
        (params,) = task.draw_episode_params(np.array([seed]))
        np.testing.assert_allclose(base.peg_half_sizes[0].numpy(), params[[P.LENGTH, P.RADIUS, P.RADIUS]], rtol=1e-6)
        assert float(base.box_hole_radii[0]) == pytest.approx(params[P.HOLE_RADIUS], rel=1e-6)
        shapes = task.episode_shapes(params)
        peg = base.peg._objs[0].find_component_by_type(sapien.physx.PhysxRigidDynamicComponent)
        (pbox,) = peg.collision_shapes
        np.testing.assert_allclose(pbox.half_size, shapes["peg"][0].half_size, rtol=1e-6)
        assert peg.mass == pytest.approx(1000 * 8 * np.prod(shapes["peg"][0].half_size), rel=1e-5)
        assert pbox.physical_material.static_friction == pytest.approx(0.3)
        box = base.box._objs[0].find_component_by_type(sapien.physx.PhysxRigidBodyComponent)
        assert box.kinematic
        theirs = sorted((tuple(np.round(s.half_size, 6)), tuple(np.round(s.local_pose.p, 6)))
                        for s in box.collision_shapes)  # fmt: skip
        ours = sorted((tuple(np.round(b.half_size, 6)), tuple(np.round(b.offset, 6))) for b in shapes["box_with_hole"])
        np.testing.assert_allclose(np.array([t[0] + t[1] for t in theirs]), np.array([o[0] + o[1] for o in ours]),
                                   atol=2e-6)  # fmt: skip


@pytest.mark.slow
def test_same_state_gives_maniskills_obs_success_and_rewards(maniskill):
    """States along two demos in ManiSkill itself (it replays them bit for bit) loaded into Newton: the observation
    within 1e-5, success as ManiSkill's ``evaluate()``, dense and normalized reward as its ``compute_dense_reward``
    with the grasp set either way (ManiSkill: ``is_grasping`` patched to answer it)."""
    base = maniskill.unwrapped
    nw = T.make(ENV_ID, robot_uids=ROBOT, num_envs=1, control_mode="pd_joint_pos", physics=FAST, auto_reset=False)
    seen = {"success": 0, "pre_inserted": 0}
    for ep in _demos()["episodes"][:2]:
        _reset(maniskill, ep["seed"])
        nw.reset(seed=ep["seed"])
        base.set_state_dict({g: {k: torch.tensor([v]) for k, v in d.items()} for g, d in ep["init_state_dict"].items()})
        for k, action in enumerate(ep["actions"]):
            if k % 5 == 0 or k >= len(ep["actions"]) - 3:
                state = base.get_state_dict()
                nw.set_state_dict(state)
                info = base.evaluate()
                np.testing.assert_allclose(nw.get_obs()[0].numpy(), base.get_obs(info)[0].numpy(), atol=1e-5)
                for grasp in (False, True):
                    axes = finger_axes(nw)
                    write_finger_forces(nw, 2.0 * axes if grasp else -2.0 * axes)
                    ev = nw.evaluate()
                    assert bool(ev["success"][0]) == bool(info["success"][0])
                    original = base.agent.is_grasping
                    base.agent.is_grasping = lambda *a, _g=grasp, **kw: torch.tensor([_g])
                    try:
                        dense = base.compute_dense_reward(obs=None, action=None, info=info)[0].item()
                        normalized = base.compute_normalized_dense_reward(obs=None, action=None, info=info)[0].item()
                    finally:
                        base.agent.is_grasping = original
                    assert nw.reward_dense.numpy()[0] == pytest.approx(dense, abs=1e-5)
                    assert nw.reward_dense.numpy()[0] / 10.0 == pytest.approx(normalized, abs=1e-5)
                    seen["pre_inserted"] += grasp and 4.0 < dense < 10.0
                seen["success"] += bool(info["success"][0])
            maniskill.step(torch.tensor([action]))
    assert seen["success"] >= 2 and seen["pre_inserted"] >= 2, seen


@pytest.mark.slow
def test_reset_distribution_is_maniskills(maniskill):
    """25 seeded resets of ManiSkill (one env, its scene rebuilt each time) and 25 x 4 of Newton: the peg's and the
    box's xy and yaw from the same distributions (KS test), z at the drawn half width / half length, the arm's rest
    qpos with joint 7 at -pi/4 and the same noise."""

    def yaw(q):
        return 2 * np.arctan2(q[:, 3], q[:, 0])

    def draws(states):
        peg = np.concatenate([s["actors"]["peg"].numpy() for s in states])
        box = np.concatenate([s["actors"]["box_with_hole"].numpy() for s in states])
        arm = np.concatenate([s["articulations"][ROBOT][:, 13:20].numpy() for s in states])
        return peg, box, arm

    theirs = []
    for seed in range(25):
        _reset(maniskill, seed)
        theirs.append(maniskill.unwrapped.get_state_dict())
    env = T.make(ENV_ID, robot_uids=ROBOT, num_envs=4, physics=FAST, auto_reset=False)
    ours = []
    for seed in range(25):
        env.reset(seed=seed, options={"reconfigure": True})
        st = env.get_state_dict()
        np.testing.assert_allclose(st["actors"]["peg"][:, 2].numpy(), env.episode_params[:, P.RADIUS], rtol=1e-6)
        np.testing.assert_allclose(st["actors"]["box_with_hole"][:, 2].numpy(), env.episode_params[:, P.LENGTH],
                                   rtol=1e-6)  # fmt: skip
        ours.append(st)
    (tp, tb, ta), (op, ob, oa) = draws(theirs), draws(ours)
    for t, o in ((tp[:, 0], op[:, 0]), (tp[:, 1], op[:, 1]), (yaw(tp[:, 3:7]), yaw(op[:, 3:7])),
                 (tb[:, 0], ob[:, 0]), (tb[:, 1], ob[:, 1]), (yaw(tb[:, 3:7]), yaw(ob[:, 3:7]))):  # fmt: skip
        assert scipy_stats.ks_2samp(t, o).pvalue > 1e-3
    rest = np.asarray(P.REST_QPOS[:7])
    assert np.abs(ta.mean(0) - rest).max() < 0.02 and np.abs(oa.mean(0) - rest).max() < 0.01
    assert abs((ta - rest).std() - (oa - rest).std()) < 0.006
