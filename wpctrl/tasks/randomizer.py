"""The device side of :class:`~wpctrl.tasks.randomization.TaskRandomization`: one kernel draws every reset env's
factors and writes the scaled values into MuJoCo-Warp's per-world model arrays."""

from __future__ import annotations

import numpy as np
import warp as wp

from ..config import ConfigError
from .randomization import TaskRandomization

RAND_STREAM = wp.constant(1 << 20)
"""Offset of the randomisation's draws in an env's random stream (its initial state draws from offset 0 upwards)."""


@wp.kernel
def _draw_and_apply(
    mask: wp.array[wp.bool],
    seed: wp.array[wp.int32],
    reset_count: wp.array[wp.int32],
    low: wp.vec3,
    high: wp.vec3,
    bodies: wp.array[wp.int32],
    base_friction: wp.array2d[wp.vec3],
    base_solref: wp.array2d[wp.vec2],
    base_mass: wp.array2d[float],
    base_inertia: wp.array2d[wp.vec3],
    base_invweight: wp.array2d[wp.vec2],
    base_subtreemass: wp.array2d[float],
    dofs: wp.array[wp.int32],
    base_dof_invweight: wp.array2d[float],
    factors: wp.array2d[float],
    geom_friction: wp.array2d[wp.vec3],
    geom_solref: wp.array2d[wp.vec2],
    body_mass: wp.array2d[float],
    body_inertia: wp.array2d[wp.vec3],
    body_invweight0: wp.array2d[wp.vec2],
    body_subtreemass: wp.array2d[float],
    dof_invweight0: wp.array2d[float],
):
    e = wp.tid()
    if not mask[e]:
        return
    rng = wp.rand_init(seed[e], reset_count[e] + RAND_STREAM)
    mu = low[0] + (high[0] - low[0]) * wp.randf(rng)
    tc = low[1] + (high[1] - low[1]) * wp.randf(rng)
    m = low[2] + (high[2] - low[2]) * wp.randf(rng)
    factors[e, 0] = mu
    factors[e, 1] = tc
    factors[e, 2] = m
    for g in range(geom_friction.shape[1]):
        f = base_friction[e, g]
        geom_friction[e, g] = wp.vec3(f[0] * mu, f[1], f[2])
        r = base_solref[e, g]
        geom_solref[e, g] = wp.vec2(r[0] * tc, r[1])
    added = wp.float32(0.0)
    for i in range(bodies.shape[0]):
        b = bodies[i]
        body_mass[e, b] = base_mass[e, b] * m
        body_inertia[e, b] = base_inertia[e, b] * m
        body_invweight0[e, b] = base_invweight[e, b] / m
        body_subtreemass[e, b] = base_subtreemass[e, b] * m
        added += base_mass[e, b] * (m - 1.0)
    body_subtreemass[e, 0] = base_subtreemass[e, 0] + added  # the world's subtree holds every body
    for i in range(dofs.shape[0]):
        d = dofs[i]
        dof_invweight0[e, d] = base_dof_invweight[e, d] / m


_ARRAYS = ("geom_friction", "geom_solref", "body_mass", "body_inertia", "body_invweight0", "body_subtreemass",
           "dof_invweight0")
"""The MuJoCo-Warp model arrays the draws write, each (worlds, geoms or bodies)."""


class Randomizer:
    """The env's side of :class:`TaskRandomization`: the solver model's values the factors scale (refreshed by
    :meth:`capture_base` whenever the env tells the solver of a model change) and the kernel that draws and writes."""

    def __init__(self, env, cfg: TaskRandomization):
        self.env = env
        m = env.solver.mjw_model
        for name in _ARRAYS:
            a = getattr(m, name)
            if a.ndim != 2 or a.shape[0] != env.num_envs:
                raise RuntimeError(f"randomization: MuJoCo-Warp's {name} is not per world (shape {a.shape})")
        ranges = cfg.ranges()
        self.low, self.high = wp.vec3(*ranges[:, 0]), wp.vec3(*ranges[:, 1])
        why = cfg.contact_time_problem(float(m.geom_solref.numpy()[..., 0].min()), env.dt)
        if why:
            raise ConfigError(why)
        to_newton = env.solver.mjc_body_to_newton.numpy()[0]
        wanted = [env.scene.actor_body0[a.name] for a in env.task_spec.bodies]
        mj_bodies = np.array([int(np.flatnonzero(to_newton == b)[0]) for b in wanted], np.int32)
        self.bodies = wp.array(mj_bodies, dtype=wp.int32, device=env.wp_device)
        adr, num = m.body_dofadr.numpy(), m.body_dofnum.numpy()
        dofs = [d for b in mj_bodies for d in range(adr[b], adr[b] + num[b])]
        self.dofs = wp.array(np.array(dofs, np.int32), dtype=wp.int32, device=env.wp_device)
        self.base = {name: wp.clone(getattr(m, name)) for name in _ARRAYS}
        self.factors = wp.ones((env.num_envs, 3), dtype=wp.float32, device=env.wp_device)

    def capture_base(self) -> None:
        """Take the solver model's current values as the ones the factors scale (after it was told of a change)."""
        m = self.env.solver.mjw_model
        for name in _ARRAYS:
            wp.copy(self.base[name], getattr(m, name))

    def apply(self, mask: wp.array) -> None:
        """Draw the factors of ``mask``'s envs (their next episode's) and write the scaled values."""
        env, m, b = self.env, self.env.solver.mjw_model, self.base
        wp.launch(
            _draw_and_apply,
            dim=env.num_envs,
            inputs=[mask, env.seed_buf, env.reset_count, self.low, self.high, self.bodies, b["geom_friction"],
                    b["geom_solref"], b["body_mass"], b["body_inertia"], b["body_invweight0"], b["body_subtreemass"],
                    self.dofs, b["dof_invweight0"]],
            outputs=[self.factors] + [getattr(m, name) for name in _ARRAYS],
            device=env.wp_device,
        )  # fmt: skip
