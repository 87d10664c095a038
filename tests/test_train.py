"""Training through wpctrl (``python -m wpctrl train``): the reach env's pieces against numpy re-derivations, and a
short PPO run on the CPU that learns."""

from __future__ import annotations

import json
import math

import newton
import numpy as np
import pytest
import warp as wp

pytest.importorskip("rsl_rl", reason="the train extra (rsl-rl-lib) is not installed")  # a dev dependency
torch = pytest.importorskip("torch", reason="torch is not installed")  # a dev dependency

from wpctrl.train.reach import GOAL_HI, GOAL_LO, ReachEnv  # noqa: E402

E = 8


@pytest.fixture(scope="module")
def env():
    return ReachEnv(E, device="cpu", seed=3)


def _tcp_numpy(env) -> np.ndarray:
    """The TCP in each env's base frame from Newton's FK of the current joint state and the site's transform."""
    s = env.model.state()
    newton.eval_fk(env.model, env.state.joint_q, env.state.joint_qd, s)
    body_q = s.body_q.numpy().reshape(E, env.bodies, 7)[:, env.tcp_body]
    off = env.tcp_offset
    out = []
    for e in range(E):
        x = wp.transform(wp.vec3(*body_q[e, :3]), wp.quat(*body_q[e, 3:])) * off
        out.append(np.array(x.p))
    return np.array(out) - env.env_origin.numpy()


def test_observation_and_reward_against_numpy(env):
    rng = np.random.default_rng(0)
    actions = torch.as_tensor(rng.uniform(-1, 1, (E, env.num_actions)).astype(np.float32))
    obs, reward, done, extras = env.step(actions)
    o = obs["policy"].numpy()
    q = env.state.joint_q.numpy().reshape(E, -1)[:, : env.dofs]
    qd = env.state.joint_qd.numpy().reshape(E, -1)[:, : env.dofs]
    tcp = _tcp_numpy(env)
    goal = env.goal.numpy()
    np.testing.assert_allclose(o[:, : env.dofs], q, atol=1e-6)
    np.testing.assert_allclose(o[:, env.dofs : 2 * env.dofs], qd, atol=1e-6)
    np.testing.assert_allclose(o[:, 2 * env.dofs : 2 * env.dofs + 3], tcp, atol=2e-6)
    np.testing.assert_allclose(o[:, 2 * env.dofs + 3 :], goal - tcp, atol=2e-6)
    d = np.linalg.norm(goal - tcp, axis=1)
    np.testing.assert_allclose(reward.numpy(), 1 - np.tanh(2 * d) + 0.5 * (1 - np.tanh(20 * d)), atol=1e-5)
    assert not done.numpy().any() and (extras["time_outs"].numpy() == 0).all()
    assert ((goal >= np.array(GOAL_LO) - 1e-6) & (goal <= np.array(GOAL_HI) + 1e-6)).all()


def test_done_envs_alone_are_reset_with_a_new_goal(env):
    env.reset()
    env.take_stats()
    steps = env.episode_step.numpy()
    steps[[2, 5]] = env.max_episode_length - 1  # these two end their episode at the next step
    env.episode_step.assign(steps)
    q_before = env.state.joint_q.numpy().reshape(E, -1).copy()
    goal_before = env.goal.numpy().copy()
    obs, _, done, extras = env.step(torch.zeros(E, env.num_actions))
    d = done.numpy()
    assert d.tolist() == [e in (2, 5) for e in range(E)]
    np.testing.assert_array_equal(extras["time_outs"].numpy(), d.astype(np.float32))
    q = env.state.joint_q.numpy().reshape(E, -1)
    start = env.start_q.numpy()
    for e in (2, 5):  # back at the start pose (within the start noise), at rest, with another goal
        assert np.abs(q[e, : env.dofs] - start).max() <= env.start_noise + 1e-6
        assert np.abs(env.state.joint_qd.numpy().reshape(E, -1)[e]).max() == 0.0
        assert not np.allclose(env.goal.numpy()[e], goal_before[e])
        assert env.episode_step.numpy()[e] == 0
    others = [e for e in range(E) if e not in (2, 5)]
    np.testing.assert_array_equal(env.goal.numpy()[others], goal_before[others])
    assert np.abs(q[others] - q_before[others]).max() < 0.05  # they only moved by one control step
    # the controller restarted the reset envs from their new pose: target = start = measured q
    arm = env.ctrl["arm"]
    np.testing.assert_allclose(arm.start_qpos.numpy()[[2, 5]], q[[2, 5], :7], atol=1e-6)
    stats = env.take_stats()
    assert stats["episodes"] == 2 and stats["env_steps"] == E


def test_ppo_learns_on_the_cpu(tmp_path):
    """A short run: the run finishes, train.json is strict JSON, and the mean step reward of the last 3 iterations
    exceeds that of the first 3 by a clear margin (measured: see docs/training.md)."""
    from wpctrl.train.cli import main

    out = tmp_path / "run"
    assert main(["--envs", "64", "--iterations", "20", "--seed", "0", "--out", str(out), "--eval-episodes", "64"]) == 0

    def strict(text):
        return json.loads(text, parse_constant=lambda c: (_ for _ in ()).throw(ValueError(f"non-strict JSON: {c}")))

    summary = strict((out / "train.json").read_text())
    h = summary["history"]
    assert len(h) == 20 and summary["envs"] == 64
    first = np.mean([r["mean_step_reward"] for r in h[:3]])
    last = np.mean([r["mean_step_reward"] for r in h[-3:]])
    assert last > first + MARGIN, (first, last)
    assert all(r["collection_env_steps_per_s"] > 0 and math.isfinite(r["wall_s"]) for r in h)
    assert 0.0 <= summary["evaluation"]["success_rate"] <= 1.0
    assert (out / "learning_curve.png").stat().st_size > 1000 and (out / "policy.pt").exists()


MARGIN = 0.1  # measured (seed 0, 64 envs, 20 iterations): first 3 iterations 0.44, last 3 0.62-0.65
