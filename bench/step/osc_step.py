"""Time wpctrl's operational-space control step against its end-effector step and Newton's OSC controller.

On N Pandas, one control step (K = 5 substeps at ManiSkill's 20 / 100 Hz) of:

* ``osc_ee_delta_pose`` (wpctrl): ``set_action`` + K × ``before_simulation_step``: the target pose once, then before
  every substep the OSC torques (full inertial decoupling, gravity compensation, null-space posture) from the
  measured state, clamped and written to ``Control.joint_f``; the gripper's mimic drive targets;
* ``joint_impedance_delta_pos`` (wpctrl): the same structure, joint impedance with inertial and gravity compensation;
* ``pd_ee_delta_pose`` (wpctrl): ManiSkill's EE mode (one damped least-squares IK step, position drive targets: the
  solver's implicit drive, no per-substep work);
* Newton's ``ControllerOperationalSpace`` with the same options, gains, frame, target and posture, stepped K times per
  control step (its torques depend on the state, as wpctrl's), writing the arm's DOFs of ``Control.joint_f``.

Each eager and captured in a graph (``wp.ScopedCapture``; Newton's controller is graphable). Before timing, the
script checks that wpctrl's OSC torques equal Newton's on the same state (``check``: max |Δτ| / max |τ|).

With ``--physics-envs N`` (default: the CUDA default 4096, off on CPU) it also times one MuJoCo-Warp step of the
same Pandas and reports each control step as a fraction of the control step's K physics steps.

Run ``python bench/step/osc_step.py --help``; results go to ``<out>/osc_step_<device>.{json,md}``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

from bench.common import (  # noqa: E402
    Sync,
    add_run_args,
    build_panda_model,
    finish_run,
    fmt_envs,
    fmt_ratio,
    fmt_us,
    md_table,
    measure,
    measure_interleaved,
    meta_markdown,
    panda_mode,
    parse_envs,
    parse_run_args,
    start_run,
)

VARIANTS = ["osc_eager", "osc_graph", "ji_eager", "ji_graph", "ee_eager", "ee_graph", "newton_eager", "newton_graph"]
LABELS = {
    "osc_eager": "wpctrl osc_ee_delta_pose eager",
    "osc_graph": "wpctrl osc_ee_delta_pose graph",
    "ji_eager": "wpctrl joint_impedance_delta_pos eager",
    "ji_graph": "wpctrl joint_impedance_delta_pos graph",
    "ee_eager": "wpctrl pd_ee_delta_pose eager",
    "ee_graph": "wpctrl pd_ee_delta_pose graph",
    "newton_eager": "Newton ControllerOperationalSpace eager",
    "newton_graph": "Newton ControllerOperationalSpace graph",
}


class NewtonOSC:
    """Newton's ControllerOperationalSpace with the options, gains, target and posture of a wpctrl OSC controller,
    stepped on ``state`` into the arm's DOFs of ``control.joint_f`` (an indexed view: the controller scatters)."""

    def __init__(self, ctrl, model, state, control):
        from newton.controllers import ControllerOperationalSpace

        arm = ctrl["arm"]
        cfg = arm.config
        E = ctrl.num_envs
        dev = model.device
        kp = arm.task_stiffness.numpy()[0]
        kd = arm.task_damping.numpy()[0]
        unit = arm._ee
        root = unit.env_root.numpy()
        # the operational frame: each env's root frame in the world (env_root maps it onto env 0's world frame)
        frames = [wp.transform_inverse(wp.transform(*r)) for r in root]
        self.ctrl = ControllerOperationalSpace(
            model,
            tool_sites=cfg.ee_link,
            joints=list(cfg.joint_names),
            motion_stiffness=wp.array([wp.spatial_vector(*kp)] * E, dtype=wp.spatial_vector, device=dev),
            motion_damping=wp.array([wp.spatial_vector(*kd)] * E, dtype=wp.spatial_vector, device=dev),
            operational_frame_pose_world=wp.array(frames, dtype=wp.transform, device=dev),
            use_inertia_decoupling=cfg.inertial_dynamics_decoupling,
            use_partial_inertia_decoupling=cfg.partial_inertial_dynamics_decoupling,
            use_gravity_compensation=cfg.gravity_compensation,
            use_null_space_control=cfg.nullspace_control == "position",
            null_space_stiffness=wp.array(arm.stiffness.numpy().reshape(-1), dtype=float, device=dev),
            null_space_damping=wp.array(arm.damping.numpy().reshape(-1), dtype=float, device=dev),
        )
        self.inputs = self.ctrl.input()
        self.outputs = self.ctrl.output()
        self.inputs.joint_q = state.joint_q
        self.inputs.joint_qd = state.joint_qd
        tp = arm.target_pose.numpy()
        self.inputs.desired_tool_pose_operational.assign(
            np.concatenate([tp[:, :3], tp[:, 4:], tp[:, 3:4]], axis=1).astype(np.float32)
        )
        self.inputs.joint_q_des_null.assign(arm.target_qpos.numpy().reshape(-1))
        self.inputs.joint_qd_des_null.zero_()
        self.outputs.joint_f = control.joint_f[self.ctrl.qd_start]

    def step(self):
        self.ctrl.step(inputs=self.inputs, outputs=self.outputs, dt=0.01)


def _setup(name: str, model, state, control, seed: int):
    import wpctrl

    mode = panda_mode(name)
    if name != "pd_ee_delta_pose":
        mode["balance_passive_force"] = False  # the controller compensates gravity (any solver)
    ctrl = wpctrl.build_controller(mode, model)
    rng = np.random.default_rng(seed)
    action = wp.array(rng.uniform(-1, 1, (ctrl.num_envs, ctrl.action_dim)).astype(np.float32), device=model.device)
    ctrl.reset(state, control=control)
    K = ctrl.num_substeps

    def step():
        ctrl.set_action(action, state)
        for _ in range(K):
            ctrl.before_simulation_step(state, control)

    return ctrl, step


def run_one(args, n_envs: int, device, sync: Sync) -> list[dict]:
    import newton

    t0 = time.perf_counter()
    model = build_panda_model(n_envs, device)
    state = model.state()
    rng = np.random.default_rng(0)
    q = state.joint_q.numpy().reshape(n_envs, -1)
    q[:, :7] += rng.uniform(-0.2, 0.2, (n_envs, 7)).astype(np.float32)
    state.joint_q.assign(q.reshape(-1))
    state.joint_qd.assign(rng.uniform(-0.3, 0.3, state.joint_qd.shape[0]).astype(np.float32))
    controls = {k: model.control() for k in ("osc", "ji", "ee", "newton")}
    steps, ctrls = {}, {}
    for key, name in (("osc", "osc_ee_delta_pose"), ("ji", "joint_impedance_delta_pos"), ("ee", "pd_ee_delta_pose")):
        if f"{key}_eager" in args.variants or f"{key}_graph" in args.variants or key == "osc":
            ctrls[key], steps[key] = _setup(name, model, state, controls[key], seed=1)
    osc = ctrls["osc"]
    steps["osc"]()
    newton_osc = NewtonOSC(osc, model, state, controls["newton"])
    steps["newton"] = lambda: [newton_osc.step() for _ in range(osc.num_substeps)]
    build_s = time.perf_counter() - t0
    # Same state, same target: the torques of one substep.
    osc.before_simulation_step(state, controls["osc"])
    newton_osc.step()
    sync()
    dof = osc["arm"].dof_index
    ours = osc["arm"].target_effort.numpy().astype(np.float64)  # the commanded torque (joint_f: clamped to 100 N·m)
    ref = controls["newton"].joint_f.numpy()[dof].astype(np.float64)
    check = {"osc_vs_newton_max_rel_torque_diff": float(np.abs(ours - ref).max() / max(np.abs(ref).max(), 1e-9))}
    print(f"[{fmt_envs(n_envs)}] check {check}", flush=True)
    fns = {}
    for key in ("osc", "ji", "ee", "newton"):
        if key not in steps:
            continue
        if f"{key}_eager" in args.variants:
            fns[f"{key}_eager"] = steps[key]
        if f"{key}_graph" in args.variants:
            steps[key]()
            sync()
            with wp.ScopedCapture(device=device) as cap:
                steps[key]()
            fns[f"{key}_graph"] = (lambda g: lambda: wp.capture_launch(g))(cap.graph)
    times = measure_interleaved(
        fns, sync, repeats=args.repeats, min_time=args.min_time, warmup=args.warmup, clock=args.clock
    )
    t_ee = times.get("ee_graph", {}).get("median_s")
    t_newton = times.get("newton_graph", {}).get("median_s")
    rows = []
    for name in VARIANTS:
        if name not in times:
            continue
        t = times[name]["median_s"]
        rows.append(
            {
                "envs": n_envs,
                "num_substeps": osc.num_substeps,
                "variant": name,
                "us_per_step": t * 1e6,
                "ns_per_env_step": t * 1e9 / n_envs,
                "over_ee_graph": (t / t_ee) if t_ee else None,
                "newton_graph_over_this": (t_newton / t) if t_newton else None,
                "iters": times[name]["iters"],
                "samples_us": [x * 1e6 for x in times[name]["samples_s"]],
                "clock": args.clock,
                "build_s": build_s,
                "check": check,
            }
        )
    if n_envs == args.physics_envs:
        solver = newton.solvers.SolverMuJoCo(model, disable_contacts=True)
        s1 = model.state()
        newton.eval_fk(model, state.joint_q, state.joint_qd, state)
        c = controls["osc"]

        def phys():
            solver.step(state, s1, c, None, 1.0 / 100)
            state.assign(s1)

        phys()
        sync()
        t_phys = measure(phys, sync, repeats=args.repeats, min_time=args.min_time, warmup=2)["median_s"]
        K = osc.num_substeps
        rows.append(
            {
                "envs": n_envs,
                "variant": "mujoco_warp_step",
                "us_per_step": t_phys * 1e6,
                "step_over_control_step_physics": {k: v["median_s"] / (K * t_phys) for k, v in times.items()},
            }
        )
    return rows


def markdown(meta: dict, rows: list[dict]) -> str:
    out = ["# OSC control step: wpctrl vs its EE step and Newton's ControllerOperationalSpace\n", meta_markdown(meta)]
    out.append("")
    table = []
    for r in rows:
        if r["variant"] == "mujoco_warp_step":
            continue
        table.append(
            [
                fmt_envs(r["envs"]),
                LABELS[r["variant"]],
                fmt_us(r["us_per_step"] * 1e-6),
                f"{r['ns_per_env_step']:.1f}",
                fmt_ratio(r["over_ee_graph"]),
                fmt_ratio(r["newton_graph_over_this"]),
            ]
        )
    header = ["envs", "variant", "µs / control step", "ns / env-step", "÷ EE step (graph)", "Newton graph ÷ this"]
    out.append(md_table(header, table))
    checks = {fmt_envs(r["envs"]): r["check"]["osc_vs_newton_max_rel_torque_diff"] for r in rows if "check" in r}
    out.append(f"\nTorques vs Newton's on the same state (max |Δτ| / max |τ|): {checks}\n")
    for r in rows:
        if r["variant"] == "mujoco_warp_step":
            fr = ", ".join(f"{LABELS[k]} {100 * v:.1f} %" for k, v in r["step_over_control_step_physics"].items())
            out.append(
                f"MuJoCo-Warp Panda step at {fmt_envs(r['envs'])} envs: {fmt_us(r['us_per_step'] * 1e-6)} µs. "
                f"Control step / the control step's K physics steps: {fr}.\n"
            )
    return "\n".join(out)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_args(p, envs_help="comma list, k/M suffixes (default: cpu 1,64; cuda 1k,4k,16k)", variants=VARIANTS,
                 torch_threads=False)  # fmt: skip
    p.add_argument("--physics-envs", type=int, default=None, help="time MuJoCo-Warp at this N (default: cuda 4096)")
    args = parse_run_args(p, argv)
    device, sync, meta = start_run(p, args, cpu_envs="1,64", cuda_envs="1k,4k,16k")
    if args.physics_envs is None:
        args.physics_envs = 4096 if device.is_cuda else -1
    rows = []
    t_start = time.perf_counter()
    for n in parse_envs(args.envs):
        try:
            got = run_one(args, n, device, sync)
        except (RuntimeError, MemoryError) as e:
            print(f"[{fmt_envs(n)}] skipped: {type(e).__name__}: {e}", flush=True)
            break
        for r in got:
            if r["variant"] == "mujoco_warp_step":
                print(f"[{fmt_envs(n)}] MuJoCo-Warp step {r['us_per_step']:.1f} us", flush=True)
                continue
            print(
                f"[{fmt_envs(n)}] {LABELS[r['variant']]:>40}: {r['us_per_step']:10.2f} us/step "
                f"{r['ns_per_env_step']:9.2f} ns/env-step  ÷EE {fmt_ratio(r['over_ee_graph']):>7}  "
                f"Newton÷this {fmt_ratio(r['newton_graph_over_this']):>7}",
                flush=True,
            )
        rows += got
        finish_run(args, device, meta, rows, t_start, "osc_step", lambda r=rows: markdown(meta, r))  # every size


if __name__ == "__main__":
    main()
