"""Multi-process rollouts: wpctrl.distributed on its own, and the demo under torchrun with 2 CPU processes (gloo)."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import pytest
from conftest import ROOT

from wpctrl import distributed

TORCHRUN_ENV = ("RANK", "LOCAL_RANK", "WORLD_SIZE", "LOCAL_WORLD_SIZE", "MASTER_ADDR", "MASTER_PORT")


@pytest.fixture
def no_torchrun(monkeypatch):
    for k in TORCHRUN_ENV:
        monkeypatch.delenv(k, raising=False)


def test_single_process_context_without_torchrun(no_torchrun):
    ctx = distributed.init(device="cpu", seed=7)
    assert not distributed.launched() and not ctx.distributed and ctx.is_main
    assert (ctx.rank, ctx.world_size, ctx.device, ctx.seed, ctx.backend) == (0, 1, "cpu", 7, None)
    # The reductions are the identity on one process.
    assert ctx.all_reduce_sum([1.0, 2.0]).tolist() == [1.0, 2.0]
    assert ctx.all_gather([3.0, 4.0]).tolist() == [[3.0, 4.0]]
    ctx.barrier()
    ctx.shutdown()


def test_rank_seeds_differ_and_are_reproducible():
    seeds = [distributed.rank_seed(0, r) for r in range(8)]
    assert len(set(seeds)) == 8 and seeds == [distributed.rank_seed(0, r) for r in range(8)]
    assert distributed.rank_seed(1, 0) != distributed.rank_seed(0, 1)  # not seed + rank


def test_device_choice_under_torchrun(monkeypatch):
    resolve = distributed._resolve_device
    assert resolve("cpu", 3, 4) == "cpu"
    with pytest.raises(ValueError, match="would share one GPU"):
        resolve("cuda:0", 1, 2)
    with pytest.raises(ValueError, match="expected 'cpu', 'cuda' or 'cuda:N'"):
        resolve("gpu", 0, 1)
    monkeypatch.setenv("RANK", "x")
    monkeypatch.setenv("WORLD_SIZE", "2")
    with pytest.raises(ValueError, match="RANK: expected an integer"):
        distributed.init(device="cpu")


def _no_constant(name):
    raise ValueError(f"bare {name} in summary.json")


@pytest.mark.slow  # two processes under torchrun (CI runs it)
def test_demo_under_torchrun_two_cpu_processes(tmp_path):
    """torchrun --nproc-per-node=2 -m wpctrl demo --device cpu: 2 gloo ranks, 2 envs each; rank 0 reduces and
    writes. (Each process loads the compiled kernels from Warp's cache, warm from the other demo tests.)"""
    pytest.importorskip("torch")
    out = tmp_path / "demo"
    env = {k: v for k, v in os.environ.items() if k not in TORCHRUN_ENV}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env["OMP_NUM_THREADS"] = "1"
    cmd = [
        sys.executable,
        "-m",
        "torch.distributed.run",
        "--standalone",
        "--nproc-per-node=2",
        "-m",
        "wpctrl",
        "demo",
        "--device",
        "cpu",
        "--envs",
        "2",
        "--seconds",
        "1",
        "--seed",
        "3",
        "--no-progress",
        "--out",
        str(out),
    ]
    p = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    s = json.loads((out / "summary.json").read_text(), parse_constant=_no_constant)
    assert s["world_size"] == 2 and s["backend"] == "gloo"
    assert s["envs_per_rank"] == 2 and s["envs"] == 4 and s["all_finite"]
    ranks = s["per_rank"]
    assert [r["rank"] for r in ranks] == [0, 1] and all(r["envs"] == 2 for r in ranks)
    assert len(set(s["seeds"])) == 2 and s["seeds"] == [distributed.rank_seed(3, r) for r in (0, 1)]
    for r in ranks:
        for key in ("env_steps_per_s", "controller_ms_per_step", "solver_ms_per_step"):
            assert math.isfinite(r[key]) and r[key] > 0, (r["rank"], key)
        assert r["nonfinite_envs"] == 0 and r["control_steps"] == 20
        assert 0 < r["tracking_rms"]["arm"] < 0.06
    # The aggregate is the reduction of the ranks' figures.
    assert s["env_steps_per_s"] == pytest.approx(sum(r["env_steps_per_s"] for r in ranks))
    assert s["tracking_max"]["arm"] == max(r["tracking_max"]["arm"] for r in ranks)
    assert min(r["tracking_rms"]["arm"] for r in ranks) <= s["tracking_rms"]["arm"]
    assert s["tracking_rms"]["arm"] <= max(r["tracking_rms"]["arm"] for r in ranks)
    sc = s["scaling"]
    assert sc["efficiency"] > 0 and len(sc["concurrent_s_per_step"]) == 2
    # Rank 0 alone prints the table and writes the files.
    assert (
        p.stdout.count("env-steps/s per rank") == 1
        and p.stdout.count("wpctrl demo: 2 Pandas") == 1
        and p.stdout.count("compiling Warp kernels") <= 1
    )
    assert (out / "tracking.png").stat().st_size > 10_000
