"""The main job: N Pandas driven through a ManiSkill control mode by wpctrl inside a real Newton solver.

``python -m wpctrl demo`` (or the ``wpctrl demo`` console script) builds N Pandas in one Newton model, runs a
scripted policy that exercises every part of the chosen control mode (sinusoidal joint motion and a gripper that
opens and closes, expressed in the mode's action space), resets a few random envs now and then, and reports
throughput, the controller's share of a control step and the tracking error against the policy's desired
trajectory. It writes ``summary.json`` (strict JSON: ``null`` for a non-finite number) and ``tracking.png`` into
``--out``.

Under ``torchrun --nproc-per-node=N -m wpctrl demo ...`` every rank runs ``--envs`` Pandas of its own on its own
device (``--device cuda``: ``cuda:{LOCAL_RANK}``) with its own seed; the statistics are reduced with
torch.distributed and rank 0 prints and writes them (:mod:`wpctrl.distributed`).

Gravity is off, as ManiSkill's Panda runs with ``balance_passive_force`` (gravity disabled on the robot links).
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from . import report
from .joint_task import JointTask

# This module imports only numpy at the top: the compile notice is printed before newton (~4 s) and the kernels load.
SOLVERS = ("mujoco", "xpbd", "featherstone")
ACTUATIONS = ("implicit", "explicit")
DEFAULT_OUT = "wpctrl-demo"  # git-ignored in this repository
STABLE_MIN_SIM_FREQ = 500  # [Hz] stable explicit PD tracks the Panda's 1000/100 gains from here (measured)
FEATHERSTONE_MIN_SIM_FREQ = 1000  # [Hz] Featherstone's penalty joint limits hold the fingers from here (measured)
COMPILE_NOTICE = "compiling kernels (first run only: ~1.5 min on a 2-core CPU; later runs load them from the cache)..."


def explicit_pd_choices() -> tuple[str, ...]:
    """The controller's own list of explicit PD laws (``build_controller(explicit_pd=...)``): a new law shows up
    in the demo without an edit here."""
    from ..controllers.base import _EXPLICIT_PD

    return tuple(_EXPLICIT_PD)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="wpctrl demo", description=__doc__.split("\n\n")[0])
    p.add_argument("--envs", type=int, default=16, help="parallel envs (Pandas), default 16; per rank under torchrun")
    p.add_argument(
        "--device", default="cpu", help="cpu | cuda | cuda:N (default cpu); under torchrun 'cuda' = cuda:LOCAL_RANK"
    )
    p.add_argument(
        "--control-mode",
        default="pd_joint_delta_pos",
        help="a ManiSkill Panda control mode, one of wpctrl.robots.PANDA_CONTROL_MODES (pd_joint_delta_pos, "
        "pd_joint_pos, pd_joint_target_delta_pos, pd_joint_vel, pd_joint_pos_vel, pd_joint_delta_pos_vel, ...)",
    )
    p.add_argument("--actuation", default="implicit", choices=ACTUATIONS)
    p.add_argument(
        "--explicit-pd",
        default=None,
        help="build_controller's explicit_pd with --actuation explicit: coupled (default: PhysX's coupled implicit "
        f"drive, 100 Hz) | stable (per-joint response, {STABLE_MIN_SIM_FREQ} Hz) | naive (refused: does not hold the "
        "Panda's gains)",
    )
    p.add_argument(
        "--solver",
        default="mujoco",
        choices=SOLVERS,
        help="mujoco (default: holds ManiSkill's 1000/100 Panda gains at 100 Hz), featherstone (with --actuation "
        f"explicit, at {FEATHERSTONE_MIN_SIM_FREQ} Hz), xpbd (refused: diverges on the Panda)",
    )
    p.add_argument("--seconds", type=float, default=4.0, help="simulated time [s] (default 4)")
    p.add_argument(
        "--sim-freq",
        type=int,
        default=None,
        help=f"solver steps per second [Hz] (default 100; {STABLE_MIN_SIM_FREQ} with --explicit-pd stable, "
        f"{FEATHERSTONE_MIN_SIM_FREQ} with featherstone)",
    )
    p.add_argument("--control-freq", type=int, default=20, help="control steps per second [Hz]")
    p.add_argument("--seed", type=int, default=0, help="run seed (each torchrun rank derives its own)")
    p.add_argument("--out", default=DEFAULT_OUT, help=f"folder for summary.json and tracking.png ({DEFAULT_OUT})")
    p.add_argument("--graph", action=argparse.BooleanOptionalAction, default=True, help="capture the control step")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=True, help="tqdm progress bar")
    return p


def _fail(parser: argparse.ArgumentParser, msg: str):
    parser.print_usage(sys.stderr)
    print(f"wpctrl demo: error: {msg}", file=sys.stderr)
    raise SystemExit(2)


DEFAULT_EXPLICIT_PD = "coupled"
"""The demo's explicit PD law: PhysX's coupled implicit drive holds the Panda at 100 Hz (arm RMS 0.034 rad)."""


def default_sim_freq(solver: str, actuation: str, explicit_pd: str | None = None) -> int:
    """The demo's solver rate [Hz] for a combination: the lowest rate measured to track the Panda at its gains."""
    if solver == "featherstone":
        return FEATHERSTONE_MIN_SIM_FREQ
    if actuation == "explicit" and (explicit_pd or DEFAULT_EXPLICIT_PD) == "stable":
        return STABLE_MIN_SIM_FREQ
    return 100


def unsupported(solver: str, actuation: str, explicit_pd: str | None, sim_freq: int) -> str | None:
    """Why a combination cannot hold the Panda at ManiSkill's gains (1000/100), or None when it can.

    Measured on the CPU with Newton 1.8 and MuJoCo-Warp 3.17 (this demo, 16 envs, 4 s; shared/reference/newton.md
    section 8 for XPBD and Featherstone's built-in drive). Arm RMS error against the desired trajectory: MuJoCo
    implicit 100 Hz 0.029 rad; stable explicit PD with MuJoCo 0.113 (100 Hz, chatter at the control rate), 0.047
    (200 Hz), 0.034 (500 Hz), 0.032 (1 kHz); with Featherstone 0.032 (1 kHz), NaN at 100 Hz. Coupled explicit PD
    (PhysX's drive) with MuJoCo 0.034 at 100 Hz.
    """
    if solver == "xpbd":
        return (
            "--solver xpbd: Newton 1.8's XPBD goes non-finite on the Panda once its gripper fingers are driven at "
            "ManiSkill's gains (NaN within 0.3 s at 100 Hz and 1 kHz, 4-16 iterations, implicit or explicit); use "
            "--solver mujoco, or featherstone with --actuation explicit"
        )
    if actuation == "implicit" and solver == "featherstone":
        return (
            "--solver featherstone --actuation implicit: Featherstone's built-in joint drive is an explicit PD and "
            "diverges at the Panda's 1000/100 gains (NaN within 0.05 s at 100 Hz); use --actuation explicit "
            "(coupled PD, the default) or --solver mujoco"
        )
    if actuation == "explicit" and explicit_pd == "naive":
        return (
            "--explicit-pd naive: the textbook explicit PD does not hold the Panda's 1000/100 gains (NaN within 0.1 s "
            "at 100 Hz; at 1 kHz finite but 0.8 rad RMS arm error: the 15 g fingers need a step under 2 m / Kd = "
            "0.3 ms); use --explicit-pd coupled (the default) or --actuation implicit"
        )
    if solver == "featherstone" and sim_freq < FEATHERSTONE_MIN_SIM_FREQ:
        return (
            f"--solver featherstone at --sim-freq {sim_freq}: Featherstone's joint limits are explicit penalty springs "
            f"(ke 1e4, kd 10) that the 15 g fingers hit when the gripper closes (NaN within 0.25 s at 100 Hz); use "
            f"--sim-freq {FEATHERSTONE_MIN_SIM_FREQ} (its default) or more, or --solver mujoco"
        )
    if actuation == "explicit" and explicit_pd == "stable" and sim_freq < STABLE_MIN_SIM_FREQ:
        return (
            f"--explicit-pd stable at --sim-freq {sim_freq}: stable PD uses each joint's own response only, and "
            f"below {STABLE_MIN_SIM_FREQ} Hz the coupled arm chatters at the control rate (arm RMS 0.11 rad at 100 "
            f"Hz vs 0.034 at 500 Hz); use --sim-freq {STABLE_MIN_SIM_FREQ} (its default) or more, --explicit-pd "
            "coupled (100 Hz), or --actuation implicit"
        )
    return None


def supported_combinations() -> str:
    """One line: what holds the Panda, at the demo's defaults."""
    return (
        f"MuJoCo with --actuation implicit (100 Hz), MuJoCo with --actuation explicit (coupled PD, 100 Hz; "
        f"--explicit-pd stable at --sim-freq {STABLE_MIN_SIM_FREQ}) and Featherstone with --actuation explicit "
        f"(--sim-freq {FEATHERSTONE_MIN_SIM_FREQ}) hold ManiSkill's Panda gains"
    )


def _check_args(parser, args) -> None:
    """Checks that need no heavy import (before the compile notice)."""
    if args.envs < 1:
        _fail(parser, f"--envs: expected >= 1, got {args.envs}")
    if not (args.seconds > 0 and math.isfinite(args.seconds)):
        _fail(parser, f"--seconds: expected a positive number, got {args.seconds}")
    if args.actuation == "explicit" and args.explicit_pd is None:
        args.explicit_pd = DEFAULT_EXPLICIT_PD
    if args.sim_freq is None:
        args.sim_freq = default_sim_freq(args.solver, args.actuation, args.explicit_pd)
    if args.control_freq < 1 or args.sim_freq < 1 or args.sim_freq % args.control_freq:
        _fail(
            parser,
            f"--sim-freq must be a positive multiple of --control-freq, got {args.sim_freq} and {args.control_freq}",
        )
    if args.actuation == "implicit" and args.explicit_pd is not None:
        _fail(parser, f"--explicit-pd {args.explicit_pd}: applies to --actuation explicit only")
    why = unsupported(args.solver, args.actuation, args.explicit_pd, args.sim_freq)
    if why:
        _fail(parser, why)
    if args.device != "cpu" and not (args.device == "cuda" or args.device.startswith("cuda:")):
        _fail(parser, f"--device: expected cpu, cuda or cuda:N, got {args.device!r}")


def _check_args_loaded(parser, args) -> None:
    """Checks against what newton / warp / wpctrl know (after the compile notice)."""
    import warp as wp

    from ..robots import PANDA_CONTROL_MODES

    if args.control_mode not in PANDA_CONTROL_MODES:
        _fail(parser, f"--control-mode: expected one of {list(PANDA_CONTROL_MODES)}, got {args.control_mode!r}")
    if args.explicit_pd is not None and args.explicit_pd not in explicit_pd_choices():
        _fail(parser, f"--explicit-pd: expected one of {list(explicit_pd_choices())}, got {args.explicit_pd!r}")
    if args.device != "cpu":
        if not wp.is_cuda_available():
            _fail(parser, f"--device {args.device}: no CUDA device is available on this machine")
        try:
            wp.get_device(args.device)
        except Exception as e:  # noqa: BLE001 - report any unknown device the same way
            _fail(parser, f"--device {args.device}: {e}")


def _check_extras(args) -> None:
    """A one-line error naming the extra to install, before anything is built (the base install lacks them)."""
    needed = [("matplotlib", "matplotlib")]
    if args.progress:
        needed.append(("tqdm", "tqdm"))
    if args.solver == "mujoco":
        needed += [("mujoco", "MuJoCo"), ("mujoco_warp", "MuJoCo-Warp")]
    missing = []
    for module, label in needed:
        try:  # found without importing it (matplotlib and MuJoCo-Warp take seconds to import)
            found = importlib.util.find_spec(module) is not None
        except (ImportError, ValueError):
            found = False
        if not found:
            missing.append(label)
    if missing:
        print(
            f"wpctrl demo: error: {', '.join(missing)} not installed; the demo needs the [demo] extra: "
            f'pip install -e ".[demo]" (in a clone) or pip install "wpctrl[demo]"',
            file=sys.stderr,
        )
        raise SystemExit(2)


# ----------------------------------------------------------------------------------------------------------------------
# What a control mode's demo does: the policy, the tracked quantities and the plotted trace. A mode family plugs in
# its own task through make_task (e.g. the end-effector modes in their own module).


def make_task(mode_name: str, ctrl, model, rest, num_envs: int, rng) -> JointTask:
    """The task for ``mode_name``. A family of modes plugs in here with its own module and an object with the same
    interface as :class:`JointTask`: ``groups`` ({name: (columns, SI unit, shown unit, scale)}; the first group also
    feeds the per-env histogram), ``tracking_label``, ``names`` (one per tracked column, for the plot),
    ``action(t_next, state) -> (num_envs, action_dim) float32`` and ``tracked(t, state, control) -> (measured,
    desired, drive target)``, each (num_envs, len(names))."""
    if mode_name.startswith("pd_ee"):  # end-effector modes: TCP actions and tracking (ee_task.py)
        from .ee_task import EETask

        return EETask(mode_name, ctrl, model, rest, num_envs, rng)
    return JointTask(mode_name, ctrl, model, rest, num_envs, rng)


def _make_solver(name: str, model):
    import newton

    if name == "mujoco":
        return newton.solvers.SolverMuJoCo(model, disable_contacts=True)
    if name == "xpbd":
        return newton.solvers.SolverXPBD(model, iterations=4)
    return newton.solvers.SolverFeatherstone(model)


def _say(ctx, msg: str) -> None:
    if ctx is None or ctx.is_main:
        print(msg, flush=True)


def run(args, ctx=None) -> dict:
    """Run the demo for parsed ``args`` (on this rank of ``ctx``, a :class:`wpctrl.distributed.DistContext`);
    returns the summary (rank 0 also writes it to ``args.out/summary.json``; other ranks return it too)."""
    import newton
    import warp as wp

    import wpctrl

    from ..robots import PANDA_INITIAL_Q, panda, panda_control_modes

    if ctx is None:
        from ..distributed import DistContext

        ctx = DistContext(device=args.device, seed=args.seed)
    device = wp.get_device(ctx.device)
    rng = np.random.default_rng(ctx.seed)
    t_start = time.perf_counter()
    builder = newton.ModelBuilder()
    builder.replicate(panda(), args.envs)
    model = builder.finalize(device=device)
    model.set_gravity((0.0, 0.0, 0.0))  # every world (replicate copies the robot builder's gravity per world)
    mode = panda_control_modes()[args.control_mode]
    extra = {"explicit_pd": args.explicit_pd} if args.actuation == "explicit" else {}
    ctrl = wpctrl.build_controller(mode, model, args.control_freq, args.sim_freq, actuation=args.actuation, **extra)
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
    task = make_task(args.control_mode, ctrl, model, rest, args.envs, rng)
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

    control_step()  # warm-up on a zero action: every kernel of the step is compiled (or loaded) here
    wp.synchronize_device(device)
    compile_s = time.perf_counter() - t_start
    _say(ctx, f"kernels ready in {compile_s:.1f} s (model, controller and solver built)")

    graph = None
    if args.graph:
        with wp.ScopedCapture(device=device) as cap:
            control_step()
        graph = cap.graph

    # Reset every env back to the rest pose (the warm-up and the capture ran steps on a zero action).
    q_host = s0.joint_q.numpy()
    q_host[coord] = rest
    s0.joint_q.assign(q_host)
    s0.joint_qd.zero_()
    if maximal:
        newton.eval_fk(model, s0.joint_q, s0.joint_qd, s0)
    ctrl.reset(s0, control=control)
    setup_s = time.perf_counter() - t_start

    steps_per_reset = max(1, args.control_freq)  # a few random envs reset every simulated second
    hist = {"t": [], "measured": [], "desired": [], "target": []}
    err_sq = {g: 0.0 for g in task.groups}
    err_max = {g: 0.0 for g in task.groups}
    err_count = 0
    first_group = next(iter(task.groups))
    env_err = np.zeros(args.envs)
    env_n = np.zeros(args.envs)
    since_reset = np.zeros(args.envs)
    nonfinite_env = np.zeros(args.envs, dtype=bool)
    diverged_at = None
    resets = 0
    loop_s = 0.0
    steps_done = 0
    progress = None
    if args.progress and ctx.is_main:
        from tqdm.auto import tqdm

        desc = f"{args.control_mode} x{args.envs}" + (f" x{ctx.world_size} ranks" if ctx.world_size > 1 else "")
        progress = tqdm(total=n_steps, desc=desc, unit="step", leave=False)
    t = 0.0
    for i in range(n_steps):
        action.assign(task.action(t + 1.0 / args.control_freq, s0))
        wp.synchronize_device(device)
        t0 = time.perf_counter()
        if graph is not None:
            wp.capture_launch(graph)
        else:
            control_step()
        wp.synchronize_device(device)
        loop_s += time.perf_counter() - t0
        steps_done += 1
        t += 1.0 / args.control_freq

        q = s0.joint_q.numpy()[coord]
        bad = ~np.isfinite(q).all(axis=1) | ~np.isfinite(control.joint_f.numpy()[dof]).all(axis=1)
        nonfinite_env |= bad
        measured, desired, target = task.tracked(t, s0, control)
        err = np.abs(measured - desired)
        since_reset += 1.0 / args.control_freq
        # Score envs half a second after they (re)started at rest, off the trajectory.
        live = since_reset > 0.5
        if live.any():
            for group, (cols, *_) in task.groups.items():
                e = err[live][:, cols]
                err_sq[group] += float((e**2).mean()) * int(live.sum())
                err_max[group] = float(np.maximum(err_max[group], e.max()))  # NaN propagates, as in the RMS
            env_err[live] += err[live][:, task.groups[first_group][0]].mean(axis=1)
            env_n[live] += 1
            err_count += int(live.sum())
        hist["t"].append(t)
        hist["measured"].append(measured[0].copy())
        hist["desired"].append(desired[0].copy())
        hist["target"].append(target[0].copy())
        if progress is not None:
            progress.update(1)
        if bad.any():
            diverged_at = t  # nothing to learn from a NaN rollout: stop here
            break

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
        progress.close()

    ctrl_s, solver_s = report.time_parts(controller_part, solver_part, device, args.graph)
    scaling = None
    if ctx.distributed:
        scaling = report.solo_vs_concurrent(ctx, graph, control_step, device, args.envs)

    env_mean = env_err / np.maximum(env_n, 1)
    env_mean[nonfinite_env] = np.nan
    step_s = loop_s / steps_done
    rank_stats = report.RankStats(
        rank=ctx.rank,
        seed=ctx.seed,
        envs=args.envs,
        control_steps=steps_done,
        loop_s=loop_s,
        env_steps_per_s=args.envs / step_s,
        controller_ms_per_step=1e3 * ctrl_s,
        solver_ms_per_step=1e3 * solver_s,
        err_sq=err_sq,
        err_max=err_max,
        err_count=err_count,
        nonfinite_envs=int(nonfinite_env.sum()),
        bad_actions=int(ctrl.bad_action_count.numpy().sum()),
        partial_resets=resets,
        setup_s=setup_s,
        compile_s=compile_s,
        diverged_at=diverged_at,
    )
    config = {
        "device": str(device),
        "control_mode": args.control_mode,
        "actuation": args.actuation,
        "explicit_pd": args.explicit_pd if args.actuation == "explicit" else None,
        "solver": args.solver,
        "graph": bool(args.graph),
        "sim_freq": args.sim_freq,
        "control_freq": args.control_freq,
        "substeps": K,
        "seed": args.seed,
        "tracking": task.tracking_label,
        "units": {g: u for g, (_, u, *_) in task.groups.items()},
    }
    summary, env_means = report.combine(ctx, rank_stats, config, env_mean, scaling, task.groups, args.control_freq)
    if ctx.is_main:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "summary.json").write_text(report.strict_json(summary))
        report.plot(out / "tracking.png", {k: np.array(v) for k, v in hist.items()}, env_means, task, summary)
    return summary


def main(argv=None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    _check_args(parser, args)
    _check_extras(args)
    from .. import distributed

    if not distributed.launched() or os.environ.get("RANK") == "0":
        print(COMPILE_NOTICE, flush=True)  # within a second or two of the command: newton's import alone takes ~4 s
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING  # no banner, no "Module ... load" lines: the demo says what it does
    _check_args_loaded(parser, args)

    try:
        ctx = distributed.init(device=args.device, seed=args.seed)
    except (ValueError, ImportError, RuntimeError) as e:
        _fail(parser, str(e))
    try:
        summary = run(args, ctx)
    finally:
        ctx.shutdown()
    if not ctx.is_main:
        return 0 if summary["all_finite"] else 1
    print(report.format_summary(summary))
    if not summary["all_finite"]:
        print(
            f"  the simulation went non-finite at t = {summary['diverged_at_s']} s: {summary['solver']} with "
            f"{summary['actuation']} actuation did not hold the Panda's gains at {summary['sim_freq']} Hz; "
            f"{supported_combinations()} (see the README)",
            file=sys.stderr,
        )
    print(f"  wrote {Path(args.out) / 'summary.json'} and {Path(args.out) / 'tracking.png'}")
    return 0 if summary["all_finite"] else 1
