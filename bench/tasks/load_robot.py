"""How long a ManiSkill robot takes from its uid to a running wpctrl controller for N envs.

For each robot: ``wpctrl.maniskill.load_robot(uid)`` (the agent's asset through Newton's importer, its control modes
translated), ``ModelBuilder.replicate`` into N envs, ``finalize``, ``wpctrl.build_controller`` for one of its modes,
then the first control step (``set_action`` + K ``before_simulation_step``: Warp loads or compiles the step kernels
of that mode's layout here) and a second one. ``--cold`` points Warp at an empty kernel cache first, so the first
step includes compiling.

    python bench/tasks/load_robot.py --envs 4k --device cpu
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

ROBOTS = {
    "panda": "pd_joint_delta_pos",
    "fetch": "pd_joint_delta_pos",
    "allegro_hand_right": "pd_joint_delta_pos",
    "unitree_g1_simplified_legs": "pd_joint_delta_pos",
    "humanoid": "pd_joint_delta_pos",
}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--envs", default="4k", help="number of envs (k = 1024)")
    p.add_argument("--device", default="cpu")
    p.add_argument("--robots", default=",".join(ROBOTS), help="comma-separated agent uids")
    p.add_argument("--cold", action="store_true", help="start from an empty Warp kernel cache")
    p.add_argument("--out", default=str(ROOT / "bench" / "results"))
    args = p.parse_args(argv)

    import warp as wp

    if args.cold:
        wp.config.kernel_cache_dir = tempfile.mkdtemp(prefix="wpctrl-cold-cache-")
    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING

    from bench.common import fmt_envs, machine_info, meta_markdown, parse_envs, write_results

    n = parse_envs(args.envs)[0]
    t = time.perf_counter()
    import newton
    import numpy as np

    import wpctrl
    from wpctrl.maniskill import load_robot

    wp.init()
    t_import_wpctrl = time.perf_counter() - t
    t = time.perf_counter()
    import mani_skill.agents.registration  # noqa: F401

    t_import_ms = time.perf_counter() - t
    rows = []
    for uid in args.robots.split(","):
        mode_name = ROBOTS.get(uid, "pd_joint_delta_pos")
        row = {"robot": uid, "mode": mode_name, "envs": n}
        t0 = time.perf_counter()
        robot = load_robot(uid)
        t1 = time.perf_counter()
        builder = newton.ModelBuilder()
        builder.replicate(robot.builder, n)
        t2 = time.perf_counter()
        model = builder.finalize(device=args.device)
        t3 = time.perf_counter()
        ctrl = wpctrl.build_controller(robot.control_modes[mode_name], model)
        state, control = model.state(), model.control()
        wp.synchronize()
        t4 = time.perf_counter()
        action = np.zeros((n, ctrl.action_dim), np.float32)
        times = []
        for _ in range(2):
            s = time.perf_counter()
            ctrl.set_action(action, state)
            for _ in range(ctrl.num_substeps):
                ctrl.before_simulation_step(state, control)
            wp.synchronize()
            times.append(time.perf_counter() - s)
        row.update(
            dof=len(robot.joint_names),
            bodies=model.body_count,
            load_robot_s=t1 - t0,
            replicate_s=t2 - t1,
            finalize_s=t3 - t2,
            build_controller_s=t4 - t3,
            first_step_s=times[0],
            second_step_s=times[1],
            total_s=t4 - t0 + times[0],
        )
        rows.append(row)
        print(
            f"{uid:28s} {fmt_envs(n)} envs: load {row['load_robot_s']:.2f} s, replicate {row['replicate_s']:.2f} s, "
            f"finalize {row['finalize_s']:.2f} s, build_controller {row['build_controller_s']:.2f} s, first step "
            f"{row['first_step_s']:.2f} s, second {row['second_step_s'] * 1e3:.1f} ms; total {row['total_s']:.2f} s",
            flush=True,
        )
        del ctrl, model, builder, robot

    meta = machine_info(args.device)
    meta.update(envs=n, cold_kernel_cache=args.cold, import_wpctrl_s=t_import_wpctrl, import_mani_skill_s=t_import_ms)
    lines = [
        f"# From a ManiSkill uid to a running controller: {fmt_envs(n)} envs on {args.device}"
        + (" (empty kernel cache)" if args.cold else ""),
        "",
        meta_markdown(meta),
        "",
        f"Imports: wpctrl + Newton + Warp init {t_import_wpctrl:.2f} s, mani_skill {t_import_ms:.2f} s (once).",
        "",
        "| robot | mode | DOF | bodies | load_robot | replicate | finalize | build_controller | first step | "
        "second step | total to first step |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['robot']} | {r['mode']} | {r['dof']} | {r['bodies']} | {r['load_robot_s']:.2f} s | "
            f"{r['replicate_s']:.2f} s | {r['finalize_s']:.2f} s | {r['build_controller_s']:.2f} s | "
            f"{r['first_step_s']:.2f} s | {r['second_step_s'] * 1e3:.1f} ms | {r['total_s']:.2f} s |"
        )
    dev = "cuda" if str(args.device).startswith("cuda") else "cpu"
    stem = f"load_robot_{dev}_{fmt_envs(n)}" + ("_cold" if args.cold else "")
    jpath, mpath = write_results(args.out, stem, meta, rows, "\n".join(lines) + "\n")
    print(f"wrote {jpath} and {mpath}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
