"""The real ManiSkill 3.0.1 side of the differential tests: an ``Empty-v1`` env with one agent on PhysX CPU
(``render_backend="none"``), its controller driven directly (``agent.set_action`` / ``agent.before_simulation_step``,
no physics step), and the drive targets read back from PhysX.

Robots whose assets carry visual materials (fetch, G1, so100, koch, TriFinger, the MJCF humanoid) cannot load
without a rendering device; while such an env is built, ManiSkill's URDF loader builds links without visuals and its
MJCF loader loads no visual bodies (and never makes a render material), as the conformance traces' README describes.
Physics, collision shapes, inertials, joints and the controllers are stock.
"""

from __future__ import annotations

import warnings

import numpy as np

from wpctrl.tasks.maniskill_side import no_visual_loaders

# every agent whose assets ship in the mani-skill 3.0.1 wheel
AGENTS = [
    "panda", "panda_wristcam", "panda_stick", "floating_panda_gripper", "fetch", "allegro_hand_right", "dclaw",
    "floating_ability_hand_right", "fixed_inspire_hand_right", "floating_inspire_hand_right", "xarm7_ability",
    "so100", "koch-v1.1", "trifingerpro", "unitree_g1_simplified_legs", "unitree_g1",
    "unitree_g1_simplified_upper_body", "humanoid", "allegro_hand_left", "allegro_hand_right_touch",
    "fixed_inspire_hand_left", "floating_inspire_hand_left", "unitree_g1_simplified_upper_body_right_arm",
    "unitree_g1_simplified_upper_body_with_head_camera",
]  # fmt: skip


# stock modes ManiSkill itself cannot run, and why
CANNOT_RUN = {
    ("fetch", "pd_ee_delta_pose_align"): "frame 'ee_align' is not implemented in ManiSkill (UnboundLocalError)",
    ("panda_stick", "pd_ee_delta_pose_align"): "frame 'ee_align' is not implemented in ManiSkill",
    ("floating_panda_gripper", "pd_ee_pose"): "pos_lower=None gives NaN action bounds that gymnasium's Box rejects",
    ("floating_panda_gripper", "pd_ee_pose_quat"): "pos_lower=None gives NaN action bounds that gymnasium rejects",
    ("fetch", "pd_joint_pos_vel"): "normalising over infinite joint limits: ManiSkill's targets are NaN",
}


class ManiSkillSide:
    """One agent of the real ManiSkill, its controller for ``mode``, and read-outs of what it commands."""

    def __init__(self, uid, mode: str):
        """``uid``: a registered agent uid or an agent class."""
        import gymnasium as gym
        import mani_skill.envs  # noqa: F401  (registers Empty-v1)

        with warnings.catch_warnings(), no_visual_loaders():
            warnings.simplefilter("ignore")
            self.env = gym.make(
                "Empty-v1",
                robot_uids=uid,
                control_mode=mode,
                sim_backend="physx_cpu",
                render_backend="none",
                num_envs=1,
                obs_mode="state",
            )
            self.env.reset(seed=0)
        self.agent = self.env.unwrapped.agent
        self.robot = self.agent.robot
        self.controller = self.agent.controller
        self.joint_names = [j.name for j in self.robot.active_joints]
        self.processed: dict[str, np.ndarray] = {}
        subs = getattr(self.controller, "controllers", {"__single__": self.controller})
        for name, ctrl in subs.items():
            self._record(name, ctrl)

    def _record(self, name, ctrl) -> None:
        original = ctrl._preprocess_action

        def preprocess(action, _orig=original, _name=name):
            out = _orig(action)
            self.processed[_name] = np.asarray(out.detach().cpu().numpy() if hasattr(out, "detach") else out)
            return out

        ctrl._preprocess_action = preprocess

    @property
    def qlimits(self) -> np.ndarray:
        return self.robot.get_qlimits().cpu().numpy()[0]

    def put(self, qpos, qvel) -> None:
        import torch

        self.robot.set_qpos(torch.as_tensor(np.asarray(qpos, np.float32))[None])
        self.robot.set_qvel(torch.as_tensor(np.asarray(qvel, np.float32))[None])

    def set_action(self, action) -> None:
        import torch

        self.processed.clear()
        self.agent.set_action(torch.as_tensor(np.asarray(action, np.float32))[None])

    def substep(self) -> None:
        self.agent.before_simulation_step()

    def drive_targets(self) -> tuple[np.ndarray, np.ndarray]:
        return (
            self.robot.get_drive_targets().cpu().numpy()[0].astype(np.float64),
            self.robot.get_drive_velocities().cpu().numpy()[0].astype(np.float64),
        )

    def close(self) -> None:
        self.env.close()
