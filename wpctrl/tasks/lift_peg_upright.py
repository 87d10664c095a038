"""LiftPegUpright-v1 (``mani_skill/envs/tasks/tabletop/lift_peg_upright.py``, ``LiftPegUprightEnv``): stand a peg
that lies on the table upright.

Scene: the peg of ``actors.build_twocolor_peg`` (``mani_skill/utils/building/actors/common.py``): one box collision
shape of half sizes (0.12, 0.025, 0.025) along its x axis, density 1000 (0.6 kg), the scene's default material; its
two colours are two visual boxes only, so on Newton it is one box. Episode: the peg lying along x at
xy ~ U[-0.1, 0.1]^2, z = half width, turned +90 degrees about its own axis (``euler2quat(pi/2, 0, 0)``; no yaw).
Success: the peg upright (``| |euler_XYZ(q)[2]| - pi/2 | < 0.08``, the angles as ManiSkill's
``rotation_conversions.matrix_to_euler_angles``) and its centre within 5 mm of 0.12 m. Dense reward (max 3): how
vertical the peg's axis is, its centre's height to 0.12 m, and a fifth of reaching (1 while grasped).

Physics: ManiSkill's demos turn the peg in the half-closed fingers (gripper action -0.6). With the default
:class:`~wpctrl.tasks.TaskPhysics` (elliptic cone, impratio 10) the fingers resist that twist with ~0.56 N m where
PhysX gives way at ~0.33 N m; ``TaskPhysics(cone="pyramidal", impratio=1.0)`` resists ~0.30 N m and replays the demos
(``tests/test_task_lift_peg_upright.py``). The pyramidal cone is not the default: its sliding friction depends on the
direction (PhysX's does not), and it doubles the pushed cube's replay error on PushCube (``docs/tasks.md``,
"LiftPegUpright-v1").
"""

from __future__ import annotations

import math

import warp as wp

from .definitions import Actor, Box, ObsField
from .funcs import Sim, actor_pos, actor_quat, is_grasping, obj_pose, set_actor_pose, tcp_pos, tcp_pose7
from .registry import Task, register_task

__all__ = ["LiftPegUpright", "peg_matrix_entries"]

PEG_HALF_LENGTH = 0.12
"""``LiftPegUprightEnv.peg_half_length`` [m]: the box's half size along the peg's x axis (``build_twocolor_peg``'s
``length``), and the success height of its centre."""
PEG_HALF_WIDTH = 0.025
"""``LiftPegUprightEnv.peg_half_width`` [m]: the box's half size along y and z (``width``), the height it lies at."""
PEG_DENSITY = 1000.0
"""``build_twocolor_peg`` -> ``ActorBuilder.build`` with SAPIEN's default collision density [kg/m^3]."""
SPAWN_HALF = 0.1
"""``_initialize_episode``: ``xyz[..., :2] = torch.rand((b, 2)) * 0.2 - 0.1`` [m]."""
LIE_DOWN_QUAT = (math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0)
"""``_initialize_episode``: ``q = euler2quat(np.pi / 2, 0, 0)`` (wxyz), a quarter turn about the peg's own x axis."""
_LIE_W, _LIE_X = LIE_DOWN_QUAT[0], LIE_DOWN_QUAT[1]
UPRIGHT_TOL = 0.08
"""``evaluate``: ``torch.abs(torch.abs(euler[:, 2]) - np.pi / 2) < 0.08`` [rad]."""
HEIGHT_TOL = 0.005
"""``evaluate``: ``torch.abs(self.peg.pose.p[:, 2] - self.peg_half_length) < 0.005`` [m]."""
MAX_REWARD = 3.0
"""``compute_dense_reward``: ``reward[info["success"]] = 3``; ``compute_normalized_dense_reward``: ``/ 3``."""
PEG = 0
"""The peg's actor index (and contact column)."""


@wp.func
def peg_matrix_entries(q: wp.quat) -> wp.vec3:
    """``m[0, 0]``, ``m[0, 1]``, ``m[2, 0]`` of ``rotation_conversions.quaternion_to_matrix`` (which divides by
    ``|q|^2``) of the peg's quaternion (Warp's xyzw)."""
    i, j, k, r = q[0], q[1], q[2], q[3]
    two_s = 2.0 / (r * r + i * i + j * j + k * k)
    return wp.vec3(1.0 - two_s * (j * j + k * k), two_s * (i * j - k * r), two_s * (i * k - j * r))


@wp.func
def lift_peg_initialize(s: Sim, e: int, rng: wp.uint32):
    x = wp.randf(rng) * 0.2 - SPAWN_HALF
    y = wp.randf(rng) * 0.2 - SPAWN_HALF
    set_actor_pose(s, e, PEG, wp.vec3(x, y, PEG_HALF_WIDTH), wp.quat(_LIE_X, 0.0, 0.0, _LIE_W))


@wp.func
def lift_peg_evaluate(s: Sim, e: int):
    m = peg_matrix_entries(actor_quat(s, e, PEG))
    # matrix_to_euler_angles(m, "XYZ")[2] = _angle_from_tan("Z", "Y", m[0, :], True, True) = atan2(-m[0, 1], m[0, 0])
    euler_z = wp.atan2(-m[1], m[0])
    upright = wp.abs(wp.abs(euler_z) - wp.pi / 2.0) < UPRIGHT_TOL
    close_to_table = wp.abs(actor_pos(s, e, PEG)[2] - PEG_HALF_LENGTH) < HEIGHT_TOL
    s.info[e, 0] = upright and close_to_table


@wp.func
def lift_peg_dense_reward(s: Sim, e: int) -> float:
    p = actor_pos(s, e, PEG)
    # rotation: |(R @ [1, 0, 0]) . [0, 0, 1]|, the peg's axis against the vertical (either end up)
    r = wp.abs(peg_matrix_entries(actor_quat(s, e, PEG))[2])
    r = r + 1.0 - wp.tanh(5.0 * wp.abs(p[2] - PEG_HALF_LENGTH))
    reach = 1.0 - wp.tanh(5.0 * wp.length(p - tcp_pos(s, e)))
    if is_grasping(s, e, PEG):
        reach = 1.0
    return r + reach / 5.0


@register_task("LiftPegUpright-v1", max_episode_steps=50)
class LiftPegUpright(Task):
    peg_half_length = PEG_HALF_LENGTH
    peg_half_width = PEG_HALF_WIDTH
    actors = (
        # name, collision shapes, density, static friction (None: the scene default), build height
        Actor("peg", (Box((PEG_HALF_LENGTH, PEG_HALF_WIDTH, PEG_HALF_WIDTH)),), PEG_DENSITY, None, PEG_HALF_WIDTH),
    )
    contact_actors = ("peg",)
    obs_extra = (
        ObsField("extra", "tcp_pose", 7, tcp_pose7),
        ObsField("extra", "obj_pose", 7, obj_pose),
    )
    max_reward = MAX_REWARD
    initialize = lift_peg_initialize
    evaluate = lift_peg_evaluate
    dense_reward = lift_peg_dense_reward
