"""Full control steps of N Pandas with a Newton solver: env-steps/s and the controller's share of the step.

One control step = ``set_action`` + K x (``before_simulation_step`` + ``solver.step``), K = sim_freq // control_freq
(100 Hz / 20 Hz = 5). XPBD does not integrate ``joint_q``, so each XPBD substep also runs ``newton.eval_ik`` to give
the controller measured joint positions (counted as solver work). With K odd, the last substep copies the state back
(``State.assign``) instead of swapping, so that a captured step replays correctly; eager and captured runs do the
same work. Steps alternate the actions +a and -a so that the virtual targets oscillate rather than drift.

For every (solver, N): eager and graph-captured (``wp.ScopedCapture`` of two control steps, ``wp.capture_launch``)
timings of the full step and of the controller alone (set_action + K before_simulation_step on the same state);
``ctrl share`` = controller time / full step time. ``env-steps/s`` = N / seconds per control step.

Run ``python bench/tasks/rollout.py --help``; results go to ``<out>/rollout_<device>.{json,md}``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402
import torch  # noqa: E402
import warp as wp  # noqa: E402

from bench.common import (  # noqa: E402
    DEFAULT_OUT,
    Sync,
    build_panda_model,
    fmt_envs,
    fmt_us,
    load_average,
    machine_info,
    md_table,
    measure,
    meta_markdown,
    panda_mode,
    parse_envs,
    write_results,
)

SOLVERS = ("mujoco", "xpbd")


def make_solver(name: str, model):
    import newton

    if name == "mujoco":
        return newton.solvers.SolverMuJoCo(model)
    if name == "xpbd":
        return newton.solvers.SolverXPBD(model)
    raise ValueError(f"unknown solver {name!r}; known: {SOLVERS}")


def run_one(args, solver_name: str, n_envs: int, device, sync: Sync) -> dict:
    import newton

    import wpctrl

    t0 = time.perf_counter()
    model = build_panda_model(n_envs, device, gravity=args.gravity)
    t_model = time.perf_counter() - t0
    mode = panda_mode(args.mode, args.interpolate)
    t0 = time.perf_counter()
    # Before the solver: MuJoCo creates its actuators from joint_target_mode at construction.
    ctrl = wpctrl.build_controller(
        mode, model, control_freq=args.control_freq, sim_freq=args.sim_freq, actuation=args.actuation
    )
    t_ctrl = time.perf_counter() - t0
    t0 = time.perf_counter()
    solver = make_solver(solver_name, model)
    t_solver = time.perf_counter() - t0
    K = ctrl.num_substeps
    dt = 1.0 / args.sim_freq
    states = [model.state(), model.state()]
    control = model.control()
    newton.eval_fk(model, states[0].joint_q, states[0].joint_qd, states[0])
    ctrl.reset(states[0])
    xpbd = solver_name == "xpbd"

    tdev = torch.device("cuda", wp.get_device(device).ordinal) if sync.cuda else torch.device("cpu")
    gen = torch.Generator(device=tdev).manual_seed(0)
    a_pos = torch.rand((n_envs, ctrl.action_dim), generator=gen, device=tdev) * 2 - 1
    a_neg = -a_pos
    sync()

    def control_step(action):
        s = states
        ctrl.set_action(action, s[0])
        for k in range(K):
            ctrl.before_simulation_step(s[0], control)
            solver.step(s[0], s[1], control, None, dt)
            if xpbd:
                newton.eval_ik(model, s[1], s[1].joint_q, s[1].joint_qd)
            if k == K - 1 and K % 2 == 1:
                s[0].assign(s[1])
            else:
                s[0], s[1] = s[1], s[0]

    def full_two():
        control_step(a_pos)
        control_step(a_neg)

    def ctrl_two():
        for action in (a_pos, a_neg):
            ctrl.set_action(action, states[0])
            for _ in range(K):
                ctrl.before_simulation_step(states[0], control)

    t0 = time.perf_counter()
    full_two()  # first use: kernel loading / compilation
    sync()
    t_first = time.perf_counter() - t0

    kw = {"repeats": args.repeats, "min_time": args.min_time, "warmup": 1, "clock": args.clock}
    # --steps control steps per timed sample at the least (two per call).
    kw["max_iters"] = 1 << 14
    res = {}
    res["full_eager"] = measure(full_two, sync, **kw, min_iters=max(1, args.steps // 2))
    res["ctrl_eager"] = measure(ctrl_two, sync, **kw, min_iters=max(1, args.steps // 2))
    graphs = {}
    if not args.no_graph:
        for name, fn in (("full_graph", full_two), ("ctrl_graph", ctrl_two)):
            with wp.ScopedCapture(device=device) as cap:
                fn()
            graphs[name] = cap.graph
            res[name] = measure(lambda g=cap.graph: wp.capture_launch(g), sync, **kw, min_iters=max(1, args.steps // 2))
    graph_check = None
    if "full_graph" in graphs:
        # The captured step does the eager step's work: from one snapshot, two eager control steps and one replay
        # reach the same joint positions (solver warm starts may differ by rounding).
        snap_q = wp.clone(states[0].joint_q)
        snap_qd = wp.clone(states[0].joint_qd)
        snap_body_q = wp.clone(states[0].body_q)
        snap_body_qd = wp.clone(states[0].body_qd)
        snap_ctrl = {u: {k: v.numpy().copy() for k, v in d.items()} for u, d in ctrl.get_state().items()}

        def restore():
            states[0].joint_q.assign(snap_q)
            states[0].joint_qd.assign(snap_qd)
            states[0].body_q.assign(snap_body_q)
            states[0].body_qd.assign(snap_body_qd)
            ctrl.set_state(snap_ctrl)

        restore()
        control_step(a_pos)
        q_one = states[0].joint_q.numpy().copy()
        control_step(a_neg)
        sync()
        q_eager = states[0].joint_q.numpy().copy()
        restore()
        wp.capture_launch(graphs["full_graph"])
        sync()
        q_graph = states[0].joint_q.numpy()
        moved = float(np.nanmax(np.abs(q_one - snap_q.numpy()))) if np.isfinite(q_one).any() else None
        graph_check = {
            "max_abs_dq_eager_vs_graph": float(np.nanmax(np.abs(q_graph - q_eager))),
            "max_abs_dq_in_one_control_step": moved,  # the robot does move (the +a/-a response is 2-periodic)
        }
    q = states[0].joint_q.numpy()
    finite = bool(np.isfinite(q).all())
    out = {
        "solver": solver_name,
        "envs": n_envs,
        "mode": args.mode,
        "actuation": args.actuation,
        "interpolate": args.interpolate,
        "num_substeps": K,
        "gravity": args.gravity,
        "finite_at_end": finite,
        "build_model_s": t_model,
        "build_controller_s": t_ctrl,
        "build_solver_s": t_solver,
        "first_two_steps_s": t_first,
        "graph_check": graph_check,
    }
    for kind in ("eager", "graph"):
        f, c = res.get(f"full_{kind}"), res.get(f"ctrl_{kind}")
        if f is None:
            continue
        t_full = f["median_s"] / 2  # per control step
        t_ctrl = c["median_s"] / 2
        out[kind] = {
            "us_per_control_step": t_full * 1e6,
            "env_steps_per_s": n_envs / t_full,
            "ctrl_us_per_control_step": t_ctrl * 1e6,
            "ctrl_share": t_ctrl / t_full,
            "control_steps_per_sample": 2 * f["iters"],
            "samples_us_per_control_step": [x * 1e6 / 2 for x in f["samples_s"]],
        }
    if "eager" in out and "graph" in out:
        out["graph_speedup"] = out["eager"]["us_per_control_step"] / out["graph"]["us_per_control_step"]
    return out


def markdown(meta: dict, rows: list[dict]) -> str:
    a = meta["args"]
    out = [
        "# Rollout: wpctrl + a Newton solver, full control steps\n",
        meta_markdown(meta) + "\n",
        f"Mode `{a['mode']}`, {a['actuation']} actuation, interpolate={a['interpolate']}, "
        f"{a['sim_freq']} Hz / {a['control_freq']} Hz (K = {a['sim_freq'] // a['control_freq']}), "
        f"gravity {'on' if a['gravity'] else 'off'}, no contacts. Per control step; 'ctrl' = set_action + K "
        f"before_simulation_step alone; share = ctrl / full. Clock: {a['clock']}, median of {a['repeats']}.\n\n",
    ]
    body = []
    for r in rows:
        for kind in ("eager", "graph"):
            if kind not in r:
                continue
            k = r[kind]
            body.append(
                [
                    r["solver"],
                    fmt_envs(r["envs"]),
                    kind,
                    fmt_us(k["us_per_control_step"] * 1e-6),
                    f"{k['env_steps_per_s']:,.0f}",
                    fmt_us(k["ctrl_us_per_control_step"] * 1e-6),
                    f"{100 * k['ctrl_share']:.1f} %",
                    "yes" if r["finite_at_end"] else "**no (NaN)**",
                ]
            )
    out.append(
        md_table(["solver", "envs", "run", "µs/control step", "env-steps/s", "ctrl µs", "ctrl share", "finite"], body)
    )
    return "".join(out)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--device", default="cuda:0" if wp.is_cuda_available() else "cpu")
    p.add_argument("--envs", default=None, help="comma list, k suffix (default: cpu 1,16,64; cuda 1k,4k,16k)")
    p.add_argument("--solver", default="mujoco,xpbd", help="comma list of: " + ", ".join(SOLVERS))
    p.add_argument("--steps", type=int, default=10, help="control steps per timed sample, at the least")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--min-time", type=float, default=None, help="seconds per sample (default cpu 0.2, cuda 0.05)")
    p.add_argument("--mode", default="pd_joint_target_delta_pos")
    p.add_argument(
        "--actuation",
        default="implicit",
        choices=["implicit", "explicit"],
        help="implicit (default): the solver's drive tracks the targets, as PhysX does for ManiSkill",
    )
    p.add_argument("--interpolate", action="store_true")
    p.add_argument(
        "--gravity", action="store_true", help="gravity on the robots (default off: ManiSkill's balance_passive_force)"
    )
    p.add_argument("--control-freq", type=int, default=20)
    p.add_argument("--sim-freq", type=int, default=100)
    p.add_argument("--no-graph", action="store_true")
    p.add_argument("--clock", default="wall", choices=["wall", "thread"])
    p.add_argument("--out", default=str(DEFAULT_OUT))
    p.add_argument("--tag", default=None)
    args = p.parse_args(argv)

    wp.init()
    device = wp.get_device(args.device)
    sync = Sync(device)
    if args.clock == "thread" and device.is_cuda:
        p.error("--clock thread only makes sense on the CPU device")
    if args.min_time is None:
        args.min_time = 0.05 if device.is_cuda else 0.2
    if args.envs is None:
        args.envs = "1k,4k,16k" if device.is_cuda else "1,16,64"
    envs = parse_envs(args.envs)
    solvers = [s.strip() for s in args.solver.split(",") if s.strip()]
    meta = machine_info(device)
    meta.update({"args": vars(args), "loadavg_start": load_average()})
    print(meta_markdown(meta), flush=True)
    rows = []
    t_start = time.perf_counter()
    for solver_name in solvers:
        for n in envs:
            try:
                r = run_one(args, solver_name, n, device, sync)
            except (RuntimeError, MemoryError) as e:
                print(f"[{solver_name} {fmt_envs(n)}] failed: {type(e).__name__}: {e}", flush=True)
                continue
            rows.append(r)
            for kind in ("eager", "graph"):
                if kind in r:
                    k = r[kind]
                    print(
                        f"[{solver_name} {fmt_envs(n)} {kind:>5}] {k['us_per_control_step']:10.1f} us/control step "
                        f"{k['env_steps_per_s']:12,.0f} env-steps/s  ctrl {k['ctrl_us_per_control_step']:8.1f} us "
                        f"({100 * k['ctrl_share']:.1f} %)  finite={r['finite_at_end']}  "
                        f"(build: model {r['build_model_s']:.1f} s, ctrl {r['build_controller_s']:.1f} s, "
                        f"solver {r['build_solver_s']:.1f} s, first steps {r['first_two_steps_s']:.1f} s) "
                        f"graph check {r['graph_check']}",
                        flush=True,
                    )
    meta["wall_s"] = time.perf_counter() - t_start
    meta["loadavg_end"] = load_average()
    tag = args.tag or ("cuda" if device.is_cuda else "cpu")
    j, m = write_results(args.out, f"rollout_{tag}", meta, rows, markdown(meta, rows))
    print(f"wrote {j} and {m}", flush=True)


if __name__ == "__main__":
    main()
