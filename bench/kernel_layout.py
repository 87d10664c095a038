"""wpctrl's control-step kernels against an independent row-parallel implementation (bench-only kernels).

History: up to wpctrl 1bc1a1a the kernels ran one thread per env walking the env's rows. At small N a kernel then
took the latency of one thread's serial chain of loads and stores (~7 µs per kernel on an H200) and at large N a
warp's accesses were 9 floats apart. This script measured the same control step with one thread per (env, row)
1.4-1.9x faster on an H200 with bit-identical outputs (bench/README.md keeps those numbers), and wpctrl switched to
that layout in 615b826. It now serves as a cross-check: a second implementation of the same math that must write
the same values, and whose speed says how far wpctrl's kernels are from a plain row-parallel version.

Bench row-parallel set_action: thread (env, r) for every row that is not a mimic follower; that thread also writes
the followers of its row (they only read their source's new target), so there is no race. Substep: thread (env, r),
no inter-row dependency; the substep counter is per (env, row), so no thread reads a counter that another writes.
Explicit naive PD, as wpctrl's default. ``python bench/kernel_layout.py --help``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
import torch  # noqa: E402
import warp as wp  # noqa: E402

from bench.common import (  # noqa: E402
    DEFAULT_OUT,
    Sync,
    build_panda_model,
    fmt_envs,
    fmt_ratio,
    fmt_us,
    load_average,
    machine_info,
    md_table,
    measure,
    meta_markdown,
    panda_mode,
    parse_envs,
    real_setup,
    synthetic_setup,
    write_results,
)

wp.set_module_options({"enable_backward": False})

ROW_POS = wp.constant(0)
FLAG_NORMALIZE = wp.constant(1)
FLAG_DELTA = wp.constant(2)
FLAG_TARGET = wp.constant(4)
FLAG_INTERPOLATE = wp.constant(8)
FLAG_VEL_TARGET = wp.constant(16)


@wp.func
def _scale(a: float, lo: float, hi: float, normalize: int):
    if normalize == 0:
        return a
    c = wp.clamp(a, -1.0, 1.0)
    return 0.5 * (hi + lo) + (0.5 * (hi - lo)) * c


@wp.func
def _pos_target(
    env: int,
    r: int,
    q: float,
    flags: int,
    col: int,
    lo: float,
    hi: float,
    action_in: wp.array2d[float],
    target_qpos_out: wp.array2d[float],
    processed_action_out: wp.array2d[float],
):
    t = target_qpos_out[env, r]
    if col >= 0:
        a = _scale(action_in[env, col], lo, hi, flags & FLAG_NORMALIZE)
        processed_action_out[env, col] = a
        t = a
        if flags & FLAG_DELTA:
            if flags & FLAG_TARGET:
                t = target_qpos_out[env, r] + a
            else:
                t = q + a
    return t


@wp.kernel
def set_action_rows(
    row_kind: wp.array[wp.int32],
    row_flags: wp.array[wp.int32],
    row_act_col: wp.array[wp.int32],
    row_vel_col: wp.array[wp.int32],
    row_lo: wp.array[float],
    row_hi: wp.array[float],
    row_vlo: wp.array[float],
    row_vhi: wp.array[float],
    row_mimic_src: wp.array[wp.int32],
    row_mimic_mul: wp.array[float],
    row_mimic_off: wp.array[float],
    row_q_off: wp.array[wp.int32],
    env_q_base: wp.array[wp.int32],
    action_in: wp.array2d[float],
    joint_q_in: wp.array[float],
    processed_action_out: wp.array2d[float],
    start_qpos_out: wp.array2d[float],
    target_qpos_out: wp.array2d[float],
    target_qvel_out: wp.array2d[float],
    step_rows_out: wp.array2d[wp.int32],
    bad_action_count_out: wp.array[wp.int32],
):
    tid = wp.tid()
    num_rows = row_kind.shape[0]
    env = tid // num_rows
    r = tid - env * num_rows
    if row_mimic_src[r] >= 0:
        return  # written by its source row's thread
    for c in range(action_in.shape[1]):
        if not wp.isfinite(action_in[env, c]):
            if r == 0:
                bad_action_count_out[env] = bad_action_count_out[env] + 1
            return
    q_base = env_q_base[env]
    kind = row_kind[r]
    flags = row_flags[r]
    step_rows_out[env, r] = 0
    if kind == ROW_POS:
        q = joint_q_in[q_base + row_q_off[r]]
        start_qpos_out[env, r] = q
        t = _pos_target(
            env, r, q, flags, row_act_col[r], row_lo[r], row_hi[r], action_in, target_qpos_out, processed_action_out
        )
        target_qpos_out[env, r] = t
        vcol = row_vel_col[r]
        if vcol >= 0:
            v = _scale(action_in[env, vcol], row_vlo[r], row_vhi[r], flags & FLAG_NORMALIZE)
            processed_action_out[env, vcol] = v
            target_qvel_out[env, r] = v
        # followers of this row
        for m in range(num_rows):
            if row_mimic_src[m] == r:
                start_qpos_out[env, m] = joint_q_in[q_base + row_q_off[m]]
                target_qpos_out[env, m] = t * row_mimic_mul[m] + row_mimic_off[m]
                step_rows_out[env, m] = 0
    elif row_act_col[r] >= 0:  # velocity row
        v = _scale(action_in[env, row_act_col[r]], row_lo[r], row_hi[r], flags & FLAG_NORMALIZE)
        processed_action_out[env, row_act_col[r]] = v
        target_qvel_out[env, r] = v


@wp.kernel
def substep_rows(
    row_kind: wp.array[wp.int32],
    row_flags: wp.array[wp.int32],
    row_q_off: wp.array[wp.int32],
    row_qd_off: wp.array[wp.int32],
    env_q_base: wp.array[wp.int32],
    env_qd_base: wp.array[wp.int32],
    kp: wp.array2d[float],
    kd: wp.array2d[float],
    force_limit: wp.array2d[float],
    row_accel: wp.array[wp.int32],
    num_substeps: int,
    explicit_pd: int,
    joint_q_in: wp.array[float],
    joint_qd_in: wp.array[float],
    response_in: wp.array2d[float],
    start_qpos_in: wp.array2d[float],
    target_qpos_in: wp.array2d[float],
    target_qvel_in: wp.array2d[float],
    step_rows_out: wp.array2d[wp.int32],
    joint_target_q_out: wp.array[float],
    joint_target_qd_out: wp.array[float],
    joint_f_out: wp.array[float],
):
    tid = wp.tid()
    num_rows = row_kind.shape[0]
    env = tid // num_rows
    r = tid - env * num_rows
    kind = row_kind[r]
    flags = row_flags[r]
    qi = env_q_base[env] + row_q_off[r]
    di = env_qd_base[env] + row_qd_off[r]
    vel_target = kind != ROW_POS or (flags & FLAG_VEL_TARGET) != 0
    tqd = float(0.0)  # noqa: UP018 (a mutable Warp local)
    if vel_target:
        tqd = target_qvel_in[env, r]
        joint_target_qd_out[di] = tqd
    tq = float(0.0)  # noqa: UP018
    if kind == ROW_POS:
        tq = target_qpos_in[env, r]
        if flags & FLAG_INTERPOLATE:
            k = step_rows_out[env, r] + 1
            step_rows_out[env, r] = k
            step_size = (tq - start_qpos_in[env, r]) / float(num_substeps)
            tq = start_qpos_in[env, r] + step_size * float(wp.min(k, num_substeps))
        joint_target_q_out[qi] = tq
    if explicit_pd != 0:
        g = 0
        if kp.shape[0] > 1:
            g = env
        # The same per-row work as wpctrl's kernel, acceleration-drive scaling included (unused by this mode).
        kpe = float(0.0)  # noqa: UP018
        e = float(0.0)  # noqa: UP018
        if kind == ROW_POS:
            kpe = kp[g, r]
            e = tq - joint_q_in[qi]
        kde = kd[g, r]
        gr = 0
        if response_in.shape[0] > 1:
            gr = env
        if row_accel[r] != 0:
            resp = response_in[gr, r]
            kpe = kpe / resp
            kde = kde / resp
        u = kpe * e + kde * (tqd - joint_qd_in[di])
        lim = force_limit[g, r]
        joint_f_out[di] = wp.clamp(u, -lim, lim)


class RowParallel:
    """The control step of a wpctrl controller's engine, run with the row-parallel kernels (own target arrays)."""

    def __init__(self, eng, state, control):
        self.eng = eng
        dev = eng.device
        E, R = eng.num_envs, eng.num_rows
        self.start = wp.clone(eng.start_qpos)
        self.target = wp.clone(eng.target_qpos)
        self.target_qvel = wp.clone(eng.target_qvel)
        self.processed = wp.zeros_like(eng.processed_action)
        self.step_rows = wp.zeros((E, R), dtype=wp.int32, device=dev)
        self.bad = wp.zeros(E, dtype=wp.int32, device=dev)
        self.K = eng.num_substeps
        self._zeros_rows = wp.zeros(max(R, 1), dtype=wp.int32, device=dev)  # older wpctrl: no acceleration drives
        self._ones_rows = wp.ones((1, max(R, 1)), dtype=wp.float32, device=dev)
        self.state, self.control = state, control
        self._sa = None
        self._ss = None

    def set_action(self, action: wp.array) -> None:
        e = self.eng
        if self._sa is None:
            inputs = [
                e.row_kind,
                e.row_flags,
                e.row_act_col,
                e.row_vel_col,
                e.row_lo,
                e.row_hi,
                e.row_vlo,
                e.row_vhi,
                e.row_mimic_src,
                e.row_mimic_mul,
                e.row_mimic_off,
                e.row_q_off,
                e.env_q_base,
                action,
                self.state.joint_q,
                self.processed,
                self.start,
                self.target,
                self.target_qvel,
                self.step_rows,
                self.bad,
            ]
            self._sa = wp.launch(
                set_action_rows, dim=e.num_envs * e.num_rows, inputs=inputs, device=e.device, record_cmd=True
            )
        self._sa.launch()

    def substep(self) -> None:
        e = self.eng
        if self._ss is None:
            c = self.control
            inputs = [
                e.row_kind,
                e.row_flags,
                e.row_q_off,
                e.row_qd_off,
                e.env_q_base,
                e.env_qd_base,
                e.kp,
                e.kd,
                e.force_limit,
                getattr(e, "row_accel", self._zeros_rows),
                self.K,
                1,
                self.state.joint_q,
                self.state.joint_qd,
                getattr(e, "response", self._ones_rows),
                self.start,
                self.target,
                self.target_qvel,
                self.step_rows,
                c.joint_target_q,
                c.joint_target_qd,
                c.joint_f,
            ]
            self._ss = wp.launch(
                substep_rows, dim=e.num_envs * e.num_rows, inputs=inputs, device=e.device, record_cmd=True
            )
        self._ss.launch()


def run_one(args, setup, interp: bool, sync, device) -> list[dict]:
    ctrl, state, control = setup.ctrl, setup.state, setup.control
    eng = ctrl._engine
    K = ctrl.num_substeps
    n = setup.num_envs
    tdev = torch.device("cuda", device.ordinal) if device.is_cuda else torch.device("cpu")
    gen = torch.Generator(device=tdev).manual_seed(0)
    action_t = torch.rand((n, ctrl.action_dim), generator=gen, device=tdev) * 2 - 1
    action_w = wp.from_torch(action_t)
    ctrl.reset(state)
    control_r = setup.new_control()
    rp = RowParallel(eng, state, control_r)
    sync()

    # Same values: a few steps of each from the same start.
    for _ in range(2):
        ctrl.set_action(action_w, state)
        rp.set_action(action_w)
        for _ in range(K):
            ctrl.before_simulation_step(state, control)
            rp.substep()
    sync()
    diff = {
        name: float(np.abs(getattr(control, name).numpy() - getattr(control_r, name).numpy()).max())
        for name in ("joint_target_q", "joint_target_qd", "joint_f")
    }
    diff["target_qpos"] = float(np.abs(eng.target_qpos.numpy() - rp.target.numpy()).max())

    def wp_step():
        ctrl.set_action(action_w, state)
        for _ in range(K):
            ctrl.before_simulation_step(state, control)

    def rp_step():
        rp.set_action(action_w)
        for _ in range(K):
            rp.substep()

    def rp_substeps():
        for _ in range(K):
            rp.substep()

    def wp_substeps():
        for _ in range(K):
            ctrl.before_simulation_step(state, control)

    rows = []
    graphs = {}
    for name, fn in (
        ("wpctrl", wp_step),
        ("bench row-parallel", rp_step),
        ("wpctrl substeps only", wp_substeps),
        ("bench row-parallel substeps only", rp_substeps),
    ):
        fn()
        sync()
        with wp.ScopedCapture(device=device) as cap:
            fn()
        graphs[name] = cap.graph
        r = measure(
            lambda g=cap.graph: wp.capture_launch(g),
            sync,
            repeats=args.repeats,
            min_time=args.min_time,
            clock=args.clock,
        )
        rows.append(
            {
                "envs": n,
                "layout": setup.layout_kind,
                "interpolate": interp,
                "variant": name,
                "us_per_step": r["median_s"] * 1e6,
                "ns_per_env_step": r["median_s"] * 1e9 / n,
                "samples_us": [x * 1e6 for x in r["samples_s"]],
                "max_abs_diff": diff,
            }
        )
    base = {r["variant"]: r["us_per_step"] for r in rows}
    for r in rows:
        ref = base["wpctrl"] if "substeps" not in r["variant"] else base["wpctrl substeps only"]
        r["speedup_vs_wpctrl"] = ref / r["us_per_step"]
    return rows


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--device", default="cuda:0" if wp.is_cuda_available() else "cpu")
    p.add_argument("--envs", default=None, help="default: cpu 1,1k,4k; cuda 1,4k,64k,1M")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--min-time", type=float, default=None)
    p.add_argument("--clock", default="wall", choices=["wall", "thread"])
    p.add_argument("--max-real-envs", type=int, default=4096)
    p.add_argument("--out", default=str(DEFAULT_OUT))
    p.add_argument("--tag", default=None)
    args = p.parse_args(argv)
    wp.init()
    device = wp.get_device(args.device)
    sync = Sync(device)
    if args.min_time is None:
        args.min_time = 0.02 if device.is_cuda else 0.05
    if args.envs is None:
        args.envs = "1,4k,64k,1M" if device.is_cuda else "1,1k,4k"
    if args.clock == "thread":
        torch.set_num_threads(1)
    meta = machine_info(device)
    meta.update({"args": vars(args), "loadavg_start": load_average()})
    print(meta_markdown(meta), flush=True)
    rows = []
    small = None
    for n in parse_envs(args.envs):
        model = build_panda_model(n, device) if n <= args.max_real_envs else None
        if model is None and small is None:
            small = build_panda_model(2, device)
        for interp in (False, True):
            mode = panda_mode("pd_joint_target_delta_pos", interp)
            kw = {"actuation": "explicit", "control_freq": 20, "sim_freq": 100}
            setup = real_setup(mode, model, **kw) if model is not None else synthetic_setup(mode, small, n, **kw)
            got = run_one(args, setup, interp, sync, device)
            for r in got:
                print(
                    f"[{fmt_envs(n)} interp={int(interp)}] {r['variant']:>28}: {r['us_per_step']:9.2f} us "
                    f"({fmt_ratio(r['speedup_vs_wpctrl'])})  max diff {r['max_abs_diff']}",
                    flush=True,
                )
            rows += got
    meta["loadavg_end"] = load_average()
    md = [
        "# wpctrl's kernels vs an independent row-parallel implementation\n",
        meta_markdown(meta) + "\n",
        "Panda `pd_joint_target_delta_pos`, explicit naive PD, K = 5; graph-captured replay, "
        f"{args.clock} clock, median of {args.repeats}. 'speedup' is against wpctrl's kernels for the same work.\n\n",
    ]
    md.append(
        md_table(
            ["envs", "interp", "variant", "µs/step", "ns/env-step", "speedup", "max abs diff vs wpctrl"],
            [
                [
                    fmt_envs(r["envs"]) + ("*" if r["layout"] == "synthetic" else ""),
                    r["interpolate"],
                    r["variant"],
                    fmt_us(r["us_per_step"] * 1e-6),
                    f"{r['ns_per_env_step']:.3g}",
                    fmt_ratio(r["speedup_vs_wpctrl"]),
                    f"{max(r['max_abs_diff'].values()):.2g}",
                ]
                for r in rows
            ],
        )
    )
    tag = args.tag or ("cuda" if device.is_cuda else "cpu")
    j, m = write_results(args.out, f"kernel_layout_{tag}", meta, rows, "".join(md))
    print(f"wrote {j} and {m}", flush=True)


if __name__ == "__main__":
    main()
