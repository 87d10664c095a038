"""Time wpctrl's end-effector control step against a torch port of ManiSkill's GPU EE path, and against physics.

One EE control step of ``pd_ee_delta_pose`` (arm: PDEEPose, ManiSkill's GPU semantics: one damped least-squares step;
gripper: mimic) on N Pandas: processed action, FK of the chain from ``State.joint_q``, geometric Jacobian, the
Levenberg–Marquardt solve ``(JᵀJ + λI) dq = Jᵀ dx``, targets, drive targets written into Newton's ``Control``.

Variants (one row each):

* ``wpctrl eager``: ``set_action`` + K × ``before_simulation_step`` from Python (3 + K launches);
* ``wpctrl graph``: the same captured with ``wp.ScopedCapture``;
* ``torch eager``: :class:`TorchEEPose`, the same math written the way ManiSkill runs it on GPU (batched 4×4 chain
  transforms as pytorch_kinematics does, ``torch.linalg.solve``; pytorch_kinematics itself is not installable here),
  reading ``joint_q`` and writing ``joint_target_q`` through zero-copy torch views of the Newton arrays;
* ``torch CUDA graph``: the torch step captured with ``torch.cuda.graph`` (CUDA only; ``linalg.solve_ex``).

With ``--physics-envs N`` (default 4096 on CUDA, off on CPU) it also times one MuJoCo-Warp step of N Pandas
(``SolverMuJoCo.step``, no contacts) and reports the EE step as a fraction of one physics step and of a control
step's K physics steps.

Run ``python bench/step/ee_step.py --help``; results go to ``<out>/ee_step_<device>.{json,md}``.
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

VARIANTS = ["wpctrl_eager", "wpctrl_graph", "torch_eager", "torch_graph"]
LABELS = {
    "wpctrl_eager": "wpctrl eager",
    "wpctrl_graph": "wpctrl graph",
    "torch_eager": "torch eager",
    "torch_graph": "torch CUDA graph",
}


# ----------------------------------------------------------------------------------------------------------------------
# The torch baseline: ManiSkill's GPU EE path (PDEEPoseController + pytorch_kinematics jacobian + LM step).


def _mat(t7: np.ndarray) -> np.ndarray:
    """4×4 matrix of a Warp transform row (px, py, pz, qx, qy, qz, qw)."""
    x, y, z, w = t7[3:]
    m = np.eye(4)
    m[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    m[:3, 3] = t7[:3]
    return m


class TorchEEPose:
    """ManiSkill's ``pd_ee_delta_pose`` arm + mimic gripper on torch tensors (use_delta, no use_target, GPU path)."""

    def __init__(self, ctrl, state, control, device: torch.device):
        arm = ctrl["arm"]
        part = arm._ee
        model = ctrl.model
        self.dev = device
        self.coord_arm = torch.as_tensor(arm.coord_index.astype(np.int64), device=device)
        self.coord_grip = torch.as_tensor(ctrl["gripper"].coord_index.astype(np.int64), device=device)
        self.joint_q = wp.to_torch(state.joint_q)
        self.joint_target_q = wp.to_torch(control.joint_target_q)
        # The serial chain of env 0 (as pytorch_kinematics builds it from the URDF): per joint, parent offset,
        # axis, and the child-frame correction; the TCP offset last.
        chain = part.chain_joint.numpy()[0]
        xp = model.joint_X_p.numpy()
        xc = model.joint_X_c.numpy()
        ax = model.joint_axis.numpy()
        qd0 = model.joint_qd_start.numpy()
        self.offsets = torch.tensor(np.stack([_mat(xp[j]) for j in chain]), dtype=torch.float32, device=device)
        self.child_inv = torch.tensor(
            np.stack([np.linalg.inv(_mat(xc[j])) for j in chain]), dtype=torch.float32, device=device
        )
        axes = np.stack([ax[qd0[j]] for j in chain]).astype(np.float64)
        self.axes = torch.tensor(axes, dtype=torch.float32, device=device)
        skew = np.zeros((len(chain), 3, 3))
        skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -axes[:, 2], axes[:, 1], -axes[:, 0]
        skew -= skew.transpose(0, 2, 1)
        self.skew = torch.tensor(skew, dtype=torch.float32, device=device)
        self.skew2 = self.skew @ self.skew
        self.eye3 = torch.eye(3, device=device)
        self.eye4 = torch.eye(4, device=device)
        types = model.joint_type.numpy()[chain]
        assert (types == 1).all(), "the torch baseline ports revolute chains only"
        off = part.ee_offset
        self.tcp = torch.tensor(_mat(np.array([*off.p, *off.q])), dtype=torch.float32, device=device)
        rows = ctrl._engine.rows  # the mode's raw action bounds (wpctrl internals, read by this baseline)
        self.lo = torch.tensor(rows.action_low[:3], device=device)
        self.hi = torch.tensor(rows.action_high[:3], device=device)
        self.rot_lower = float(arm.config.rot_lower)
        self.g_lo = float(rows.action_low[6])
        self.g_hi = float(rows.action_high[6])
        self.lam = 1e-4
        n = self.coord_arm.shape[0]
        self.eye = torch.eye(7, device=device).expand(n, 7, 7)
        self.target_qpos = torch.zeros((n, 7), device=device)

    def _axis_angle(self, i: int, q: torch.Tensor) -> torch.Tensor:
        """Batched 4×4 rotations about joint i's unit axis (Rodrigues with precomputed [a]× and [a]×²)."""
        s, c = torch.sin(q)[:, None, None], torch.cos(q)[:, None, None]
        m = self.eye4.repeat(q.shape[0], 1, 1)
        m[:, :3, :3] = self.eye3 + s * self.skew[i] + (1 - c) * self.skew2[i]
        return m

    def fk_jacobian(self, q: torch.Tensor):
        n = q.shape[0]
        t = self.eye4.repeat(n, 1, 1)
        origins, axes = [], []
        for i in range(q.shape[1]):
            t = t @ self.offsets[i] @ self._axis_angle(i, q[:, i])
            origins.append(t[:, :3, 3])
            axes.append(t[:, :3, :3] @ self.axes[i])
            t = t @ self.child_inv[i]
        ee = t @ self.tcp
        p = ee[:, :3, 3]
        z = torch.stack(axes, dim=2)  # (n, 3, 7)
        o = torch.stack(origins, dim=2)
        jv = torch.linalg.cross(z, p[:, :, None] - o, dim=1)
        return ee, torch.cat([jv, z], dim=1)  # (n, 6, 7)

    def set_action(self, action: torch.Tensor) -> None:
        # _preprocess_action: position clip-and-scale, rotation clipped by norm times rot_lower (ManiSkill's quirk)
        pos = 0.5 * (self.hi + self.lo) + 0.5 * (self.hi - self.lo) * torch.clamp(action[:, :3], -1, 1)
        rot = action[:, 3:6].clone()
        norm = torch.linalg.norm(rot, dim=1)
        rot = torch.where((norm > 1)[:, None], rot / norm[:, None], rot) * self.rot_lower
        dx = torch.cat([pos, rot], dim=1)
        q0 = self.joint_q[self.coord_arm]
        _, jac = self.fk_jacobian(q0)
        jt = jac.transpose(1, 2)
        dq = torch.linalg.solve_ex(jt @ jac + self.lam * self.eye, (jt @ dx[:, :, None]))[0][:, :, 0]
        self.target_qpos = q0 + dq
        self.joint_target_q[self.coord_arm] = self.target_qpos  # set_drive_targets
        g = 0.5 * (self.g_hi + self.g_lo) + 0.5 * (self.g_hi - self.g_lo) * torch.clamp(action[:, 6:7], -1, 1)
        self.joint_target_q[self.coord_grip] = g.expand(-1, 2)


# ----------------------------------------------------------------------------------------------------------------------


def run_one(args, n_envs: int, device, sync: Sync) -> list[dict]:
    import wpctrl

    tdev = torch.device("cuda", wp.get_device(device).ordinal) if sync.cuda else torch.device("cpu")
    t0 = time.perf_counter()
    model = build_panda_model(n_envs, device)
    ctrl = wpctrl.build_controller(panda_mode(args.mode), model)
    build_s = time.perf_counter() - t0
    state, control = model.state(), model.control()
    control_t = model.control()
    K = ctrl.num_substeps
    gen = torch.Generator(device=tdev).manual_seed(0)
    action = torch.rand((n_envs, ctrl.action_dim), generator=gen, device=tdev) * 2.4 - 1.2
    ref = TorchEEPose(ctrl, state, control_t, tdev)
    ctrl.reset(state)

    def wp_step():
        ctrl.set_action(action, state)
        for _ in range(K):
            ctrl.before_simulation_step(state, control)

    def torch_step():
        ref.set_action(action)

    wp_step()
    torch_step()
    sync()
    q0 = wp.to_torch(state.joint_q)[ref.coord_arm]
    _, jac = ref.fk_jacobian(q0)
    dq_wp = wp.to_torch(ctrl["arm"].target_qpos) - q0
    dq_t = ref.target_qpos - q0
    check = {
        "max_abs_diff_task_step": float((jac @ (dq_wp - dq_t)[:, :, None]).abs().max()),
        "max_abs_diff_target_qpos": float((dq_wp - dq_t).abs().max()),
    }
    fns = {}
    if "wpctrl_eager" in args.variants:
        fns["wpctrl_eager"] = wp_step
    if "wpctrl_graph" in args.variants:
        with wp.ScopedCapture(device=device) as cap:
            wp_step()
        graph = cap.graph
        fns["wpctrl_graph"] = lambda: wp.capture_launch(graph)
    if "torch_eager" in args.variants:
        fns["torch_eager"] = torch_step
    if "torch_graph" in args.variants and sync.cuda:
        try:
            s = torch.cuda.Stream(device=tdev)
            s.wait_stream(torch.cuda.current_stream(tdev))
            with torch.cuda.stream(s):
                for _ in range(3):
                    torch_step()
            torch.cuda.current_stream(tdev).wait_stream(s)
            tgraph = torch.cuda.CUDAGraph()
            with torch.cuda.graph(tgraph):
                torch_step()
            fns["torch_graph"] = tgraph.replay
        except RuntimeError as e:  # a solver backend that cannot be captured
            print(f"[{fmt_envs(n_envs)}] torch CUDA graph skipped: {e}", flush=True)
    times = measure_interleaved(
        fns, sync, repeats=args.repeats, min_time=args.min_time, warmup=args.warmup, clock=args.clock
    )
    t_torch = times.get("torch_eager", {}).get("median_s")
    rows = []
    for name in VARIANTS:
        if name not in times:
            continue
        t = times[name]["median_s"]
        rows.append(
            {
                "envs": n_envs,
                "mode": args.mode,
                "num_substeps": K,
                "variant": name,
                "us_per_step": t * 1e6,
                "ns_per_env_step": t * 1e9 / n_envs,
                "speedup_vs_torch_eager": (t_torch / t) if t_torch else None,
                "iters": times[name]["iters"],
                "samples_us": [x * 1e6 for x in times[name]["samples_s"]],
                "clock": args.clock,
                "build_s": build_s,
                "check": check,
            }
        )
    if n_envs == args.physics_envs:
        rows += physics_rows(args, model, ctrl, state, control, fns, sync, n_envs)
    return rows


def physics_rows(args, model, ctrl, state, control, fns, sync, n_envs) -> list[dict]:
    """One MuJoCo-Warp step of the same Pandas, and the EE step as a fraction of it."""
    import newton

    solver = newton.solvers.SolverMuJoCo(model, disable_contacts=True)
    s1 = model.state()
    newton.eval_fk(model, state.joint_q, state.joint_qd, state)

    def phys():
        solver.step(state, s1, control, None, 1.0 / 100)
        state.assign(s1)

    phys()
    sync()
    t_phys = measure(phys, sync, repeats=args.repeats, min_time=args.min_time, warmup=2)["median_s"]
    ee = {k: measure(f, sync, repeats=args.repeats, min_time=args.min_time)["median_s"] for k, f in fns.items()}
    K = ctrl.num_substeps
    return [
        {
            "envs": n_envs,
            "variant": "mujoco_warp_step",
            "us_per_step": t_phys * 1e6,
            "ee_step_over_physics_step": {k: v / t_phys for k, v in ee.items()},
            "ee_step_over_control_step_physics": {k: v / (K * t_phys) for k, v in ee.items()},
        }
    ]


def markdown(meta: dict, rows: list[dict]) -> str:
    out = ["# EE control step: wpctrl vs a torch port of ManiSkill's GPU path\n", meta_markdown(meta) + "\n"]
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
                fmt_ratio(r["speedup_vs_torch_eager"]),
            ]
        )
    out.append(md_table(["envs", "variant", "µs / control step", "ns / env-step", "vs torch eager"], table))
    for r in rows:
        if r["variant"] == "mujoco_warp_step":
            fr = ", ".join(f"{LABELS[k]} {100 * v:.1f} %" for k, v in r["ee_step_over_physics_step"].items())
            fk = ", ".join(f"{LABELS[k]} {100 * v:.1f} %" for k, v in r["ee_step_over_control_step_physics"].items())
            out.append(
                f"\nMuJoCo-Warp Panda step at {fmt_envs(r['envs'])} envs: {fmt_us(r['us_per_step'] * 1e-6)} µs. "
                f"EE control step / one physics step: {fr}; / the control step's K physics steps: {fk}.\n"
            )
    return "\n".join(out)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_args(p, envs_help="comma list, k/M suffixes (default: cpu 1,64,1k,4k; cuda 1..64k)", variants=VARIANTS)
    p.add_argument("--mode", default="pd_ee_delta_pose")
    p.add_argument("--physics-envs", type=int, default=None, help="time MuJoCo-Warp at this N (default: cuda 4096)")
    args = parse_run_args(p, argv)
    if args.mode not in ("pd_ee_delta_pose",):
        p.error("--mode: the torch baseline ports pd_ee_delta_pose only")
    device, sync, meta = start_run(
        p, args, cpu_envs="1,64,1k,4k", cuda_envs="1,64,1k,4k,16k,64k", thread_clock_cpu_only=False
    )
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
                print(
                    f"[{fmt_envs(n)}] MuJoCo-Warp step {r['us_per_step']:.1f} us; "
                    f"EE/physics {r['ee_step_over_physics_step']}"
                )
                continue
            print(
                f"[{fmt_envs(n)}] {LABELS[r['variant']]:>16}: {r['us_per_step']:10.2f} us/step "
                f"{r['ns_per_env_step']:9.2f} ns/env-step  vs torch {fmt_ratio(r['speedup_vs_torch_eager']):>7}  "
                f"check {r['check']}",
                flush=True,
            )
        rows += got
        if device.is_cuda:
            torch.cuda.empty_cache()
    finish_run(args, device, meta, rows, t_start, "ee_step", lambda: markdown(meta, rows))


if __name__ == "__main__":
    main()
