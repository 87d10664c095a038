"""Observation entries a trained policy does not read (``wpctrl train --hide-obs``).

ManiSkill's flattened ``obs_mode="state"`` observation begins with the Panda's joint positions and velocities. In a
still grip PhysX reports the finger joints moving at 0.01-0.4 m/s while their positions stay put to 0.01 mm (its
solve leaves the drive's push against the contact in the velocities); Newton reports 0, the fingers' motion. A policy
trained on Newton that reads those velocities meets values in ManiSkill it never saw, exactly when it holds an object.
``finger_qvel`` (the default) hides them: the training env hands the policy and the critic zeros in their place, and
the exported policy zeroes them itself, so it takes ManiSkill's observation unchanged and its action does not depend
on them. The fingers' positions stay in view.
"""

from __future__ import annotations

__all__ = ["DEFAULT_HIDE_OBS", "HIDE_OBS", "hidden_columns"]

HIDE_OBS = ("finger_qvel", "none")
"""What ``--hide-obs`` takes: the Panda's two finger-joint velocities, or nothing."""
DEFAULT_HIDE_OBS = "finger_qvel"


def hidden_columns(task: str, hide: str) -> list[int]:
    """The columns of ``task``'s flattened observation that ``hide`` (one of :data:`HIDE_OBS`) hides."""
    if hide not in HIDE_OBS:
        raise ValueError(f"hide_obs: expected one of {list(HIDE_OBS)}, got {hide!r}")
    if hide == "none":
        return []
    from ..robots.panda_model import PANDA_GRIPPER_JOINTS, PANDA_JOINTS
    from ..tasks import TASKS

    qvel = TASKS[task].obs_slices()["agent"]["qvel"]
    return [qvel.start + PANDA_JOINTS.index(j) for j in PANDA_GRIPPER_JOINTS]
