"""One demo run: build N Pandas, a controller and a solver, warm up and capture the control step, roll the scripted
policy out with partial resets, and reduce the tracking statistics (over ranks under torchrun)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from . import report
from .joint_task import JointTask
from .notice import CompileNotice
from .options import COMPILE_ESTIMATE, MAXIMAL_SOLVERS, SCORE_AFTER_S, compile_what

# ----------------------------------------------------------------------------------------------------------------------
# What a control mode's demo does: the policy, the tracked quantities and the plotted trace. A mode family plugs in
# its own task through make_task (e.g. the end-effector modes in their own module).


def make_task(mode_name: str, ctrl, model, rest, num_envs: int, rng, robot: str = "panda") -> JointTask:
    """The task for ``mode_name``. A family of modes plugs in here with its own module and an object with the same
    interface as :class:`JointTask`: ``groups`` ({name: (columns, SI unit, shown unit, scale)}; the first group also
    feeds the per-env histogram), ``tracking_label``, ``names`` (one per tracked column, for the plot),
    ``action(t_next, state) -> (num_envs, action_dim) float32`` and ``tracked(t, state, control) -> (measured,
    desired, drive target)``, each (num_envs, len(names)); optionally ``extra_names``, ``extra_unit`` and
    ``extra(state, control) -> (applied, commanded)`` for plot panels that are not scored (the impedance modes'
    torques). A robot other than the Panda gets the generic task (robot_task.py)."""
    if robot != "panda":
        from .robot_task import RobotTask

        return RobotTask(mode_name, ctrl, model, num_envs, rng, robot)
    if mode_name.startswith("pd_ee"):  # end-effector modes: TCP actions and tracking (ee_task.py)
        from .ee_task import EETask

        return EETask(mode_name, ctrl, model, rest, num_envs, rng)
    if mode_name.startswith(("osc_", "joint_impedance")):  # torque-level modes, their torques plotted too
        from .impedance_task import JointImpedanceTask, OSCTask

        cls = OSCTask if mode_name.startswith("osc_") else JointImpedanceTask
        return cls(mode_name, ctrl, model, rest, num_envs, rng)
    return JointTask(mode_name, ctrl, model, rest, num_envs, rng)


def _make_solver(name: str, model, contacts: bool = False):
    """The demo's Newton solver ``name`` with the settings it was measured with (contacts only where a floating robot
    stands on the ground: a Panda is alone in its world, its self-collision off)."""
    import newton

    S = newton.solvers
    if name == "mujoco":
        return S.SolverMuJoCo(model, disable_contacts=not contacts)
    if name == "steel":
        return S.SolverSteel(model, enable_joint_limits=True)  # the fingers' limits (off by default in Steel)
    if name == "kamino":
        return S.SolverKamino(model)
    if name == "semi_implicit":
        return S.SolverSemiImplicit(model)
    if name == "xpbd":
        return S.SolverXPBD(model, iterations=4)
    return S.SolverFeatherstone(model)


def _say(ctx, msg: str) -> None:
    if ctx is None or ctx.is_main:
        print(msg, flush=True)


MIN_BODY_MASS = 1e-3  # [kg]
MIN_BODY_INERTIA = 1e-6  # [kg m^2]


def _bound_mass(builder) -> None:
    """Give massless bodies a token mass and inertia, as MuJoCo's ``boundmass`` / ``boundinertia`` would: MuJoCo
    refuses moving bodies without mass, and some ManiSkill assets have them (Fetch's planar base joints hang on two
    massless links)."""
    import warp as wp

    for b, m in enumerate(builder.body_mass):
        if m <= 0.0:
            inertia = wp.mat33(MIN_BODY_INERTIA, 0.0, 0.0, 0.0, MIN_BODY_INERTIA, 0.0, 0.0, 0.0, MIN_BODY_INERTIA)
            builder.body_mass[b] = MIN_BODY_MASS
            builder.body_inv_mass[b] = 1.0 / MIN_BODY_MASS
            builder.body_inertia[b] = inertia
            builder.body_inv_inertia[b] = wp.inverse(inertia)


class Rig:
    """N Pandas in one Newton model with the controller and the solver: the demo's control step and its two parts."""

    def __init__(self, args, device):
        import newton
        import warp as wp

        import wpctrl

        from ..robots import panda, panda_control_modes

        builder = newton.ModelBuilder()
        self.ground = False
        if args.robot == "panda":
            builder.replicate(panda(), args.envs)
            mode = panda_control_modes()[args.control_mode]
        else:
            from ..maniskill import load_robot

            robot = load_robot(args.robot)
            _bound_mass(robot.builder)
            builder.replicate(robot.builder, args.envs)
            mode = robot.control_modes[args.control_mode]
            free = int(newton.JointType.FREE)
            if any(t == free for t in robot.builder.joint_type):  # a floating robot stands on the ground
                builder.add_ground_plane()
                self.ground = True
        self.model = model = builder.finalize(device=device)
        extra = {"explicit_pd": args.explicit_pd} if args.actuation == "explicit" else {}
        if args.solver != "mujoco":
            # ManiSkill's balance_passive_force (gravity off the robot) needs MuJoCo's per-body gravity compensation;
            # with any other solver the demo switches it off and takes gravity out of the (robot-only) worlds instead.
            extra["balance_passive_force"] = False
            model.set_gravity((0.0, 0.0, 0.0))
        self.ctrl = wpctrl.build_controller(
            mode, model, args.control_freq, args.sim_freq, actuation=args.actuation, **extra
        )
        self.solver = _make_solver(args.solver, model, contacts=self.ground)
        self.maximal = args.solver in MAXIMAL_SOLVERS  # joint_q is recovered from the bodies with eval_ik
        self.s0, self.s1 = model.state(), model.state()
        self.control = model.control()
        newton.eval_fk(model, self.s0.joint_q, self.s0.joint_qd, self.s0)
        self.ctrl.reset(self.s0, control=self.control)
        self.dt = 1.0 / args.sim_freq
        self.action = wp.zeros((args.envs, self.ctrl.action_dim), dtype=wp.float32, device=device)

    def controller_part(self):
        """set_action and the K substep calls, without the solver."""
        self.ctrl.set_action(self.action, self.s0)
        for _ in range(self.ctrl.num_substeps):
            self.ctrl.before_simulation_step(self.s0, self.control)

    def advance(self, with_controller: bool):
        """K solver substeps (with wpctrl's substep call before each); the final state ends up in s0."""
        import newton

        a, b = self.s0, self.s1
        for _ in range(self.ctrl.num_substeps):
            if with_controller:
                self.ctrl.before_simulation_step(a, self.control)
            self.solver.step(a, b, self.control, None, self.dt)
            if self.maximal:
                newton.eval_ik(self.model, b, b.joint_q, b.joint_qd)
            a, b = b, a
        if a is not self.s0:
            self.s0.assign(a)

    def solver_part(self):
        self.advance(with_controller=False)

    def control_step(self):
        self.ctrl.set_action(self.action, self.s0)
        self.advance(with_controller=True)


def run(args, ctx=None) -> dict:
    """Run the demo for parsed ``args`` (on this rank of ``ctx``, a :class:`wpctrl.distributed.DistContext`);
    returns the summary (rank 0 also writes it to ``args.out/summary.json``; other ranks return it too)."""
    import newton
    import warp as wp

    from ..robots import PANDA_INITIAL_Q

    if ctx is None:
        from ..distributed import DistContext

        ctx = DistContext(device=args.device, seed=args.seed)
    device = wp.get_device(ctx.device)
    rng = np.random.default_rng(ctx.seed)
    t_start = time.perf_counter()
    notice = CompileNotice(lambda msg: _say(ctx, msg), compile_what(args), COMPILE_ESTIMATE)
    with notice:  # says so just before Warp compiles a module (a cold kernel cache), not otherwise
        rig = Rig(args, device)
        rest = np.asarray(PANDA_INITIAL_Q, np.float32)
        task = make_task(args.control_mode, rig.ctrl, rig.model, rest, args.envs, rng, args.robot)
        rig.control_step()  # warm-up on a zero action: every kernel of the step is compiled (or loaded) here
    wp.synchronize_device(device)
    compile_s = time.perf_counter() - t_start
    _say(ctx, f"kernels ready in {compile_s:.1f} s ({notice.summary()}; model, controller and solver built)")
    model, ctrl, s0, control = rig.model, rig.ctrl, rig.s0, rig.control
    action, control_step = rig.action, rig.control_step
    n_steps = max(1, round(args.seconds * args.control_freq))
    coord = ctrl._engine.binding.coord_index
    dof = ctrl._engine.binding.dof_index
    reset_mask = wp.zeros(args.envs, dtype=wp.bool, device=device)

    graph = None
    if args.graph:
        with wp.ScopedCapture(device=device) as cap:
            control_step()
        graph = cap.graph

    # Reset every env back to the rest pose (the warm-up and the capture ran steps on a zero action).
    q_rest = model.joint_q.numpy()  # the model's initial pose: the Panda's rest, a ManiSkill robot's keyframe
    if args.robot == "panda":
        q_rest[coord] = rest
    nq, nd = model.joint_coord_count // args.envs, model.joint_dof_count // args.envs  # per world (replicated)
    s0.joint_q.assign(q_rest)
    s0.joint_qd.zero_()
    newton.eval_fk(model, s0.joint_q, s0.joint_qd, s0)
    ctrl.reset(s0, control=control)
    setup_s = time.perf_counter() - t_start

    steps_per_reset = max(1, args.control_freq)  # a few random envs reset every simulated second
    hist = {"t": [], "measured": [], "desired": [], "target": []}
    if hasattr(task, "extra"):  # extra plot panels (the impedance modes' torques)
        hist.update(extra_applied=[], extra_commanded=[])
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
        live = since_reset > SCORE_AFTER_S
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
        if "extra_applied" in hist:
            applied, commanded = task.extra(s0, control)
            hist["extra_applied"].append(applied[0].copy())
            hist["extra_commanded"].append(commanded[0].copy())
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
                qd_host = s0.joint_qd.numpy()
                for w in np.flatnonzero(mask):  # the whole world back to its rest pose (a floating root included)
                    q_host[w * nq : (w + 1) * nq] = q_rest[w * nq : (w + 1) * nq]
                    qd_host[w * nd : (w + 1) * nd] = 0.0
                if args.robot == "panda":  # and the arm a little off it
                    noise = rng.normal(0, 0.05, (int(mask.sum()), 7)).astype(np.float32)
                    q_host[coord[mask][:, :7]] += noise
                s0.joint_q.assign(q_host)
                s0.joint_qd.assign(qd_host)
                newton.eval_fk(model, s0.joint_q, s0.joint_qd, s0)
                reset_mask.assign(mask)
                ctrl.reset(s0, env_ids=reset_mask, control=control)
                resets += int(mask.sum())
                since_reset[mask] = 0.0
    if progress is not None:
        progress.close()

    ctrl_s, solver_s = report.time_parts(rig.controller_part, rig.solver_part, device, args.graph)
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
        "robot": args.robot,
        "control_mode": args.control_mode,
        "actuation": args.actuation,
        "explicit_pd": args.explicit_pd if args.actuation == "explicit" else None,
        "solver": args.solver,
        "graph": bool(args.graph),
        "sim_freq": args.sim_freq,
        "control_freq": args.control_freq,
        "substeps": ctrl.num_substeps,
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
