"""How fast PPO collects on the reach task, against the same envs stepped without a policy.

Every part below is the reach env's own model, solver, controller and buffers (``wpctrl.train.reach.ReachEnv``), each
captured in its own CUDA graph (eager on the CPU) and replayed back to back; µs per control step (median of
``--repeats`` samples):

* **MuJoCo-Warp rollout**: K solver steps alone, the rate of simulating these envs with no controller and no policy;
* **controller calls**: ``set_action`` + K × ``before_simulation_step`` alone (the controller's share of the step);
* **env.step without a policy**: the env's whole step as PPO calls it (action copy, its graph: controller, physics,
  FK, observation / reward / done, partial reset; the returned copies), with a zero action.

With ``--train-json`` (a ``python -m wpctrl train`` run on the same device), the run's collection rate (median over
its iterations after the first, policy inference and rsl-rl's storage included) is divided by both rates.

    python bench/train_rate.py --envs 4096 --train-json runs/reach/train.json --out bench/results

Writes ``<out>/train_rate_<cpu|cuda>.{json,md}``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import warp as wp  # noqa: E402

from bench.common import machine_info, md_table, meta_markdown, write_results  # noqa: E402


def _time(fn, sync, min_s: float, repeats: int) -> float:
    """Median seconds per call of ``fn`` over ``repeats`` samples of at least ``min_s`` each."""
    fn()
    sync()
    n = 1
    while True:
        t = time.perf_counter()
        for _ in range(n):
            fn()
        sync()
        if time.perf_counter() - t >= min_s:
            break
        n *= 2
    samples = []
    for _ in range(repeats):
        t = time.perf_counter()
        for _ in range(n):
            fn()
        sync()
        samples.append((time.perf_counter() - t) / n)
    return statistics.median(samples)


def collection_rate(train_json: Path, envs: int, device: str) -> dict:
    """The collection rate of a training run: the median over its iterations after the first (the first includes
    the policy's first-call warm-up)."""
    run = json.loads(Path(train_json).read_text())
    if run["envs"] != envs or not str(run["device"]).startswith(device.split(":")[0]):
        raise SystemExit(
            f"--train-json: expected a run with {envs} envs on {device}, got {run['envs']} on {run['device']}"
        )
    rates = [h["collection_env_steps_per_s"] for h in run["history"]]
    return {
        "collection_env_steps_per_s": statistics.median(rates[1:] or rates),
        "iterations": len(rates),
        "time_to_target_s": run.get("time_to_target_s"),
        "evaluation_success": run["evaluation"]["success_rate"],
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--envs", type=int, default=4096)
    p.add_argument("--device", default="cuda:0" if wp.is_cuda_available() else "cpu")
    p.add_argument("--control-mode", default="pd_ee_delta_pos")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--min-s", type=float, default=0.25, help="minimum seconds per timing sample")
    p.add_argument("--train-json", type=Path, default=None, help="a training run's train.json: its collection rate")
    p.add_argument("--out", default="bench/results")
    args = p.parse_args(argv)
    import torch

    from wpctrl.train.reach import ReachEnv

    cuda = args.device.startswith("cuda")
    train = collection_rate(args.train_json, args.envs, args.device) if args.train_json else None
    env = ReachEnv(args.envs, device=args.device, control_mode=args.control_mode, graph=cuda)
    dev = env.wp_device

    def sync():
        wp.synchronize_device(dev)

    zero = torch.zeros(args.envs, env.num_actions, device=args.device)
    ctrl, s0, s1, c = env.ctrl, env.state, env._other, env.control

    def physics():
        for k in range(ctrl.num_substeps):
            src, dst = (s0, s1) if k % 2 == 0 else (s1, s0)
            env.solver.step(src, dst, c, None, env.dt)

    def ctrl_calls():
        ctrl.set_action(env.action, s0)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(s0, c)

    parts = {"MuJoCo-Warp rollout (K solver steps)": physics, "controller calls": ctrl_calls}
    fns = {}
    for name, f in parts.items():
        if cuda:  # on the env's stream (Warp's current one, shared with torch)
            f()
            with wp.ScopedCapture(device=dev) as cap:
                f()
            fns[name] = lambda g=cap.graph: wp.capture_launch(g)
        else:
            fns[name] = f
    fns["env.step without a policy"] = lambda: env.step(zero)
    sec = {name: _time(f, sync, args.min_s, args.repeats) for name, f in fns.items()}
    rollout, step = sec["MuJoCo-Warp rollout (K solver steps)"], sec["env.step without a policy"]
    result = {
        "envs": args.envs,
        "control_mode": args.control_mode,
        "substeps": ctrl.num_substeps,
        "graph": cuda,
        "us_per_control_step": {k: v * 1e6 for k, v in sec.items()},
        "rollout_env_steps_per_s": args.envs / rollout,
        "env_step_env_steps_per_s": args.envs / step,
        "controller_share_of_env_step": sec["controller calls"] / step,
    }
    if train:
        rate = train["collection_env_steps_per_s"]
        result["training"] = train
        result["collection_over_rollout"] = rate / result["rollout_env_steps_per_s"]
        result["collection_over_env_step"] = rate / result["env_step_env_steps_per_s"]
    meta = machine_info(args.device)
    name = meta.get("device_name", args.device)
    rows = [[k, f"{v * 1e6:,.1f}", f"{args.envs / v:,.0f}", f"{v / step:.1%}"] for k, v in sec.items()]
    md = [
        f"# PPO collection on the reach task vs the same envs without a policy: {args.envs} envs, {name}\n",
        meta_markdown(meta) + "\n",
        f"Mode `{args.control_mode}`, K = {ctrl.num_substeps} substeps per control step, "
        + ("each part a CUDA graph.\n" if cuda else "eager (CPU).\n"),
        md_table(["part", "µs per control step", "env-steps/s", "share of env.step"], rows),
        f"Controller share of the env step: {result['controller_share_of_env_step']:.1%}.\n",
    ]
    if train:
        md.append(
            f"PPO collection (policy + rsl-rl storage + env.step, median of {train['iterations']} iterations): "
            f"{train['collection_env_steps_per_s']:,.0f} env-steps/s = {result['collection_over_rollout']:.0%} of "
            f"the MuJoCo-Warp rollout, {result['collection_over_env_step']:.0%} of env.step without a policy.\n"
        )
    stem = f"train_rate_{'cuda' if cuda else 'cpu'}"
    jpath, mpath = write_results(args.out, stem, meta, [result], "\n".join(md))
    print("\n".join(md))
    print(f"wrote {jpath} and {mpath}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
