"""The tasks' per-env device work as Warp kernels, one thread per env, generated for each task from its declaration
(:class:`~wpctrl.tasks.registry.Task`): episode initialisation (the Panda's, then the task's ``initialize``),
evaluation, observation and reward (the task's ``evaluate``, its observation fields in their declared order and its
``dense_reward``), and the episode bookkeeping of ``ManiSkillVectorEnv`` (termination, truncation, auto reset). The
task's device functions are compiled into the kernels (``wp.static``); nothing here names a task. Every kernel is
capturable: nothing is read back to the host.
"""

from __future__ import annotations

from typing import Any

import warp as wp

from .definitions import PANDA_ARM_DOF, PANDA_DOF
from .funcs import Sim, zero_actor_velocity

__all__ = ["episode_kernel", "task_kernels"]

_KERNELS: dict[type, tuple] = {}


@wp.func
def _put(obs: wp.array2d[float], e: int, start: int, value: Any):
    """One observation field (a vector of its width) into env e's row from column ``start``."""
    for k in range(len(value)):
        obs[e, start + k] = value[k]


def task_kernels(task) -> tuple:
    """``(reset_kernel, observe_kernel)`` of ``task``, built once per task class."""
    cls = type(task)
    if cls not in _KERNELS:
        _KERNELS[cls] = _build(task)
    return _KERNELS[cls]


def _kernel(fn, task):
    """``fn`` as a Warp kernel of its own module, named after the task (the generated code differs per task)."""
    slug = "".join(c if c.isalnum() else "_" for c in task.env_id)
    fn.__name__ = fn.__qualname__ = f"{fn.__name__}_{slug}"
    return wp.kernel(fn, enable_backward=False, module="unique")


def _build(task) -> tuple:
    initialize, evaluate, dense_reward = task.initialize, task.evaluate, task.dense_reward
    n_bodies = len(task.bodies)
    fields = [f.func for f in task.obs_extra]
    sizes = [f.size for f in task.obs_extra]
    starts = [2 * PANDA_DOF + sum(sizes[:i]) for i in range(len(sizes))]
    max_reward = float(task.max_reward)

    def reset_kernel(
        s: Sim,
        seed: wp.array[wp.int32],
        mask: wp.array[wp.bool],
        rest_qpos: wp.array[float],
        qpos_noise: float,
        reset_count: wp.array[wp.int32],
        elapsed: wp.array[wp.int32],
    ):
        """ManiSkill's episode initialisation of the envs in ``mask``: the Panda at rest + N(0, noise) (fingers
        0.04), zero velocities, every actor at rest; then the task's ``initialize`` draws and places its actors."""
        e = wp.tid()
        if not mask[e]:
            return
        rng = wp.rand_init(seed[e], reset_count[e])  # env e's draws: a function of its own seed and episode count
        reset_count[e] = reset_count[e] + 1
        q0 = s.robot_q0 + e * s.nq
        qd0 = s.robot_qd0 + e * s.nqd
        for j in range(wp.static(PANDA_ARM_DOF)):
            s.joint_q[q0 + j] = rest_qpos[j] + qpos_noise * wp.randn(rng)
        for j in range(wp.static(PANDA_ARM_DOF), wp.static(PANDA_DOF)):
            s.joint_q[q0 + j] = rest_qpos[j]
        for j in range(wp.static(PANDA_DOF)):
            s.joint_qd[qd0 + j] = 0.0
        for i in range(wp.static(n_bodies)):
            zero_actor_velocity(s, e, i)
        wp.static(initialize)(s, e, rng)
        elapsed[e] = 0

    def observe_kernel(s: Sim, obs: wp.array2d[float], reward_dense: wp.array[float]):
        """``evaluate()``, the flattened ``obs_mode="state"`` observation (the Panda's qpos and qvel, then the task's
        fields) and ``compute_dense_reward`` of the current state (``max_reward`` where successful)."""
        e = wp.tid()
        wp.static(evaluate)(s, e)
        q0 = s.robot_q0 + e * s.nq
        qd0 = s.robot_qd0 + e * s.nqd
        for j in range(wp.static(PANDA_DOF)):
            obs[e, j] = s.joint_q[q0 + j]
            obs[e, wp.static(PANDA_DOF) + j] = s.joint_qd[qd0 + j]
        for i in range(wp.static(len(fields))):
            _put(obs, e, wp.static(starts[i]), wp.static(fields[i])(s, e))
        r = wp.static(dense_reward)(s, e)
        if s.info[e, 0]:
            r = wp.static(max_reward)
        reward_dense[e] = r

    return _kernel(reset_kernel, task), _kernel(observe_kernel, task)


@wp.kernel(enable_backward=False)
def episode_kernel(
    max_steps: int,
    max_reward: float,
    reward_mode: int,
    ignore_terminations: int,
    success: wp.array2d[wp.bool],
    reward_dense: wp.array[float],
    elapsed: wp.array[wp.int32],
    reward: wp.array[float],
    terminated: wp.array[wp.bool],
    truncated: wp.array[wp.bool],
    done: wp.array[wp.bool],
):
    """After a step: ``elapsed += 1``, the reward of ``reward_mode`` (0 dense, 1 normalized dense, 2 sparse: success),
    ``terminated = success`` (no ``fail``; False with ``ignore_terminations``), ``truncated = elapsed >= max_steps``,
    and ``done`` (either: the envs an auto reset resets). ``success[e, 0]``: the evaluation's first column."""
    e = wp.tid()
    n = elapsed[e] + 1
    elapsed[e] = n
    r = reward_dense[e]
    if reward_mode == 1:
        r = r / max_reward
    elif reward_mode == 2:
        r = wp.where(success[e, 0], 1.0, 0.0)
    reward[e] = r
    term = success[e, 0] and ignore_terminations == 0
    trunc = n >= max_steps
    terminated[e] = term
    truncated[e] = trunc
    d = term or trunc
    done[e] = d
