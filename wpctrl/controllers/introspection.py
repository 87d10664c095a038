"""What a controller runs and where its joints are: the options as they run, the joints' indices in Newton's arrays,
the plan as text.

:class:`IntrospectionMixin` is a base of :class:`wpctrl.BaseController`. Everything here reads the built engine (the
options resolved: the explicit law and inertia update that run, None where nothing of the kind runs), so it tells
what the controller does, not what it was asked; a child controller (``ctrl["arm"]``) gives its own joints' indices.
"""

from __future__ import annotations

import newton
import numpy as np
import warp as wp

from ..config.options import ControllerOptions


def _option(path: str, doc: str) -> property:
    """A read-only property: the field ``path`` (dotted) of :attr:`IntrospectionMixin.options`."""

    def get(self):
        value = self.options
        for name in path.split("."):
            value = getattr(value, name)
        return value

    return property(get, doc=doc)


class IntrospectionMixin:
    """The options that run, the controlled joints' indices, the plan (see the module docstring)."""

    # -- the options that run ----------------------------------------------------------------------------------------

    @property
    def options(self) -> ControllerOptions:
        """The mode's option groups as they run: :class:`wpctrl.Actuation` with the explicit law and the inertia
        update resolved (None where nothing of the kind runs), :class:`wpctrl.Delay` (or None),
        :class:`wpctrl.Diagnostics`, and whether gravity is off the robot."""
        return self._engine.plan.resolved_options

    actuation = _option("actuation.mode", """``"implicit"`` or ``"explicit"``: who computes the drive force.""")
    explicit_pd = _option(
        "actuation.explicit_pd",
        """The explicit PD law that runs (``"naive"``, ``"stable"``, ``"coupled"``), or None (implicit actuation).""",
    )
    inertia_update = _option(
        "actuation.inertia_update",
        """When the inertia is recomputed (``"control"`` or ``"substep"``), or None when the mode computes none.""",
    )
    nan_policy = _option("diagnostics.nan_policy", "What an action with NaN/Inf does (:class:`wpctrl.Diagnostics`).")
    clip_targets = _option(
        "diagnostics.clip_targets", "The clipping of the position targets (:class:`wpctrl.Diagnostics`)."
    )
    track_effort = _option("diagnostics.track_effort", "Whether the computed and applied efforts are read out.")
    balance_passive_force = _option(
        "balance_passive_force", "Whether gravity is off the controlled robot's links (ManiSkill's agent-level switch)."
    )

    @property
    def substep_launch(self) -> bool:
        """Whether :meth:`~wpctrl.BaseController.before_simulation_step` launches a kernel at every substep
        (explicit torques, effort rows, interpolation, a delay, the effort readout, a per-substep inertia update).
        False: the drive targets are constant over the control step, ``set_action`` writes them into the known
        Control and the substep launches nothing."""
        return self._engine.per_substep

    def describe(self) -> str:
        """What runs, as text: the control mode's plan (rows, their kinds and action columns, the index layout, the
        engine parts that are on, whether the substep launches)."""
        return str(self._engine.plan)

    # -- where the controlled joints are -------------------------------------------------------------------------

    @property
    def model(self) -> newton.Model:
        """The Newton model the controller drives."""
        return self._engine.model

    @property
    def coord_index(self) -> np.ndarray:
        """(num_envs, n_joints) int32: each controlled joint's coordinate index in ``State.joint_q`` /
        ``Control.joint_target_q``, per env (a copy; ``joint_q.numpy()[ctrl.coord_index]`` gathers the joints)."""
        return np.array(self._engine.binding.coord_index.reshape(self.num_envs, -1)[:, self._rows])

    @property
    def joint_index(self) -> np.ndarray:
        """(num_envs, n_joints) int32: each controlled joint's Newton joint id (``Model.joint_type[...]``, ...), per
        env (a copy)."""
        return np.array(self._engine.binding.joint_index.reshape(self.num_envs, -1)[:, self._rows])

    @property
    def dof_index(self) -> np.ndarray:
        """(num_envs, n_joints) int32: each controlled joint's DOF index in ``State.joint_qd`` /
        ``Control.joint_target_qd`` / ``Control.joint_f`` and the per-DOF model arrays, per env (a copy)."""
        return np.array(self._engine.binding.dof_index.reshape(self.num_envs, -1)[:, self._rows])

    @property
    def joint_limits(self) -> np.ndarray:
        """(n_joints, 2) float32: each controlled joint's lower and upper position limit [rad or m] in the model
        (env 0's, as ManiSkill's ``get_qlimits()[0]``; infinite for an unlimited joint) (a copy)."""
        return np.array(self._engine.binding.qlimits[self._rows])

    @property
    def coupled_iterations(self) -> wp.array | None:
        """(num_envs,) int32: the active-set iterations of the coupled drive's last solve per env
        (``explicit_pd="coupled"``; the rows + 2 cap means the fallback sweeps ran), else None. The whole mode's."""
        part = self._engine.part("coupled_drive")
        return None if part is None else part.coupled_iterations
