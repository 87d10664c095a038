"""The tasks' per-env device work as Warp kernels, one thread per env: episode initialisation (ManiSkill's
``_initialize_episode`` draws), evaluation, observation and reward (``evaluate``, ``_get_obs_extra``,
``compute_dense_reward``), and the episode bookkeeping of ``ManiSkillVectorEnv`` (termination, truncation, auto
reset). Every kernel is capturable: nothing is read back to the host.

Layout: env ``e``'s robot coordinates start at ``robot_q0 + e * nq`` (9 of them, ManiSkill's qpos order), its cube
free joint at ``cube_q0 + e * nq`` (p, q xyzw) and ``cube_qd0 + e * nqd`` (v, w in the world frame); bodies at
``body0 + e * nb``. Quaternions leave as ManiSkill's ``(w, x, y, z)``.
"""

from __future__ import annotations

import warp as wp

PUSH = wp.constant(0)
PICK = wp.constant(1)


@wp.struct
class Layout:
    """Where one env's entities sit in Newton's arrays (env 0's index; add ``e`` times the stride)."""

    nq: int
    nqd: int
    nb: int
    robot_q0: int
    robot_qd0: int
    cube_q0: int
    cube_qd0: int
    cube_body0: int
    tcp_body0: int
    lfinger_body0: int
    rfinger_body0: int


@wp.struct
class TaskParams:
    """A task's constants (:class:`~wpctrl.tasks.definitions.TaskSpec`)."""

    kind: int
    half_size: float
    spawn_half: float
    random_yaw: int
    goal_radius: float
    max_goal_height: float
    push_goal_offset: float
    max_reward: float
    static_threshold: float
    grasp_min_force: float
    grasp_cos_max_angle: float
    qpos_noise: float
    goal_quat: wp.quat
    """wxyz stored as (w, x, y, z) in a quat's 4 slots."""


@wp.func
def _wxyz(q: wp.quat) -> wp.vec4:
    return wp.vec4(q[3], q[0], q[1], q[2])


@wp.kernel
def reset_kernel(
    L: Layout,
    P: TaskParams,
    seed: wp.array[wp.int32],
    mask: wp.array[wp.bool],
    rest_qpos: wp.array[float],
    reset_count: wp.array[wp.int32],
    joint_q: wp.array[float],
    joint_qd: wp.array[float],
    goal_pos: wp.array[wp.vec3],
    elapsed: wp.array[wp.int32],
):
    """ManiSkill's episode initialisation of the envs in ``mask``: the Panda at rest + N(0, noise) (fingers 0.04),
    zero velocities; the cube flat on the table at U[-h, h]^2 (PickCube: a uniform yaw); the goal (PushCube: 0.2 m in
    +x of the cube at z = 1e-3; PickCube: U[-h, h]^2 and z = half size + U[0, max height])."""
    e = wp.tid()
    if not mask[e]:
        return
    n = mask.shape[0]
    rng = wp.rand_init(seed[0], e + n * reset_count[e])
    reset_count[e] = reset_count[e] + 1
    q0 = L.robot_q0 + e * L.nq
    qd0 = L.robot_qd0 + e * L.nqd
    for j in range(7):
        joint_q[q0 + j] = rest_qpos[j] + P.qpos_noise * wp.randn(rng)
    joint_q[q0 + 7] = rest_qpos[7]
    joint_q[q0 + 8] = rest_qpos[8]
    for j in range(9):
        joint_qd[qd0 + j] = 0.0
    x = (wp.randf(rng) * 2.0 - 1.0) * P.spawn_half
    y = (wp.randf(rng) * 2.0 - 1.0) * P.spawn_half
    c = L.cube_q0 + e * L.nq
    joint_q[c + 0] = x
    joint_q[c + 1] = y
    joint_q[c + 2] = P.half_size
    yaw = 0.0
    if P.random_yaw != 0:
        yaw = wp.randf(rng) * 2.0 * wp.pi
    joint_q[c + 3] = 0.0
    joint_q[c + 4] = 0.0
    joint_q[c + 5] = wp.sin(0.5 * yaw)
    joint_q[c + 6] = wp.cos(0.5 * yaw)
    cd = L.cube_qd0 + e * L.nqd
    for j in range(6):
        joint_qd[cd + j] = 0.0
    if P.kind == PUSH:
        goal_pos[e] = wp.vec3(x + P.push_goal_offset, y, 1.0e-3)
    else:
        gx = (wp.randf(rng) * 2.0 - 1.0) * P.spawn_half
        gy = (wp.randf(rng) * 2.0 - 1.0) * P.spawn_half
        goal_pos[e] = wp.vec3(gx, gy, P.half_size + wp.randf(rng) * P.max_goal_height)
    elapsed[e] = 0


@wp.func
def _grasping(force: wp.vec3, direction: wp.vec3, min_force: float, cos_max: float) -> bool:
    """``Panda.is_grasping``'s per-finger test: ||f|| >= min_force and angle(direction, f) <= max_angle."""
    f = wp.length(force)
    if f < min_force:
        return False
    return wp.dot(direction, force) >= cos_max * f * wp.length(direction)


@wp.kernel
def observe_kernel(
    L: Layout,
    P: TaskParams,
    joint_q: wp.array[float],
    joint_qd: wp.array[float],
    body_q: wp.array[wp.transform],
    finger_force: wp.array2d[wp.vec3],
    goal_pos: wp.array[wp.vec3],
    obs: wp.array2d[float],
    success: wp.array[wp.bool],
    is_grasped: wp.array[wp.bool],
    is_obj_placed: wp.array[wp.bool],
    is_robot_static: wp.array[wp.bool],
    reward_dense: wp.array[float],
):
    """``evaluate()``, the flattened ``obs_mode="state"`` observation and ``compute_dense_reward`` of the current
    state. ``finger_force[2e + i, 0]``: the contact force on env e's finger i (0 left, 1 right) from its cube."""
    e = wp.tid()
    q0 = L.robot_q0 + e * L.nq
    qd0 = L.robot_qd0 + e * L.nqd
    c = L.cube_q0 + e * L.nq
    cube_p = wp.vec3(joint_q[c], joint_q[c + 1], joint_q[c + 2])
    cube_q = wp.quat(joint_q[c + 3], joint_q[c + 4], joint_q[c + 5], joint_q[c + 6])
    tcp = body_q[L.tcp_body0 + e * L.nb]
    tcp_p = wp.transform_get_translation(tcp)
    tcp_q = wp.transform_get_rotation(tcp)
    goal = goal_pos[e]

    # evaluate()
    static = True
    for j in range(7):
        if wp.abs(joint_qd[qd0 + j]) > P.static_threshold:
            static = False
    grasped = False
    placed = False
    ok = False
    if P.kind == PUSH:
        dxy = wp.vec2(cube_p[0] - goal[0], cube_p[1] - goal[1])
        placed = wp.length(dxy) < P.goal_radius and cube_p[2] < P.half_size + 5.0e-3
        ok = placed
    else:
        lf = wp.transform_get_rotation(body_q[L.lfinger_body0 + e * L.nb])
        rf = wp.transform_get_rotation(body_q[L.rfinger_body0 + e * L.nb])
        lflag = _grasping(finger_force[2 * e, 0], wp.quat_rotate(lf, wp.vec3(0.0, 1.0, 0.0)), P.grasp_min_force,
                          P.grasp_cos_max_angle)  # fmt: skip
        rflag = _grasping(finger_force[2 * e + 1, 0], -wp.quat_rotate(rf, wp.vec3(0.0, 1.0, 0.0)),
                          P.grasp_min_force, P.grasp_cos_max_angle)  # fmt: skip
        grasped = lflag and rflag
        placed = wp.length(goal - cube_p) <= P.goal_radius
        ok = placed and static
    success[e] = ok
    is_grasped[e] = grasped
    is_obj_placed[e] = placed
    is_robot_static[e] = static

    # observation: agent qpos, qvel, then the task's extras in ManiSkill's dict order
    for j in range(9):
        obs[e, j] = joint_q[q0 + j]
        obs[e, 9 + j] = joint_qd[qd0 + j]
    k = 18
    if P.kind == PICK:
        obs[e, k] = wp.where(grasped, 1.0, 0.0)
        k = k + 1
    tq = _wxyz(tcp_q)
    cq = _wxyz(cube_q)
    for i in range(3):
        obs[e, k + i] = tcp_p[i]
    for i in range(4):
        obs[e, k + 3 + i] = tq[i]
    for i in range(3):
        obs[e, k + 7 + i] = goal[i]
    for i in range(3):
        obs[e, k + 10 + i] = cube_p[i]
    for i in range(4):
        obs[e, k + 13 + i] = cq[i]
    if P.kind == PICK:
        for i in range(3):
            obs[e, k + 17 + i] = cube_p[i] - tcp_p[i]
            obs[e, k + 20 + i] = goal[i] - cube_p[i]

    # compute_dense_reward
    r = 0.0
    if P.kind == PUSH:
        push_p = cube_p + wp.vec3(-P.half_size - 0.005, 0.0, 0.0)
        d = wp.length(push_p - tcp_p)
        r = 1.0 - wp.tanh(5.0 * d)
        if d < 0.01:
            dg = wp.length(wp.vec2(cube_p[0] - goal[0], cube_p[1] - goal[1]))
            place = 1.0 - wp.tanh(5.0 * dg)
            r = r + place + place * (1.0 - wp.tanh(5.0 * wp.abs(cube_p[2] - P.half_size)))
    else:
        r = 1.0 - wp.tanh(5.0 * wp.length(cube_p - tcp_p))
        if grasped:
            r = r + 1.0 + (1.0 - wp.tanh(5.0 * wp.length(goal - cube_p)))
        if placed:
            v2 = 0.0
            for j in range(7):
                v2 = v2 + joint_qd[qd0 + j] * joint_qd[qd0 + j]
            r = r + 1.0 - wp.tanh(5.0 * wp.sqrt(v2))
    if ok:
        r = P.max_reward
    reward_dense[e] = r


@wp.kernel
def episode_kernel(
    max_steps: int,
    max_reward: float,
    reward_mode: int,
    ignore_terminations: int,
    success: wp.array[wp.bool],
    reward_dense: wp.array[float],
    elapsed: wp.array[wp.int32],
    reward: wp.array[float],
    terminated: wp.array[wp.bool],
    truncated: wp.array[wp.bool],
    done: wp.array[wp.bool],
):
    """After a step: ``elapsed += 1``, the reward of ``reward_mode`` (0 dense, 1 normalized dense, 2 sparse: success),
    ``terminated = success`` (no ``fail``; False with ``ignore_terminations``), ``truncated = elapsed >= max_steps``,
    and ``done`` (either: the envs an auto reset resets)."""
    e = wp.tid()
    n = elapsed[e] + 1
    elapsed[e] = n
    r = reward_dense[e]
    if reward_mode == 1:
        r = r / max_reward
    elif reward_mode == 2:
        r = wp.where(success[e], 1.0, 0.0)
    reward[e] = r
    term = success[e] and ignore_terminations == 0
    trunc = n >= max_steps
    terminated[e] = term
    truncated[e] = trunc
    d = term or trunc
    done[e] = d
