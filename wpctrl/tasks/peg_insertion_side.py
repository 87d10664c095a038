"""PegInsertionSide-v1 (``mani_skill/envs/tasks/tabletop/peg_insertion_side.py``, ``PegInsertionSideEnv``): pick up a
peg lying on the table and push its head sideways into the hole of a box.

Scene, drawn per env from its episode seed (``_load_scene`` with ``_batched_episode_rng``: one
``np.random.RandomState(seed)`` per env, in this order): the peg's half length l ~ U[0.085, 0.125] and half width
r ~ U[0.015, 0.025], then the hole's centre in the box, ``0.5 (l - r) U[-1, 1]^2`` along the box's y and z. The peg is
one box of half sizes (l, r, r) (density 1000, the scene's default material; its two colours are visual only). The
box with the hole is kinematic: four boxes around a square hole of half width r + 3 mm (``_build_box_with_hole``:
inner radius r + clearance, outer radius and depth l), its x axis the hole's direction. ManiSkill draws the scene again
on every reset of a single env (``reconfiguration_freq`` 1), never with more; ``make(reconfiguration_freq=)`` and
``reset(options={"reconfigure": True})`` do the same here (:mod:`wpctrl.tasks.geometry`).

Episode: the peg flat on the table (z = r) at xy ~ U([-0.1, -0.3], [0.1, 0]) with a yaw in pi/2 +- pi/3; the box on the
table (z = l) at xy ~ U([-0.05, 0.2], [0.05, 0.4]) with a yaw in pi/2 +- pi/8; the Panda at its rest qpos with joint 7
at -pi/4 (not the table scene's +pi/4) plus N(0, 0.02). Success: the peg's head (``peg.pose * (l, 0, 0)``) in the
hole's frame at x >= -0.015 and |y|, |z| <= the hole's half width. Dense reward (max 10): reach the peg's tail, grasp it
(``is_grasping(max_angle=20)``), line it up with the hole, insert it.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from .definitions import Actor, Box, ObsField
from .funcs import (
    Sim,
    actor_pos,
    actor_pose7,
    actor_quat,
    is_grasping_within,
    param,
    pose7,
    set_actor_pose,
    tcp_pos,
    tcp_pose7,
    vec1,
    vec7,
    yaw_quat,
)
from .registry import Task, register_task

__all__ = ["PegInsertionSide", "box_with_hole"]

LENGTH_RANGE = (0.085, 0.125)
"""``_load_scene``: ``lengths = self._batched_episode_rng.uniform(0.085, 0.125)``, the peg's half length [m]."""
RADIUS_RANGE = (0.015, 0.025)
"""``radii = self._batched_episode_rng.uniform(0.015, 0.025)``, the peg's half width [m]."""
CLEARANCE = 0.003
"""``PegInsertionSideEnv._clearance`` [m]: the hole's half width is the peg's plus this."""
PEG_DENSITY = 1000.0
"""``builder.add_box_collision(half_size=[length, radius, radius])`` with SAPIEN's default density [kg/m^3]."""
PEG_REGION = ((-0.1, -0.3), (0.1, 0.0))
"""``_initialize_episode``: the peg's ``xy = randomization.uniform(low=[-0.1, -0.3], high=[0.1, 0])`` [m]."""
PEG_YAW = (math.pi / 2 - math.pi / 3, math.pi / 2 + math.pi / 3)
"""``random_quaternions(b, lock_x=True, lock_y=True, bounds=(np.pi / 2 - np.pi / 3, np.pi / 2 + np.pi / 3))``."""
BOX_REGION = ((-0.05, 0.2), (0.05, 0.4))
"""The box's ``xy = randomization.uniform(low=[-0.05, 0.2], high=[0.05, 0.4])`` [m]."""
BOX_YAW = (math.pi / 2 - math.pi / 8, math.pi / 2 + math.pi / 8)
REST_QPOS = (0.0, math.pi / 8, 0.0, -math.pi * 5 / 8, 0.0, math.pi * 3 / 4, -math.pi / 4, 0.04, 0.04)
"""``_initialize_episode``'s own qpos (joint 7 at -pi/4), before ``_episode_rng.normal(0, 0.02)``."""
INSERTED_X = -0.015
"""``has_peg_inserted``: ``x_flag = -0.015 <= peg_head_pos_at_hole[:, 0]`` [m]."""
GRASP_MAX_ANGLE = 20.0
"""``compute_dense_reward``: ``self.agent.is_grasping(self.peg, max_angle=20)`` [deg]."""
TAIL_OFFSET = -0.06
"""``compute_dense_reward``: the grasp target ``peg.pose * sapien.Pose([-0.06, 0, 0])`` [m]."""
PRE_INSERTED = 0.01
"""``pre_inserted = (peg_head_wrt_goal_yz_dist < 0.01) & (peg_wrt_goal_yz_dist < 0.01)`` [m]."""
MAX_REWARD = 10.0
"""``reward[info["success"]] = 10``; ``compute_normalized_dense_reward``: ``/ 10``."""
PEG, BOX = 0, 1
"""The actors' indices (the peg is also contact column 0)."""
LENGTH, RADIUS, HOLE_RADIUS, CENTER_Y, CENTER_Z = 0, 1, 2, 3, 4
"""The episode parameters' columns (:attr:`PegInsertionSide.episode_params`)."""
_GRASP_COS = math.cos(math.radians(GRASP_MAX_ANGLE))
PHYSICS = {"finger_torsion": 0.2, "finger_solimp": (0.95, 0.95, 0.001), "cone": "pyramidal", "arm_drive": "mujoco"}
"""The task's departures from :class:`~wpctrl.tasks.TaskPhysics`'s defaults: the fingers' grip on the carried peg.

- ``finger_torsion``: torsional friction on the fingers, so the carried peg stays in the grip as on PhysX. ManiSkill's
  finger material (``patch_radius`` / ``min_patch_radius`` 0.1 m) gives every finger contact PhysX's torsional patch
  friction, which resists a twist about the contact normal; MuJoCo's condim-3 contacts have none. Without it the peg,
  held 6 cm off its centre under a 0.16 N m moment, turns 34 degrees in the fingers over a carry where PhysX's turns
  0.1 degrees, and reaches the box 1.5-2.9 cm off, five to ten times the hole's clearance. ``finger_torsion`` gives the
  finger shapes MuJoCo's condim 4 with this coefficient. From 0.2 m the grip holds in every demo; 0.115-0.16 m (about
  the pair's friction, 1.15, times the 0.1 m radius) do not reliably, MuJoCo's elliptic cone sharing one bound between
  sliding and twisting, of which the held peg's weight takes part.
- ``finger_solimp``: finger contacts stiffer than the defaults' 0.7 (which sink a pressed fingertip as far as PhysX's,
  :class:`~wpctrl.tasks.TaskPhysics`). With the softer contacts in the grip, insertions PhysX made miss
  the hole's 3 mm clearance: of 26 motion-planned demos recorded in ManiSkill
  (``bench/tasks/record_demos.py``, ``tests/data/validation``) 13 insert at 0.7, 21 at 0.9, 22 at 0.95 (the peg within
  0.19 cm of PhysX's in the median), 23 with the contacts as stiff as the other shapes' (1.6 cm off: the peg then
  slides along its axis in the grip).
- ``cone``: MuJoCo's pyramidal friction cone instead of the elliptic one. Under the elliptic cone (impratio 10) the
  carried peg turns in the grip about the hand's approach axis as the arm yaws it toward the box (48 mrad on seed
  222, 22 on seed 205; PhysX's within 1 mrad) and does not droop about the closing axis (within 1 mrad; PhysX's 6-9);
  under the pyramidal cone 2-5 mrad and 2-5 mrad. With it 24 of the 26 demos and all four public ones insert, the peg
  about 1 cm from PhysX's at the end (it slides further into the hole).
- ``arm_drive``: MuJoCo's own drive of the arm rather than PhysX's TGS pass. The grip above was chosen with it; with
  the TGS pass 17 of the 26 demos insert instead of 24 (the peg 1.2 cm from PhysX's in the median).

The defaults suit the other tasks (LiftPegUpright's demos need its peg to turn in the fingers), so these are the
task's alone (``docs/tasks.md``)."""


def box_with_hole(inner: float, outer: float, depth: float, center: tuple[float, float]) -> tuple[Box, ...]:
    """``_build_box_with_hole``'s four collision boxes (x: the hole's direction): half sizes and offsets."""
    thickness = (outer - inner) * 0.5
    hc = (0.5 * center[0], 0.5 * center[1])
    offset = thickness + inner
    return (
        Box((depth, thickness - hc[0], outer), (0.0, offset + hc[0], 0.0)),
        Box((depth, thickness + hc[0], outer), (0.0, -offset + hc[0], 0.0)),
        Box((depth, outer, thickness - hc[1]), (0.0, 0.0, offset + hc[1])),
        Box((depth, outer, thickness + hc[1]), (0.0, 0.0, -offset + hc[1])),
    )


_MID_L, _MID_R = 0.5 * sum(LENGTH_RANGE), 0.5 * sum(RADIUS_RANGE)  # the shapes the worlds are built with


_PEG_LOW, _PEG_SPAN = wp.constant(wp.vec2(*PEG_REGION[0])), wp.constant(wp.vec2(*np.subtract(*PEG_REGION[::-1])))
_BOX_LOW, _BOX_SPAN = wp.constant(wp.vec2(*BOX_REGION[0])), wp.constant(wp.vec2(*np.subtract(*BOX_REGION[::-1])))
_PEG_YAW0, _PEG_YAW_SPAN = PEG_YAW[0], PEG_YAW[1] - PEG_YAW[0]
_BOX_YAW0, _BOX_YAW_SPAN = BOX_YAW[0], BOX_YAW[1] - BOX_YAW[0]


@wp.func
def peg_insertion_initialize(s: Sim, e: int, rng: wp.uint32):
    # every draw here (a @wp.func gets a copy of rng): randomization.uniform = rand * (high - low) + low, and
    # random_quaternions' yaw, uniform in its bounds (w = cos(yaw / 2) > 0 on these ranges, as ManiSkill's)
    px = wp.randf(rng) * _PEG_SPAN[0] + _PEG_LOW[0]
    py = wp.randf(rng) * _PEG_SPAN[1] + _PEG_LOW[1]
    peg_yaw = wp.randf(rng) * _PEG_YAW_SPAN + _PEG_YAW0
    bx = wp.randf(rng) * _BOX_SPAN[0] + _BOX_LOW[0]
    by = wp.randf(rng) * _BOX_SPAN[1] + _BOX_LOW[1]
    box_yaw = wp.randf(rng) * _BOX_YAW_SPAN + _BOX_YAW0
    set_actor_pose(s, e, PEG, wp.vec3(px, py, param(s, e, RADIUS)), yaw_quat(peg_yaw))
    set_actor_pose(s, e, BOX, wp.vec3(bx, by, param(s, e, LENGTH)), yaw_quat(box_yaw))


@wp.func
def hole_pos(s: Sim, e: int) -> wp.vec3:
    """``box.pose * box_hole_offsets``: the hole's centre (its frame turns with the box)."""
    return actor_pos(s, e, BOX) + wp.quat_rotate(actor_quat(s, e, BOX),
                                                 wp.vec3(0.0, param(s, e, CENTER_Y), param(s, e, CENTER_Z)))


@wp.func
def peg_point(s: Sim, e: int, x: float) -> wp.vec3:
    """``peg.pose * Pose([x, 0, 0])``'s position: a point on the peg's axis."""
    return actor_pos(s, e, PEG) + wp.quat_rotate(actor_quat(s, e, PEG), wp.vec3(x, 0.0, 0.0))


@wp.func
def head_in_hole(s: Sim, e: int) -> wp.vec3:
    """``(box_hole_pose.inv() * peg_head_pose).p``: the peg's head in the hole's frame."""
    return wp.quat_rotate_inv(actor_quat(s, e, BOX), peg_point(s, e, param(s, e, LENGTH)) - hole_pos(s, e))


@wp.func
def peg_insertion_evaluate(s: Sim, e: int):
    h = head_in_hole(s, e)
    r = param(s, e, HOLE_RADIUS)
    s.info[e, 0] = h[0] >= INSERTED_X and wp.abs(h[1]) <= r and wp.abs(h[2]) <= r


@wp.func
def _yz(v: wp.vec3) -> float:
    return wp.sqrt(v[1] * v[1] + v[2] * v[2])


@wp.func
def peg_insertion_dense_reward(s: Sim, e: int) -> float:
    reward = 1.0 - wp.tanh(4.0 * wp.length(tcp_pos(s, e) - peg_point(s, e, TAIL_OFFSET)))
    grasped = is_grasping_within(s, e, PEG, wp.static(_GRASP_COS))
    if grasped:
        reward = reward + 1.0
        # the goal pose: box * hole offset * peg head offset^-1 (the box's orientation; its origin one length back)
        box_q = actor_quat(s, e, BOX)
        goal = hole_pos(s, e) - wp.quat_rotate(box_q, wp.vec3(param(s, e, LENGTH), 0.0, 0.0))
        head = _yz(wp.quat_rotate_inv(box_q, peg_point(s, e, param(s, e, LENGTH)) - goal))
        centre = _yz(wp.quat_rotate_inv(box_q, actor_pos(s, e, PEG) - goal))
        reward = reward + 3.0 * (1.0 - wp.tanh(0.5 * (head + centre) + 4.5 * wp.max(head, centre)))
        if head < PRE_INSERTED and centre < PRE_INSERTED:
            reward = reward + 5.0 * (1.0 - wp.tanh(5.0 * wp.length(head_in_hole(s, e))))
    return reward


@wp.func
def obs_peg_pose(s: Sim, e: int) -> vec7:
    return actor_pose7(s, e, PEG)


@wp.func
def obs_peg_half_size(s: Sim, e: int) -> wp.vec3:
    return wp.vec3(param(s, e, LENGTH), param(s, e, RADIUS), param(s, e, RADIUS))


@wp.func
def obs_box_hole_pose(s: Sim, e: int) -> vec7:
    return pose7(hole_pos(s, e), actor_quat(s, e, BOX))


@wp.func
def obs_box_hole_radius(s: Sim, e: int) -> vec1:
    return vec1(param(s, e, HOLE_RADIUS))


@register_task("PegInsertionSide-v1", max_episode_steps=100)
class PegInsertionSide(Task):
    robot_uids = "panda_wristcam"  # __init__(robot_uids="panda_wristcam"): the Panda with its wrist camera
    clearance = CLEARANCE
    actors = (
        Actor("peg", (Box((_MID_L, _MID_R, _MID_R)),), PEG_DENSITY, None, _MID_R),
        Actor("box_with_hole", box_with_hole(_MID_R + CLEARANCE, _MID_L, _MID_L, (0.0, 0.0)), build_height=_MID_L,
              kinematic=True),  # fmt: skip
    )
    contact_actors = ("peg",)
    obs_extra = (
        ObsField("extra", "tcp_pose", 7, tcp_pose7),
        ObsField("extra", "peg_pose", 7, obs_peg_pose),
        ObsField("extra", "peg_half_size", 3, obs_peg_half_size),
        ObsField("extra", "box_hole_pose", 7, obs_box_hole_pose),
        ObsField("extra", "box_hole_radius", 1, obs_box_hole_radius),
    )
    max_reward = MAX_REWARD
    rest_qpos = REST_QPOS
    initialize = peg_insertion_initialize
    evaluate = peg_insertion_evaluate
    dense_reward = peg_insertion_dense_reward
    episode_params = ("length", "radius", "hole_radius", "center_y", "center_z")
    physics = PHYSICS

    def draw_episode_params(self, seeds: np.ndarray) -> np.ndarray:
        out = np.zeros((len(seeds), len(self.episode_params)))
        for i, seed in enumerate(seeds):
            rng = np.random.RandomState(int(seed))  # BatchedRNG: env i's own stream, drawn in _load_scene's order
            length = rng.uniform(*LENGTH_RANGE)
            radius = rng.uniform(*RADIUS_RANGE)
            center = 0.5 * (length - radius) * rng.uniform(-1, 1, size=(2,))
            out[i] = (length, radius, radius + CLEARANCE, center[0], center[1])
        return out

    def episode_shapes(self, params: np.ndarray) -> dict[str, tuple[Box, ...]]:
        length, radius, hole, cy, cz = (float(v) for v in params)
        return {"peg": (Box((length, radius, radius)),), "box_with_hole": box_with_hole(hole, length, length, (cy, cz))}

    def reconfiguration_freq(self, num_envs: int) -> int:
        return 1 if num_envs == 1 else 0  # PegInsertionSideEnv.__init__'s default
