"""The reach task's success, checked on cases whose answer is known: goals placed at chosen distances from the TCP
either side of the success radius, and the evaluation of scripted policies (one that reaches every goal, one that
reaches half of them)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("rsl_rl", reason="the train extra (rsl-rl-lib) is not installed")  # a dev dependency
torch = pytest.importorskip("torch", reason="torch is not installed")  # a dev dependency

from wpctrl.train.cli import evaluate  # noqa: E402
from wpctrl.train.reach import ReachEnv  # noqa: E402


def _tcp(env) -> np.ndarray:
    d = env.dofs
    return env.get_observations()["policy"].numpy()[:, 2 * d : 2 * d + 3].copy()


def _reward(d):
    return 1 - np.tanh(2 * d) + 0.5 * (1 - np.tanh(20 * d))


def test_success_is_the_final_distance_against_the_radius():
    """Goals 0, 3.5, 4.5 and 8 cm from the TCP (radius 4 cm), zero actions for a 3-step episode (the arm holds still:
    gravity is off the robot): the episodes at 0 and 3.5 cm succeed, the others fail; the episode return is the sum
    of the closed-form rewards of the distances."""
    env = ReachEnv(4, device="cpu", seed=1, episode_steps=3, success_radius=0.04, start_noise=0.0)
    env.reset()
    env.take_stats()
    tcp = _tcp(env)
    offsets = np.array([0.0, 0.035, 0.045, 0.08])
    direction = np.array([[0.6, 0.0, 0.8], [0.0, 1.0, 0.0], [-0.6, 0.0, -0.8], [0.0, -0.6, 0.8]])
    goal = (tcp + offsets[:, None] * direction).astype(np.float32)
    env.goal.assign(goal)
    zero = torch.zeros(env.num_envs, env.num_actions)
    returns = np.zeros(4)
    for k in range(3):
        _, reward, done, _ = env.step(zero)
        returns += reward.numpy()
        assert done.numpy().tolist() == [k == 2] * 4
    distance = env.distance.numpy()
    np.testing.assert_allclose(distance, offsets, atol=2e-3)  # the TCP barely moved
    np.testing.assert_allclose(returns[0], 3 * _reward(0.0), atol=5e-3)
    stats = env.take_stats()
    assert stats["episodes"] == 4
    assert stats["success_rate"] == pytest.approx(0.5)  # 0 and 3.5 cm inside, 4.5 and 8 cm outside
    assert stats["mean_episode_reward"] == pytest.approx(returns.mean(), rel=1e-5)
    assert stats["env_steps"] == 12


class _Scripted:
    """A stand-in for rsl-rl's runner: its inference policy steps the TCP toward the goal (the observation's
    ``goal - TCP``) in the envs of ``mask``, and stays still in the others."""

    def __init__(self, env, mask):
        self.env, self.mask = env, torch.as_tensor(mask)

    def get_inference_policy(self, device=None):
        d = self.env.dofs

        def policy(obs):
            err = obs["policy"][:, 2 * d + 3 : 2 * d + 6]
            act = torch.zeros(obs["policy"].shape[0], self.env.num_actions)
            act[:, :3] = torch.clamp(err / 0.1, -1.0, 1.0)  # pd_ee_delta_pos: 0.1 m per unit action
            return act * self.mask[:, None]

        return policy


@pytest.mark.parametrize("mask, rate", [([True] * 4, 1.0), ([True, False, True, False], 0.5)])
def test_evaluation_of_scripted_policies(mask, rate):
    """``evaluate`` on 4 envs, 2 episodes each: a policy that reaches every goal succeeds on all of them; one that
    moves only in half of the envs, on half (a goal drawn in the 30 x 50 x 40 cm box does not land within 2.5 cm of
    the resting TCP in these episodes: checked from the distances)."""
    env = ReachEnv(4, device="cpu", seed=2, episode_steps=25)
    out = evaluate(env, _Scripted(env, mask), episodes=8)
    assert out["episodes"] == 8
    assert out["success_rate"] == pytest.approx(rate)


def test_resets_draw_start_poses_and_goals_from_the_seed_over_their_whole_ranges():
    """Each reset draws the arm's start pose within ``start_noise`` of the rest pose (spread over that range, the
    fingers exact) and the goal uniformly in the goal box (spread over it); another seed draws other values, the same
    seed the same ones; ``start_noise=0`` starts exactly at the rest pose."""
    from wpctrl.train.reach import GOAL_HI, GOAL_LO

    def draws(seed, noise, resets=6):
        env = ReachEnv(16, device="cpu", seed=seed, start_noise=noise)
        q, g = [], []
        for _ in range(resets):
            env.reset()
            q.append(env.state.joint_q.numpy().reshape(16, -1)[:, : env.dofs].copy())
            g.append(env.goal.numpy().copy())
        return env, np.concatenate(q), np.concatenate(g)

    env, q, g = draws(4, 0.2)
    dev = q - env.start_q.numpy()
    assert np.abs(dev[:, :7]).max() <= 0.2 + 1e-6 and np.abs(dev[:, :7]).max() > 0.18
    assert dev[:, :7].min() < -0.18  # both signs: uniform in [-noise, noise]
    np.testing.assert_array_equal(dev[:, 7:], 0.0)
    lo, hi = np.array(GOAL_LO), np.array(GOAL_HI)
    assert ((g >= lo - 1e-6) & (g <= hi + 1e-6)).all()
    span = hi - lo
    assert (g.min(axis=0) < lo + 0.1 * span).all() and (g.max(axis=0) > hi - 0.1 * span).all()
    _, q_same, g_same = draws(4, 0.2)
    np.testing.assert_array_equal(g_same, g)
    np.testing.assert_array_equal(q_same, q)
    _, q_other, g_other = draws(5, 0.2)
    assert np.abs(g_other - g).max() > 0.05 and np.abs(q_other - q).max() > 0.05
    env0, q0, _ = draws(4, 0.0, resets=1)
    np.testing.assert_array_equal(q0, np.tile(env0.start_q.numpy(), (16, 1)))
