"""A controller on a non-default GPU leaves the other GPUs alone (skipped without 2 CUDA devices).

One process per GPU (torchrun) only scales if nothing lands on cuda:0 by default. A fresh Python process builds the
Pandas, the controller and its State/Control on cuda:1 only, runs eager steps, numpy and wp.array actions, a
partial reset and a captured graph, then asks the CUDA driver whether a primary context exists on each device
(``cuDevicePrimaryCtxGetState``: no context means no allocation and no launch could have happened there) and asks
Warp the same. The check must see the context on cuda:1, so it cannot pass vacuously.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import warp as wp
from conftest import ROOT

pytestmark = pytest.mark.skipif(wp.get_cuda_device_count() < 2, reason="needs 2 CUDA devices")

CHILD = textwrap.dedent(
    """
    import ctypes, json, sys
    import numpy as np
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING
    wp.init()
    import newton
    import wpctrl
    from wpctrl.robots import panda, panda_control_modes

    dev = "cuda:1"
    actuation = sys.argv[1]
    b = newton.ModelBuilder()
    b.replicate(panda(), 8)
    model = b.finalize(device=dev)
    extra = {"explicit_pd": "stable"} if actuation == "explicit" else {}
    ctrl = wpctrl.build_controller(panda_control_modes()["pd_joint_target_delta_pos"], model, 20, 100,
                                   actuation=actuation, **extra)
    s, c = model.state(), model.control()
    ctrl.reset(s, control=c)
    rng = np.random.default_rng(0)
    act = wp.array(rng.uniform(-1, 1, (8, ctrl.action_dim)).astype(np.float32), device=dev)
    for k in range(3):
        ctrl.set_action(act if k else act.numpy(), s)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(s, c)
    ctrl.reset(s, env_ids=[1, 3], control=c)
    mask = wp.array(np.arange(8) % 2 == 0, dtype=wp.bool, device=dev)
    with wp.ScopedCapture(device=dev) as cap:
        ctrl.set_action(act, s)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(s, c)
        ctrl.reset(s, env_ids=mask, control=c)
    for _ in range(3):
        wp.capture_launch(cap.graph)
    wp.synchronize_device(dev)
    cuda = ctypes.CDLL("libcuda.so.1")

    def primary_context_active(i):
        d = ctypes.c_int()
        assert cuda.cuDeviceGet(ctypes.byref(d), i) == 0
        flags, active = ctypes.c_uint(), ctypes.c_int()
        assert cuda.cuDevicePrimaryCtxGetState(d, ctypes.byref(flags), ctypes.byref(active)) == 0
        return bool(active.value)

    n = wp.get_cuda_device_count()
    print(json.dumps({
        "driver_primary_context": [primary_context_active(i) for i in range(n)],
        "warp_has_context": [wp.get_device(f"cuda:{i}").has_context for i in range(n)],
        "target_qpos": ctrl.target_qpos.numpy().tolist(),
        "device": str(ctrl.target_qpos.device),
    }))
    """
)


@pytest.mark.parametrize("actuation", ["implicit", "explicit"])
def test_controller_on_cuda1_never_touches_cuda0(actuation, tmp_path):
    script = tmp_path / "child.py"
    script.write_text(CHILD)
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env.pop("CUDA_VISIBLE_DEVICES", None)  # both devices visible: nothing hides cuda:0 from the child
    p = subprocess.run([sys.executable, str(script), actuation], env=env, capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    r = json.loads(p.stdout.strip().splitlines()[-1])
    assert r["device"] == "cuda:1"
    assert r["driver_primary_context"][1] and r["warp_has_context"][1]  # the check does see a used device
    assert not r["driver_primary_context"][0], "a CUDA context was created on cuda:0"
    assert not r["warp_has_context"][0]
    others = r["driver_primary_context"][2:]
    assert not any(others), f"contexts on other devices: {others}"
    assert np.isfinite(np.asarray(r["target_qpos"])).all()
