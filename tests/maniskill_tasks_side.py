"""The real ManiSkill 3.0.1 side of the task tests: ``PushCube-v1`` / ``PickCube-v1`` on PhysX CPU
(``render_backend="none"``, one env), built while ManiSkill's visual side is stubbed out: no render materials or
textures, no visual shapes (the actor builders' ``add_*_visual*`` calls and the URDF loader's link visuals are
skipped), since they need a rendering device. Physics, collision shapes, materials, controllers, observations,
rewards and evaluation are stock.
"""

from __future__ import annotations

from wpctrl.tasks.maniskill_side import make_maniskill, no_visuals

__all__ = ["IKFeasible", "make_maniskill", "no_visuals", "record_episode", "replay_shifted", "state_dict_lists"]


def state_dict_lists(state: dict) -> dict:
    """A ManiSkill state dict (torch, batch 1) as the recordings store it (plain lists, no batch)."""
    return {g: {k: v[0].tolist() for k, v in d.items()} for g, d in state.items() if g in ("actors", "articulations")}


class IKFeasible:
    """The recordings' guard on ``pd_ee_delta_pos`` actions: where ManiSkill's IK would fail for the TCP step (the
    controller then holds the arm where it is, and the outcome hangs on the IK solver's failure behaviour), the step
    is halved and checked again, at most 6 times, else the arm's action is 0. The check repeats what ManiSkill's
    ``PDEEPosController.set_action`` does on the CPU (target = ``Pose(p=0.1 * a) * ee_pose_at_base``, pinocchio IK
    seeded with the current qpos) with a ``Kinematics`` of its own, so the controller is not touched."""

    def __init__(self, env):
        from mani_skill.agents.controllers.utils.kinematics import Kinematics

        arm = env.unwrapped.agent.controller.controllers["arm"]
        self.arm = arm
        self.kinematics = Kinematics(arm.config.urdf_path, arm.config.ee_link, arm.articulation,
                                     arm.active_joint_indices)  # fmt: skip

    def __call__(self, action):
        import torch
        from mani_skill.utils.structs.pose import Pose

        action = action.clone()
        arm = self.arm
        q0 = arm.articulation.get_qpos()
        step = action[:, :3].clamp(-1.0, 1.0)
        for _ in range(7):
            target = Pose.create_from_pq(p=0.1 * step) * arm.ee_pose_at_base
            if self.kinematics.compute_ik(target, q0) is not None:
                action[:, :3] = step
                return action
            step = step * 0.5
        action[:, :3] = torch.zeros_like(step)
        return action


def record_episode(env, policy, seed: int, steps: int = 50) -> dict:
    """One episode of ``policy`` (a function of the flattened observation) on the real ManiSkill env, in the format
    of ManiSkill's recordings that :func:`wpctrl.tasks.replay` reads. In ``pd_ee_delta_pos`` the actions pass
    :class:`IKFeasible` first, as in ManiSkill's recordings (their ``header.policy``)."""
    obs, info = env.reset(seed=seed)
    base = env.unwrapped
    guard = IKFeasible(env) if base.control_mode == "pd_ee_delta_pos" else None
    ep = {"seed": seed, "init_state_dict": state_dict_lists(base.get_state_dict()), "actions": [],
          "info": {"success": [bool(info["success"][0])]}, "cube_pose": [], "obs": [obs[0].tolist()]}  # fmt: skip
    cube = base.obj if hasattr(base, "obj") else base.cube
    ep["cube_pose"].append(cube.pose.raw_pose[0].tolist())
    if "is_grasped" in info:
        ep["info"]["is_grasped"] = [bool(info["is_grasped"][0])]
    for _ in range(steps):
        action = policy(obs)
        if guard is not None:
            action = guard(action)
        obs, _, _, _, info = env.step(action)
        ep["actions"].append(action[0].tolist())
        ep["obs"].append(obs[0].tolist())
        ep["info"]["success"].append(bool(info["success"][0]))
        if "is_grasped" in info:
            ep["info"]["is_grasped"].append(bool(info["is_grasped"][0]))
        ep["cube_pose"].append(cube.pose.raw_pose[0].tolist())
    ep["success_at_end"] = ep["info"]["success"][-1]
    return ep


def replay_shifted(env, episode: dict, shift) -> list:
    """ManiSkill replaying its own recorded ``episode`` open-loop from the recorded initial state with the cube moved
    by ``shift`` (x, y metres) on the table: the cube's final position. Its distance from the recorded one is
    PhysX's own sensitivity to a start that differs by that much (its noise floor for a replay's cube error)."""
    import torch

    base = env.unwrapped
    env.reset(seed=episode["seed"])
    state = base.get_state_dict()
    for group in ("actors", "articulations"):
        for name, value in episode["init_state_dict"][group].items():
            state[group][name] = torch.tensor([value])
    state["actors"]["cube"][0, :2] += torch.tensor(shift, dtype=torch.float32)
    base.set_state_dict(state)
    for action in episode["actions"]:
        env.step(torch.tensor([action]))
    cube = base.obj if hasattr(base, "obj") else base.cube
    return cube.pose.raw_pose[0, :3].tolist()
