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


class IntrospectionMixin:
    """The options that run, the controlled joints' indices, the plan (see the module docstring)."""

    # -- the options that run ----------------------------------------------------------------------------------------

    @property
    def options(self) -> ControllerOptions:
        """The mode's option groups as they run: :class:`wpctrl.Actuation` with the explicit law and the inertia
        update resolved (None where nothing of the kind runs), :class:`wpctrl.Delay` (or None),
        :class:`wpctrl.Diagnostics`, and whether gravity is off the robot."""
        return self._engine.plan.resolved_options

    @property
    def actuation(self) -> str:
        """``"implicit"`` or ``"explicit"``: who computes the drive force."""
        return self.options.actuation.mode

    @property
    def explicit_pd(self) -> str | None:
        """The explicit PD law that runs (``"naive"``, ``"stable"``, ``"coupled"``), or None with implicit
        actuation."""
        return self.options.actuation.explicit_pd

    @property
    def inertia_update(self) -> str | None:
        """When the inertia is recomputed (``"control"`` or ``"substep"``), or None when the mode computes none."""
        return self.options.actuation.inertia_update

    @property
    def nan_policy(self) -> str:
        return self.options.diagnostics.nan_policy

    @property
    def clip_targets(self) -> str:
        return self.options.diagnostics.clip_targets

    @property
    def track_effort(self) -> bool:
        return self.options.diagnostics.track_effort

    @property
    def balance_passive_force(self) -> bool:
        """Whether gravity is off the controlled robot's links (ManiSkill's agent-level switch)."""
        return self.options.balance_passive_force

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
