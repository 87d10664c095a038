"""The DC-motor torque-speed envelope as the effort readout shows it: a MuJoCo-Warp rollout of Pandas whose arm has a
``wpctrl.DCMotor`` actuator, every substep's (measured velocity, applied effort) of one joint plotted over the
envelope ``[max(s (-1 - v / v_max), -L), min(s (1 - v / v_max), L)]`` (and the PD torque it clipped).

Run ``python bench/actuators/actuator_envelope.py --out docs/img``; writes ``dc_motor_envelope.png`` and prints how many
samples lie outside the envelope (0 expected).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

wp.config.log_level = wp.LOG_WARNING


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--envs", type=int, default=64)
    p.add_argument("--steps", type=int, default=60, help="control steps at 20 Hz (default: 60, 3 s)")
    p.add_argument("--device", default="cpu")
    p.add_argument("--joint", type=int, default=1, help="DC-motor joint to plot (0-3; default: 1, panda_joint2)")
    p.add_argument("--out", default="docs/img")
    args = p.parse_args(argv)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import newton

    import wpctrl
    from wpctrl.robots import PANDA_ARM_JOINTS, PANDA_GRIPPER_JOINTS, panda

    sat, vmax, lim = 40.0, 1.5, 60.0
    builder = newton.ModelBuilder()
    builder.replicate(panda(), args.envs)
    model = builder.finalize(device=args.device)
    # The DC motors drive the four heavy joints; the wrist (links of ~0.01 kg m^2) keeps the plain clamp: an explicit
    # torque of tens of N·m there changes its velocity by tens of rad/s per 10 ms substep.
    mode = {
        "arm": wpctrl.PDJointPosControllerConfig(
            PANDA_ARM_JOINTS[:4], -1.0, 1.0, 600.0, 30.0, lim, actuator=wpctrl.DCMotor(sat, vmax)
        ),
        "wrist": wpctrl.PDJointPosControllerConfig(PANDA_ARM_JOINTS[4:], -1.0, 1.0, 100.0, 10.0, 12.0),
        "gripper": wpctrl.PDJointPosMimicControllerConfig(
            PANDA_GRIPPER_JOINTS, -0.01, 0.04, 1e3, 1e2, mimic={"panda_finger_joint2": {"joint": "panda_finger_joint1"}}
        ),
    }
    ctrl = wpctrl.build_controller(mode, model, 20, 100, actuation="explicit", explicit_pd="stable", track_effort=True)
    solver = newton.solvers.SolverMuJoCo(model, disable_contacts=True)
    s0, s1, control = model.state(), model.state(), model.control()
    ctrl.reset(s0, control=control)
    dof = ctrl.dof_index[:, args.joint]
    rng = np.random.default_rng(0)
    v_all, u_all, f_all = [], [], []
    for _ in range(args.steps):
        ctrl.set_action(rng.uniform(-1, 1, ctrl.action_space.shape).astype(np.float32), s0)
        for _ in range(ctrl.num_substeps):
            qd = s0.joint_qd.numpy()[dof]
            ctrl.before_simulation_step(s0, control)
            v_all.append(qd)
            u_all.append(ctrl["arm"].computed_effort.numpy()[:, args.joint].copy())  # (numpy() is a view on the CPU)
            f_all.append(ctrl["arm"].applied_effort.numpy()[:, args.joint].copy())
            solver.step(s0, s1, control, None, 0.01)
            s0, s1 = s1, s0
    v, u, f = (np.concatenate(x).astype(np.float64) for x in (v_all, u_all, f_all))
    corner = vmax * (1 + lim / sat)
    vc = np.clip(v, -corner, corner)
    hi, lo = np.minimum(sat * (1 - vc / vmax), lim), np.maximum(sat * (-1 - vc / vmax), -lim)
    outside = int(((f > hi + 1e-3) | (f < lo - 1e-3)).sum())
    grid = np.linspace(min(v.min(), -vmax) * 1.1, max(v.max(), vmax) * 1.1, 400)
    gc = np.clip(grid, -corner, corner)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    ax.scatter(v, u, s=3, c="0.75", label="PD torque (computed_effort)")
    ax.scatter(v, f, s=3, c="tab:blue", label="applied torque (applied_effort)")
    ax.plot(grid, np.minimum(sat * (1 - gc / vmax), lim), "k-", lw=1.2, label="DC-motor envelope")
    ax.plot(grid, np.maximum(sat * (-1 - gc / vmax), -lim), "k-", lw=1.2)
    ax.set_ylim(-1.6 * lim, 1.6 * lim)
    ax.set_xlabel(f"measured velocity of {PANDA_ARM_JOINTS[args.joint]} [rad/s]")
    ax.set_ylabel("torque [N·m]")
    ax.set_title(f"DCMotor(saturation_effort={sat:g}, velocity_limit={vmax:g}), force_limit={lim:g}, {args.envs} envs")
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(alpha=0.3)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(out / "dc_motor_envelope.png", dpi=120)
    print(f"{v.size} samples, {outside} outside the envelope, wrote {out / 'dc_motor_envelope.png'}")
    return 0 if outside == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
