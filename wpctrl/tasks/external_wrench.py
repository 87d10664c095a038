"""External forces and torques on a task's actors: pushes, pulls and loads that are not the robot's (a perturbation
for robust training, a test's load, a user's probe).

A wrench set here is written into Newton's ``State.body_f`` of the env's two state buffers, which Newton's MuJoCo
solver applies at every one of its steps: it acts in the world frame about the actor's centre of mass, constant
through each control step, and stays until it is set again. Resets and
:meth:`~wpctrl.tasks.env.TaskEnv.set_state_dict` keep it. The captured step needs nothing new: the solver already
reads ``body_f`` at every step.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from ..config import ConfigError
from ._validate import env_mask, row_vectors

__all__ = ["ExternalWrenchMixin"]

_WHO = "set_external_wrench"


class ExternalWrenchMixin:
    """:meth:`set_external_wrench` / :meth:`get_external_wrench` of :class:`~wpctrl.tasks.env.TaskEnv`."""

    def _wrench_views(self) -> list:
        """Zero-copy (num_envs, bodies_per_env, 6) torch views of both state buffers' ``body_f``."""
        n, nb = self.num_envs, self.scene.bodies_per_env
        return [wp.to_torch(s.body_f).view(n, nb, 6) for s in (self.state, self._other)]

    def _actor_body(self, actor) -> int:
        names = [a.name for a in self.task_spec.bodies]
        if actor not in names:
            raise ConfigError(f"{_WHO}: actor expected one of {self.task_spec.env_id}'s free bodies {names}, got "
                              f"{actor!r}")  # fmt: skip
        return self.scene.actor_body0[actor]

    def set_external_wrench(self, actor: str, force=None, torque=None, env_idx=None) -> None:
        """Push ``actor`` (one of the task's free bodies, e.g. ``"cube"``) in ``env_idx``'s envs (None: all) with
        ``force`` [N] and ``torque`` [N m], in the world frame about its centre of mass, from the next step on and
        until set again. Each is (3,) for every env selected or (k, 3), a row per env selected (in increasing env
        order); None is zero, so ``set_external_wrench(actor)`` removes the wrench. A force ``f`` at a world point
        ``p`` of a body whose centre of mass is at ``c`` is the force ``f`` with the torque ``(p - c) x f``.
        Everything is checked on the host before anything is written."""
        torch = self._torch
        body = self._actor_body(actor)
        mask = self._all if env_idx is None else env_mask(env_idx, self.num_envs, self.wp_device)
        idx = torch.nonzero(wp.to_torch(mask), as_tuple=False).flatten()
        rows = int(idx.numel())
        zero = np.zeros((rows, 3), np.float32)
        f = zero if force is None else row_vectors(force, "force", rows, 3, _WHO)
        t = zero if torque is None else row_vectors(torque, "torque", rows, 3, _WHO)
        wrench = np.concatenate([f, t], axis=1)
        w = torch.as_tensor(wrench, device=self.device)
        for view in self._wrench_views():
            view[idx, body] = w

    def get_external_wrench(self, actor: str):
        """The (num_envs, 6) wrench on ``actor``, force then torque (a new torch tensor on the env's device)."""
        body = self._actor_body(actor)
        return self._wrench_views()[0][:, body].clone()
