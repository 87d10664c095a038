"""The workload that ``bench/profile_ncu.sh`` profiles: a few eager control steps of N Pandas.

Builds the controller (synthetic layout above ``--max-real-envs``, as ``controller_step.py``), warms up (compiles and
loads the kernels, writes the first Control), then runs ``--steps`` control steps (``set_action`` + K
``before_simulation_step``) between ``cudaProfilerStart`` / ``cudaProfilerStop`` so that ``ncu
--profile-from-start off`` sees only those launches. On the CPU it runs the same steps (a check of the script).

    python bench/profiling/ncu_target.py --device cuda:0 --envs 1M --actuation implicit --interpolate off
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import torch  # noqa: E402
import warp as wp  # noqa: E402

from bench.common import Sync, build_panda_model, panda_mode, parse_envs, real_setup, synthetic_setup  # noqa: E402


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--device", default="cuda:0" if wp.is_cuda_available() else "cpu")
    p.add_argument("--envs", default="1M")
    p.add_argument("--mode", default="pd_joint_target_delta_pos")
    p.add_argument("--actuation", default="implicit", choices=["implicit", "explicit"])
    p.add_argument("--interpolate", default="off", choices=["on", "off"])
    p.add_argument("--steps", type=int, default=1, help="profiled control steps")
    p.add_argument("--max-real-envs", type=int, default=4096)
    args = p.parse_args(argv)
    wp.init()
    device = wp.get_device(args.device)
    sync = Sync(device)
    n = parse_envs(args.envs)[0]
    mode = panda_mode(args.mode, args.interpolate == "on")
    kw = {"actuation": args.actuation, "control_freq": 20, "sim_freq": 100}
    if n <= args.max_real_envs:
        setup = real_setup(mode, build_panda_model(n, device), **kw)
    else:
        setup = synthetic_setup(mode, build_panda_model(2, device), n, **kw)
    ctrl, state, control = setup.ctrl, setup.state, setup.control
    tdev = torch.device("cuda", device.ordinal) if device.is_cuda else torch.device("cpu")
    action = torch.rand((n, ctrl.action_dim), generator=torch.Generator(tdev).manual_seed(0), device=tdev) * 2 - 1
    ctrl.reset(state)

    def step():
        ctrl.set_action(action, state)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(state, control)

    for _ in range(2):
        step()
    sync()
    per_substep = ctrl.substep_launch
    print(
        f"envs {n} ({setup.layout_kind}), {args.mode}, {args.actuation}, interpolate {args.interpolate}: "
        f"{1 + (ctrl.num_substeps if per_substep else 0)} launches per control step",
        flush=True,
    )
    if device.is_cuda:
        torch.cuda.profiler.start()
    for _ in range(args.steps):
        step()
    sync()
    if device.is_cuda:
        torch.cuda.profiler.stop()
    print("done", flush=True)


if __name__ == "__main__":
    main()
