"""Mutations: ManiSkill robots."""

from .model import M

MUTATIONS = [
    M(
        "load_robot_root_pose_ignored",
        "wpctrl/maniskill/__init__.py",
        "pose = root_pose if root_pose is not None else (kf.pose if kf else None)",
        "pose = kf.pose if kf else None",
        "load_robot ignores root_pose",
        ("tests/test_maniskill_options.py",),
    ),
    M(
        "load_robot_keyframe_always_first",
        "wpctrl/maniskill/__init__.py",
        'chosen = (next(iter(keyframes), None) if keyframe == "default" else keyframe) if keyframes else None',
        "chosen = next(iter(keyframes), None) if keyframes else None",
        "load_robot starts at the first keyframe whatever keyframe= names (None included)",
        ("tests/test_maniskill_options.py",),
    ),
    M(
        "load_robot_collapse_ignored",
        "wpctrl/maniskill/__init__.py",
        "collapse_fixed_joints=collapse_fixed_joints, **importer_kwargs,",
        "collapse_fixed_joints=False, **importer_kwargs,",
        "load_robot ignores collapse_fixed_joints",
        ("tests/test_maniskill_options.py",),
    ),
    M(
        "load_robot_keyframe_qpos_dropped",
        "wpctrl/maniskill/__init__.py",
        "missing = set_joint_positions(builder, kf.qpos)",
        "missing = []",
        "load_robot leaves the joints at zero instead of the keyframe's qpos",
        ("tests/test_maniskill_options.py",),
    ),
    M(
        "load_robot_floating_pose_dropped",
        "wpctrl/maniskill/__init__.py",
        "    if not fix_root and pose is not None:\n        set_root_pose(builder, pose)\n",
        "",
        "a floating robot's root stays at the origin instead of the keyframe's (or the given) pose",
        ("tests/test_maniskill_options.py",),
    ),
    M(
        "load_robot_self_collisions_on",
        "wpctrl/maniskill/__init__.py",
        'not bool(getattr(cls, "disable_self_collisions", False)))',
        "True)",
        "load_robot ignores the agent's disable_self_collisions",
        ("tests/test_maniskill_robot.py",),
    ),
]
