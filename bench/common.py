"""Shared pieces of the benchmarks: Panda models (real or a synthetic large-N layout), timing, and result files."""

from __future__ import annotations

import argparse
import copy
import datetime
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

# BENCH_WPCTRL_TREE: the source tree whose ``wpctrl`` the benchmark imports (the A/B stages of ``python -m bench``
# set it to the baseline tree). That tree goes first on the path; the ``bench`` package stays this one (it is
# already imported), so the same benchmark code times both trees.
WPCTRL_TREE = os.environ.get("BENCH_WPCTRL_TREE") or None
if WPCTRL_TREE:
    WPCTRL_TREE = str(Path(WPCTRL_TREE).resolve())
    if not (Path(WPCTRL_TREE) / "wpctrl" / "__init__.py").is_file():
        raise SystemExit(f"BENCH_WPCTRL_TREE={WPCTRL_TREE}: no wpctrl package there")
    if "wpctrl" in sys.modules:
        raise SystemExit("BENCH_WPCTRL_TREE is set but wpctrl was imported before bench.common")
    sys.path.insert(0, WPCTRL_TREE)

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

wp.config.log_level = wp.LOG_WARNING

DEFAULT_OUT = ROOT / "bench" / "results"


def parse_envs(text: str) -> list[int]:
    """``"1,64,1k,4k,1M"`` -> [1, 64, 1024, 4096, 1048576]."""
    out = []
    for tok in text.replace(" ", "").split(","):
        if not tok:
            continue
        mult = 1
        if tok[-1] in "kK":
            mult, tok = 1024, tok[:-1]
        elif tok[-1] in "mM":
            mult, tok = 1024 * 1024, tok[:-1]
        out.append(int(float(tok) * mult))
    return out


def fmt_envs(n: int) -> str:
    if n >= 1024 * 1024 and n % (1024 * 1024) == 0:
        return f"{n // (1024 * 1024)}M"
    if n >= 1024 and n % 1024 == 0:
        return f"{n // 1024}k"
    return str(n)


# ----------------------------------------------------------------------------------------------------------------------
# Models


def panda_mode(name: str = "pd_joint_target_delta_pos", interpolate: bool = False) -> dict:
    """A fresh copy of ManiSkill's Panda control mode ``name`` with ``interpolate`` set on every child."""
    from wpctrl.robots import panda_control_modes

    mode = panda_control_modes()[name]
    out = {}
    for uid, c in mode.items():
        c = copy.deepcopy(c)
        if hasattr(c, "interpolate"):
            c.interpolate = interpolate
        out[uid] = c
    return out


def build_panda_model(num_envs: int, device, *, gravity: bool = True, visual_shapes: bool = False):
    """``num_envs`` Pandas (wpctrl.robots.panda), one per world, through ``ModelBuilder.replicate``."""
    import newton

    from wpctrl.robots import panda

    builder = newton.ModelBuilder()
    builder.replicate(panda(visual_shapes=visual_shapes), num_envs)
    model = builder.finalize(device=device)
    if not gravity:  # ModelBuilder(gravity=...) does not reach replicated worlds: they keep panda()'s gravity
        model.set_gravity((0.0, 0.0, 0.0))
    return model


class _WideModel:
    """What wpctrl's engine and its State/Control checks read from a model, for a synthetic layout."""

    def __init__(self, device, coord_count: int, dof_count: int):
        self.device = device
        self.joint_coord_count = coord_count
        self.joint_dof_count = dof_count


@dataclass
class ControllerSetup:
    """A wpctrl controller over ``num_envs`` Pandas with its State and Control (the solver is not involved)."""

    num_envs: int
    layout_kind: str  # "real" (replicated model) or "synthetic" (a small model's layout tiled to num_envs)
    ctrl: object
    state: object
    control: object
    layout: object  # bench.step.reference_torch.JointLayout of the mode's joints
    build_s: float

    def new_control(self):
        """Another Control with the same initial contents (for the torch baseline, so the two never alias)."""
        c = self.control
        return _control(wp.clone(c.joint_target_q), wp.clone(c.joint_target_qd), wp.clone(c.joint_f))


def _control(joint_target_q, joint_target_qd, joint_f):
    import newton

    c = newton.Control()
    c.joint_target_q, c.joint_target_qd, c.joint_f = joint_target_q, joint_target_qd, joint_f
    return c


def real_setup(mode: dict, model, *, actuation: str, control_freq: int, sim_freq: int, **options) -> ControllerSetup:
    """``options``: further ``build_controller`` keywords (delay, track_effort, clip_targets, ...)."""
    import wpctrl
    from bench.step.reference_torch import layout_from_model

    t0 = time.perf_counter()
    ctrl = wpctrl.build_controller(
        mode, model, control_freq=control_freq, sim_freq=sim_freq, actuation=actuation, **options
    )
    state, control = model.state(), model.control()
    layout = layout_from_model(model, list(ctrl.joint_names))
    return ControllerSetup(int(model.world_count), "real", ctrl, state, control, layout, time.perf_counter() - t0)


def synthetic_setup(
    mode: dict, small_model, num_envs: int, *, actuation: str, control_freq: int, sim_freq: int, **options
) -> ControllerSetup:
    """A controller for ``num_envs`` Pandas without building ``num_envs`` of them.

    The controller is built through the public API on ``small_model`` (a few replicated worlds), then its engine is
    rebuilt over the same rows with the per-world index tables tiled to ``num_envs`` worlds at ``replicate``'s stride,
    over flat State/Control arrays tiled from the small model's first world. Kernels see exactly the layout that a
    replicated model of ``num_envs`` Pandas has (tests/test_bench_reference.py checks it against a real model).
    Uses wpctrl internals (``engine._Engine``, ``engine.make_plan``, ``binding.JointBinding``): bench-only.
    """
    import wpctrl
    from bench.step.reference_torch import layout_from_model, tile_layout
    from wpctrl.binding import JointBinding
    from wpctrl.engine import _Engine, make_plan

    t0 = time.perf_counter()
    small = wpctrl.build_controller(
        mode, small_model, control_freq=control_freq, sim_freq=sim_freq, actuation=actuation, **options
    )
    eng0 = small._engine
    b0 = eng0.binding
    w = b0.num_envs
    cs = small_model.joint_coord_count // w
    ds = small_model.joint_dof_count // w
    if small_model.joint_coord_count != w * cs or small_model.joint_dof_count != w * ds:
        raise ValueError("synthetic layout: the small model's worlds differ in size")
    if not (np.array_equal(b0.q_base - b0.q_base[0], np.arange(w) * cs)):
        raise ValueError("synthetic layout: the small model's worlds are not at a constant stride")
    e = np.arange(num_envs, dtype=np.int64)[:, None]
    binding = JointBinding(
        joint_names=list(b0.joint_names),
        num_envs=num_envs,
        joint_index=(b0.joint_index[:1] + e * (small_model.joint_count // w)).astype(np.int32),
        coord_index=(b0.coord_index[:1] + e * cs).astype(np.int32),
        dof_index=(b0.dof_index[:1] + e * ds).astype(np.int32),
        q_base=(b0.q_base[0] + e[:, 0] * cs).astype(np.int32),
        qd_base=(b0.qd_base[0] + e[:, 0] * ds).astype(np.int32),
        q_off=b0.q_off.copy(),
        qd_off=b0.qd_off.copy(),
        qlimits=b0.qlimits.copy(),
    )
    dev = small_model.device
    shim = _WideModel(dev, num_envs * cs, num_envs * ds)
    # Rebuild the small engine's plan over the wide binding; the shim model takes no model writes.
    if eng0.needs_response:
        raise NotImplementedError("synthetic layout: controllers that need the joint-space response need a real model")
    plan = make_plan(eng0.rows, binding, eng0.plan.options, eng0.plan.ee_specs)
    engine = _Engine(plan, shim, write_model=False)
    ctrl = copy.copy(small)
    ctrl._engine = engine
    ctrl.children = {}  # the small controller's child views point at the small engine

    def tile(arr, per_world):
        return wp.array(np.tile(arr.numpy()[:per_world], num_envs), dtype=wp.float32, device=dev)

    import newton

    state = newton.State()  # wpctrl accepts newton.State / newton.Control only: flat arrays in real ones
    state.joint_q = tile(small_model.joint_q, cs)
    state.joint_qd = tile(small_model.joint_qd, ds)
    control = _control(
        tile(small_model.joint_target_q, cs),
        tile(small_model.joint_target_qd, ds),
        wp.zeros(num_envs * ds, dtype=wp.float32, device=dev),
    )
    layout = tile_layout(layout_from_model(small_model, list(small.joint_names)), num_envs)
    return ControllerSetup(num_envs, "synthetic", ctrl, state, control, layout, time.perf_counter() - t0)


# ----------------------------------------------------------------------------------------------------------------------
# Timing


class Sync:
    """Waits for all queued device work (Warp's stream and, on CUDA, torch's current stream)."""

    def __init__(self, device):
        self.device = wp.get_device(device)
        self.cuda = self.device.is_cuda
        self._torch = None
        if self.cuda:
            try:
                import torch

                if torch.cuda.is_available():
                    self._torch = torch
            except ImportError:
                pass

    def __call__(self) -> None:
        if self.cuda:
            wp.synchronize_device(self.device)
            if self._torch is not None:
                self._torch.cuda.synchronize()


def measure(
    fn,
    sync,
    *,
    repeats: int = 5,
    min_time: float = 0.02,
    warmup: int = 3,
    max_iters: int = 1 << 16,
    clock: str = "wall",
    min_iters: int = 1,
) -> dict:
    """Median seconds per call of ``fn``.

    ``warmup`` calls, then a calibration that doubles the loop count until one loop takes ``min_time / 4``; each of
    ``repeats`` samples times ``iters`` back-to-back calls between two device syncs (host launch cost and device time
    overlap as they would in a training loop), divided by ``iters``. Every sample records wall time and the calling
    thread's CPU time (``time.thread_time``); ``clock`` picks the one reported as ``median_s``. Thread time is the
    robust choice on a shared CPU when all work runs on the calling thread (Warp's CPU backend, torch with 1 thread).
    """
    for _ in range(warmup):
        fn()
    sync()
    iters = max(1, min_iters)
    while True:
        t0 = time.perf_counter()
        for _ in range(iters):
            fn()
        sync()
        dt = time.perf_counter() - t0
        if dt >= min_time / 4 or iters >= max_iters:
            break
        iters *= 2
    iters = int(min(max_iters, max(min_iters, 1, round(iters * min_time / max(dt, 1e-9)))))
    wall, cpu = [], []
    for _ in range(repeats):
        sync()
        t0 = time.perf_counter()
        c0 = time.thread_time()
        for _ in range(iters):
            fn()
        sync()
        cpu.append((time.thread_time() - c0) / iters)
        wall.append((time.perf_counter() - t0) / iters)
    samples = cpu if clock == "thread" else wall
    if not samples:
        return {"median_s": float("nan"), "samples_s": [], "iters": iters}
    return {
        "median_s": statistics.median(samples),
        "samples_s": samples,
        "wall_median_s": statistics.median(wall),
        "thread_median_s": statistics.median(cpu),
        "clock": clock,
        "iters": iters,
    }


def measure_interleaved(
    fns: dict,
    sync,
    *,
    repeats: int = 5,
    min_time: float = 0.02,
    warmup: int = 3,
    max_iters: int = 1 << 16,
    clock: str = "wall",
) -> dict:
    """:func:`measure` for several functions, with the samples taken round-robin (one sample of each per round).

    On a shared or throttling machine, slow phases then hit every variant alike, so their ratios stay meaningful.
    """
    iters = {}
    for name, fn in fns.items():
        iters[name] = measure(fn, sync, repeats=0, min_time=min_time, warmup=warmup, max_iters=max_iters)["iters"]
    wall = {n: [] for n in fns}
    cpu = {n: [] for n in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            it = iters[name]
            sync()
            t0 = time.perf_counter()
            c0 = time.thread_time()
            for _ in range(it):
                fn()
            sync()
            cpu[name].append((time.thread_time() - c0) / it)
            wall[name].append((time.perf_counter() - t0) / it)
    out = {}
    for name in fns:
        samples = cpu[name] if clock == "thread" else wall[name]
        out[name] = {
            "median_s": statistics.median(samples),
            "samples_s": samples,
            "wall_median_s": statistics.median(wall[name]),
            "thread_median_s": statistics.median(cpu[name]),
            "clock": clock,
            "iters": iters[name],
        }
    return out


def capture_graph(fn, device):
    """``fn`` called once (kernels loaded, buffers allocated), then captured into a graph, which is returned."""
    fn()
    with wp.ScopedCapture(device=device) as cap:
        fn()
    return cap.graph


def solver_load(env) -> dict:
    """MuJoCo-Warp's contacts and constraint rows over all worlds of a task env after its last step: the physics'
    cost follows them, so two timings compare only under the same load."""
    d = env.solver.mjw_data
    return {"contacts": int(d.nacon.numpy().sum()), "constraint_rows": int(d.nefc.numpy().sum())}


def task_step_parts(env):
    """Two callables that split one control step of a :func:`wpctrl.tasks.make` env the way ``TaskEnv`` runs it:
    ``physics`` (the K x substeps MuJoCo-Warp steps, the contacts and the contact sensor of the last one, no
    controller) and ``controller`` (``set_action`` and the K ``before_simulation_step`` calls, no physics)."""
    ctrl, solver = env.ctrl, env.solver
    steps = ctrl.num_substeps * env.physics.substeps

    def physics():
        src, dst = env.state, env._other
        for i in range(steps):
            last = i == steps - 1
            solver.step(src, dst, env.control, env._contacts if last else None, env.dt,
                        observables=env._observables if last else None)  # fmt: skip
            src, dst = dst, src
        env._sensor.update(None, env._contacts, observables=env._observables)

    def controller():
        ctrl.set_action(env.action_buf, env.state)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(env.state, env.control)

    return physics, controller


def load_average() -> list[float]:
    try:
        return list(os.getloadavg())
    except OSError:
        return []


# ----------------------------------------------------------------------------------------------------------------------
# Command line and run bookkeeping of the step benchmarks (controller_step, ee_step, actuation_cost)


def add_run_args(p: argparse.ArgumentParser, *, envs_help: str, variants, torch_threads: bool = True) -> None:
    """The options every step benchmark takes (the script adds its own): device, sizes, timing, variants, output."""
    p.add_argument("--device", default="cuda:0" if wp.is_cuda_available() else "cpu")
    p.add_argument("--envs", default=None, help=envs_help)
    p.add_argument("--repeats", type=int, default=5, help="timed samples per row (median reported)")
    p.add_argument("--min-time", type=float, default=None, help="seconds per sample (default cpu 0.05, cuda 0.02)")
    p.add_argument("--warmup", type=int, default=3)
    p.add_argument("--variants", default=",".join(variants))
    p.add_argument(
        "--clock",
        default="wall",
        choices=["wall", "thread"],
        help="wall time (default) or the calling thread's CPU time (robust on a shared CPU)",
    )
    if torch_threads:
        p.add_argument(
            "--torch-threads",
            type=int,
            default=None,
            help="torch.set_num_threads (Warp's CPU backend is single-threaded; --clock thread forces 1)",
        )
    p.add_argument("--out", default=str(DEFAULT_OUT))
    p.add_argument("--tag", default=None, help="file-name suffix (default: the device kind)")


def parse_run_args(p: argparse.ArgumentParser, argv) -> argparse.Namespace:
    """Parse; ``--variants`` becomes a list."""
    args = p.parse_args(argv)
    args.variants = [v.strip() for v in args.variants.split(",") if v.strip()]
    return args


def start_run(p, args, *, cpu_envs: str, cuda_envs: str, thread_clock_cpu_only: bool = True):
    """Initialise Warp, apply the device-dependent defaults (``--min-time``, ``--envs``) and the clock / torch thread
    settings, print the machine metadata. Returns (device, sync, meta)."""
    wp.init()
    device = wp.get_device(args.device)
    sync = Sync(device)
    if args.clock == "thread":
        if thread_clock_cpu_only and device.is_cuda:
            p.error("--clock thread only makes sense on the CPU device (GPU work runs on no host thread)")
        if hasattr(args, "torch_threads"):
            args.torch_threads = 1
    if getattr(args, "torch_threads", None):
        import torch

        torch.set_num_threads(args.torch_threads)
    if args.min_time is None:
        args.min_time = 0.02 if device.is_cuda else 0.05
    if args.envs is None:
        args.envs = cuda_envs if device.is_cuda else cpu_envs
    meta = machine_info(device)
    meta.update({"args": vars(args), "loadavg_start": load_average()})
    print(meta_markdown(meta), flush=True)
    return device, sync, meta


def finish_run(args, device, meta: dict, rows: list[dict], t_start: float, stem: str, render) -> None:
    """Record the run's wall time and end load into ``meta``, then write ``<out>/<stem>_<tag>.{json,md}`` with the
    Markdown from ``render()`` (called after ``meta`` is complete)."""
    meta["wall_s"] = time.perf_counter() - t_start
    meta["loadavg_end"] = load_average()
    tag = args.tag or ("cuda" if device.is_cuda else "cpu")
    j, m = write_results(args.out, f"{stem}_{tag}", meta, rows, render())
    print(f"wrote {j} and {m}", flush=True)


# ----------------------------------------------------------------------------------------------------------------------
# Metadata and result files


def _sh(cmd: str) -> str:
    try:
        return subprocess.run(cmd, shell=True, capture_output=True, text=True, timeout=10).stdout.strip()
    except Exception:  # noqa: BLE001
        return ""


def machine_info(device) -> dict:
    import newton

    info = {
        "date_utc": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC"),
        "host": platform.node(),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "cpu": _sh("lscpu | grep 'Model name' | sed 's/Model name:\\s*//'") or platform.processor(),
        "cpu_count": os.cpu_count(),
        "warp": wp.__version__,
        "newton": newton.__version__,
        "numpy": np.__version__,
        "device": str(device),
        "wpctrl_commit": _sh(f"cd '{ROOT}' && git rev-parse --short HEAD 2>/dev/null") or "unknown",
        "wpctrl_dirty": bool(_sh(f"cd '{ROOT}' && git status --porcelain wpctrl 2>/dev/null")),
    }
    import wpctrl

    info["wpctrl_path"] = str(Path(wpctrl.__file__).resolve().parent)
    if WPCTRL_TREE:  # another tree's wpctrl: its recorded commit (a tree without git metadata has a COMMIT file)
        commit_file = Path(WPCTRL_TREE) / "COMMIT"
        info["wpctrl_commit"] = (
            commit_file.read_text().strip()
            if commit_file.is_file()
            else _sh(f"cd '{WPCTRL_TREE}' && git rev-parse --short HEAD 2>/dev/null") or "unknown"
        )
        info["wpctrl_dirty"] = None
    try:
        import torch

        info["torch"] = torch.__version__
        info["torch_threads"] = torch.get_num_threads()
        if torch.cuda.is_available():
            info["torch_cuda"] = torch.version.cuda
    except ImportError:
        pass
    try:
        import mujoco_warp

        info["mujoco_warp"] = getattr(mujoco_warp, "__version__", "?")
    except ImportError:
        pass
    d = wp.get_device(device)
    info["device_name"] = d.name
    if d.is_cuda:
        info["gpu"] = d.name
        info["gpu_arch"] = d.arch
        info["driver"] = _sh("nvidia-smi --query-gpu=driver_version --format=csv,noheader | head -1")
    return info


def write_results(out_dir, stem: str, meta: dict, rows: list[dict], markdown: str) -> tuple[Path, Path]:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    jpath = out / f"{stem}.json"
    mpath = out / f"{stem}.md"
    jpath.write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
    mpath.write_text(markdown)
    return jpath, mpath


def meta_markdown(meta: dict) -> str:
    keys = [
        "date_utc",
        "device",
        "device_name",
        "cpu",
        "cpu_count",
        "python",
        "warp",
        "newton",
        "torch",
        "torch_threads",
        "mujoco_warp",
        "driver",
        "wpctrl_commit",
    ]
    return "; ".join(f"{k}: {meta[k]}" for k in keys if k in meta)


def md_table(header: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    for r in rows:
        lines.append("| " + " | ".join(str(x) for x in r) + " |")
    return "\n".join(lines) + "\n"


def fmt_us(seconds: float) -> str:
    us = seconds * 1e6
    if us >= 100:
        return f"{us:,.0f}"
    if us >= 10:
        return f"{us:.1f}"
    return f"{us:.2f}"


def fmt_ratio(x: float | None) -> str:
    if x is None:
        return "–"
    return f"{x:.2f}×" if x < 10 else f"{x:.1f}×"
