"""How fast PPO collects on the reach task, against the same envs stepped without a policy.

Every part below is the reach env's own model, solver, controller and buffers (``wpctrl.train.reach.ReachEnv``), each
captured in its own CUDA graph (eager on the CPU) and replayed back to back; µs per control step (median of
``--repeats`` samples):

* **MuJoCo-Warp rollout**: K solver steps alone, the rate of simulating these envs with no controller and no policy;
* **controller calls**: ``set_action`` + K × ``before_simulation_step`` alone (the controller's share of the step);
* **env.step without a policy**: the env's whole step as PPO calls it (action copy, its graph: controller, physics,
  FK, observation / reward / done, partial reset; the returned copies), with a zero action;
* **rsl-rl alone**: PPO's ``act`` + ``process_env_step`` (policy and value networks, sampling, rollout storage) on a
  fixed observation, no env step;
* **PPO collection step**: ``act`` → ``env.step`` → ``process_env_step``, PPO's collection loop (an untrained policy
  costs what a trained one does). Its rate divided by the rollout's is the collection efficiency; set against the
  sum and the larger of the env step and rsl-rl alone, it tells whether the host's policy work overlaps the GPU's
  env step (no host sync in between) or adds to it.

With ``--train-json`` (a ``python -m wpctrl train`` run on the same device), that run's collection rate (median over
its iterations after the first) is divided by the rollout's as well.

    python bench/training/train_rate.py --envs 4096 --train-json runs/reach/train.json --out bench/results

Writes ``<out>/train_rate_<cpu|cuda>.{json,md}``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

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


def _host_time(fn, sync, calls: int = 20, repeats: int = 5) -> float:
    """Median host seconds per call of ``fn`` issued back to back after a sync, not waiting for the device: what
    the host spends per call while the GPU works (the GPU-bound part does not show here)."""
    samples = []
    for _ in range(repeats):
        sync()
        t = time.perf_counter()
        for _ in range(calls):
            fn()
        samples.append((time.perf_counter() - t) / calls)
        sync()
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
    import contextlib
    import io

    import torch
    from rsl_rl.runners import OnPolicyRunner

    from wpctrl.train.cli import train_cfg
    from wpctrl.train.reach import ReachEnv

    cuda = args.device.startswith("cuda")
    train = collection_rate(args.train_json, args.envs, args.device) if args.train_json else None
    env = ReachEnv(args.envs, device=args.device, control_mode=args.control_mode, graph=cuda)
    dev = env.wp_device

    def sync():
        wp.synchronize_device(dev)
        if cuda:
            torch.cuda.synchronize()

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

    with contextlib.redirect_stdout(io.StringIO()):
        alg = OnPolicyRunner(env, train_cfg(), log_dir=None, device=args.device).alg
    alg.train_mode()
    obs0 = env.get_observations()
    rew0, done0, extras0 = env.reward_t.clone(), env.done_t.clone(), {"time_outs": env.time_out_t.clone()}
    live = {"obs": obs0}

    def room():
        if alg.storage.step >= alg.storage.num_transitions_per_env:
            alg.storage.clear()

    def rsl_rl_alone():
        room()
        alg.act(obs0)
        alg.process_env_step(obs0, rew0, done0, extras0)

    def collection_step():
        room()
        actions = alg.act(live["obs"])
        live["obs"], rewards, dones, extras = env.step(actions)
        alg.process_env_step(live["obs"], rewards, dones, extras)

    fns["rsl-rl alone (act + process_env_step)"] = rsl_rl_alone
    fns["PPO collection step"] = collection_step
    with torch.inference_mode():
        sec = {name: _time(f, sync, args.min_s, args.repeats) for name, f in fns.items()}
        host = {name: _host_time(f, sync, repeats=args.repeats) for name, f in fns.items()} if cuda else None
    rollout, step = sec["MuJoCo-Warp rollout (K solver steps)"], sec["env.step without a policy"]
    policy, collect = sec["rsl-rl alone (act + process_env_step)"], sec["PPO collection step"]
    result = {
        "envs": args.envs,
        "control_mode": args.control_mode,
        "substeps": ctrl.num_substeps,
        "graph": cuda,
        "us_per_control_step": {k: v * 1e6 for k, v in sec.items()},
        "host_us_per_call": {k: v * 1e6 for k, v in host.items()} if host else None,
        "rollout_env_steps_per_s": args.envs / rollout,
        "env_step_env_steps_per_s": args.envs / step,
        "controller_share_of_env_step": sec["controller calls"] / step,
        "collection_env_steps_per_s": args.envs / collect,
        "collection_over_rollout": rollout / collect,
        "collection_over_env_step": step / collect,
        "collection_us_if_serial": (step + policy) * 1e6,
        "collection_us_if_overlapped": max(step, policy) * 1e6,
    }
    if train:
        rate = train["collection_env_steps_per_s"]
        result["training"] = train
        result["training_collection_over_rollout"] = rate / result["rollout_env_steps_per_s"]
    meta = machine_info(args.device)
    name = meta.get("device_name", args.device)
    rows = [
        [k, f"{v * 1e6:,.1f}", f"{host[k] * 1e6:,.1f}" if host else "–", f"{args.envs / v:,.0f}", f"{v / step:.1%}"]
        for k, v in sec.items()
    ]
    md = [
        f"# PPO collection on the reach task vs the same envs without a policy: {args.envs} envs, {name}\n",
        meta_markdown(meta) + "\n",
        f"Mode `{args.control_mode}`, K = {ctrl.num_substeps} substeps per control step, "
        + ("each part a CUDA graph.\n" if cuda else "eager (CPU).\n"),
        md_table(["part", "µs per control step", "host µs per call", "env-steps/s", "share of env.step"], rows),
        "(host µs: what the host spends per call when it does not wait for the device.)\n",
        f"Controller share of the env step: {result['controller_share_of_env_step']:.1%}.\n",
        f"PPO collection: {args.envs / collect:,.0f} env-steps/s = {result['collection_over_rollout']:.0%} of the "
        f"MuJoCo-Warp rollout, {result['collection_over_env_step']:.0%} of env.step without a policy. Per step "
        f"{collect * 1e6:,.0f} µs, against {(step + policy) * 1e6:,.0f} µs if rsl-rl's work and the env step ran one "
        f"after the other and {max(step, policy) * 1e6:,.0f} µs if they overlapped entirely.\n",
    ]
    if train:
        md.append(
            f"The training run ({args.train_json.name}, median of its {train['iterations']} iterations' collection): "
            f"{rate:,.0f} env-steps/s = {result['training_collection_over_rollout']:.0%} of the MuJoCo-Warp "
            "rollout.\n"
        )
    stem = f"train_rate_{'cuda' if cuda else 'cpu'}"
    jpath, mpath = write_results(args.out, stem, meta, [result], "\n".join(md))
    print("\n".join(md))
    print(f"wrote {jpath} and {mpath}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
