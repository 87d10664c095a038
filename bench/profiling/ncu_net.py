"""The workload that Nsight Compute profiles for the actuator networks: one substep of each network kernel.

Builds ``bench/actuators/actuator_cost.py``'s MLP and LSTM controllers (``--variants``; synthetic layout above 4,096
envs), runs two control steps (compiles and loads every kernel), then one ``set_action`` and one
``before_simulation_step`` of each controller between ``cudaProfilerStart`` / ``cudaProfilerStop``, so that

    ncu --profile-from-start off --kernel-name regex:wpctrl_actuator_net python bench/profiling/ncu_net.py --envs 1M

sees one launch of each network kernel. On the CPU it runs the same steps (a check of the script).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

from bench.actuators.actuator_cost import _mode  # noqa: E402
from bench.common import Sync, build_panda_model, parse_envs, real_setup, synthetic_setup  # noqa: E402


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--device", default="cuda:0" if wp.is_cuda_available() else "cpu")
    p.add_argument("--envs", default="1M")
    p.add_argument("--variants", default="mlp,lstm,mlp_tiled,lstm_tiled")
    p.add_argument("--max-real-envs", type=int, default=4096)
    args = p.parse_args(argv)
    wp.init()
    device = wp.get_device(args.device)
    sync = Sync(device)
    n = parse_envs(args.envs)[0]
    kw = {"actuation": "explicit", "control_freq": 20, "sim_freq": 100}
    model = build_panda_model(n, device) if n <= args.max_real_envs else None
    small = build_panda_model(2, device) if model is None else None
    runs = []
    for name in args.variants.split(","):
        mode = _mode(name, "pd_joint_target_delta_pos")
        su = real_setup(mode, model, **kw) if model is not None else synthetic_setup(mode, small, n, **kw)
        action = wp.array(np.random.default_rng(1).uniform(-1, 1, (n, su.ctrl.action_dim)).astype(np.float32),
                          device=device)  # fmt: skip
        su.ctrl.reset(su.state)
        for _ in range(2):
            su.ctrl.set_action(action, su.state)
            for _ in range(su.ctrl.num_substeps):
                su.ctrl.before_simulation_step(su.state, su.control)
        group = su.ctrl._engine.part("actuator_models").nets[0]
        print(f"{name}: {n} envs ({su.layout_kind}), kernel {group.kernel_kind}, {n * group.n} rows", flush=True)
        runs.append((su, action))
    sync()
    if device.is_cuda:
        import torch

        torch.cuda.profiler.start()
    for su, action in runs:
        su.ctrl.set_action(action, su.state)
        su.ctrl.before_simulation_step(su.state, su.control)
    sync()
    if device.is_cuda:
        import torch

        torch.cuda.profiler.stop()
    print("profiled one substep of each", flush=True)


if __name__ == "__main__":
    main()
