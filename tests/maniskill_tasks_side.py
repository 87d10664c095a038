"""The real ManiSkill 3.0.1 side of the task tests: ``PushCube-v1`` / ``PickCube-v1`` on PhysX CPU
(``render_backend="none"``, one env), built while ManiSkill's visual side is stubbed out: no render materials or
textures, no visual shapes (the actor builders' ``add_*_visual*`` calls and the URDF loader's link visuals are
skipped), since they need a rendering device. Physics, collision shapes, materials, controllers, observations,
rewards and evaluation are stock.
"""

from __future__ import annotations

from wpctrl.tasks.maniskill_side import make_maniskill, no_visuals

__all__ = ["make_maniskill", "no_visuals", "record_episode", "state_dict_lists"]


def state_dict_lists(state: dict) -> dict:
    """A ManiSkill state dict (torch, batch 1) as the recordings store it (plain lists, no batch)."""
    return {g: {k: v[0].tolist() for k, v in d.items()} for g, d in state.items() if g in ("actors", "articulations")}


def record_episode(env, policy, seed: int, steps: int = 50) -> dict:
    """One episode of ``policy`` (a function of the flattened observation) on the real ManiSkill env, in the format
    of ManiSkill's recordings that :func:`wpctrl.tasks.replay` reads."""
    obs, info = env.reset(seed=seed)
    base = env.unwrapped
    ep = {"seed": seed, "init_state_dict": state_dict_lists(base.get_state_dict()), "actions": [],
          "info": {"success": [bool(info["success"][0])]}, "cube_pose": [], "obs": [obs[0].tolist()]}  # fmt: skip
    cube = base.obj if hasattr(base, "obj") else base.cube
    ep["cube_pose"].append(cube.pose.raw_pose[0].tolist())
    if "is_grasped" in info:
        ep["info"]["is_grasped"] = [bool(info["is_grasped"][0])]
    for _ in range(steps):
        action = policy(obs)
        obs, _, _, _, info = env.step(action)
        ep["actions"].append(action[0].tolist())
        ep["obs"].append(obs[0].tolist())
        ep["info"]["success"].append(bool(info["success"][0]))
        if "is_grasped" in info:
            ep["info"]["is_grasped"].append(bool(info["is_grasped"][0]))
        ep["cube_pose"].append(cube.pose.raw_pose[0].tolist())
    ep["success_at_end"] = ep["info"]["success"][-1]
    return ep
