"""Newton-side helpers of the task tests: the fingers' opening directions and contact forces written into the contact
sensor's matrix (to set ``is_grasping`` either way on a state loaded from ManiSkill)."""

from __future__ import annotations

import numpy as np
import warp as wp


def finger_axes(env) -> np.ndarray:
    """(N, 2, 3) the fingers' opening directions: +y of the left finger, -y of the right one (world frame)."""
    from scipy.spatial.transform import Rotation

    sc = env.scene
    body_q = env.state.body_q.numpy().reshape(env.num_envs, sc.bodies_per_env, 7)
    out = np.zeros((env.num_envs, 2, 3))
    for f, sign in ((0, 1.0), (1, -1.0)):
        out[:, f] = sign * Rotation.from_quat(body_q[:, sc.finger_bodies0[f], 3:7]).apply([0.0, 1.0, 0.0])
    return out


def write_finger_forces(env, forces: np.ndarray, column: int = 0) -> None:
    """Put (N, 2, 3) contact forces from contact actor ``column`` on the fingers into the sensor's matrix, all of them
    normal force (no friction part)."""
    fm = env._sensor.force_matrix
    values = fm.numpy()
    values[:, column] = forces.reshape(2 * env.num_envs, 3)
    fm.assign(wp.array(values, dtype=wp.vec3, device=fm.device))
    env._sensor.force_matrix_friction.zero_()  # all of it normal force, as PhysX reports it


def ref_is_grasping(forces: np.ndarray, directions: np.ndarray, max_angle: float = 85.0) -> np.ndarray:
    """ManiSkill's ``Panda.is_grasping`` re-derived in numpy: per finger ``||f|| >= 0.5`` N and the angle between its
    opening direction and ``f`` at most ``max_angle`` degrees; both fingers. ``forces``, ``directions``: (N, 2, 3)."""
    norm = np.linalg.norm(forces, axis=-1)
    cos = np.einsum("nfk,nfk->nf", forces, directions) / np.maximum(norm * np.linalg.norm(directions, axis=-1), 1e-12)
    return ((norm >= 0.5) & (np.degrees(np.arccos(np.clip(cos, -1, 1))) <= max_angle)).all(axis=1)


def grasp_forces(axes: np.ndarray, grasp: bool, off_cone_env: int = 3) -> np.ndarray:
    """(N, 2, 3) finger contact forces for the flag tests: 2 N along each finger's opening direction where ``grasp``
    (env ``off_cone_env``'s left finger turned 86 degrees off it, just outside ``is_grasping``'s 85-degree cone), else
    none."""
    import math

    if not grasp:
        return np.zeros_like(axes)
    forces = 2.0 * axes
    side = np.cross(axes[off_cone_env, 0], [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    rad = math.radians(86.0)
    forces[off_cone_env, 0] = 2.0 * (math.cos(rad) * axes[off_cone_env, 0] + math.sin(rad) * side)
    return forces


def maniskill_demo_states(ms, episodes: list, every: int) -> list:
    """The real ManiSkill env ``ms``'s state dicts along recorded demos (it replays them bit for bit from their initial
    state dicts): every ``every``-th step, the last three and the end."""
    import torch

    base = ms.unwrapped
    out = []
    for ep in episodes:
        ms.reset(seed=ep["seed"])
        base.set_state_dict({g: {k: torch.tensor([v]) for k, v in d.items()} for g, d in ep["init_state_dict"].items()})
        for k, action in enumerate(ep["actions"]):
            if k % every == 0 or k >= len(ep["actions"]) - 3:
                out.append(base.get_state_dict())
            ms.step(torch.tensor([action]))
        out.append(base.get_state_dict())
    return out


def check_same_state_flags_and_rewards(ms, nw, states: list, flags: tuple[str, str, str], max_reward: float) -> dict:
    """Each of ManiSkill's ``states`` loaded into the real env ``ms`` and the Newton env ``nw`` (one env), for a task
    whose success is ``placed and static and not grasped`` (``flags``: the grasped, placed and static names). With the
    grasp set either way (ManiSkill: in the info it is given; Newton: the fingers' contact forces written along /
    against their opening directions): the flags and success as ManiSkill's ``evaluate()`` gives them, the dense and
    normalized reward as its ``compute_dense_reward`` within 1e-5, and, where the grasp is ManiSkill's own, the
    observation within 1e-5. Then the state dict round trip. Returns how many states were placed and how many checks
    succeeded."""
    import pytest
    import torch

    grasped, placed, static = flags
    base = ms.unwrapped
    seen = {"on": 0, "success": 0}
    for state in states:
        base.set_state_dict(state)
        info = base.evaluate()
        obs = base.get_obs(info)[0].numpy()
        nw.set_state_dict(state)
        axes = finger_axes(nw)
        for grasp in (False, True):
            write_finger_forces(nw, 2.0 * axes if grasp else -2.0 * axes)
            ev = nw.evaluate()
            theirs = dict(info)
            theirs[grasped] = torch.tensor([grasp])
            theirs["success"] = info[placed] & info[static] & ~theirs[grasped]
            for k in ("success", grasped, placed, static):
                assert bool(ev[k][0]) == bool(theirs[k][0]), k
            dense = base.compute_dense_reward(obs=None, action=None, info=theirs)[0].item()
            normalized = base.compute_normalized_dense_reward(obs=None, action=None, info=theirs)[0].item()
            assert nw.reward_dense.numpy()[0] == pytest.approx(dense, abs=1e-5)
            assert nw.reward_dense.numpy()[0] / max_reward == pytest.approx(normalized, abs=1e-5)
            if grasp == bool(info[grasped][0]):
                np.testing.assert_allclose(nw.get_obs()[0].numpy(), obs, atol=1e-5)
            seen["success"] += bool(ev["success"][0])
        seen["on"] += bool(info[placed][0])
        back = nw.get_state_dict()
        for group in ("actors", "articulations"):
            for k, v in state[group].items():
                torch.testing.assert_close(back[group][k], v, rtol=0, atol=2e-7)
    return seen
