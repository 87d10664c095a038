"""Mutations: the response r = (H^-1)_ii, acceleration drives and stable PD."""

from .model import M

MUTATIONS = [
    M(
        "substep_inertia_only_in_set_action",
        "wpctrl/engine/parts/response.py",
        "    def before_set_action(self, engine, action, state) -> None:\n"
        "        if not self.update_per_substep:\n"
        "            self.update(engine, state)\n\n"
        "    def before_substep(self, engine, state, control) -> None:\n"
        "        if self.update_per_substep:\n"
        "            self.update(engine, state)\n",
        "    def before_set_action(self, engine, action, state) -> None:\n"
        "        self.update(engine, state)\n\n"
        "    def before_substep(self, engine, state, control) -> None:\n"
        "        pass\n",
        'inertia_update="substep" refreshes r only in set_action',
        ("tests/test_acceleration.py",),
    ),
    M(
        "accel_gains_not_notified",
        "wpctrl/engine/parts/response.py",
        "            engine.notify_solver()\n",
        "",
        "the implicit acceleration drive does not notify the solver after writing Kp/r, Kd/r",
        ("tests/test_acceleration.py",),
    ),
    M(
        "accel_gain_times_r",
        "wpctrl/kernels/pd_substep.py",
        "                        kpr = kpr / resp[r]\n",
        "                        kpr = kpr * resp[r]\n",
        "explicit acceleration drive multiplies Kp by r instead of dividing",
        ("tests/test_acceleration.py",),
    ),
    M(
        "accel_model_kd_from_kp",
        "wpctrl/engine/parts/response.py",
        "drive.joint_target_kd[di] = drive.kd[_bidx(drive.kd.shape[0], env), r] / resp",
        "drive.joint_target_kd[di] = drive.kp[_bidx(drive.kp.shape[0], env), r] / resp",
        "implicit acceleration drive writes Kp/r as the solver's damping",
        ("tests/test_actuation.py",),
    ),
    M(
        "stable_pd_denominator_without_kp",
        "wpctrl/kernels/pd_substep.py",
        "1.0 + resp[r] * dt * (kdr + dt * kpr)",
        "1.0 + resp[r] * dt * kdr",
        "stable explicit PD drops the dt^2 Kp term of its denominator",
        ("tests/test_coupled.py", "tests/test_acceleration.py"),
    ),
]
