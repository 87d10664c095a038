"""The cost of each actuator model on one control step, for N parallel Pandas, next to the plain explicit step and
next to Newton's own clamping component doing the same work.

One control step = ``set_action`` + K x ``before_simulation_step`` (K = 5), ManiSkill's Panda mode
``pd_joint_target_delta_pos``, explicit actuation (naive PD); the arm's config carries the model:

* ``plain``: no model (ManiSkill's clamp to ``force_limit``);
* ``dc_motor``: ``wpctrl.DCMotor(87, 2.6)``;
* ``position_limit``: ``wpctrl.PositionBasedEffortLimit`` with an 8-entry table;
* ``mlp``: ``wpctrl.ActuatorNet`` of a 6-32-32-1 softsign MLP over 3 history taps (random weights), its defaults
  (``kernel="auto"``: the unrolled kernel, the weights compiled in, one thread per row; ``launch="auto"``: in the
  substep kernel's launch);
* ``lstm``: ``wpctrl.ActuatorNet`` of a 2-layer, 8-unit LSTM with a linear head (random weights), its defaults;
* ``mlp_unrolled`` / ``lstm_unrolled``: the same networks with ``kernel="unrolled"`` and ``launch="separate"`` (one
  thread per row at every size, in a launch of its own after the substep kernel's: two launches per substep);
* ``mlp_tiled`` / ``lstm_tiled``: the same networks with ``kernel="tiled"`` (weights staged in shared memory, rows in
  64-row tiles, each layer a ``wp.tile_matmul``);
* ``mlp_3xtf32``: the MLP with ``kernel="3xtf32"`` (each layer a warp-wide tensor-core product at float32 accuracy,
  32 rows per warp; its own launch after the substep kernel's);
* ``mlpwide_tiled`` / ``mlpwide_3xtf32``: a 6-80-80-1 softsign MLP (6,960 multiply-adds per row, past what
  ``"auto"`` compiles into the unrolled kernel) with ``kernel="tiled"`` / ``"3xtf32"``;
* ``mlp_fused`` / ``lstm_fused``: ``kernel="unrolled"``, ``launch="fused"``: the unrolled kernel's network code run in
  the substep kernel's launch (one launch per substep in place of two; what the defaults run here);
* ``torch_mlp`` / ``torch_lstm``: the same control step with the network's substep written in torch on the same
  rows, in place of wpctrl's network launch (``launch="separate"``; bench/actuators/torch_actuator_net.py: cuBLAS /
  cuDNN, Isaac Lab's ``ActuatorNetMLP`` / ``ActuatorNetLSTM`` code path). On CUDA, wpctrl's launches and the torch
  ops are captured in one CUDA graph, or, where that capture fails, as a Warp graph and a torch graph replayed back
  to back on one stream (the ``torch_capture`` field says which); on the CPU the step is timed eagerly only (torch's
  ops are no Warp launches to capture);
* ``newton_dc``: the plain step plus Newton 1.8's ``ClampingDCMotor`` applied to ``joint_f`` after every substep
  (its own launch over every DOF): what the same DC-motor envelope costs as Newton's component.

Graph-captured replay (and eager with ``--eager``), round-robin. Before timing, each torch variant's first control
step is checked against the matching wpctrl one (``check_max_abs_joint_f``: max |joint_f| difference; a network
variant's against the unrolled kernel's when that ran before it; ``kernel``: the network kernel that ran), and on
CUDA one replay of its graph from the same start against that eager step (``replay_check_max_abs_joint_f``). A
variant that cannot be built, run or captured is reported (``failures`` in the results) and the others are still
timed. Run ``python bench/actuators/actuator_cost.py --help``; results go to ``<out>/actuator_cost_<device>.{json,md}``.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

from bench.common import (  # noqa: E402
    add_run_args,
    build_panda_model,
    finish_run,
    fmt_envs,
    fmt_ratio,
    fmt_us,
    md_table,
    measure_interleaved,
    meta_markdown,
    panda_mode,
    parse_envs,
    parse_run_args,
    real_setup,
    start_run,
    synthetic_setup,
)

VARIANTS = ("plain", "dc_motor", "position_limit", "mlp", "lstm", "mlp_unrolled", "lstm_unrolled", "mlp_tiled",
            "lstm_tiled", "mlp_fused", "lstm_fused",
            "mlp_3xtf32", "mlpwide_tiled", "mlpwide_3xtf32", "torch_mlp", "torch_lstm", "newton_dc")  # fmt: skip
LABELS = {
    "plain": "plain explicit step",
    "dc_motor": "DCMotor",
    "position_limit": "PositionBasedEffortLimit",
    "mlp": "ActuatorNet (MLP 6-32-32-1)",
    "lstm": "ActuatorNet (LSTM 2x8)",
    "mlp_unrolled": "ActuatorNet (MLP, unrolled kernel, two launches)",
    "lstm_unrolled": "ActuatorNet (LSTM, unrolled kernel, two launches)",
    "mlp_tiled": "ActuatorNet (MLP, tiled kernel)",
    "lstm_tiled": "ActuatorNet (LSTM, tiled kernel)",
    "mlp_fused": "ActuatorNet (MLP, in the substep's launch)",
    "mlp_3xtf32": "ActuatorNet (MLP, tensor cores, 3xTF32)",
    "mlpwide_tiled": "ActuatorNet (MLP 6-80-80-1, tiled kernel)",
    "mlpwide_3xtf32": "ActuatorNet (MLP 6-80-80-1, tensor cores)",
    "lstm_fused": "ActuatorNet (LSTM, in the substep's launch)",
    "torch_mlp": "MLP in torch",
    "torch_lstm": "LSTM in torch",
    "newton_dc": "plain + Newton ClampingDCMotor",
}


def _actuator(name: str):
    import wpctrl

    torch_baseline = name.startswith("torch_")
    name, _, kernel = name.removeprefix("torch_").partition("_")

    if name == "dc_motor":
        return wpctrl.DCMotor(87.0, 2.6)
    if name == "position_limit":
        return wpctrl.PositionBasedEffortLimit(np.linspace(-2.8, 2.8, 8).tolist(), [20, 40, 60, 87, 87, 60, 40, 20])
    if name in ("mlp", "lstm", "mlpwide"):
        import torch

        torch.manual_seed(0)
        if name == "mlpwide":
            net = torch.nn.Sequential(
                torch.nn.Linear(6, 80), torch.nn.Softsign(), torch.nn.Linear(80, 80), torch.nn.Softsign(),
                torch.nn.Linear(80, 1),
            )  # fmt: skip
        elif name == "mlp":
            net = torch.nn.Sequential(
                torch.nn.Linear(6, 32), torch.nn.Softsign(), torch.nn.Linear(32, 32), torch.nn.Softsign(),
                torch.nn.Linear(32, 1),
            )  # fmt: skip
        else:

            class _LSTM(torch.nn.Module):
                def __init__(self):
                    super().__init__()
                    self.lstm = torch.nn.LSTM(2, 8, 2, batch_first=True)
                    self.linear = torch.nn.Linear(8, 1)

            net = _LSTM()
        # *_unrolled: two launches; *_fused: one; a torch baseline replaces the network's own launch
        launch = {"unrolled": "separate", "fused": "fused"}.get(kernel, "separate" if torch_baseline else "auto")
        kernel = "unrolled" if kernel == "fused" else kernel or "auto"
        return wpctrl.ActuatorNet(net, torque_scale=10.0, saturation_effort=87.0, velocity_limit=2.6, kernel=kernel,
                                  launch=launch)  # fmt: skip
    return None


def _mode(name: str, base: str) -> dict:
    mode = panda_mode(base)
    act = _actuator(name)
    if act is not None:
        mode["arm"] = dataclasses.replace(mode["arm"], actuator=act)
    return mode


def _newton_dc(ctrl, device):
    """A launch of Newton's ClampingDCMotor over the controller's DOFs of ``joint_f``, in place."""
    from newton.actuators import ClampingDCMotor

    dof = ctrl.dof_index.reshape(-1).astype(np.uint32)
    n = dof.size
    comp = ClampingDCMotor(
        wp.full(n, 87.0, dtype=wp.float32, device=device),
        wp.full(n, 2.6, dtype=wp.float32, device=device),
        wp.full(n, 87.0, dtype=wp.float32, device=device),
    )
    idx = wp.array(dof, dtype=wp.uint32, device=device)
    scratch = wp.zeros(n, dtype=wp.float32, device=device)
    return comp, idx, scratch


def _torch_net(ctrl, state, control, lstm_cells: bool = False):
    """Replace the controller's network launch by the torch baseline's substep
    (bench/actuators/torch_actuator_net.py)."""
    from bench.actuators.torch_actuator_net import TorchActuatorNet

    tnet = TorchActuatorNet(ctrl, state, control, lstm_cells)
    group = ctrl._engine.part("actuator_models").nets[0]
    group.launch = lambda engine, state, control: tnet.substep()
    return tnet


def _reference(name: str) -> str | None:
    """The variant whose first control step ``name``'s must reproduce: a torch baseline's network kernel (its default
    one), a network kernel's the unrolled kernel of the same network."""
    if name.startswith("torch_"):
        return name.removeprefix("torch_")
    net, _, kernel = name.partition("_")
    if net in ("mlp", "lstm") and kernel != "unrolled":
        return f"{net}_unrolled"
    if net == "mlpwide" and kernel != "tiled":  # (past the unrolled kernel's size)
        return "mlpwide_tiled"
    return None


def _setup_variant(args, name, n_envs, model, small_model, sync, device, first_f, checks, lstm_cells):
    """Build variant ``name``, run its first control step (recorded in ``first_f``; a torch baseline's difference to
    the matching network kernel's in ``checks``) and capture it: ``(replay function or None, eager step)``."""
    kw = {"actuation": "explicit", "control_freq": 20, "sim_freq": 100}
    mode = _mode(name, args.mode)
    su = real_setup(mode, model, **kw) if model is not None else synthetic_setup(mode, small_model, n_envs, **kw)
    ctrl, state, control = su.ctrl, su.state, su.control
    action = wp.array(np.random.default_rng(1).uniform(-1, 1, (n_envs, ctrl.action_dim)).astype(np.float32),
                      device=device)  # fmt: skip
    ctrl.reset(state)
    tnet = _torch_net(ctrl, state, control, lstm_cells) if name.startswith("torch_") else None
    extra = _newton_dc(ctrl, device) if name == "newton_dc" else None

    def step(ctrl=ctrl, state=state, control=control, action=action, extra=extra):
        ctrl.set_action(action, state)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(state, control)
            if extra is not None:  # Newton's component: read joint_f at the DOFs, clamp, write back
                comp, idx, scratch = extra
                comp.modify_forces(control.joint_f, scratch, state.joint_q, state.joint_qd, idx, idx)

    inner = step
    cuda = wp.get_device(device).is_cuda
    if tnet is not None and cuda:  # eager: Warp's launches and torch's ops on one stream, so that they stay in order
        from bench.actuators.torch_actuator_net import run_on_shared_stream

        def step(inner=inner, device=device):
            run_on_shared_stream(inner, device)

    sync()
    step()
    sync()
    # the first control step's joint_f (same action, same start): the torch baseline against wpctrl's kernel
    first_f[name] = control.joint_f.numpy().copy()
    base = name.removeprefix("torch_")
    ref = _reference(name)
    if ref in first_f:
        checks[name] = float(np.abs(first_f[name] - first_f[ref]).max())
        print(f"[{fmt_envs(n_envs)}] {name}: max |joint_f - {ref}'s| after one step = {checks[name]:.3g}")
    nets = ctrl._engine.part("actuator_models").nets if ctrl._engine.part("actuator_models") else []
    if nets and tnet is None:  # which network kernel ran (private attributes: the bench reports them)
        kind = nets[0].kernel_kind
        if ctrl._engine.part("actuator_models").fused is not None:
            kind += ", in the substep's launch"
        checks[name + ":kernel"] = kind
        print(f"[{fmt_envs(n_envs)}] {name}: kernel {kind}", flush=True)
    if tnet is None:
        with wp.ScopedCapture(device=device) as cap:
            step()
        # the graph replays into these arrays: keep them alive with it (a freed one would be reused or unmapped)
        return (lambda g=cap.graph, keep=(su, action, extra): wp.capture_launch(g)), step
    if not cuda:  # torch's ops are no Warp launches: on the CPU the torch baseline is timed eagerly only
        replay, how = step, "eager (CPU)"
    else:
        from bench.actuators.torch_actuator_net import capture_apart, capture_joint

        try:
            replay = capture_joint(inner, device)
            how = "one graph"
        except Exception as e:  # noqa: BLE001 - the two-graph fallback below
            print(f"[{fmt_envs(n_envs)}] {name}: one graph failed ({type(e).__name__}: {e}); trying two graphs")
            checks[name + ":one graph error"] = f"{type(e).__name__}: {e}"
            sync()
            group = ctrl._engine.part("actuator_models").nets[0]
            group.launch = lambda engine, state, control: None
            replay = capture_apart(inner, tnet, ctrl.num_substeps, device)
            how = "two graphs"
    checks[name + ":capture"] = how
    # a replay from the same start must give the eager first step's joint_f (and so agree with the kernel's)
    sync()
    ctrl.reset(state)
    tnet.reset()
    sync()
    replay()
    sync()
    got = control.joint_f.numpy()
    checks[name + ":replay"] = float(np.abs(got - first_f[name]).max())
    if base in first_f:
        checks[name + ":replay_vs_kernel"] = float(np.abs(got - first_f[base]).max())
    print(f"[{fmt_envs(n_envs)}] {name}: {how}; max |joint_f| of a replay from the start - the first step's = "
          f"{checks[name + ':replay']:.3g}")  # fmt: skip
    if not cuda:
        return None, step
    return (lambda r=replay, keep=(su, action, tnet): r()), step


def run_one(args, n_envs, model, small_model, sync, device, failures: list) -> list[dict]:
    """Time every variant at ``n_envs``. A variant that cannot be built, run or captured is printed and appended to
    ``failures``; the others are still timed."""
    fns = {}
    checks = {}
    first_f = {}
    for name in args.variants:
        tries = (False, True) if name == "torch_lstm" else (False,)
        got = None
        for cells in tries:  # the torch LSTM through cuDNN, else (a batch cuDNN refuses) as cell equations
            try:
                got = _setup_variant(args, name, n_envs, model, small_model, sync, device, first_f, checks, cells)
                break
            except Exception as e:  # noqa: BLE001 - reported, the other variants go on
                label = f"{name} (lstm cells)" if cells else name
                print(f"[{fmt_envs(n_envs)}] {label}: failed ({type(e).__name__}: {e})", flush=True)
                failures.append({"envs": n_envs, "variant": label, "error": f"{type(e).__name__}: {e}"})
                try:
                    sync()
                except Exception:  # noqa: BLE001, S110 - a sticky device error shows in the next variant's failure
                    pass
        if got is None:
            continue
        graph_fn, step = got
        if graph_fn is not None:
            fns[name + ":graph"] = graph_fn
        if args.eager or graph_fn is None:
            fns[name + ":eager"] = step
    times = measure_interleaved(
        fns, sync, repeats=args.repeats, min_time=args.min_time, warmup=args.warmup, clock=args.clock
    )
    rows = []
    base = {k: times.get(f"plain:{k}", {}).get("median_s") for k in ("graph", "eager")}
    for key, t in times.items():
        name, how = key.split(":")
        rows.append(
            {
                "envs": n_envs,
                "layout": "real" if model is not None else "synthetic",
                "variant": name,
                "replay": how,
                "us": t["median_s"] * 1e6,
                "x_plain": (t["median_s"] / base[how]) if base.get(how) else None,
                "samples_us": [x * 1e6 for x in t["samples_s"]],
                "iters": t["iters"],
                "clock": args.clock,
                "kernel": checks.get(name + ":kernel"),
                "check_max_abs_joint_f": checks.get(name),
                "torch_capture": checks.get(name + ":capture"),
                "torch_one_graph_error": checks.get(name + ":one graph error"),
                "replay_check_max_abs_joint_f": checks.get(name + ":replay"),
                "replay_vs_kernel_max_abs_joint_f": checks.get(name + ":replay_vs_kernel"),
            }
        )
    return rows


def markdown(meta: dict, rows: list[dict], args) -> str:
    out = ["# Actuator models: cost per control step\n", meta_markdown(meta) + "\n"]
    out.append(
        f"Mode `{args.mode}`, explicit actuation (naive PD), K = 5. µs per control step (set_action + 5 substeps); "
        f"'× plain' = this / the plain explicit step of the same replay kind. Clock: {args.clock}, median of "
        f"{args.repeats} round-robin samples.\n\n"
    )
    body = [
        [
            fmt_envs(r["envs"]) + ("*" if r["layout"] == "synthetic" else ""),
            LABELS[r["variant"]] + ("†" if r.get("torch_capture") == "two graphs" else ""),
            r["replay"],
            fmt_us(r["us"] * 1e-6),
            fmt_ratio(r["x_plain"]),
            r.get("kernel") or "",
        ]
        for r in rows
    ]
    out.append(md_table(["envs", "variant", "replay", "µs", "× plain", "network kernel"], body))
    if any(r["layout"] == "synthetic" for r in rows):
        out.append("\n\\* synthetic layout (bench/common.py): a small model's layout tiled to N envs.\n")
    if any(r.get("torch_capture") == "two graphs" for r in rows):
        out.append("\n† wpctrl's step and the torch network as two graphs replayed back to back on one stream (one "
                   "graph of both could not be captured).\n")  # fmt: skip
    checks = {(r["envs"], r["variant"]): r for r in rows if r.get("check_max_abs_joint_f") is not None}.values()
    if checks:
        each = []
        for r in checks:
            txt = f"{fmt_envs(r['envs'])} {r['variant']} {_g(r['check_max_abs_joint_f'])}"
            if r.get("replay_check_max_abs_joint_f") is not None:
                txt += (
                    f" (a replay from the start: {_g(r['replay_vs_kernel_max_abs_joint_f'])} against the kernel, "
                    f"{_g(r['replay_check_max_abs_joint_f'])} against the eager step; {r['torch_capture']})"
                )
            each.append(txt)
        out.append(f"\nMax |joint_f| difference (N·m) after the first control step, a torch baseline against the "
                   f"network kernel, a network kernel against the unrolled one (the 6-80-80-1 MLP: the tiled one): "
                   f"{'; '.join(each)}.\n")  # fmt: skip
    failures = meta.get("failures") or []
    if failures:
        out.append("\nNot timed: " + "; ".join(f"{fmt_envs(f['envs'])} {f['variant']}: {f['error']}" for f in failures)
                   + ".\n")  # fmt: skip
    return "".join(out)


def _g(x) -> str:
    return "n/a" if x is None else f"{x:.2g}"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_args(p, envs_help="comma list, k/M suffixes (default: cpu 1,64,1k; cuda up to 1M)", variants=VARIANTS,
                 torch_threads=False)  # fmt: skip
    p.add_argument("--mode", default="pd_joint_target_delta_pos")
    p.add_argument("--eager", action="store_true", help="also time the eager calls")
    p.add_argument("--max-real-envs", type=int, default=4096)
    blocks = "Warp's cooperative CPU blocks (the tiled kernels run their GPU blocks on the CPU)"
    p.add_argument("--cpu-blocks", action="store_true", help=blocks)
    args = parse_run_args(p, argv)
    if args.cpu_blocks:
        wp.config.enable_cpu_blocks = True
    device, sync, meta = start_run(p, args, cpu_envs="1,64,1k", cuda_envs="1,1k,4k,64k,1M")
    rows = []
    failures = meta.setdefault("failures", [])
    small_model = None
    t0 = time.perf_counter()
    for n in parse_envs(args.envs):
        model = build_panda_model(n, device) if n <= args.max_real_envs else None
        if model is None and small_model is None:
            small_model = build_panda_model(2, device)
        try:
            got = run_one(args, n, model, small_model, sync, device, failures)
        except (RuntimeError, MemoryError) as e:
            print(f"[{fmt_envs(n)}] skipped: {type(e).__name__}: {e}", flush=True)
            break
        for r in got:
            print(
                f"[{fmt_envs(n)}] {LABELS[r['variant']]:>32} {r['replay']:>5}: "
                f"{r['us']:10.2f} us  x plain "
                f"{fmt_ratio(r['x_plain']):>7}",
                flush=True,
            )
        rows += got
        del model
        # written after every size, so that a run stopped at its time limit keeps what it measured
        finish_run(args, device, meta, rows, t0, "actuator_cost", lambda r=rows: markdown(meta, r, args))


if __name__ == "__main__":
    main()
