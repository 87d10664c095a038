"""What a training run writes besides the checkpoint: ``train.json`` (strict JSON) and the learning curve."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

__all__ = ["fmt", "median", "plot", "write_json"]


def median(xs):
    xs = sorted(x for x in xs if x is not None)
    return xs[len(xs) // 2] if xs else None


def fmt(x) -> str:
    return "   –  " if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:6.3f}"


def write_json(path: Path, data: dict) -> None:
    path.write_text(json.dumps(data, indent=1, allow_nan=False))


def plot(history, evaluations, path: Path, title: str, success_label: str) -> None:
    """Episode reward and success rate per iteration (training episodes), with the evaluations of the deterministic
    policy on fresh episodes."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("wpctrl train: matplotlib is not installed: no learning_curve.png", file=sys.stderr)
        return

    def series(key):
        return [math.nan if h.get(key) is None else h[key] for h in history]

    its = [h["iteration"] for h in history]
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.8))
    a.plot(its, series("mean_episode_reward"), "-")
    a.set_xlabel("PPO iteration")
    a.set_ylabel("mean episode reward")
    a.grid(alpha=0.3)
    b.plot(its, series("success_rate"), "-", label="training episodes (stochastic policy)")
    b.plot(
        [e["iteration"] for e in evaluations],
        [e["success_rate"] for e in evaluations],
        "ko--",
        ms=4,
        lw=1,
        label="evaluation (deterministic, fresh episodes)",
    )
    b.set_xlabel("PPO iteration")
    b.set_ylabel(success_label)
    b.set_ylim(-0.02, 1.02)
    b.legend(loc="lower right", fontsize=8)
    b.grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
