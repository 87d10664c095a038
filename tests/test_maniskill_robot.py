"""The robot ``wpctrl.maniskill.load_robot(uid)`` builds, against the one the real ManiSkill 3.0.1 builds (PhysX CPU,
``render_backend="none"``), for every agent whose assets ship in the mani-skill wheel: the active joints in ManiSkill's
order; every link's world pose at the agent's keyframe (qpos and root pose: Newton's FK of the builder's initial
state vs PhysX's link poses after ManiSkill sets the same keyframe); per-link friction / restitution from the agent's
``urdf_config``; which link pairs never collide (the SRDF's excluded pairs, parent-child links,
``disable_self_collisions``)."""

from __future__ import annotations

import itertools

import newton
import numpy as np
import pytest

pytest.importorskip("mani_skill", reason="the maniskill extra (mani-skill) is not installed")  # a dev dependency
pytestmark = [pytest.mark.filterwarnings("ignore"), pytest.mark.slow]  # the real ManiSkill side by side

from maniskill_side import AGENTS, ManiSkillSide  # noqa: E402

from wpctrl.maniskill import control_modes, load_robot  # noqa: E402

SCENE_DEFAULT_FRICTION = np.float32(0.3)  # ManiSkill's scene-wide default material, not part of the robot
# collision bits an agent's own code sets on the built robot (Fetch's _after_init: wheels 30, base 31, which its scenes
# pair with the floor); load_robot builds no scene and does not run that code
# and the G1 upper body's fingers / torso (bits 1-3) in its _after_init
G1_UPPER_BITS = (1 << 1) | (1 << 2) | (1 << 3)
RUNTIME_BITS = {
    "fetch": (1 << 30) | (1 << 31),
    "unitree_g1_simplified_upper_body": G1_UPPER_BITS,
    "unitree_g1_simplified_upper_body_right_arm": G1_UPPER_BITS,
    "unitree_g1_simplified_upper_body_with_head_camera": G1_UPPER_BITS,
}


def _maniskill_robot(uid, robot):
    """ManiSkill's robot at ``robot``'s keyframe: active joints, link world poses ``[x, y, z, qw, qx, qy, qz]``, and
    {link: (static friction, restitution, collision group 2 bits, parent link)} for links with collision shapes."""
    import sapien

    ms = ManiSkillSide(uid, next(iter(control_modes(uid))))
    try:
        kf = robot.keyframes.get(robot.keyframe) if robot.keyframe else None
        if kf is not None:
            q = np.array([kf.qpos[n] for n in ms.joint_names], np.float32)
            ms.put(q, np.zeros_like(q))
            if kf.pose is not None:
                ms.robot.set_pose(sapien.Pose(kf.pose[:3], kf.pose[3:]))
        else:
            ms.put(np.zeros(len(ms.joint_names), np.float32), np.zeros(len(ms.joint_names), np.float32))
            ms.robot.set_pose(sapien.Pose())
        poses = {link.name: link.pose.raw_pose.cpu().numpy()[0].astype(np.float64) for link in ms.robot.links}
        links = {}
        for link in ms.robot.links:
            comp = link._objs[0]
            shapes = comp.collision_shapes
            if not shapes:
                continue
            mats = {(s.physical_material.static_friction, s.physical_material.restitution) for s in shapes}
            groups = {int(s.get_collision_groups()[2]) & ~RUNTIME_BITS.get(uid, 0) for s in shapes}
            assert len(mats) == 1 and len(groups) == 1, f"{uid} {link.name}: shapes differ within the link"
            parent = comp.parent.entity.name if comp.parent is not None else None
            links[link.name] = (*mats.pop(), groups.pop(), parent)
        return list(ms.joint_names), poses, links
    finally:
        ms.close()


def _newton_links(builder):
    """{link: [collision shape indices]} and the set of filtered shape pairs of a Newton builder."""
    collide = int(newton.ShapeFlags.COLLIDE_SHAPES)
    names = [label.rsplit("/", 1)[-1] for label in builder.body_label]
    shapes: dict[str, list[int]] = {}
    for s, b in enumerate(builder.shape_body):
        if b >= 0 and int(builder.shape_flags[s]) & collide:
            shapes.setdefault(names[b], []).append(s)
    return shapes, set(builder.shape_collision_filter_pairs)


@pytest.mark.parametrize("uid", AGENTS)
def test_robot_matches_maniskill(uid):
    robot = load_robot(uid)
    joint_names, poses, theirs = _maniskill_robot(uid, robot)
    assert robot.joint_names == joint_names, "active joints in ManiSkill's order"
    # one robot, nothing else (ManiSkill's agent is the articulation alone: no floor from an MJCF)
    assert robot.builder.articulation_count == 1
    assert min(robot.builder.shape_body) >= 0, "a static shape in the robot's builder"

    # the keyframe: every link ManiSkill and Newton both have (ManiSkill's MJCF loader adds dummy links) in place
    model = robot.builder.finalize(device="cpu")
    state = model.state()
    newton.eval_fk(model, model.joint_q, model.joint_qd, state)
    body_q = state.body_q.numpy().astype(np.float64)
    common = 0
    for i, label in enumerate(model.body_label):
        name = label.rsplit("/", 1)[-1]
        if name not in poses:
            continue
        common += 1
        want, got = poses[name], body_q[i]
        quat = got[[6, 3, 4, 5]]  # Newton's xyzw -> wxyz
        assert np.abs(got[:3] - want[:3]).max() < 1e-5, f"{name}: position {got[:3]} vs ManiSkill's {want[:3]}"
        dq = min(np.abs(quat - want[3:]).max(), np.abs(quat + want[3:]).max())
        assert dq < 1e-5, f"{name}: orientation {quat} vs ManiSkill's {want[3:]}"
    assert common >= len(joint_names) // 2

    shapes, filtered = _newton_links(robot.builder)
    assert set(shapes) == set(theirs), "links with collision shapes"
    default_mu = newton.ModelBuilder.ShapeConfig().mu
    for link, (mu, rest, _, _) in theirs.items():
        ours_mu = {np.float32(robot.builder.shape_material_mu[s]) for s in shapes[link]}
        ours_rest = {np.float32(robot.builder.shape_material_restitution[s]) for s in shapes[link]}
        if np.float32(mu) != SCENE_DEFAULT_FRICTION:  # set by the agent's urdf_config: static friction
            assert ours_mu == {np.float32(mu)}, f"{link}: friction {ours_mu} vs ManiSkill's {mu}"
        else:
            assert ours_mu <= {SCENE_DEFAULT_FRICTION, np.float32(default_mu)}, f"{link}: friction {ours_mu}"
        assert ours_rest == {np.float32(rest)}, f"{link}: restitution {ours_rest} vs ManiSkill's {rest}"
    for a, b in itertools.combinations(sorted(theirs), 2):
        _, _, ga, pa = theirs[a]
        _, _, gb, pb = theirs[b]
        # PhysX (SAPIEN's filter): articulation parent-child links never collide; shapes sharing a bit of
        # collision group 2 neither (SRDF pairs, disable_self_collisions)
        want = pa == b or pb == a or (ga & gb) != 0
        got = all((min(x, y), max(x, y)) in filtered for x in shapes[a] for y in shapes[b])
        assert got == want, f"{uid}: links {a} / {b} filtered: ours {got}, ManiSkill {want}"
