"""Fidelity against PhysX: replay ManiSkill's recorded Panda traces through wpctrl on MuJoCo-Warp, per actuation.

The traces (``tests/data/conformance/*.json``, or ``--traces DIR``) hold PhysX's measured ``qpos``/``qvel`` before and
after every control step of a real ManiSkill Panda (gains 1000/100, force limit 100, 100 Hz, K = 5, gravity off on
the robot). For each actuation option this measures:

* **one-step error**: every control step of a trace is replayed from PhysX's state before it (all steps of a trace
  run at once, one env each, so the state is re-synced to PhysX before every step): after the K substeps,
  ``|q_newton - q_physx| / |q_physx - q_before|`` over the 7 arm joints. Median / p95 over the steps of the
  *small-move* traces (delta, target-delta and velocity modes) and of the *large-move* traces (absolute position
  modes, where the drive saturates);
* **open-loop drift**: each trace replayed from its reset state with no re-sync; the largest arm error [rad] over its
  steps (traces with mid-episode resets are skipped);
* **divergences**: runs that produced non-finite or runaway (|qd| > 1e3) states.

Options: ``implicit`` (MuJoCo's built-in PD, Newton's joint-level effort clamp), ``implicit-actclamp`` (the same PD
with the clamp moved to the actuator's force range: see ``bench/actuators/mujoco_clamp.py``), ``explicit`` with
``explicit_pd`` = ``naive`` / ``stable`` / ``coupled``, and ``stable x15`` / ``coupled x15`` (15 solver substeps per
10 ms), ``implicit x16`` / ``coupled x16`` (16, the tasks' :class:`wpctrl.tasks.TaskPhysics` default),
``coupled H per control step`` (``inertia_update="control"``: the coupled drive's H computed once per control step).
``python bench/actuators/fidelity.py --help``; writes ``fidelity_<device>.json`` / ``.md`` under ``--out``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

from bench.common import DEFAULT_OUT, machine_info, md_table, meta_markdown, write_results  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_TRACES = ROOT / "tests" / "data" / "conformance"  # the traces that ship with the tests
ARM = 7

# label: (actuation, explicit_pd, substeps per 10 ms, clamp at the MuJoCo actuator's force range, inertia_update)
# inertia_update: stable PD refreshes r every substep here; None keeps the drive's default (the coupled drive: A every
# substep)
OPTIONS = {
    "implicit": ("implicit", None, 1, False, None),
    "implicit-actclamp": ("implicit", None, 1, True, None),
    "naive": ("explicit", "naive", 1, False, None),
    "stable": ("explicit", "stable", 1, False, "substep"),
    "coupled": ("explicit", "coupled", 1, False, None),
    "stable x15": ("explicit", "stable", 15, False, "substep"),
    "coupled x15": ("explicit", "coupled", 15, False, None),
    "implicit x16": ("implicit", None, 16, False, None),  # the tasks' physics (wpctrl.tasks.TaskPhysics)
    "coupled x16": ("explicit", "coupled", 16, False, None),
    "coupled H per control step": ("explicit", "coupled", 1, False, "control"),
}
LARGE_MODES = ("pd_joint_pos", "pd_joint_pos_vel")


def load_traces(directory: Path) -> dict[str, dict]:
    out = {}
    for p in sorted(Path(directory).glob("*.json")):
        t = json.loads(p.read_text())
        if "steps" in t and "setup" in t and "qpos_after" in t["steps"][0]:
            out[p.stem] = t
    if not out:
        raise SystemExit(f"no traces in {directory}")
    return out


def group_of(trace: dict) -> str:
    return "large" if trace["setup"]["control_mode"] in LARGE_MODES else "small"


def mode_of(trace: dict) -> dict:
    import wpctrl

    cls = {
        "PDJointPosController": wpctrl.PDJointPosControllerConfig,
        "PDJointPosMimicController": wpctrl.PDJointPosMimicControllerConfig,
        "PDJointVelController": wpctrl.PDJointVelControllerConfig,
        "PDJointPosVelController": wpctrl.PDJointPosVelControllerConfig,
        "PassiveController": wpctrl.PassiveControllerConfig,
    }
    mode = {}
    for uid, c in trace["setup"]["controllers"].items():
        mode[uid] = cls[c["cls"]](**{k: v for k, v in c["config"].items() if k != "controller_cls"})
    return mode


class Rig:
    """``num_envs`` Pandas on MuJoCo-Warp with a wpctrl controller for one trace's control mode and one option."""

    def __init__(self, trace: dict, option: str, num_envs: int, device, inertia_merge: str):
        import newton

        import wpctrl
        from wpctrl.robots import panda

        actuation, explicit_pd, mult, actclamp, inertia_update = OPTIONS[option]
        setup = trace["setup"]
        builder = newton.ModelBuilder()
        builder.replicate(panda(inertia_merge=inertia_merge, visual_shapes=False), num_envs)
        self.model = builder.finalize(device=device)
        # ManiSkill disables gravity on the robot's links. Set it on the model: ModelBuilder(gravity=...) does not
        # reach worlds added by replicate(), which take the panda() builder's default gravity.
        self.model.set_gravity((0.0, 0.0, 0.0))
        self.mult = mult
        self.ctrl = wpctrl.build_controller(
            mode_of(trace),
            self.model,
            setup["control_freq"],
            setup["sim_freq"] * mult,
            actuation=actuation,
            explicit_pd=explicit_pd,
            inertia_update=inertia_update,
        )
        assert self.ctrl.joint_names == setup["active_joint_names"]
        self.solver = newton.solvers.SolverMuJoCo(self.model, disable_contacts=True)
        self.ctrl.attach_solver(self.solver)
        if actclamp:
            actuator_force_range_clamp(self.solver)
        self.dt = 1.0 / (setup["sim_freq"] * mult)
        self.s0, self.s1 = self.model.state(), self.model.state()
        self.control = self.model.control()
        self.coord, self.dof = self.ctrl.coord_index, self.ctrl.dof_index

    def put(self, qpos, qvel):
        q, qd = self.s0.joint_q.numpy(), self.s0.joint_qd.numpy()
        q[self.coord] = np.asarray(qpos, np.float32)
        qd[self.dof] = np.asarray(qvel, np.float32)
        self.s0.joint_q.assign(q)
        self.s0.joint_qd.assign(qd)

    def control_step(self, action):
        self.ctrl.set_action(np.asarray(action, np.float32), self.s0)
        for _ in range(self.ctrl.num_substeps):
            self.ctrl.before_simulation_step(self.s0, self.control)
            self.solver.step(self.s0, self.s1, self.control, None, self.dt)
            self.s0, self.s1 = self.s1, self.s0
        return self.s0.joint_q.numpy()[self.coord], self.s0.joint_qd.numpy()[self.dof]


def actuator_force_range_clamp(solver) -> None:
    """Move MuJoCo-Warp's effort clamp from the joint (``jnt_actfrcrange``) to the actuators' own force ranges.

    Newton puts a revolute/prismatic joint's ``effort_limit`` on ``jnt_actfrcrange``, which clamps the summed actuator
    force but is invisible to MuJoCo's implicit velocity derivative (``implicitfast`` keeps ``-kv`` in its matrix even
    when the force is clamped). An actuator's own ``forcerange`` is honoured by the derivative (a clamped actuator
    drops out of it), but Newton builds a POSITION_VELOCITY drive as *two* MuJoCo actuators (stiffness and damping):
    their ranges clamp P and D separately (the sum can reach twice the limit), and the damping actuator leaves the
    implicit solve exactly when its own force saturates, which makes it explicit (``dt kd / I`` up to ~100 on the
    Panda's wrist): the option diverges at 100 Hz (``bench/actuators/fidelity.py``,
    ``bench/actuators/mujoco_clamp.py``).
    """
    m = solver.mjw_model
    rng = m.jnt_actfrcrange.numpy()  # (worlds | 1, njnt) vec2
    trn = solver.mj_model.actuator_trnid[:, 0]
    fr = m.actuator_forcerange.numpy()
    fr[...] = rng[:, trn] if rng.ndim == 3 else rng[trn]
    m.actuator_forcerange.assign(fr)
    m.actuator_forcelimited.assign(np.ones(m.actuator_forcelimited.shape, dtype=bool))
    m.jnt_actfrclimited.assign(np.zeros(m.jnt_actfrclimited.shape, dtype=bool))


def _sync_virtual_targets(rig: Rig, trace: dict, steps: list[int]) -> None:
    """Target-delta controllers: their virtual target before each replayed step, from the recorded internals."""
    state = {}
    for uid, child in rig.ctrl.children.items():
        if not child._uses_target:
            continue
        rows = []
        for k in steps:
            rec = trace["reset"]["controllers"] if k == 0 else trace["steps"][k - 1]["after_step_controllers"]
            rows.append(rec[uid]["target_qpos"])
        state[uid] = {"target_qpos": np.asarray(rows, np.float32)}
    if state:
        rig.ctrl.set_state(state)


def one_step(trace: dict, option: str, device, merge: str) -> dict:
    """All steps of a trace at once (one env each), each from PhysX's state before it."""
    steps = [k for k in range(len(trace["steps"])) if not _near_event(trace, k)]
    rig = Rig(trace, option, len(steps), device, merge)
    st = [trace["steps"][k] for k in steps]
    rig.put([s["qpos_before"] for s in st], [s["qvel_before"] for s in st])
    rig.ctrl.reset(rig.s0)
    _sync_virtual_targets(rig, trace, steps)
    q, qd = rig.control_step([s["action"] for s in st])
    q_before = np.asarray([s["qpos_before"] for s in st])[:, :ARM]
    q_physx = np.asarray([s["qpos_after"] for s in st])[:, :ARM]
    finite = np.isfinite(q).all(axis=1) & np.isfinite(qd).all(axis=1) & (np.abs(qd).max(axis=1) < 1e3)
    err = np.linalg.norm(q[:, :ARM] - q_physx, axis=1) / np.maximum(np.linalg.norm(q_physx - q_before, axis=1), 1e-9)
    iters = None
    if rig.ctrl.coupled_iterations is not None:
        iters = int(rig.ctrl.coupled_iterations.numpy().max())
    return {"err": np.where(finite, err, np.inf), "diverged": int((~finite).sum()), "max_iterations": iters}


def _near_event(trace: dict, k: int) -> bool:
    return any(ev.get("before_step") == k for ev in trace.get("events", []))


def open_loop(trace: dict, option: str, device, merge: str) -> dict:
    """The trace from its reset state with no re-sync: the largest arm error [rad] over its steps."""
    if trace.get("events"):
        return {"drift": None, "diverged": 0}
    rig = Rig(trace, option, 1, device, merge)
    rig.put([trace["reset"]["qpos"]], [trace["reset"]["qvel"]])
    rig.ctrl.reset(rig.s0)
    worst = 0.0
    for s in trace["steps"]:
        q, qd = rig.control_step([s["action"]])
        if not (np.isfinite(q).all() and np.isfinite(qd).all() and np.abs(qd).max() < 1e3):
            return {"drift": float("inf"), "diverged": 1}
        worst = max(worst, float(np.linalg.norm(q[0, :ARM] - np.asarray(s["qpos_after"])[:ARM])))
    return {"drift": worst, "diverged": 0}


def _stats(x: list[float]) -> tuple[float, float]:
    if not x:
        return float("nan"), float("nan")
    a = np.asarray(x)  # diverged steps count as inf: order statistics without interpolation
    return float(np.percentile(a, 50, method="nearest")), float(np.percentile(a, 95, method="nearest"))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--device", default="cpu")
    p.add_argument("--traces", default=str(DEFAULT_TRACES), help="directory of ManiSkill/PhysX trace JSON files")
    p.add_argument("--options", default=",".join(OPTIONS), help=f"comma list of {list(OPTIONS)}")
    p.add_argument("--inertia-merge", default="exact", choices=["exact", "newton"])
    p.add_argument("--no-open-loop", action="store_true")
    p.add_argument("--out", default=str(DEFAULT_OUT))
    args = p.parse_args(argv)
    wp.config.log_level = wp.LOG_WARNING
    device = wp.get_device(args.device)
    traces = load_traces(Path(args.traces))
    rows = []
    for option in [o.strip() for o in args.options.split(",") if o.strip()]:
        if option not in OPTIONS:
            raise SystemExit(f"--options: unknown {option!r}; known: {list(OPTIONS)}")
        t0 = time.perf_counter()
        errs = {"small": [], "large": []}
        drift = {"small": [], "large": []}
        diverged = 0
        iters = []
        for _name, tr in traces.items():
            g = group_of(tr)
            r = one_step(tr, option, device, args.inertia_merge)
            errs[g] += r["err"].tolist()
            diverged += r["diverged"]
            if r["max_iterations"] is not None:
                iters.append(r["max_iterations"])
            if not args.no_open_loop:
                o = open_loop(tr, option, device, args.inertia_merge)
                diverged += o["diverged"]
                if o["drift"] is not None:
                    drift[g].append(o["drift"])
        sm, sp = _stats(errs["small"])
        lm, lp = _stats(errs["large"])
        row = {
            "option": option,
            "small_median": sm,
            "small_p95": sp,
            "large_median": lm,
            "large_p95": lp,
            "small_steps": len(errs["small"]),
            "large_steps": len(errs["large"]),
            "drift_small_rad": max(drift["small"]) if drift["small"] else None,
            "drift_large_rad": max(drift["large"]) if drift["large"] else None,
            "divergences": diverged,
            "coupled_max_iterations": max(iters) if iters else None,
            "seconds": time.perf_counter() - t0,
        }
        rows.append(row)
        print(json.dumps(row), flush=True)
    meta = machine_info(device)
    meta.update({"traces": sorted(traces), "inertia_merge": args.inertia_merge})

    def f(x):
        return "—" if x is None else ("inf" if not np.isfinite(x) else f"{x:.3g}")

    table = md_table(
        [
            "wpctrl on MuJoCo-Warp, 100 Hz",
            "small moves: median / p95",
            "large moves: median / p95",
            "open-loop drift small / large [rad]",
            "divergences",
        ],
        [
            [
                r["option"],
                f"{f(r['small_median'])} / {f(r['small_p95'])}",
                f"{f(r['large_median'])} / {f(r['large_p95'])}",
                f"{f(r['drift_small_rad'])} / {f(r['drift_large_rad'])}",
                r["divergences"],
            ]
            for r in rows
        ],
    )
    md = (
        "# Fidelity against PhysX (ManiSkill Panda traces)\n"
        + meta_markdown(meta)
        + f"\nTraces: {', '.join(sorted(traces))}; Panda inertia_merge={args.inertia_merge!r}, gravity off. One-step "
        "error = |q_newton - q_physx| / |q_physx - q_before| over the arm after each control step (K = 5 substeps), "
        "state re-synced to PhysX before every step. Open-loop drift: largest arm error over a whole trace without "
        "re-sync. 'x15': 15 solver substeps per 10 ms.\n\n" + table + "\n"
    )
    write_results(args.out, f"fidelity_{'cuda' if device.is_cuda else 'cpu'}", meta, rows, md)
    print(md)


if __name__ == "__main__":
    main()
