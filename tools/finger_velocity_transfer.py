"""A Newton-trained PickCube policy in the real ManiSkill, with ManiSkill's observation as it is and with the finger
joints' reported velocities replaced by the fingers' motion over the control step (finite differences of their
positions): what PhysX's velocity readings in a still grip cost the policy. Both runs go through
:func:`wpctrl.train.evaluate.evaluate_maniskill`, the loop of ``wpctrl evaluate --sim maniskill``.

    python tools/finger_velocity_transfer.py POLICY.ts [--episodes 60] [--seed 5000]
"""

from __future__ import annotations

import argparse
import warnings

FINGER_QPOS, FINGER_QVEL = slice(7, 9), slice(16, 18)
"""The fingers' joints in ManiSkill's flattened state observation (the Panda's qpos 0:9, qvel 9:18)."""
CONTROL_DT = 1.0 / 20.0
"""ManiSkill's control step [s]."""


class FiniteDifferenceFingers:
    """``policy`` seeing the fingers' velocities as their motion since the previous control step. Every
    ``episode_steps`` calls an episode starts (``evaluate_maniskill`` runs every episode to its end), and its first
    observation has no motion yet."""

    def __init__(self, policy, episode_steps: int):
        self.policy, self.episode_steps, self.calls, self.previous = policy, episode_steps, 0, None

    def __call__(self, obs):
        if self.calls % self.episode_steps == 0:
            self.previous = obs[:, FINGER_QPOS].clone()
        self.calls += 1
        seen = obs.clone()
        seen[:, FINGER_QVEL] = (obs[:, FINGER_QPOS] - self.previous) / CONTROL_DT
        self.previous = obs[:, FINGER_QPOS].clone()
        return self.policy(seen)


def main() -> None:
    from wpctrl.tasks import TASKS
    from wpctrl.train.evaluate import evaluate_maniskill, load_policy

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("policy")
    ap.add_argument("--episodes", type=int, default=60)
    ap.add_argument("--seed", type=int, default=5000)
    args = ap.parse_args()
    warnings.filterwarnings("ignore")
    policy, meta = load_policy(args.policy)
    task, mode = meta["task"], meta["control_mode"]
    variants = {"as reported": policy,
                "finite differences": FiniteDifferenceFingers(policy, TASKS[task].max_episode_steps)}  # fmt: skip
    for name, seen_by in variants.items():
        result = evaluate_maniskill(seen_by, task, mode, args.episodes, seed=args.seed)
        print(f"finger velocities {name}: success once {result['success_rate']:.1%}, "
              f"at the end {result['success_at_end_rate']:.1%} ({args.episodes} episodes)", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
