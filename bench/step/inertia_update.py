"""Cost of the joint-space response update and of the drives that use it, per env-step.

Acceleration drives and stable explicit PD need r = (H^-1)_ii of every controlled joint; the coupled drive needs the
whole controlled block of H^-1 every substep. wpctrl computes them with one fused kernel per env (FK from
``joint_q``, H by bodies, float64 Cholesky in registers: ``wpctrl/kernels/inertia.py``); Newton's generic path is
``JointSpaceResponse.refresh`` (FK, mass matrix, block inverse) plus a gather. This times, for a list of N, a whole
control step (set_action + K substeps) of each variant and the response update alone, eager and graph-replayed,
both paths side by side, and the coupled drive next to stable. ``python bench/step/inertia_update.py --help``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import warp as wp  # noqa: E402

from bench.common import (  # noqa: E402
    DEFAULT_OUT,
    Sync,
    build_panda_model,
    fmt_envs,
    fmt_us,
    machine_info,
    md_table,
    measure,
    meta_markdown,
    parse_envs,
    write_results,
)

VARIANTS = (
    # label, drive_mode, actuation, explicit_pd, inertia_update, response path
    ("force, implicit (no update)", "force", "implicit", None, None, "fused"),
    ("acceleration, implicit [JointSpaceResponse]", "acceleration", "implicit", None, "control", "jsr"),
    ("acceleration, implicit [fused]", "acceleration", "implicit", None, "control", "fused"),
    ("stable, H per control step [JointSpaceResponse]", "force", "explicit", "stable", "control", "jsr"),
    ("stable, H per control step [fused]", "force", "explicit", "stable", "control", "fused"),
    ("stable, H per substep [fused]", "force", "explicit", "stable", "substep", "fused"),
    ("coupled, H per substep [fused, in the drive kernel]", "force", "explicit", "coupled", "substep", "fused"),
    ("coupled, H per control step [fused, in the drive kernel]", "force", "explicit", "coupled", "control", "fused"),
)


def mujoco_step(n: int, device):
    """K = 5 MuJoCo-Warp solver steps of the same Pandas (no controller): the physics a control step pays for."""
    import newton

    model = build_panda_model(n, device, gravity=False)
    solver = newton.solvers.SolverMuJoCo(model, disable_contacts=True)
    s0, s1, control = model.state(), model.state(), model.control()

    def step():
        a, b = s0, s1
        for _ in range(5):
            solver.step(a, b, control, None, 0.01)
            a, b = b, a

    return step


def _use_joint_space_response(ctrl, model) -> None:
    """Route the controller's response update through Newton's JointSpaceResponse (the pre-fused path)."""
    from newton.actuators import JointSpaceResponse

    part = ctrl._engine.response_part
    part._fused = None
    part._jsr = JointSpaceResponse(model)


def newton_implicit_actuator(n: int, device):
    """Newton 1.8's coupled implicit actuator (DrivePD + ClampingMaxEffort, set_effort_mode_implicit) on the same
    Pandas: per substep JointSpaceResponse.refresh, joint_f.zero_() and Actuator.step. Returns the control step."""
    import newton
    from newton.actuators import ClampingMaxEffort, DrivePD, JointSpaceResponse

    from wpctrl.robots import panda

    tmpl = panda(visual_shapes=False)
    for dof in range(tmpl.joint_dof_count):
        tmpl.add_actuator(DrivePD, index=dof, clamping=[(ClampingMaxEffort, {"max_effort": 100.0})], kp=1e3, kd=1e2)
    builder = newton.ModelBuilder()
    builder.replicate(tmpl, n)
    model = builder.finalize(device=device)
    model.set_gravity((0.0, 0.0, 0.0))
    state, control = model.state(), model.control()
    control.joint_target_q.assign(model.joint_q.numpy() + 0.05)
    jsr = JointSpaceResponse(model)
    acts = list(model.actuators)
    for a in acts:
        a.set_effort_mode_implicit(jsr)
    states = [(a.state(), a.state()) for a in acts]

    def step():
        for _ in range(5):
            jsr.refresh(state)
            control.joint_f.zero_()
            for a, (cur, nxt) in zip(acts, states, strict=True):
                a.step(state, control, cur, nxt, 0.01)

    return step


def run(n: int, device, repeats: int, sync, only: str = "", with_mujoco: bool = False) -> list[dict]:
    import numpy as np

    import wpctrl
    from wpctrl.robots import PANDA_ARM_JOINTS, PANDA_GRIPPER_JOINTS

    model = build_panda_model(n, device, gravity=False)
    names = PANDA_ARM_JOINTS + PANDA_GRIPPER_JOINTS
    rows = []
    for label, drive_mode, actuation, explicit_pd, inertia_update, path in VARIANTS:
        if only and not any(w.strip() and w.strip() in label for w in only.split(",")):
            continue
        cfg = wpctrl.PDJointPosControllerConfig(
            names, None, None, 1e3, 1e2, 100.0, normalize_action=False, drive_mode=drive_mode
        )
        ctrl = wpctrl.build_controller(
            cfg, model, 20, 100, actuation=actuation, explicit_pd=explicit_pd, inertia_update=inertia_update
        )
        if path == "jsr":
            _use_joint_space_response(ctrl, model)
        state, control = model.state(), model.control()
        ctrl.reset(state)
        act = wp.array(np.tile(model.joint_q.numpy()[:9] + 0.05, (n, 1)), dtype=wp.float32, device=device)

        def step(ctrl=ctrl, act=act, state=state, control=control):
            ctrl.set_action(act, state)
            for _ in range(ctrl.num_substeps):
                ctrl.before_simulation_step(state, control)

        def update(ctrl=ctrl, state=state):
            ctrl._engine.update_response(state)

        timed = [("control step", step)]
        if ctrl._engine.needs_response and explicit_pd != "coupled":
            timed.append(("response update", update))
        for what, fn in timed:
            fn()  # compile / warm up outside the capture
            with wp.ScopedCapture(device=device) as cap:
                fn()
            graph = cap.graph
            eager = measure(fn, sync, repeats=repeats)["median_s"]
            replay = measure(lambda g=graph: wp.capture_launch(g), sync, repeats=repeats)["median_s"]
            rows.append(
                {
                    "envs": n,
                    "variant": label,
                    "what": what,
                    "eager_s": eager,
                    "graph_s": replay,
                    "graph_ns_per_env_step": replay / n * 1e9,
                }
            )
    extras = []
    if not only or "Newton" in only:
        extras.append(("Newton actuator, set_effort_mode_implicit (+ JointSpaceResponse.refresh per substep)",
                       newton_implicit_actuator(n, device)))  # fmt: skip
    if with_mujoco:
        extras.append(("MuJoCo-Warp, K = 5 solver steps (no controller)", mujoco_step(n, device)))
    for label, step in extras:
        step()
        with wp.ScopedCapture(device=device) as cap:
            step()
        eager = measure(step, sync, repeats=repeats)["median_s"]
        replay = measure(lambda g=cap.graph: wp.capture_launch(g), sync, repeats=repeats)["median_s"]
        rows.append(
            {
                "envs": n,
                "variant": label,
                "what": "control step",
                "eager_s": eager,
                "graph_s": replay,
                "graph_ns_per_env_step": replay / n * 1e9,
            }
        )
    return rows


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--device", default="cpu")
    p.add_argument("--envs", default="1,64,1k")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--variants", default="", help="comma list of label fragments to run (default: all)")
    p.add_argument("--mujoco", action="store_true", help="also time K MuJoCo-Warp steps of the same envs")
    p.add_argument("--out", default=str(DEFAULT_OUT))
    args = p.parse_args(argv)
    device = wp.get_device(args.device)
    sync = Sync(device)
    rows = []
    for n in parse_envs(args.envs):
        rows += run(n, device, args.repeats, sync, args.variants, args.mujoco)
        print(f"{fmt_envs(n)} envs done", flush=True)
    meta = machine_info(device)
    table = md_table(
        ["envs", "variant", "timed", "eager µs", "graph µs", "graph ns/env-step"],
        [
            [
                fmt_envs(r["envs"]),
                r["variant"],
                r["what"],
                fmt_us(r["eager_s"]),
                fmt_us(r["graph_s"]),
                f"{r['graph_ns_per_env_step']:.3g}",
            ]
            for r in rows
        ],
    )
    md = (
        "# Joint-space response update and drive cost (acceleration drives, stable / coupled explicit PD)\n"
        + meta_markdown(meta)
        + "\nPanda, all 9 joints, K = 5; 'control step' = set_action + 5 substeps, including the response update "
        "where the variant has one (per control step: in set_action; per substep: before each substep; coupled: "
        "inside its drive kernel, every substep or once per control step); 'response update' = the update alone. "
        "[JointSpaceResponse]: "
        "Newton's generic path (FK, mass matrix, block inverse, gather); [fused]: wpctrl's one-launch kernel. "
        "Wall clock, median of repeats.\n\n" + table + "\n"
    )
    stem = f"inertia_update_{'cuda' if device.is_cuda else 'cpu'}"
    write_results(args.out, stem, meta, rows, md)
    print(md)


if __name__ == "__main__":
    main()
