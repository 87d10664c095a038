"""What a training run writes besides the checkpoint: ``train.json`` (strict JSON) and the learning curve."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

__all__ = ["NO_EPISODE", "figure", "fmt", "median", "plot", "smoothed", "write_json"]

NO_EPISODE = "no episode has finished yet"
"""The note on the axes of a learning curve where no training episode has finished."""


def median(xs):
    xs = sorted(x for x in xs if x is not None)
    return xs[len(xs) // 2] if xs else None


def fmt(x) -> str:
    return "   –  " if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:6.3f}"


def write_json(path: Path, data: dict) -> None:
    path.write_text(json.dumps(data, indent=1, allow_nan=False))


def smoothed(values, counts, window: int) -> list[float]:
    """Per iteration, the mean of ``values`` over the last ``window`` finished episodes up to it: iteration ``j``
    finished ``counts[j]`` episodes whose mean is ``values[j]``, so it weighs ``counts[j]`` (the oldest iteration in
    the window only the episodes that fit); iterations where none finished weigh nothing. NaN before the first
    finished episode. Per-iteration rates jump where few episodes ended (one success of two is 50 %); this curve does
    not."""
    if window < 1:
        raise ValueError(f"smoothed: window expected a positive number of episodes, got {window}")
    out = []
    for i in range(len(values)):
        need, num, den = window, 0.0, 0
        for j in range(i, -1, -1):
            n = counts[j] or 0
            if n <= 0 or values[j] is None:
                continue
            w = min(n, need)
            num += w * values[j]
            den += w
            need -= w
            if need == 0:
                break
        out.append(num / den if den else math.nan)
    return out


def figure(history, evaluations, title: str, success_label: str, window: int):
    """The learning curve's figure (matplotlib, not saved): success rate and reward against the env steps collected
    (top) and the run's wall time (bottom). Training episodes' success rate and episode reward are smoothed over the
    last ``window`` finished episodes (:func:`smoothed`); the mean step reward (every iteration has steps) on the
    reward panels' right axis; the evaluations of the deterministic policy on fresh episodes as points. Where no
    episode has finished yet the success and episode-reward axes say so (:data:`NO_EPISODE`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def col(rows, key):
        return [math.nan if r.get(key) is None else r[key] for r in rows]

    counts = [h.get("episodes") or 0 for h in history]
    success = smoothed([h.get("success_rate") for h in history], counts, window)
    reward = smoothed([h.get("mean_episode_reward") for h in history], counts, window)
    finished = sum(counts) > 0
    evals = [e for e in evaluations if e.get("env_steps") is not None]
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.2))
    for row, (key, xlabel) in enumerate((("env_steps", "env steps collected"), ("wall_s", "wall time of the run [s]"))):
        xs = col(history, key)
        a, b = axes[row]
        if finished:
            a.plot(xs, col(history, "success_rate"), ".", color="C0", alpha=0.25, ms=3, label="per iteration")
            a.plot(xs, success, "-", color="C0", label=f"training episodes, last {window} finished (stochastic)")
            b.plot(xs, reward, "-", color="C1", label=f"episode reward, last {window} finished")
        else:
            for ax, y in ((a, 0.5), (b, 0.9)):  # (above the step reward's line, mostly)
                ax.text(0.5, y, NO_EPISODE, transform=ax.transAxes, ha="center", va="center", color="0.4")
        a.plot(col(evals, key), col(evals, "success_rate"), "ko--", ms=4, lw=1,
               label="evaluation (deterministic, fresh episodes)")  # fmt: skip
        a.set_ylim(-0.02, 1.02)
        a.set_ylabel(success_label)
        b.set_ylabel("mean episode reward", color="C1")
        c = b.twinx()
        c.plot(xs, col(history, "mean_step_reward"), "-", color="C2", lw=1, label="step reward (every env step)")
        c.set_ylabel("mean step reward", color="C2")
        for ax in (a, b):
            ax.set_xlabel(xlabel)
            ax.grid(alpha=0.3)
        a.legend(loc="upper left", fontsize=7)
        handles = b.get_legend_handles_labels()[0] + c.get_legend_handles_labels()[0]
        b.legend(handles, [h.get_label() for h in handles], loc="lower right", fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot(history, evaluations, path: Path, title: str, success_label: str, window: int = 100) -> None:
    """:func:`figure` saved as ``path`` (a note on stderr instead where matplotlib is not installed)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("wpctrl train: matplotlib is not installed: no learning_curve.png", file=sys.stderr)
        return
    fig = figure(history, evaluations, title, success_label, window)
    fig.savefig(path, dpi=110)
    plt.close(fig)
