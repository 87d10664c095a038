"""The main job: N Pandas driven through a ManiSkill control mode by wpctrl inside a real Newton solver.

``python -m wpctrl demo`` (or the ``wpctrl demo`` console script) builds N Pandas in one Newton model, runs a
scripted policy that exercises every part of the chosen control mode (sinusoidal joint motion and a gripper that
opens and closes, expressed in the mode's action space), resets a few random envs now and then, and reports
throughput, the controller's share of a step and the tracking error. It writes ``summary.json`` and
``tracking.png`` into ``--out``.

Gravity is off, as ManiSkill's Panda runs with ``balance_passive_force`` (gravity disabled on the robot links).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

SOLVERS = ("mujoco", "xpbd", "featherstone")
ACTUATIONS = ("implicit", "explicit")


def _parser() -> argparse.ArgumentParser:
    from .robots import PANDA_CONTROL_MODES

    p = argparse.ArgumentParser(prog="wpctrl demo", description=__doc__.split("\n\n")[0])
    p.add_argument("--envs", type=int, default=16, help="parallel envs (Pandas), default 16")
    p.add_argument("--device", default="cpu", help="cpu | cuda:0 (default cpu)")
    p.add_argument("--control-mode", default="pd_joint_delta_pos", help=f"one of {list(PANDA_CONTROL_MODES)}")
    p.add_argument("--actuation", default="implicit", choices=ACTUATIONS)
    p.add_argument(
        "--solver",
        default="mujoco",
        choices=SOLVERS,
        help="mujoco (default: holds ManiSkill's 1000/100 Panda gains at 100 Hz), xpbd, featherstone",
    )
    p.add_argument("--seconds", type=float, default=4.0, help="simulated time [s] (default 4)")
    p.add_argument("--sim-freq", type=int, default=100, help="solver steps per second [Hz]")
    p.add_argument("--control-freq", type=int, default=20, help="control steps per second [Hz]")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="wpctrl-demo", help="output folder for summary.json and tracking.png")
    p.add_argument("--graph", action=argparse.BooleanOptionalAction, default=True, help="capture the control step")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=True, help="tqdm progress bar")
    return p


def _fail(parser: argparse.ArgumentParser, msg: str):
    parser.print_usage(sys.stderr)
    print(f"wpctrl demo: error: {msg}", file=sys.stderr)
    raise SystemExit(2)


def _check_args(parser, args) -> None:
    import warp as wp

    from .robots import PANDA_CONTROL_MODES

    if args.control_mode not in PANDA_CONTROL_MODES:
        _fail(parser, f"--control-mode: expected one of {list(PANDA_CONTROL_MODES)}, got {args.control_mode!r}")
    if args.envs < 1:
        _fail(parser, f"--envs: expected >= 1, got {args.envs}")
    if not (args.seconds > 0 and math.isfinite(args.seconds)):
        _fail(parser, f"--seconds: expected a positive number, got {args.seconds}")
    if args.control_freq < 1 or args.sim_freq < 1 or args.sim_freq % args.control_freq:
        _fail(
            parser,
            f"--sim-freq must be a positive multiple of --control-freq, got {args.sim_freq} and {args.control_freq}",
        )
    if args.device != "cpu":
        if not args.device.startswith("cuda"):
            _fail(parser, f"--device: expected cpu or cuda[:N], got {args.device!r}")
        if not wp.is_cuda_available():
            _fail(parser, f"--device {args.device}: no CUDA device is available on this machine")
        try:
            wp.get_device(args.device)
        except Exception as e:  # noqa: BLE001 - report any unknown device the same way
            _fail(parser, f"--device {args.device}: {e}")


class _Policy:
    """A scripted policy: per-env sinusoids around the rest pose for the arm, a gripper that opens and closes.

    It produces each mode's action from the desired trajectory (q_des, qd_des) and the measured state, so every
    part of the mode is used: absolute, delta from the measured position, delta on the virtual target, velocity
    and position+velocity actions, normalisation (clipped at the bounds) and the mimic gripper.
    """

    def __init__(self, mode_name: str, ctrl, rest: np.ndarray, num_envs: int, rng: np.random.Generator):
        self.mode = mode_name
        self.ctrl = ctrl
        self.rest = rest.astype(np.float64)
        self.amp = rng.uniform(0.1, 0.3, (num_envs, 7))  # [rad]
        self.freq = rng.uniform(0.2, 0.6, (num_envs, 7))  # [Hz]: peak speed < 1.2 rad/s, inside every mode's bounds
        self.phase = rng.uniform(0, 2 * math.pi, (num_envs, 7))
        self.grip_period = rng.uniform(1.0, 2.0, num_envs)  # [s]

    def desired(self, t: float):
        w = 2 * math.pi * self.freq
        q = self.rest[None, :7] + self.amp * np.sin(w * t + self.phase)
        qd = self.amp * w * np.cos(w * t + self.phase)
        closed = (t % self.grip_period) > 0.5 * self.grip_period
        grip = np.where(closed, 0.0, 0.04)  # finger opening [m]
        return q, qd, grip

    def action(self, t_next: float, q: np.ndarray) -> np.ndarray:
        """Action for the control step that ends at ``t_next`` [s]; ``q`` (num_envs, 9) measured positions."""
        q_des, qd_des, grip = self.desired(t_next)
        arm_sp = self.ctrl["arm"]
        g = np.clip((grip - 0.015) / 0.025, -1, 1)[:, None]  # gripper [-0.01, 0.04] m normalised
        m = self.mode
        if m == "pd_joint_pos":
            arm = q_des
        elif m == "pd_joint_delta_pos":
            arm = (q_des - q[:, :7]) / 0.1
        elif m == "pd_joint_target_delta_pos":
            arm = (q_des - arm_sp.target_qpos.numpy()) / 0.1
        elif m == "pd_joint_vel":
            arm = qd_des + 2.0 * (q_des - q[:, :7])  # [rad/s], normalised by the ±1 rad/s bound
        elif m == "pd_joint_pos_vel":
            arm = np.concatenate([q_des, qd_des], axis=1)
        elif m == "pd_joint_delta_pos_vel":
            arm = np.concatenate([(q_des - q[:, :7]) / 0.1, qd_des], axis=1)
        else:  # pragma: no cover - the parser validates the mode
            raise ValueError(m)
        return np.concatenate([arm, g], axis=1).astype(np.float32)


def _make_solver(name: str, model):
    import newton

    if name == "mujoco":
        return newton.solvers.SolverMuJoCo(model, disable_contacts=True)
    if name == "xpbd":
        return newton.solvers.SolverXPBD(model, iterations=4)
    return newton.solvers.SolverFeatherstone(model)


def run(args) -> dict:
    """Run the demo for parsed ``args``; returns the summary (also written to ``args.out/summary.json``)."""
    import newton
    import warp as wp

    import wpctrl

    from .robots import PANDA_INITIAL_Q, panda, panda_control_modes

    device = wp.get_device(args.device)
    rng = np.random.default_rng(args.seed)
    t_start = time.perf_counter()
    builder = newton.ModelBuilder()
    builder.replicate(panda(), args.envs)
    model = builder.finalize(device=device)
    model.set_gravity((0.0, 0.0, 0.0))  # every world (replicate copies the robot builder's gravity per world)
    mode = panda_control_modes()[args.control_mode]
    ctrl = wpctrl.build_controller(mode, model, args.control_freq, args.sim_freq, actuation=args.actuation)
    solver = _make_solver(args.solver, model)
    maximal = args.solver == "xpbd"  # maximal-coordinate solver: joint_q is recovered with eval_ik
    s0, s1 = model.state(), model.state()
    control = model.control()
    newton.eval_fk(model, s0.joint_q, s0.joint_qd, s0)
    ctrl.reset(s0, control=control)

    K = ctrl.num_substeps
    dt = 1.0 / args.sim_freq
    n_steps = max(1, round(args.seconds * args.control_freq))
    coord = ctrl._engine.binding.coord_index
    dof = ctrl._engine.binding.dof_index
    rest = np.asarray(PANDA_INITIAL_Q, np.float32)
    policy = _Policy(args.control_mode, ctrl, rest, args.envs, rng)
    if args.control_mode.startswith("pd_ee"):  # end-effector modes: EE actions, EE error and plot (demo_ee.py)
        from .demo_ee import EEPolicy

        policy = EEPolicy(policy, args.control_mode, ctrl, model)
    action = wp.zeros((args.envs, ctrl.action_dim), dtype=wp.float32, device=device)
    reset_mask = wp.zeros(args.envs, dtype=wp.bool, device=device)

    def controller_part():
        ctrl.set_action(action, s0)
        for _ in range(K):
            ctrl.before_simulation_step(s0, control)

    def advance(with_controller: bool):
        """K solver substeps (with wpctrl's substep call before each); the final state ends up in s0."""
        a, b = s0, s1
        for _ in range(K):
            if with_controller:
                ctrl.before_simulation_step(a, control)
            solver.step(a, b, control, None, dt)
            if maximal:
                newton.eval_ik(model, b, b.joint_q, b.joint_qd)
            a, b = b, a
        if a is not s0:
            s0.assign(a)

    def solver_part():
        advance(with_controller=False)

    def control_step():
        ctrl.set_action(action, s0)
        advance(with_controller=True)

    graph = None
    if args.graph:
        with wp.ScopedCapture(device=device) as cap:
            control_step()
        graph = cap.graph

    # Reset every env back to the rest pose after capture (capture ran one step on a zero action).
    q_host = s0.joint_q.numpy()
    q_host[coord] = rest
    s0.joint_q.assign(q_host)
    s0.joint_qd.zero_()
    if maximal:
        newton.eval_fk(model, s0.joint_q, s0.joint_qd, s0)
    ctrl.reset(s0, control=control)
    setup_s = time.perf_counter() - t_start

    steps_per_reset = max(1, args.control_freq)  # a few random envs reset every simulated second
    hist_t, hist_q, hist_des, hist_tgt = [], [], [], []
    err_sq = {"arm": 0.0, "gripper": 0.0}
    err_max = {"arm": 0.0, "gripper": 0.0}
    err_count = 0
    env_err = np.zeros(args.envs)
    env_n = np.zeros(args.envs)
    since_reset = np.zeros(args.envs)
    resets = 0
    loop_s = 0.0
    finite = True
    progress = None
    if args.progress:
        from tqdm.auto import tqdm

        progress = tqdm(total=n_steps, desc=f"{args.control_mode} x{args.envs}", unit="step", leave=False)
    t = 0.0
    for i in range(n_steps):
        q = s0.joint_q.numpy()[coord]
        action.assign(policy.action(t + 1.0 / args.control_freq, q))
        wp.synchronize_device(device)
        t0 = time.perf_counter()
        if graph is not None:
            wp.capture_launch(graph)
        else:
            control_step()
        wp.synchronize_device(device)
        loop_s += time.perf_counter() - t0
        t += 1.0 / args.control_freq

        q = s0.joint_q.numpy()[coord]
        finite &= bool(np.isfinite(q).all() and np.isfinite(control.joint_f.numpy()[dof]).all())
        q_des, _, grip = policy.desired(t)
        des = np.concatenate([q_des, grip[:, None], grip[:, None]], axis=1)
        err = np.abs(q - des)
        since_reset += 1.0 / args.control_freq
        # Score envs half a second after they (re)started at rest, off the trajectory.
        live = since_reset > 0.5
        if hasattr(policy, "record"):
            policy.record(t, s0, live)
        if live.any():
            for group, sl in (("arm", slice(0, 7)), ("gripper", slice(7, 9))):
                e = err[live][:, sl]
                err_sq[group] += float((e**2).mean()) * int(live.sum())
                err_max[group] = max(err_max[group], float(e.max()))
            env_err[live] += err[live][:, :7].mean(axis=1)
            env_n[live] += 1
            err_count += int(live.sum())
        hist_t.append(t)
        hist_q.append(q[0].copy())
        hist_des.append(des[0].copy())
        hist_tgt.append(control.joint_target_q.numpy()[coord[0]].copy())

        if i % steps_per_reset == steps_per_reset - 1 and args.envs > 1:
            mask = rng.random(args.envs) < 0.1
            mask[0] = False  # keep env 0's trace continuous for the plot
            if mask.any():
                q_host = s0.joint_q.numpy()
                noisy = rest[None, :] + np.concatenate(
                    [rng.normal(0, 0.05, (int(mask.sum()), 7)), np.zeros((int(mask.sum()), 2))], axis=1
                ).astype(np.float32)
                q_host[coord[mask]] = noisy
                s0.joint_q.assign(q_host)
                qd_host = s0.joint_qd.numpy()
                qd_host[dof[mask]] = 0.0
                s0.joint_qd.assign(qd_host)
                if maximal:
                    newton.eval_fk(model, s0.joint_q, s0.joint_qd, s0)
                reset_mask.assign(mask)
                ctrl.reset(s0, env_ids=reset_mask, control=control)
                resets += int(mask.sum())
                since_reset[mask] = 0.0
        if progress is not None:
            progress.update(1)
    if progress is not None:
        progress.close()

    ctrl_s, solver_s = _time_parts(controller_part, solver_part, device, args.graph)

    env_mean = env_err / np.maximum(env_n, 1)
    step_s = loop_s / n_steps
    summary = {
        "envs": args.envs,
        "device": str(device),
        "control_mode": args.control_mode,
        "actuation": args.actuation,
        "solver": args.solver,
        "graph": bool(args.graph),
        "sim_freq": args.sim_freq,
        "control_freq": args.control_freq,
        "substeps": K,
        "control_steps": n_steps,
        "sim_seconds": n_steps / args.control_freq,
        "setup_seconds": setup_s,
        "control_steps_per_s": 1.0 / step_s,
        "env_steps_per_s": args.envs / step_s,
        "controller_ms_per_step": 1e3 * ctrl_s,
        "solver_ms_per_step": 1e3 * solver_s,
        "controller_share": ctrl_s / max(ctrl_s + solver_s, 1e-12),
        "tracking_rms": {g: math.sqrt(v / max(err_count, 1)) for g, v in err_sq.items()},
        "tracking_max": err_max,
        "env_arm_error_mean": float(env_mean.mean()),
        "env_arm_error_spread": [float(x) for x in np.percentile(env_mean, [0, 50, 100])],
        "partial_resets": resets,
        "bad_actions": int(ctrl.bad_action_count.numpy().sum()),
        "all_finite": bool(finite),
    }
    if hasattr(policy, "summary"):
        summary.update(policy.summary())
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    _plot(out / "tracking.png", np.array(hist_t), np.array(hist_q), np.array(hist_des), np.array(hist_tgt),
          env_mean, ctrl.joint_names, summary)  # fmt: skip
    if hasattr(policy, "plot"):
        policy.plot(out / "ee_tracking.png", f"wpctrl demo: {args.control_mode}, env 0, TCP position")
    return summary


def _time_parts(controller_part, solver_part, device, graph: bool, repeats: int = 10):
    """Seconds per control step of the controller alone (set_action + K substep calls) and of the K solver steps
    alone, each captured in a graph when ``graph`` (as the rollout runs) or eager. Run after the rollout: it
    advances the simulation."""
    import warp as wp

    out = []
    for part in (controller_part, solver_part):
        fn = part
        if graph:
            with wp.ScopedCapture(device=device) as cap:
                part()
            g = cap.graph

            def fn(g=g):
                wp.capture_launch(g)

        fn()
        wp.synchronize_device(device)
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            fn()
            wp.synchronize_device(device)
            times.append(time.perf_counter() - t0)
        out.append(float(np.median(times)))
    return out[0], out[1]


def _plot(path: Path, t, q, des, tgt, env_err, names, summary) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(4, 3, figsize=(13, 11), constrained_layout=True)
    for j, ax in enumerate(axes.flat[:9]):
        ax.plot(t, des[:, j], "k--", lw=1, label="desired (policy)")
        ax.plot(t, tgt[:, j], color="tab:orange", lw=1, label="drive target (wpctrl)")
        ax.plot(t, q[:, j], color="tab:blue", lw=1.5, label="measured")
        ax.set_title(names[j], fontsize=9)
        ax.set_xlabel("t [s]", fontsize=8)
        ax.tick_params(labelsize=7)
    axes.flat[0].legend(fontsize=7)
    ax = axes.flat[9]
    finite = env_err[np.isfinite(env_err)]
    if finite.size:
        ax.hist(finite, bins=min(30, max(5, finite.size // 2)), color="tab:blue")
    ax.set_title("mean |arm error| per env [rad]", fontsize=9)
    ax.tick_params(labelsize=7)
    for ax in axes.flat[10:]:
        ax.axis("off")
    axes.flat[10].text(
        0.0,
        1.0,
        "\n".join(
            [
                f"{summary['control_mode']}, {summary['actuation']}, {summary['solver']}",
                f"{summary['envs']} envs on {summary['device']}",
                f"{summary['env_steps_per_s']:.0f} env-steps/s",
                f"arm RMS {summary['tracking_rms']['arm']:.4f} rad",
                f"gripper RMS {summary['tracking_rms']['gripper'] * 1e3:.2f} mm",
            ]
        ),
        va="top",
        fontsize=9,
        family="monospace",
    )
    fig.suptitle("wpctrl demo: env 0, every joint (Panda)", fontsize=11)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def format_summary(s: dict) -> str:
    from . import demo_ee

    rows = [
        ("envs", f"{s['envs']} on {s['device']}"),
        ("control mode", f"{s['control_mode']} ({s['actuation']}, {s['solver']}, graph={s['graph']})"),
        ("sim time", f"{s['sim_seconds']:.2f} s = {s['control_steps']} control steps x {s['substeps']} substeps"),
        ("control steps/s", f"{s['control_steps_per_s']:.1f}"),
        ("env-steps/s", f"{s['env_steps_per_s']:.0f}"),
        ("controller / step", f"{s['controller_ms_per_step']:.3f} ms ({100 * s['controller_share']:.1f}% of step)"),
        ("solver / step", f"{s['solver_ms_per_step']:.3f} ms"),
        ("arm tracking", f"RMS {s['tracking_rms']['arm']:.4f} rad, max {s['tracking_max']['arm']:.4f} rad"),
        (
            "gripper tracking",
            f"RMS {1e3 * s['tracking_rms']['gripper']:.2f} mm, max {1e3 * s['tracking_max']['gripper']:.2f} mm",
        ),
        *demo_ee.summary_rows(s),
        ("partial resets", str(s["partial_resets"])),
        ("all values finite", "yes" if s["all_finite"] else "NO"),
        ("setup (build, compile)", f"{s['setup_seconds']:.1f} s"),
    ]
    w = max(len(k) for k, _ in rows)
    return "\n".join(f"  {k:<{w}}  {v}" for k, v in rows)


def main(argv=None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    _check_args(parser, args)
    summary = run(args)
    print(format_summary(summary))
    if not summary["all_finite"]:
        print(
            "  the simulation went non-finite: this solver and actuation cannot hold the Panda's gains at this step "
            "size (MuJoCo with --actuation implicit holds ManiSkill's gains at 100 Hz; see the README)",
            file=sys.stderr,
        )
    extra = " and ee_tracking.png" if "ee_tracking_rms_m" in summary else ""
    print(f"  wrote {Path(args.out) / 'summary.json'} and {Path(args.out) / 'tracking.png'}{extra}")
    return 0 if summary["all_finite"] else 1
