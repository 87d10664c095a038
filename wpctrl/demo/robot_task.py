"""The demo's task for any ManiSkill robot (``--robot``): smooth per-env actions across each controller's action
space, tracked as the measured joints against wpctrl's drive targets.

The Panda's own task (:mod:`.joint_task`, :mod:`.ee_task`) knows a desired trajectory; for an arbitrary robot and
mode the demo cannot, so it asks less: every action column follows its own sinusoid inside the mode's action space
(absolute, delta, velocity, end-effector or base actions alike), and the score is how closely the solver follows
what wpctrl asked of each joint — position rows against ``Control.joint_target_q``, velocity rows (velocity and base
controllers) against ``Control.joint_target_qd``, a joint-impedance arm against its joint targets and an
operational-space arm by its TCP position against its target pose.
"""

from __future__ import annotations

import math

import numpy as np

#: controller config classes whose rows are driven by velocity targets alone
_VELOCITY_CONFIGS = ("PDJointVelControllerConfig", "PDBaseVelControllerConfig", "PDBaseForwardVelControllerConfig")


class RobotTask:
    """Sinusoidal actions inside each controller's action space; measured joints vs the drive targets."""

    tracking_label = "measured joints vs wpctrl's drive targets (positions; velocities for velocity rows)"
    plot_subject = "every controlled joint"
    has_desired = False  # the drive target is the reference

    def __init__(self, mode_name: str, ctrl, model, num_envs: int, rng: np.random.Generator, robot: str):
        import newton

        self.mode = mode_name
        binding = ctrl._engine.binding
        self.coord = binding.coord_index
        self.dof = binding.dof_index
        space = ctrl.single_action_space
        low, high = np.asarray(space.low, np.float64), np.asarray(space.high, np.float64)
        low, high = np.where(np.isfinite(low), low, -1.0), np.where(np.isfinite(high), high, 1.0)
        self.center, self.half = 0.5 * (low + high), 0.5 * (high - low)
        d = ctrl.action_dim
        self.amp = rng.uniform(0.2, 0.5, (num_envs, d))  # fraction of each column's half range
        self.freq = rng.uniform(0.2, 0.6, (num_envs, d))  # [Hz]
        self.phase = rng.uniform(0, 2 * math.pi, (num_envs, d))

        jtype = model.joint_type.numpy()[binding.joint_index[0]]
        prismatic = jtype == int(newton.JointType.PRISMATIC)
        subs = ctrl.children or {"robot": ctrl}
        # Tracked columns, grouped per child controller and unit so that each group is a contiguous run of columns.
        self.rows: list[int] = []  # controller row of each tracked column
        self.velocity: list[bool] = []
        self.groups: dict = {}
        self.tcp: list = []  # (uid, controller) of operational-space children: tracked on their TCP position
        self.joint_targets: list = []  # (first column, controller) of joint-impedance children: their joint targets
        for uid, child in subs.items():
            if hasattr(child, "task_stiffness"):  # an OperationalSpaceController: TCP vs its target pose, below
                self.tcp.append((uid, child))
                continue
            if type(child).__name__ == "JointImpedanceController":
                self.joint_targets.append((len(self.rows), child))
            rows = np.arange(child._rows.start, child._rows.stop)
            vel = type(child.config).__name__ in _VELOCITY_CONFIGS
            kinds: dict[str, list[int]] = {}
            for r in rows:
                kinds.setdefault(("m" if prismatic[r] else "rad") + ("/s" if vel else ""), []).append(int(r))
            for unit, members in kinds.items():
                start = len(self.rows)
                self.rows += members
                self.velocity += [vel] * len(members)
                name = uid if len(kinds) == 1 else f"{uid} [{unit}]"
                self.groups[name] = (slice(start, len(self.rows)), unit, unit, 1.0)
        self.rows_a = np.asarray(self.rows, np.int64)
        self.velocity_a = np.asarray(self.velocity, bool)
        self.names = [ctrl.joint_names[r] + (" (vel)" if v else "") for r, v in zip(self.rows, self.velocity)]
        for uid, _ in self.tcp:
            start = len(self.names)
            self.names += [f"{uid} TCP {a}" for a in "xyz"]
            self.groups[f"{uid} TCP"] = (slice(start, start + 3), "m", "mm", 1e3)

    def action(self, t_next: float, state) -> np.ndarray:
        """Action for the control step that ends at ``t_next`` [s] (the state is not needed)."""
        a = self.center + self.half * self.amp * np.sin(2 * math.pi * self.freq * t_next + self.phase)
        return a.astype(np.float32)

    def tracked(self, t: float, state, control):
        """(measured, drive target, drive target) of every tracked column, each (num_envs, columns): a velocity row
        compares ``joint_qd`` with ``joint_target_qd``, any other ``joint_q`` with ``joint_target_q``."""
        coord, dof = self.coord[:, self.rows_a], self.dof[:, self.rows_a]
        q, qd = state.joint_q.numpy(), state.joint_qd.numpy()
        tq, tqd = control.joint_target_q.numpy(), control.joint_target_qd.numpy()
        measured = np.where(self.velocity_a, qd[dof], q[coord])
        target = np.where(self.velocity_a, tqd[dof], tq[coord])
        for c0, child in self.joint_targets:  # joint impedance: torques, no drive target; the controller's target
            n = child._rows.stop - child._rows.start
            target[:, c0 : c0 + n] = child.target_qpos.numpy()
        if self.tcp:
            measured = np.concatenate([measured] + [c.fk_jacobian(state)[0].numpy()[:, :3] for _, c in self.tcp], 1)
            target = np.concatenate([target] + [c.target_pose.numpy()[:, :3] for _, c in self.tcp], 1)
        return measured, target, target
