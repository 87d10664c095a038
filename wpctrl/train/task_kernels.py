"""Warp kernels of the reach task: observations, reward and episode bookkeeping, and the partial reset of done envs.

One thread per env. Everything the task needs per step runs here on the device (no host sync inside a step), so the
whole environment step can be captured in one CUDA graph.
"""

from __future__ import annotations

import warp as wp

wp.set_module_options({"enable_backward": False})


@wp.func
def _tcp(body_q: wp.array[wp.transform], body: int, offset: wp.transform):
    return wp.transform_get_translation(body_q[body] * offset)


@wp.func
def _write_obs(
    e: int,
    dofs_per_env: int,
    coords_per_env: int,
    p: wp.vec3,
    g: wp.vec3,
    joint_q: wp.array[float],
    joint_qd: wp.array[float],
    obs: wp.array2d[float],
):
    for i in range(dofs_per_env):
        obs[e, i] = joint_q[e * coords_per_env + i]
        obs[e, dofs_per_env + i] = joint_qd[e * dofs_per_env + i]
    for k in range(3):
        obs[e, 2 * dofs_per_env + k] = p[k]
        obs[e, 2 * dofs_per_env + 3 + k] = g[k] - p[k]


@wp.kernel
def obs_kernel(
    dofs_per_env: int,
    coords_per_env: int,
    bodies_per_env: int,
    tcp_body: int,
    tcp_offset: wp.transform,
    env_origin: wp.array[wp.vec3],
    joint_q: wp.array[float],
    joint_qd: wp.array[float],
    body_q: wp.array[wp.transform],
    goal: wp.array[wp.vec3],
    # Out:
    obs: wp.array2d[float],
):
    """The observations alone (after a reset: the reset envs' first observation of their new episode)."""
    e = wp.tid()
    p = _tcp(body_q, e * bodies_per_env + tcp_body, tcp_offset) - env_origin[e]
    _write_obs(e, dofs_per_env, coords_per_env, p, goal[e], joint_q, joint_qd, obs)


@wp.kernel
def observe_kernel(
    dofs_per_env: int,
    coords_per_env: int,
    bodies_per_env: int,
    tcp_body: int,  # the TCP's body in env 0
    tcp_offset: wp.transform,  # the TCP site in that body's frame
    env_origin: wp.array[wp.vec3],  # (num_envs,) each env's world offset [m]
    joint_q: wp.array[float],
    joint_qd: wp.array[float],
    body_q: wp.array[wp.transform],
    goal: wp.array[wp.vec3],  # (num_envs,) in the env's frame [m]
    max_steps: int,
    success_radius: float,  # [m]
    # In/out:
    episode_step: wp.array[wp.int32],
    episode_return: wp.array[float],
    # Out:
    obs: wp.array2d[float],  # (num_envs, 2 * dofs + 6): q, qd, TCP, goal - TCP
    reward: wp.array[float],
    done: wp.array[wp.bool],
    time_out: wp.array[float],
    distance: wp.array[float],
    stats: wp.array[float],  # (5,) episodes finished, their return sum, their successes, env steps, reward sum
):
    """Observations after a control step, the dense reward ``1 - tanh(2 d) + 0.5 (1 - tanh(20 d))`` of the TCP-goal
    distance ``d`` [m] (a slope everywhere in the workspace, a sharper one near the goal), and the episode's end after
    ``max_steps`` steps (a time-out; success: ``d < success_radius`` at its end)."""
    e = wp.tid()
    p = _tcp(body_q, e * bodies_per_env + tcp_body, tcp_offset) - env_origin[e]
    g = goal[e]
    d = wp.length(g - p)
    _write_obs(e, dofs_per_env, coords_per_env, p, g, joint_q, joint_qd, obs)
    r = 1.0 - wp.tanh(2.0 * d) + 0.5 * (1.0 - wp.tanh(20.0 * d))
    n = episode_step[e] + 1
    ret = episode_return[e] + r
    end = n >= max_steps
    reward[e] = r
    distance[e] = d
    done[e] = end
    time_out[e] = wp.where(end, 1.0, 0.0)
    wp.atomic_add(stats, 3, 1.0)
    wp.atomic_add(stats, 4, r)
    if end:
        wp.atomic_add(stats, 0, 1.0)
        wp.atomic_add(stats, 1, ret)
        if d < success_radius:
            wp.atomic_add(stats, 2, 1.0)
        n = 0
        ret = 0.0
    episode_step[e] = n
    episode_return[e] = ret


@wp.kernel
def reset_kernel(
    seed: int,
    dofs_per_env: int,
    coords_per_env: int,
    noise: float,  # [rad] uniform noise on the arm joints' start positions
    goal_lo: wp.vec3,
    goal_hi: wp.vec3,
    start_q: wp.array[float],  # (dofs,) the start pose [rad, m]
    mask: wp.array[wp.bool],  # (num_envs,) the envs to reset
    counter: wp.array[wp.int32],  # (1,) draws so far (bumped after this launch)
    # Out:
    joint_q: wp.array[float],
    joint_qd: wp.array[float],
    goal: wp.array[wp.vec3],
):
    """Done envs back to the start pose (with noise), at rest, with a new goal drawn uniformly in the box."""
    e = wp.tid()
    if not mask[e]:
        return
    rng = wp.rand_init(seed, counter[0] * 1000003 + e)
    for i in range(dofs_per_env):
        q = start_q[i]
        if i < 7:
            q = q + noise * (2.0 * wp.randf(rng) - 1.0)
        joint_q[e * coords_per_env + i] = q
        joint_qd[e * dofs_per_env + i] = 0.0
    goal[e] = wp.vec3(
        goal_lo[0] + (goal_hi[0] - goal_lo[0]) * wp.randf(rng),
        goal_lo[1] + (goal_hi[1] - goal_lo[1]) * wp.randf(rng),
        goal_lo[2] + (goal_hi[2] - goal_lo[2]) * wp.randf(rng),
    )


@wp.kernel
def bump_kernel(counter: wp.array[wp.int32]):
    counter[0] = counter[0] + 1
