"""A Newton-trained PickCube policy in the real ManiSkill, with ManiSkill's observation as it is and with the finger
joints' reported velocities replaced by the fingers' motion over the control step (finite differences of their
positions): what PhysX's velocity readings in a still grip cost the policy.

    python tools/finger_velocity_transfer.py POLICY.ts [--episodes 60] [--seed 5000]
"""

from __future__ import annotations

import argparse
import warnings


def main() -> None:
    import torch

    from wpctrl.tasks.maniskill_side import make_maniskill
    from wpctrl.train.evaluate import load_policy

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("policy")
    ap.add_argument("--episodes", type=int, default=60)
    ap.add_argument("--seed", type=int, default=5000)
    args = ap.parse_args()
    warnings.filterwarnings("ignore")
    policy, meta = load_policy(args.policy)
    env = make_maniskill(meta.get("task", "PickCube-v1"), meta.get("control_mode", "pd_joint_delta_pos"))
    qpos, qvel = slice(7, 9), slice(16, 18)  # the fingers' joints in ManiSkill's flattened state observation
    dt = 1.0 / 20.0  # the control step
    for variant in ("as reported", "finite differences"):
        succeeded = 0
        for i in range(args.episodes):
            obs, _ = env.reset(seed=args.seed + i)
            previous, success = obs[:, qpos].clone(), False
            for _ in range(50):
                seen = obs.clone()
                if variant == "finite differences":
                    seen[:, qvel] = (obs[:, qpos] - previous) / dt
                previous = obs[:, qpos].clone()
                with torch.no_grad():
                    action = policy(seen)
                obs, _, _, _, info = env.step(action)
                success |= bool(info["success"][0])
            succeeded += success
        print(f"finger velocities {variant}: success once {succeeded} / {args.episodes}", flush=True)


if __name__ == "__main__":
    main()
