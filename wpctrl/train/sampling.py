"""rsl-rl's ``PPO.act`` without its host sync: the rollout's action sampling as ``mean + std * N(0, 1)``.

rsl-rl samples the Gaussian policy's actions with ``torch.distributions.Normal.sample``, which calls
``torch.normal(mean, std)`` with a std tensor; on CUDA that checks ``std >= 0`` on the host, a device-to-host copy that
waits for every launch before it, once per env step. The host then cannot queue the next env step while the GPU runs
the current one, and a rollout costs the env step's host time (its graph launch) plus its device time.

:func:`act` stores the same transition as rsl-rl's ``act`` (actions, values, log-probabilities, distribution
parameters, observations), with the actions drawn as ``mean + std * torch.randn_like(mean)``: the same distribution,
and on the CPU the same numbers as ``torch.normal`` from the same generator state (both draw the standard normals in
order, then scale and shift). Only a plain Gaussian actor (rsl-rl's ``GaussianDistribution``) is sampled this way;
anything else keeps rsl-rl's own ``act`` (:func:`sync_free`).
"""

from __future__ import annotations

import torch

from .train_config import SAMPLINGS

__all__ = ["SAMPLINGS", "act", "sync_free"]


def sync_free(alg) -> str | None:
    """Why ``alg`` (an rsl-rl ``PPO``) cannot use :func:`act`, or ``None``."""
    from rsl_rl.modules.distribution import GaussianDistribution

    if alg.actor.is_recurrent or alg.critic.is_recurrent:
        return "a recurrent actor or critic"
    if type(alg.actor.distribution) is not GaussianDistribution:
        return f"the distribution {type(alg.actor.distribution).__name__} (rsl-rl's GaussianDistribution only)"
    return None


def act(alg, obs) -> torch.Tensor:
    """rsl-rl's ``PPO.act(obs)`` for a feed-forward Gaussian actor, sampling without a host sync."""
    actor, t = alg.actor, alg.transition
    t.hidden_states = (None, None)
    mean = actor(obs)  # the MLP's output: the Gaussian's mean (deterministic_output is the identity)
    actor.distribution.update(mean)
    t.actions = (mean + actor.distribution.std * torch.randn_like(mean)).detach()
    t.values = alg.critic(obs).detach()
    t.actions_log_prob = actor.get_output_log_prob(t.actions).detach()
    t.distribution_params = tuple(p.detach() for p in actor.output_distribution_params)
    t.observations = obs
    return t.actions
