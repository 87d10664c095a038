"""Minimal reproduction: MuJoCo-Warp's implicit damping ignores Newton's joint-level effort clamp.

One revolute joint (inertia I about its axis, gravity off) with Newton's built-in PD (ke = 1000, kd = 100,
effort limit 100 N·m, POSITION_VELOCITY) on ``SolverMuJoCo`` (``implicitfast``), a few 10 ms steps from rest toward a
far target:

* the drive force saturates at 100 N·m, so a force-limited drive (PhysX's) gains ``dt * 100 / I`` rad/s per step;
* Newton writes ``joint_effort_limit`` to MuJoCo's joint-level ``jnt_actfrcrange``: the force *is* clamped, but the
  implicit integrator still folds ``dt * kd`` into its mass matrix (``qDeriv`` only skips an actuator clamped by its
  own ``actuator_forcerange``), so the joint gains ``dt * 100 / (I + dt * kd)``: ``1 / (1 + dt kd / I)`` of it
  (0.99 instead of 100 rad/s at I = 0.01 kg·m²);
* moving the clamp to the actuators' force ranges (``bench.actuators.fidelity.actuator_force_range_clamp``) does not
  fix it: Newton makes two MuJoCo actuators per DOF (stiffness, damping); the stiffness one saturates, the damping
  one does not (its force is ``-kd qd``, 0 at rest), so ``kd`` stays in the implicit solve; once the damping actuator
  saturates it leaves the solve and becomes explicit, which is unstable at ``dt kd / I`` >> 2.

Prints qd after each step per clamp, and the expected value:
``python bench/actuators/mujoco_clamp.py [--inertia 0.01]``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402


def run_steps(inertia: float, target: float, actclamp: bool, steps: int = 3, dt: float = 0.01) -> list[float]:
    import newton

    from bench.actuators.fidelity import actuator_force_range_clamp

    b = newton.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    link = b.add_link(mass=1.0, inertia=wp.mat33(inertia, 0.0, 0.0, 0.0, inertia, 0.0, 0.0, 0.0, inertia))
    j = b.add_joint_revolute(
        -1, link, axis=(0.0, 0.0, 1.0), target_q=target, target_ke=1000.0, target_kd=100.0, effort_limit=100.0,
        limit_lower=-10.0, limit_upper=10.0, actuator_mode=newton.JointTargetMode.POSITION_VELOCITY,
    )  # fmt: skip
    b.add_articulation([j])
    model = b.finalize(device="cpu")
    solver = newton.solvers.SolverMuJoCo(model, disable_contacts=True)
    if actclamp:
        actuator_force_range_clamp(solver)
    s0, s1, control = model.state(), model.state(), model.control()
    out = []
    for _ in range(steps):
        solver.step(s0, s1, control, None, dt)
        s0, s1 = s1, s0
        out.append(float(s0.joint_qd.numpy()[0]))
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--inertia", type=float, default=0.01, help="link inertia about the joint axis [kg m^2]")
    args = p.parse_args(argv)
    wp.config.log_level = wp.LOG_WARNING
    dt, kd, lim, inertia = 0.01, 100.0, 100.0, args.inertia
    for target, what in ((1.0, "saturated (target 1 rad)"), (1e-3, "unsaturated (target 1 mrad)")):
        joint = run_steps(inertia, target, actclamp=False)
        act = run_steps(inertia, target, actclamp=True)
        force = min(lim, 1000.0 * target)
        print(f"{what}: qd after each 10 ms step [rad/s]")
        print(f"  joint-level clamp (Newton's jnt_actfrcrange): {np.round(joint, 4)}")
        print(f"  actuator force-range clamps:                  {np.round(act, 4)}")
        if force >= lim:
            print(f"  force-limited drive, first step dt * limit / I: {dt * force / inertia:.4f}")
        else:
            lin = dt * 1000.0 * target / (inertia + dt * kd + dt * dt * 1000.0)
            print(f"  unclamped implicit PD, first step dt kp e / (I + dt kd + dt^2 kp): {lin:.4f}")


if __name__ == "__main__":
    main()
