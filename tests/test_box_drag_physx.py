"""A cube pressed down on its top edge and dragged along the table, PhysX (SAPIEN, ManiSkill's scene settings) beside
Newton (PickCube-v1's physics), with no robot: the contact behind the last PushCube policy episodes that part.

A learned PushCube policy presses a fingertip on the cube's top back corner and drags it. On PhysX the cube then
turns under the tip until the tip's contact normal flips to the side face and the tip slides off; on Newton it turns
about half as much and the tip stays on (docs/tasks.md, "How a loaded tip leaves a corner"). This file holds the
turn alone: 40 N down and a drag just over the friction limit (12.8 N along +x), both applied at one point on the
cube's trailing top edge, centred or 12 mm off centre. The load is set as a force and a torque about the cube's centre
once per control step (50 ms, two in all), from the point's place at that moment: on Newton through the env's
``set_external_wrench``, on PhysX the same wrench at each of its 10 ms steps.

Measured (2026-11-30, CPU): centred, neither cube turns (PhysX 0.14 degrees, Newton 0.0 in 100 ms). Off centre,
PhysX's turns 0.38 degrees per millimetre slid and Newton's 0.23 (28.4 degrees over 75 mm against 4.9 over 22 mm).
With the load point followed every 10 ms instead, 0.41 and 0.20. The turn per distance is compared, not the distance:
with the drag 0.6 N over the limit the slide is sensitive to the effective friction, which is within 5 % on both
(centred, PhysX's cube slides 68 mm in 100 ms, Newton's 26 mm). PhysX's turn is not its unconverged solve: at 100
position iterations it is the same (0.41 degrees per millimetre, the load followed every 10 ms), and without PCM 0.64.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("mani_skill")
pytestmark = pytest.mark.slow  # PhysX beside Newton: `-m slow` (CI runs it)

HALF = 0.02
"""PickCube's cube half size [m]."""
DOWN, DRAG = 40.0, 12.8
"""The load [N], pressed down and dragged along +x, at a point on the cube's trailing top edge."""
STEPS = 2
"""Control steps of 50 ms (five 10 ms physics steps each), 100 ms in all; the load is set again at each."""


def _yaw_deg(q_xyzw) -> float:
    from scipy.spatial.transform import Rotation

    return float(Rotation.from_quat(q_xyzw).as_euler("xyz", degrees=True)[2])


def _wrench(p, q_xyzw, offset: float) -> tuple[np.ndarray, np.ndarray]:
    """The load as (force, torque about the cube's centre), world frame, for the cube's pose (p, q)."""
    from scipy.spatial.transform import Rotation

    force = np.array([DRAG, 0.0, -DOWN])
    return force, np.cross(Rotation.from_quat(q_xyzw).apply([-HALF, offset, HALF]), force)


def physx_drag(offset: float) -> tuple[float, float]:
    """(distance slid along x [m], yaw [deg]) after :data:`STEPS` control steps on PhysX, ManiSkill's scene settings."""
    import sapien
    from mani_skill.utils.structs.types import DefaultMaterialsConfig, SceneConfig
    from sapien import physx

    sc = SceneConfig()
    physx.set_shape_config(contact_offset=sc.contact_offset, rest_offset=sc.rest_offset)
    physx.set_body_config(solver_position_iterations=sc.solver_position_iterations,
                          solver_velocity_iterations=sc.solver_velocity_iterations,
                          sleep_threshold=sc.sleep_threshold)  # fmt: skip
    physx.set_scene_config(gravity=np.asarray(sc.gravity), bounce_threshold=sc.bounce_threshold,
                           enable_pcm=sc.enable_pcm, enable_tgs=sc.enable_tgs, enable_ccd=sc.enable_ccd,
                           enable_enhanced_determinism=sc.enable_enhanced_determinism,
                           enable_friction_every_iteration=sc.enable_friction_every_iteration)  # fmt: skip
    physx.set_default_material(**DefaultMaterialsConfig().dict())
    scene = sapien.Scene([physx.PhysxCpuSystem()])
    scene.set_timestep(0.01)
    b = scene.create_actor_builder()
    b.add_box_collision(half_size=[0.6, 0.6, 0.1])
    b.build_static(name="table").set_pose(sapien.Pose([0.0, 0.0, -0.1]))
    b = scene.create_actor_builder()
    b.add_box_collision(half_size=[HALF] * 3, density=1000.0)
    cube = b.build(name="cube")
    cube.set_pose(sapien.Pose([0.0, 0.0, HALF]))
    body = cube.find_component_by_type(physx.PhysxRigidDynamicComponent)
    for _ in range(20):  # settle on the table
        scene.step()
    x0 = float(cube.pose.p[0])
    for _ in range(STEPS):
        w, x, y, z = cube.pose.q
        force, torque = _wrench(cube.pose.p, [x, y, z, w], offset)
        for _ in range(5):  # PhysX clears an added force after each step
            body.add_force_torque(force, torque)
            scene.step()
    w, x, y, z = cube.pose.q
    return float(cube.pose.p[0]) - x0, _yaw_deg([x, y, z, w])


def newton_drag(offset: float) -> tuple[float, float]:
    """The same on Newton: PickCube-v1's scene and physics (the Panda held at rest, far from the cube), the load set
    with ``set_external_wrench`` before each step."""
    import torch

    import wpctrl.tasks as T

    env = T.make("PickCube-v1", num_envs=1, control_mode="pd_joint_delta_pos")
    env.reset(seed=0)
    state = env.get_state_dict()
    state["actors"]["cube"][0] = torch.tensor([0.05, 0.0, HALF, 1.0, 0, 0, 0, 0, 0, 0, 0, 0, 0])
    env.set_state_dict({g: dict(d) for g, d in state.items() if g in ("actors", "articulations")})
    for _ in range(4):  # settle on the table
        env.step(torch.zeros(1, 8))

    def cube():
        c = env.get_state_dict()["actors"]["cube"][0].numpy()
        return c[:3], [*c[4:7], c[3]]  # p, q xyzw

    x0 = float(cube()[0][0])
    for _ in range(STEPS):
        force, torque = _wrench(*cube(), offset)
        env.set_external_wrench("cube", force=force, torque=torque)
        env.step(torch.zeros(1, 8))
    p, q = cube()
    return float(p[0]) - x0, _yaw_deg(q)


@pytest.fixture(scope="module")
def drags():
    return {(side, off): f(off) for side, f in (("physx", physx_drag), ("newton", newton_drag)) for off in (0.0, 0.012)}


def test_a_cube_loaded_on_its_centre_line_slides_without_turning_on_both(drags):
    """Both cubes slide forward (over 1 cm in 100 ms; measured 68 / 26 mm) and turn under half a degree (measured
    0.14 / 0.0)."""
    for side in ("physx", "newton"):
        dist, yaw = drags[(side, 0.0)]
        assert dist > 0.01 and abs(yaw) < 0.5, (side, dist, yaw)


def test_a_cube_loaded_off_centre_turns_the_same_way_on_both(drags):
    """Loaded 12 mm off centre (+y), both cubes turn clockwise seen from above, by more than 2 degrees in 100 ms."""
    for side in ("physx", "newton"):
        dist, yaw = drags[(side, 0.012)]
        assert yaw < -2.0, (side, dist, yaw)


@pytest.mark.xfail(strict=True, reason=(
    "measured: PhysX's cube turns 0.38 degrees per millimetre slid, Newton's 0.23; likely PhysX's friction bounded "
    "per contact patch rather than at every contact point by its own load, as MuJoCo's is (SAPIEN cannot switch it)"
))  # fmt: skip
def test_target_a_cube_loaded_off_centre_turns_as_far_per_distance_as_on_physx(drags):
    per_mm = {side: drags[(side, 0.012)][1] / (drags[(side, 0.012)][0] * 1e3) for side in ("physx", "newton")}
    assert per_mm["newton"] == pytest.approx(per_mm["physx"], rel=0.3), per_mm
