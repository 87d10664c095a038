"""Shared test fixtures: Warp on the CPU device, quiet logs, paths to ../shared when present."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import warp as wp

wp.config.log_level = wp.LOG_WARNING
wp.init()

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("WPCTRL_SHARED", ROOT.parent / "shared"))
CONFORMANCE = SHARED / "conformance"
PANDA_URDF = SHARED / "reference" / "panda_v2_dynamics.urdf"

HAS_CUDA = wp.is_cuda_available()


def need_shared(path: Path) -> None:
    if not path.exists():
        pytest.skip(f"{path} is absent (../shared is not checked out beside the project)")


@pytest.fixture(autouse=True)
def _cpu_device():
    with wp.ScopedDevice("cpu"):
        yield


def build_panda(num_envs: int = 1, device: str = "cpu", **kwargs):
    """A finalized Newton model of ``num_envs`` Pandas (wpctrl's built-in robot), one per world."""
    import newton

    from wpctrl.robots import panda

    builder = newton.ModelBuilder()
    builder.replicate(panda(**kwargs), num_envs)
    return builder.finalize(device=device)


@pytest.fixture
def panda_model():
    """Factory ``panda_model(num_envs)`` of fresh Panda models."""
    return build_panda
