"""What a training step of the reach task costs, by part, on one GPU: the graph-captured env step without a policy (the
rollout rate PPO's collection is compared with), the controller's calls alone and the physics alone, each its own
graph replayed back to back.

Run ``python bench/train_rate.py --envs 4096``; writes ``<out>/train_rate_<device>.{json,md}``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import warp as wp  # noqa: E402

wp.config.log_level = wp.LOG_WARNING


def _time(fn, sync, min_s=0.5, repeats=5) -> float:
    """Median seconds per call of ``fn`` over ``repeats`` samples of at least ``min_s`` each."""
    fn()
    sync()
    n = 1
    while True:
        t = time.perf_counter()
        for _ in range(n):
            fn()
        sync()
        if time.perf_counter() - t >= min_s / 4:
            break
        n *= 2
    samples = []
    for _ in range(repeats):
        t = time.perf_counter()
        for _ in range(n):
            fn()
        sync()
        samples.append((time.perf_counter() - t) / n)
    return sorted(samples)[len(samples) // 2]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--envs", type=int, default=4096)
    p.add_argument("--device", default="cuda:0" if wp.is_cuda_available() else "cpu")
    p.add_argument("--control-mode", default="pd_ee_delta_pos")
    p.add_argument("--out", default="bench/results")
    args = p.parse_args(argv)
    import torch

    from wpctrl.train.reach import ReachEnv

    cuda = args.device.startswith("cuda")
    env = ReachEnv(args.envs, device=args.device, control_mode=args.control_mode, graph=cuda)
    dev = env.wp_device

    def sync():
        wp.synchronize_device(dev)
        if cuda:
            torch.cuda.synchronize()

    zero = torch.zeros(args.envs, env.num_actions, device=args.device)
    ctrl, s0, s1, c = env.ctrl, env.state, env._other, env.control

    def ctrl_calls():
        ctrl.set_action(env.action, s0)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(s0, c)

    def physics():
        for k in range(ctrl.num_substeps):
            src, dst = (s0, s1) if k % 2 == 0 else (s1, s0)
            env.solver.step(src, dst, c, None, env.dt)

    fns = {"env.step (no policy)": lambda: env.step(zero)}
    if cuda:
        fns["env graph alone"] = lambda: wp.capture_launch(env.graph)
        for name, f in (("controller calls", ctrl_calls), ("physics (K solver steps)", physics)):
            f()
            with wp.ScopedCapture(device=dev) as cap:
                f()
            fns[name] = lambda g=cap.graph: wp.capture_launch(g)
    else:
        fns["controller calls"] = ctrl_calls
        fns["physics (K solver steps)"] = physics
    rows = {name: _time(f, sync) for name, f in fns.items()}
    step = rows["env.step (no policy)"]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    tag = "cuda" if cuda else "cpu"
    result = {
        "envs": args.envs,
        "device": args.device,
        "device_name": torch.cuda.get_device_name() if cuda else "cpu",
        "control_mode": args.control_mode,
        "us_per_call": {k: v * 1e6 for k, v in rows.items()},
        "env_steps_per_s_no_policy": args.envs / step,
        "controller_share_of_env_step": rows["controller calls"] / step,
        "date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()),
    }
    (out / f"train_rate_{tag}.json").write_text(json.dumps(result, indent=1))
    lines = [
        f"# Reach env step, {args.envs} envs, {result['device_name']}, {args.control_mode}\n",
        "| part | µs per control step | share of env.step |",
        "|---|---|---|",
    ]
    lines += [f"| {k} | {v * 1e6:,.1f} | {v / step:.1%} |" for k, v in rows.items()]
    lines.append(f"\nenv.step without a policy: {args.envs / step:,.0f} env-steps/s\n")
    (out / f"train_rate_{tag}.md").write_text("\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
