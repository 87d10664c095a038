"""The demo's report: per-rank statistics reduced over ranks, strict JSON, the printed table and the plot."""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass
class RankStats:
    """One rank's raw figures (sums, not means, where ranks are combined)."""

    rank: int
    seed: int
    envs: int
    control_steps: int
    loop_s: float
    env_steps_per_s: float
    controller_ms_per_step: float
    solver_ms_per_step: float
    err_sq: dict  # group -> sum over scored (env, step) of the mean squared error
    err_max: dict  # group -> max |error|
    err_count: int  # scored (env, step) pairs
    nonfinite_envs: int
    bad_actions: int
    partial_resets: int
    setup_s: float
    compile_s: float
    diverged_at: float | None


def _finite_or_none(x):
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def json_safe(obj):
    """``obj`` with every non-finite float replaced by None (JSON ``null``), recursively."""
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        return _finite_or_none(float(obj))
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def strict_json(obj) -> str:
    """JSON that every parser accepts: no NaN/Infinity tokens (``null`` instead)."""
    return json.dumps(json_safe(obj), indent=2, allow_nan=False)


def _rms(sq: float, count: int) -> float:
    return math.sqrt(sq / count) if count > 0 else float("nan")


def combine(ctx, s: RankStats, config: dict, env_mean: np.ndarray, scaling, groups: dict, control_freq: int):
    """The run's summary from every rank's :class:`RankStats` (collectives: every rank calls this, every rank gets
    the summary) and every env's mean error (for the histogram)."""
    gnames = list(groups)
    vec = [
        s.rank,
        s.seed,
        s.envs,
        s.control_steps,
        s.loop_s,
        s.env_steps_per_s,
        s.controller_ms_per_step,
        s.solver_ms_per_step,
        s.err_count,
        s.nonfinite_envs,
        s.bad_actions,
        s.partial_resets,
        s.setup_s,
        s.compile_s,
        np.nan if s.diverged_at is None else s.diverged_at,
        *[s.err_sq[g] for g in gnames],
        *[s.err_max[g] for g in gnames],
    ]
    rows = ctx.all_gather(vec)  # (world, n)
    # Sums with an all-reduce (NaN propagates: one diverged rank makes the aggregate RMS null, not a silent mean).
    sums = ctx.all_reduce_sum(
        [s.err_count, s.nonfinite_envs, s.bad_actions, s.partial_resets] + [s.err_sq[g] for g in gnames]
    )
    env_means = ctx.all_gather(env_mean).reshape(-1)
    n_g = len(gnames)
    base = 15
    per_rank = []
    for r in rows:
        cnt = int(r[8])
        per_rank.append(
            {
                "rank": int(r[0]),
                "seed": int(r[1]),
                "envs": int(r[2]),
                "control_steps": int(r[3]),
                "env_steps_per_s": float(r[5]),
                "controller_ms_per_step": float(r[6]),
                "solver_ms_per_step": float(r[7]),
                "tracking_rms": {g: _rms(float(r[base + i]), cnt) for i, g in enumerate(gnames)},
                "tracking_max": {g: float(r[base + n_g + i]) for i, g in enumerate(gnames)},
                "nonfinite_envs": int(r[9]),
                "bad_actions": int(r[10]),
                "setup_seconds": float(r[12]),
                "compile_seconds": float(r[13]),
            }
        )
    count = int(sums[0])
    nonfinite = int(sums[1])
    world = ctx.world_size
    envs_total = int(rows[:, 2].sum())
    steps = int(rows[:, 3].min())
    ctrl_ms = float(rows[:, 6].mean())
    solver_ms = float(rows[:, 7].mean())
    # max over ranks with NaN propagating (np.max, unlike Python's max, does not drop a NaN)
    tmax = {g: float(np.max(rows[:, base + n_g + i])) for i, g in enumerate(gnames)}
    rms = {g: _rms(float(sums[4 + i]), count) for i, g in enumerate(gnames)}
    if nonfinite:
        rms = dict.fromkeys(gnames, float("nan"))
        tmax = dict.fromkeys(gnames, float("nan"))
    div = rows[:, 14]
    diverged_at = float(np.nanmin(div)) if np.isfinite(div).any() else None
    finite_means = env_means[np.isfinite(env_means)]
    summary = {
        "envs": envs_total,
        **config,
        "control_steps": steps,
        "sim_seconds": steps / control_freq,
        "setup_seconds": float(rows[:, 12].max()),
        "compile_seconds": float(rows[:, 13].max()),
        "control_steps_per_s": float(np.mean(rows[:, 5] / rows[:, 2])),
        "env_steps_per_s": float(rows[:, 5].sum()),
        "controller_ms_per_step": ctrl_ms,
        "solver_ms_per_step": solver_ms,
        "controller_share": ctrl_ms / max(ctrl_ms + solver_ms, 1e-12),
        "tracking_rms": rms,
        "tracking_max": tmax,
        "env_arm_error_mean": float(np.mean(env_means)),
        "env_arm_error_spread": (
            [float(x) for x in np.percentile(finite_means, [0, 50, 100])] if finite_means.size else None
        ),
        "partial_resets": int(sums[3]),
        "bad_actions": int(sums[2]),
        "nonfinite_envs": nonfinite,
        "all_finite": nonfinite == 0,
        "diverged_at_s": diverged_at,
        "world_size": world,
    }
    if world > 1 or ctx.distributed:
        summary["envs_per_rank"] = s.envs
        summary["backend"] = ctx.backend
        summary["per_rank"] = per_rank
        summary["seeds"] = [p["seed"] for p in per_rank]
        if scaling is not None:
            summary["scaling"] = scaling
    return summary, env_means


def _num(x, spec: str, scale: float = 1.0) -> str:
    if x is None or not math.isfinite(x):
        return "n/a"
    return format(x * scale, spec)


def format_summary(s: dict) -> str:
    units = s.get("units", {"arm": "rad", "gripper": "m"})
    dist = s.get("world_size", 1) > 1
    envs = f"{s['envs']} on {s['device']}"
    if dist:
        envs = f"{s['envs']} = {s['world_size']} ranks x {s['envs_per_rank']} ({s['backend']}; rank 0 on {s['device']})"
    pd = f", {s['explicit_pd']} PD" if s.get("explicit_pd") else ""
    rows = [
        ("envs", envs),
        ("robot", s.get("robot", "panda")),
        ("control mode", f"{s['control_mode']} ({s['actuation']}{pd}, {s['solver']}, graph={s['graph']})"),
        ("sim time", f"{s['sim_seconds']:.2f} s = {s['control_steps']} control steps x {s['substeps']} substeps"),
        ("control steps/s", _num(s["control_steps_per_s"], ".1f")),
        ("env-steps/s", _num(s["env_steps_per_s"], ",.0f") + (" (all ranks)" if dist else "")),
    ]
    if dist:
        rows.append(("env-steps/s per rank", ", ".join(_num(p["env_steps_per_s"], ",.0f") for p in s["per_rank"])))
        sc = s.get("scaling")
        if sc:
            rows.append(
                (
                    "scaling efficiency",
                    f"{_num(sc['efficiency'], '.1%')} (rank 0 alone {_num(sc['solo_env_steps_per_s'], ',.0f')} "
                    f"env-steps/s; all ranks at once {_num(sc['concurrent_env_steps_per_s'], ',.0f')})",
                )
            )
    rows += [
        (
            "controller / control step",
            f"{_num(s['controller_ms_per_step'], '.3f')} ms ({_num(s['controller_share'], '.1%')} of the step)",
        ),
        ("solver / control step", f"{_num(s['solver_ms_per_step'], '.3f')} ms ({s['substeps']} substeps)"),
        ("tracking", s.get("tracking", "")),
    ]
    for g, u in units.items():
        scale, spec = (1e3, ".2f") if u == "m" else (1.0, ".4f")
        u = "mm" if u == "m" else u
        rows.append(
            (
                f"  {g}",
                f"RMS {_num(s['tracking_rms'][g], spec, scale)} {u}, max {_num(s['tracking_max'][g], spec, scale)} {u}",
            )
        )
    rows += [
        ("partial resets", str(s["partial_resets"])),
        ("bad actions (NaN/Inf)", str(s["bad_actions"])),
        ("all values finite", "yes" if s["all_finite"] else f"NO ({s['nonfinite_envs']} envs)"),
        ("setup (build, compile)", f"{s['setup_seconds']:.1f} s (kernels {s['compile_seconds']:.1f} s)"),
    ]
    w = max(len(k) for k, _ in rows)
    return "\n".join(f"  {k:<{w}}  {v}" for k, v in rows)


def plot(path: Path, hist: dict, env_err: np.ndarray, task, summary: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = task.names
    n = len(names)
    extra = list(getattr(task, "extra_names", ())) if "extra_applied" in hist else []
    cols = 3 if n + len(extra) <= 10 else 4 if n + len(extra) <= 18 else 6  # a hand or a humanoid: smaller panels
    rows = -(-(n + len(extra) + 2) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.4 * cols, 2.75 * rows), constrained_layout=True, squeeze=False)
    t = hist["t"]
    shown = [None] * n  # per column: (unit shown, scale from SI)
    for span, _, unit, scale in task.groups.values():
        for j in range(n)[span]:
            shown[j] = (unit, scale)
    for j, ax in enumerate(axes.flat[:n]):
        unit, scale = shown[j]
        if len(t):
            if getattr(task, "has_desired", True):
                ax.plot(t, scale * hist["desired"][:, j], "k--", lw=1, label="desired (policy)")
            ax.plot(t, scale * hist["target"][:, j], color="tab:orange", lw=1, label="drive target (wpctrl)")
            ax.plot(t, scale * hist["measured"][:, j], color="tab:blue", lw=1.5, label="measured")
        ax.set_title(names[j], fontsize=9)
        ax.set_xlabel("t [s]", fontsize=8)
        ax.set_ylabel(f"[{unit}]", fontsize=8)
        ax.tick_params(labelsize=7)
    axes.flat[0].legend(fontsize=7)
    for j, name in enumerate(extra):  # not scored: e.g. the commanded torque and the one applied after the clamp
        ax = axes.flat[n + j]
        if len(t):
            ax.plot(t, hist["extra_commanded"][:, j], color="tab:orange", lw=1, label="commanded")
            ax.plot(t, hist["extra_applied"][:, j], color="tab:blue", lw=1.5, label="applied (joint_f)")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("t [s]", fontsize=8)
        ax.set_ylabel(f"[{task.extra_unit}]", fontsize=8)
        ax.tick_params(labelsize=7)
    if extra:
        axes.flat[n].legend(fontsize=7)
    n += len(extra)
    ax = axes.flat[n]
    finite = env_err[np.isfinite(env_err)]
    first = next(iter(task.groups))
    _, _, unit, scale = task.groups[first]
    if finite.size:
        ax.hist(scale * finite, bins=min(30, max(5, finite.size // 2)), color="tab:blue")
    ax.set_title(f"mean |{first} error| per env", fontsize=9)
    ax.set_xlabel(f"[{unit}]", fontsize=8)
    ax.set_ylabel("envs", fontsize=8)
    ax.tick_params(labelsize=7)
    for ax in axes.flat[n + 1 :]:
        ax.axis("off")
    lines = [
        f"{summary['control_mode']}, {summary['actuation']}, {summary['solver']}",
        f"{summary['envs']} envs, rank 0 on {summary['device']}",
        f"{_num(summary['env_steps_per_s'], '.0f')} env-steps/s",
    ]
    for g, (_, _, u, scale) in task.groups.items():
        lines.append(f"{g} RMS {_num(summary['tracking_rms'][g], '.4f', scale)} {u}")
    axes.flat[n + 1].text(0.0, 1.0, "\n".join(lines), va="top", fontsize=9, family="monospace")
    robot = summary.get("robot", "panda")
    fig.suptitle(f"wpctrl demo, {robot}, {summary['control_mode']}: env 0 of rank 0, {task.plot_subject}", fontsize=11)
    fig.savefig(path, dpi=90)
    plt.close(fig)


# ----------------------------------------------------------------------------------------------------------------------
# Timing


def _median_seconds(fn, device, repeats: int) -> float:
    """Median wall time [s] of ``fn`` over ``repeats`` calls, each synchronised with ``device``."""
    import warp as wp

    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        wp.synchronize_device(device)
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def time_parts(controller_part, solver_part, device, graph: bool, repeats: int = 10):
    """Seconds per control step of the controller alone (set_action + K substep calls) and of the K solver steps
    alone, each captured in a graph when ``graph`` (as the rollout runs) or eager. Run after the rollout: it
    advances the simulation."""
    import warp as wp

    out = []
    for part in (controller_part, solver_part):
        fn = part
        if graph:
            with wp.ScopedCapture(device=device) as cap:
                part()
            g = cap.graph

            def fn(g=g):
                wp.capture_launch(g)

        fn()
        wp.synchronize_device(device)
        out.append(_median_seconds(fn, device, repeats))
    return out[0], out[1]


def solo_vs_concurrent(ctx, graph, control_step, device, envs: int, repeats: int = 10) -> dict:
    """Weak scaling inside one run: seconds per control step of rank 0 running alone (the others wait at a
    barrier) and of every rank running at once. Every rank calls this (collectives)."""
    import warp as wp

    def step():
        if graph is not None:
            wp.capture_launch(graph)
        else:
            control_step()

    ctx.barrier()
    solo = _median_seconds(step, device, repeats) if ctx.is_main else 0.0
    ctx.barrier()
    concurrent = _median_seconds(step, device, repeats)
    ctx.barrier()
    both = ctx.all_gather([solo, concurrent])
    solo_s = float(both[0, 0])
    slowest = float(both[:, 1].max())
    return {
        "solo_rank0_s_per_step": solo_s,
        "concurrent_s_per_step": [float(x) for x in both[:, 1]],
        "solo_env_steps_per_s": envs / solo_s,
        # Synchronous training waits for the slowest rank: aggregate = all envs / the slowest rank's step time.
        "concurrent_env_steps_per_s": ctx.world_size * envs / slowest,
        "efficiency": solo_s / slowest,
    }
