"""Shared test fixtures: Warp on the CPU device, quiet logs, the test data shipped in tests/data."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import warp as wp

wp.config.log_level = wp.LOG_WARNING
wp.init()

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
CONFORMANCE = DATA / "conformance"
"""Traces of the real ManiSkill 3.0.1 controllers (Panda joint modes, ``ee/``, ``zoo/``), with their READMEs."""
PANDA_URDF = DATA / "panda_v2_dynamics.urdf"
"""ManiSkill's Panda URDF (panda_v2) with its dynamics, for add_urdf-built Pandas."""

HAS_CUDA = wp.is_cuda_available()

try:  # WPCTRL_HYPOTHESIS_PROFILE=no-shrink: report a property test's first failure as found (shrinking a stream of
    # operations over a freshly compiled control mode can take minutes)
    from hypothesis import Phase, settings

    settings.register_profile("no-shrink", phases=[Phase.explicit, Phase.reuse, Phase.generate])
    if os.environ.get("WPCTRL_HYPOTHESIS_PROFILE"):
        settings.load_profile(os.environ["WPCTRL_HYPOTHESIS_PROFILE"])
except ImportError:  # hypothesis is a dev dependency
    pass


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
