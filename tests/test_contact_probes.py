"""The Panda's fingers on PickCube's cube, Newton beside the real ManiSkill 3.0.1 (PhysX CPU), driven the same way from
the same state (tests/contact_probes.py): a fingertip pressed down on the cube's face, edge and corner with a rising
force, a cube gripped, lifted and swung, a cube pushed at three heights.

Measured (2026-11-28, default TaskPhysics): pressed at 35-40 N a fingertip sits 1.0 / 1.4 / 1.2 mm (face / edge /
corner) deep in the cube on PhysX and 1.3 / 1.2 / 1.1 mm on Newton, within 0.35 mm at every force; with the fingers'
contacts as stiff as the others' (``finger_solimp=None``) Newton's sank 0.15-0.3 mm, 0.7-1.1 mm short. The press
tolerance, 0.45 mm, fails both that and the 2-3 mm corner sink a learned PushCube policy met. Where the tip reaches
1-3 mm onto a corner, PhysX's slides off it at 22 / 39 / 54 N (the dragged cube turns until the corner tip's normal
flips to the side face); Newton's stays on up to 85 N, creeping inward instead (a strict expected failure below).
The two finger joints set 20 mm apart close on the gripper's one target on both, but PhysX's fixed tendon
(ManiSkill's build of the URDF mimic) levels them within a control step and Newton's mimic equality leaves 11 mm
(another strict expected failure). The grasp flag counts the fingers' push on the cube, not
their friction, on both.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("mani_skill")
pytestmark = pytest.mark.slow  # the real ManiSkill side by side: `-m slow` (CI runs it)

from contact_probes import CUBE_AT, Probe  # noqa: E402

DEPTH_TOL = 0.45e-3
"""How far Newton's fingertip depth may be from PhysX's [m] (measured within 0.35 mm)."""


@pytest.fixture(scope="module")
def probe():
    return Probe()


@pytest.fixture(scope="module")
def presses(probe):
    return {where: probe.press(where) for where in ("face", "edge", "corner")}


def _on_top(out) -> list[tuple[dict, dict]]:
    """The steps where both fingertips press the cube (PhysX's force >= 10 N) and PhysX's has not slid off. Newton's
    ``force`` there is the median of its reading at the step and its two neighbours: PhysX reports the contact's
    impulse over its last 10 ms step, Newton's sensor the force of its last 0.6 ms MuJoCo step, and on an edge that
    one step's contact set flickers now and then (measured: 1.6 N for one step between 39 and 42 N, the tip's depth
    unchanged); on the ramp's straight line the median is the step's own value."""
    pairs = []
    news = out["newton"]
    for k, (px, nw) in enumerate(zip(out["physx"], news)):
        if px["reach"] <= 0.0:
            break
        if px["force"] >= 10.0:
            around = [news[j]["force"] for j in range(max(k - 1, 0), min(k + 2, len(news)))]
            pairs.append((px, dict(nw, force=float(np.median(around)))))
    return pairs


@pytest.mark.parametrize("where", ["face", "edge", "corner"])
def test_a_fingertip_pressed_on_the_cube_sinks_as_far_as_on_physx(presses, where):
    """At every force from 10 N up to PhysX's largest (35-40 N), Newton's fingertip sits as deep in the cube as
    PhysX's, within :data:`DEPTH_TOL`, under the same force (within 25 %), and both sink at least 0.7 mm at the top of
    the ramp: the finger contacts are as soft as PhysX's, where the other contacts' stiffness left 0.15-0.3 mm."""
    pairs = _on_top(presses[where])
    assert len(pairs) >= 15, len(pairs)
    for px, nw in pairs:
        assert abs(nw["depth"] - px["depth"]) <= DEPTH_TOL, (where, px["force"], px["depth"], nw["depth"])
        assert nw["force"] == pytest.approx(px["force"], rel=0.25, abs=3.0), (where, px["force"], nw["force"])
    px, nw = pairs[-1]
    assert min(px["depth"], nw["depth"]) >= 0.7e-3, (px["depth"], nw["depth"])


def test_the_pressed_cube_stays_flat_and_moves_with_the_finger_as_on_physx(presses):
    """Pressed on its face the cube tilts under 1 degree on both and is dragged the same way by the arm's give
    (within 3 mm of PhysX's at every step; measured up to 2.0 mm, across the direction of the give)."""
    for px, nw in zip(presses["face"]["physx"], presses["face"]["newton"]):
        assert px["tilt_deg"] < 1.0 and nw["tilt_deg"] < 1.0
        assert np.abs(nw["cube"] - px["cube"]).max() < 3e-3, (px["cube"], nw["cube"])


@pytest.mark.xfail(strict=True, reason=(
    "measured: with the tips 1 / 2 / 3 mm onto a corner PhysX's slide off at 22 / 39 / 54 N: they hold the cube, "
    "which turns ~4 degrees as they drag it, until the corner tip's depth passes its overlap across the side face and "
    "its contact normal turns to that face; Newton's stay on the top face up to 85 N, creeping 4-6 mm further onto it "
    "(MuJoCo's regularised friction lets a loaded contact slide slowly) while the cube turns half as much; no-slip "
    "(10 iterations) stops the creep but leaves only the 1 mm corner (at 34 N); impratio 100 leaves it at 50-57 N "
    "but breaks LiftPegUpright's demos"))  # fmt: skip
def test_target_a_fingertip_on_a_corner_slides_off_as_on_physx(probe):
    for overlap in (0.001, 0.002, 0.003):
        out = probe.press("corner", overlap=overlap, depth=0.045)
        off = [next((r["force"] for r, nxt in zip(side, side[1:]) if nxt["reach"] < 0), None)
               for side in (out["physx"], out["newton"])]
        assert off[0] is not None and off[1] is not None, (overlap, off)
        assert off[1] == pytest.approx(off[0], rel=0.3), (overlap, off)


def test_a_gripped_cube_stays_in_the_fingers_as_on_physx(probe):
    """Gripped, lifted 10 cm in four control steps, swung 10 cm sideways and back and held: the cube's place in
    the TCP's frame stays within 1 mm of PhysX's at every step after the grip (measured within 0.4 mm), and both
    simulators lift it (it ends 10 cm up)."""
    out = probe.hold()
    for px, nw in list(zip(out["physx"], out["newton"]))[9:]:
        assert np.abs(nw["cube_in_tcp"] - px["cube_in_tcp"]).max() < 1e-3, (px["cube_in_tcp"], nw["cube_in_tcp"])
    for side in ("physx", "newton"):
        assert out[side][-1]["cube"][2] > CUBE_AT[2] + 0.09, (side, out[side][-1]["cube"])


def test_the_grasp_flag_counts_the_push_and_not_the_friction_as_on_physx(probe):
    """``is_grasped`` on both simulators, step by step: fingertips closed over the cube's top face (their friction
    pushing them apart while they slide inward) are no grasp on PhysX, whose contact reports hold the normal
    impulses only, and none on Newton, whose grasp test takes the normal part of its contact force (with the friction
    in, measured: three flagged steps while the tips slide); a cube gripped and lifted is one on both."""
    top, held = probe.close_on_top(), probe.hold()
    for out in (top, held):
        flags = [[r["grasped"] for r in out[side]] for side in ("physx", "newton")]
        assert flags[0] == flags[1], flags
    assert not any(r["grasped"] for r in top["physx"])
    assert top["newton"][-1]["finger_q"].max() < 1e-3 < top["newton"][0]["finger_q"].min()  # they slid inward
    assert sum(r["grasped"] for r in held["physx"]) >= 20


@pytest.mark.parametrize("height", [0.005, 0.015, 0.025])
def test_a_cube_pushed_at_each_height_moves_as_on_physx(probe, height):
    """The closed fingertips pushed into the cube's side, their bottom 5 / 15 / 25 mm above the table: the cube ends
    within 3 mm of PhysX's and tilts under 2 degrees on both (measured within 0.1 mm; it slides 6 cm)."""
    out = probe.push(height)
    px, nw = out["physx"][-1], out["newton"][-1]
    assert px["cube"][0] - CUBE_AT[0] > 0.04, px["cube"]
    assert np.abs(nw["cube"] - px["cube"]).max() < 3e-3, (px["cube"], nw["cube"])
    assert px["tilt_deg"] < 2.0 and nw["tilt_deg"] < 2.0


@pytest.mark.xfail(strict=True, reason=(
    "measured: in a still grip PhysX reports the finger joints moving at 0.01-0.07 m/s (0.2-0.4 m/s under a learned "
    "PickCube policy's grip) while their positions stay put to 0.01 mm, the unresolved push of the drive against the "
    "contact left in the solver's velocities; Newton reports 0. A policy trained on Newton reads them: replacing "
    "ManiSkill's finger velocities by the fingers' motion over the control step lifts its ManiSkill success from "
    "66 % to 96 % (docs/training.md)"))  # fmt: skip
def test_target_a_still_grip_reports_the_finger_velocities_physx_reports(probe):
    out = probe.hold()
    physx, newton = out["physx"][-6:], out["newton"][-6:]
    for before, px, nw in zip(physx, physx[1:], newton[1:]):
        assert np.abs(px["finger_q"] - before["finger_q"]).max() < 1e-4  # PhysX's fingers are still
        assert np.abs(nw["finger_qd"] - px["finger_qd"]).max() < 0.02, (px["finger_qd"], nw["finger_qd"])


def _fingers_levelling(env_id: str = "PushCube-v1", steps: int = 3) -> dict:
    """The two finger joints set 20 mm apart (30 and 10 mm open), the arm held where it is and the gripper's target
    20 mm, on both simulators from the same state dict: each joint's opening [m] after every control step."""
    import torch

    import wpctrl.tasks as T
    from wpctrl.tasks.maniskill_side import make_maniskill

    ms = make_maniskill(env_id, "pd_joint_pos")
    ms.reset(seed=0)
    state = ms.unwrapped.get_state_dict()
    name = next(iter(state["articulations"]))
    robot = state["articulations"][name].clone()
    robot[0, 20], robot[0, 21] = 0.030, 0.010  # qpos columns 13..21: the fingers last
    state["articulations"][name] = robot
    ms.unwrapped.set_state_dict(state)
    action = torch.cat([robot[0, 13:20], torch.tensor([0.2])])[None].float()  # gripper: -1..1 -> -0.01..0.04 m
    physx = []
    for _ in range(steps):
        ms.step(action)
        physx.append(ms.unwrapped.agent.robot.get_qpos()[0, 7:9].numpy().copy())
    env = T.make(env_id, num_envs=1, control_mode="pd_joint_pos", auto_reset=False)
    env.reset(seed=0)
    env.set_state_dict({"actors": {k: v.clone() for k, v in state["actors"].items()},
                        "articulations": {"panda": robot.clone()}})  # fmt: skip
    newton = []
    for _ in range(steps):
        env.step(action)
        newton.append(env.get_state_dict()["articulations"]["panda"][0, 20:22].numpy().copy())
    return {"physx": np.array(physx), "newton": np.array(newton)}


@pytest.fixture(scope="module")
def levelling():
    return _fingers_levelling()


def test_the_fingers_close_on_their_common_target_on_both(levelling):
    """Both simulators take the two finger joints to the gripper's one target (20 mm): their mean opening is within
    0.3 mm of it after the first control step on both, and the joints' gap shrinks at every step."""
    for sim, q in levelling.items():
        assert abs(q[0].mean() - 0.020) <= 3e-4, (sim, q[0])
        gap = np.abs(q[:, 0] - q[:, 1])
        assert np.all(np.diff(gap) <= 1e-6), (sim, gap)
    assert abs(levelling["physx"][0, 0] - levelling["physx"][0, 1]) <= 5e-5, levelling["physx"][0]


@pytest.mark.xfail(strict=True, reason=(
    "measured 2026-11-29: ManiSkill builds the fingers' URDF mimic as a PhysX fixed tendon of stiffness 1e5 N/m, which "
    "levels the joints within one control step (0.0 mm of the 20 mm left); Newton's mimic is a MuJoCo joint equality "
    "at MuJoCo's default 20 ms, which leaves 11.2 mm after one step and 5.0 after two. A stiffer equality (1.25 ms) "
    "levels them as PhysX does but replays the pushes further off, so it is not the default (docs/tasks.md)"
))  # fmt: skip
def test_target_the_fingers_level_with_each_other_within_a_step_as_on_physx(levelling):
    gap = np.abs(levelling["newton"][0, 0] - levelling["newton"][0, 1])
    assert gap <= 5e-4, levelling["newton"][0]
