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
    """Put (N, 2, 3) contact forces from contact actor ``column`` on the fingers into the sensor's matrix."""
    fm = env._sensor.force_matrix
    values = fm.numpy()
    values[:, column] = forces.reshape(2 * env.num_envs, 3)
    fm.assign(wp.array(values, dtype=wp.vec3, device=fm.device))
