"""The captured control step of every kernel family, for an A/B of two wpctrl trees (``python -m bench ab-kernels``).

Imports the ``wpctrl`` of ``BENCH_WPCTRL_TREE`` (``bench/common.py``; default this tree) and uses only
``build_controller`` with its plain keywords and the controllers' per-step calls (and, for 1M envs, the synthetic
layout of ``bench.common``), so the same script times a baseline and a change. Per case and size: one control step
(``set_action`` + K = 5 ``before_simulation_step``) captured in a CUDA graph (``wp.ScopedCapture``) and replayed
(median µs over repeats), and the same step eager. The cases cover every kernel
that takes a bundled argument or the engine's accessors:

* ``joint_implicit`` / ``joint_explicit``: ``pd_joint_target_delta_pos`` (the generated step kernels), real Pandas up to
  4,096 envs and the synthetic replicated layout above (``bench.common.synthetic_setup``; 1M envs);
* ``stable``, ``accel_implicit``, ``coupled``, ``coupled_h_control``: the fused inertia kernels (the response per
  control step; the coupled drive's kernel every substep; H once per control step), on real Pandas (4k, 16k);
* ``ee``: ``pd_ee_delta_pose`` (the EE chain kernel), ``osc``: ``osc_ee_delta_pose`` (the impedance kernels: the EE
  chain and the articulation), on real Pandas;
* ``net_mlp`` / ``net_lstm``: an actuator network on the arm (Isaac Lab's MLP shape, 6 inputs and 2 x 32 ELU units,
  through the unrolled kernel; a 1 x 32 LSTM through the tiled kernel), the same torch weights in both trees (torch
  seeded), explicit actuation.

``--quick`` drops the 16k sizes (each case at 4k, the joint cases also at 1M: the sizes the step's speed is judged at),
about half the time.

``--outputs FILE`` also writes, per case, what a fixed sequence of actions and states produces at 64 envs
(``Control.joint_f`` / ``joint_target_q`` / ``joint_target_qd``, the controller's targets and readouts) to an ``.npz``,
for ``bench/ab/kernels_summary.py`` to check that the two trees compute the same bits.

    BENCH_WPCTRL_TREE=TREE python -m bench.ab.kernels --device cuda:0 --out DIR --tag A_1 [--outputs DIR/A.npz]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # bench.common imports BENCH_WPCTRL_TREE's wpctrl

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

from bench.common import (  # noqa: E402
    Sync,
    build_panda_model,
    machine_info,
    measure,
    panda_mode,
    parse_envs,
    real_setup,
    synthetic_setup,
)

ARM9 = [f"panda_joint{i}" for i in range(1, 8)] + ["panda_finger_joint1", "panda_finger_joint2"]

CASES = {
    # name: (sizes on CUDA, sizes on the CPU)
    "joint_implicit": ("4k,1M", "64"),
    "joint_explicit": ("4k,1M", "64"),
    "stable": ("4k,16k", "64"),
    "accel_implicit": ("4k,16k", "64"),
    "coupled": ("4k,16k", "64"),
    "coupled_h_control": ("4k", "64"),
    "ee": ("4k,16k", "64"),
    "osc": ("4k,16k", "64"),
    "net_mlp": ("4k,16k", "64"),
    "net_lstm": ("4k,16k", "64"),
}


def _mode(case: str):
    """(mode dict or config, build_controller keywords) of a case."""
    import wpctrl
    from wpctrl.robots import panda_control_modes

    if case.startswith("joint_"):
        return panda_mode("pd_joint_target_delta_pos"), {"actuation": case.split("_")[1]}
    if case == "ee":
        return panda_mode("pd_ee_delta_pose"), {}
    if case == "osc":
        return panda_control_modes()["osc_ee_delta_pose"], {}
    if case.startswith("net_"):
        return _net_mode(case), {"actuation": "explicit"}
    drive = "acceleration" if case == "accel_implicit" else "force"
    cfg = wpctrl.PDJointPosControllerConfig(ARM9, None, None, 1e3, 1e2, 100.0, normalize_action=False, drive_mode=drive)
    kw = {
        "stable": {"actuation": "explicit", "explicit_pd": "stable"},
        "accel_implicit": {},
        "coupled": {"actuation": "explicit", "explicit_pd": "coupled"},
        "coupled_h_control": {"actuation": "explicit", "explicit_pd": "coupled", "inertia_update": "control"},
    }[case]
    return cfg, kw


def _net_mode(case: str) -> dict:
    """The Panda's arm behind an actuator network (fixed weights: torch seeded), its gripper a plain PD."""
    import torch

    import wpctrl
    from wpctrl.robots import PANDA_ARM_JOINTS

    torch.manual_seed(0)
    if case == "net_mlp":
        net = torch.nn.Sequential(torch.nn.Linear(6, 32), torch.nn.ELU(), torch.nn.Linear(32, 32), torch.nn.ELU(),
                                  torch.nn.Linear(32, 1))  # fmt: skip
        act = wpctrl.ActuatorNet(net, input_idx=(0, 1, 2), kernel="unrolled")
    else:

        class LSTMNet(torch.nn.Module):
            def __init__(self):
                super().__init__()
                self.lstm = torch.nn.LSTM(2, 32, 1, batch_first=True)
                self.linear = torch.nn.Linear(32, 1)

            def forward(self, x, hc: tuple[torch.Tensor, torch.Tensor]):
                out, (h, c) = self.lstm(x, hc)
                return self.linear(out), (h, c)

        act = wpctrl.ActuatorNet(LSTMNet(), kernel="tiled")
    mode = panda_mode("pd_joint_delta_pos")
    arm = mode["arm"]
    mode["arm"] = wpctrl.PDJointPosControllerConfig(
        list(PANDA_ARM_JOINTS),
        arm.lower,
        arm.upper,
        arm.stiffness,
        arm.damping,
        arm.force_limit,
        use_delta=True,
        actuator=act,
    )
    return mode


def _action(ctrl, n: int, device, seed: int) -> wp.array:
    """A fixed action inside the action space (absolute targets near the model's pose for the 9-joint cases)."""
    rng = np.random.default_rng(seed)
    space = ctrl.single_action_space
    lo = np.where(np.isfinite(space.low), space.low, -1.0)
    hi = np.where(np.isfinite(space.high), space.high, 1.0)
    a = lo + (hi - lo) * rng.uniform(0.3, 0.7, (n, space.shape[0]))
    return wp.array(a.astype(np.float32), dtype=wp.float32, device=device)


def _model(n: int, device, models: dict):
    """``n`` Pandas without gravity, built once per process and size (each case's controller writes its own drive
    properties into it; nothing here steps a solver)."""
    if n not in models:
        models[n] = build_panda_model(n, device, gravity=False)
    return models[n]


def _setup(case: str, n: int, device, models: dict):
    mode, kw = _mode(case)
    kw = dict(kw, control_freq=20, sim_freq=100)
    kw.setdefault("actuation", "implicit")
    if case.startswith("joint_") and n > 4096:
        return synthetic_setup(mode, _model(2, device, models), n, **kw)
    return real_setup(mode, _model(n, device, models), **kw)


def time_case(case: str, n: int, device, sync, repeats: int, models: dict) -> dict:
    setup = _setup(case, n, device, models)
    ctrl, state, control = setup.ctrl, setup.state, setup.control
    ctrl.reset(state, control=control)
    action = _action(ctrl, n, device, seed=1)

    def step():
        ctrl.set_action(action, state)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(state, control)

    step()  # compile and warm up outside the capture
    sync()
    with wp.ScopedCapture(device=device) as cap:
        step()
    graph = cap.graph
    replay = measure(lambda: wp.capture_launch(graph), sync, repeats=repeats)["median_s"]
    eager = measure(step, sync, repeats=repeats)["median_s"]
    return {"case": case, "envs": n, "graph_us": replay * 1e6, "eager_us": eager * 1e6}


def outputs_case(case: str, device) -> dict:
    """What a fixed sequence (reset, then 3 control steps on changing states) writes, at 64 envs."""
    n = 64
    mode, kw = _mode(case)
    kw = dict(kw, control_freq=20, sim_freq=100)
    model = build_panda_model(n, device, gravity=False)
    import wpctrl

    ctrl = wpctrl.build_controller(mode, model, **kw)
    state, control = model.state(), model.control()
    rng = np.random.default_rng(7)
    q0 = model.joint_q.numpy()
    ctrl.reset(state, control=control)
    out = {}
    for k in range(3):
        q = (q0 + rng.normal(0.0, 0.05, q0.shape)).astype(np.float32)
        qd = rng.normal(0.0, 0.3, model.joint_dof_count).astype(np.float32)
        state.joint_q.assign(q)
        state.joint_qd.assign(qd)
        ctrl.set_action(_action(ctrl, n, device, seed=10 + k), state)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(state, control)
        for name in ("joint_f", "joint_target_q", "joint_target_qd"):
            out[f"{case}/{k}/{name}"] = getattr(control, name).numpy().copy()
        views = {"target_qpos": ctrl.target_qpos, "target_qvel": ctrl.target_qvel, "response": ctrl.response}
        for uid, child in (ctrl.children or {"": ctrl}).items():
            for attr in ("target_pose", "ee_pose", "target_effort"):
                if hasattr(child, attr) and getattr(child, attr) is not None:
                    views[f"{uid}.{attr}"] = getattr(child, attr)
        for name, arr in views.items():
            if arr is not None:
                out[f"{case}/{k}/{name}"] = np.array(arr.numpy())
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--device", default="cuda:0" if wp.is_cuda_available() else "cpu")
    p.add_argument("--cases", default=",".join(CASES))
    p.add_argument("--envs", default=None, help="override every case's sizes (comma list, k/M suffixes)")
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--out", required=True)
    p.add_argument("--tag", required=True)
    p.add_argument("--outputs", default=None, help="also write the fixed sequence's outputs to this .npz")
    p.add_argument("--quick", action="store_true", help="CUDA sizes without 16k (4k, and 1M for the joint cases)")
    args = p.parse_args(argv)
    wp.init()
    device = wp.get_device(args.device)
    sync = Sync(device)
    rows, models = [], {}
    meta = machine_info(device)
    Path(args.out).mkdir(parents=True, exist_ok=True)
    result = Path(args.out, f"ab_kernels_{args.tag}.json")
    t0 = time.perf_counter()
    for case in [c.strip() for c in args.cases.split(",") if c.strip()]:
        sizes = parse_envs(args.envs or CASES[case][0 if device.is_cuda else 1])
        if args.quick and device.is_cuda:
            sizes = [n for n in sizes if n != 16384]
        for n in sizes:
            try:
                r = time_case(case, n, device, sync, args.repeats, models)
            except (RuntimeError, MemoryError, NotImplementedError) as e:
                print(f"[{args.tag}] {case} {n}: skipped ({type(e).__name__}: {e})", flush=True)
                continue
            rows.append(r)
            result.write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))  # after every row: a cut run keeps it
            print(f"[{args.tag}] {case:>18} {n:>8}: graph {r['graph_us']:9.2f} us, eager {r['eager_us']:9.2f} us",
                  flush=True)  # fmt: skip
    if args.outputs:
        arrays = {}
        for case in [c.strip() for c in args.cases.split(",") if c.strip()]:
            arrays.update(outputs_case(case, device))
        np.savez(args.outputs, **{k.replace("/", "__"): v for k, v in arrays.items()})
    print(f"[{args.tag}] done in {time.perf_counter() - t0:.0f} s (wpctrl {meta.get('wpctrl_commit')})", flush=True)


if __name__ == "__main__":
    main()
