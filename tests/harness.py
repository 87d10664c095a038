"""A small test harness: a Panda model with N envs, a controller, and numpy views of Newton's arrays."""

from __future__ import annotations

import numpy as np
from conftest import build_panda

import wpctrl

ARM = [f"panda_joint{i}" for i in range(1, 8)]
FINGERS = ["panda_finger_joint1", "panda_finger_joint2"]


class Harness:
    """Controller + state + control over ``num_envs`` Pandas; q/qd/targets addressed in the controller's rows."""

    def __init__(
        self, config, num_envs: int = 1, actuation: str = "implicit", control_freq=20, sim_freq=100, device="cpu", **kw
    ):
        self.model = build_panda(num_envs, device=device)
        self.ctrl = wpctrl.build_controller(config, self.model, control_freq, sim_freq, actuation=actuation, **kw)
        self.state = self.model.state()
        self.control = self.model.control()
        b = self.ctrl._engine.binding
        self.coord = b.coord_index
        self.dof = b.dof_index
        self.num_envs = num_envs

    def put(self, q=None, qd=None):
        """Write measured positions/velocities (num_envs, n) of the controller's joints into the state."""
        if q is not None:
            a = self.state.joint_q.numpy()
            a[self.coord] = np.broadcast_to(np.asarray(q, np.float32), self.coord.shape)
            self.state.joint_q.assign(a)
        if qd is not None:
            a = self.state.joint_qd.numpy()
            a[self.dof] = np.broadcast_to(np.asarray(qd, np.float32), self.dof.shape)
            self.state.joint_qd.assign(a)

    def q(self):
        return self.state.joint_q.numpy()[self.coord]

    def drive_q(self):
        return self.control.joint_target_q.numpy()[self.coord]

    def drive_qd(self):
        return self.control.joint_target_qd.numpy()[self.dof]

    def joint_f(self):
        return self.control.joint_f.numpy()[self.dof]

    def act(self, action):
        a = np.asarray(action, np.float32)
        if a.ndim == 1:
            a = np.broadcast_to(a, (self.num_envs, a.shape[0])).copy()
        self.ctrl.set_action(a, self.state)

    def substeps(self, k=None):
        """Run k (default K) before_simulation_step calls; return the joint_target_q rows after each."""
        out = []
        for _ in range(self.ctrl.num_substeps if k is None else k):
            self.ctrl.before_simulation_step(self.state, self.control)
            out.append(self.drive_q())
        return out

    def step(self, action):
        self.act(action)
        return self.substeps()


def delta_arm(**kw):
    return wpctrl.PDJointPosControllerConfig(ARM, -0.1, 0.1, 1e3, 1e2, 100, use_delta=True, **kw)


def gripper(**kw):
    return wpctrl.PDJointPosMimicControllerConfig(
        FINGERS, -0.01, 0.04, 1e3, 1e2, 100, mimic={"panda_finger_joint2": {"joint": "panda_finger_joint1"}}, **kw
    )
