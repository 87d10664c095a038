"""wpctrl.tasks on CUDA: the same env as on the CPU (a state, a step), graph replay against eager launches, and the
scripted solve on many envs. Skipped without a CUDA device."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

torch = pytest.importorskip("torch")

pytestmark = pytest.mark.skipif(
    not wp.get_cuda_device_count() or not torch.cuda.is_available(),
    reason="needs a CUDA device (Warp and torch): the tasks' CUDA path",
)

import wpctrl.tasks as T  # noqa: E402
from wpctrl.tasks.scripted import policy_for  # noqa: E402


@pytest.mark.parametrize("task", ["PushCube-v1", "PickCube-v1"])
def test_cuda_matches_cpu_for_the_same_state_and_step(task):
    envs = {d: T.make(task, num_envs=8, device=d, control_mode="pd_ee_delta_pos") for d in ("cpu", "cuda:0")}
    envs["cpu"].reset(seed=3)
    state = envs["cpu"].get_state_dict()
    obs, loaded = {}, {}
    for d, env in envs.items():
        env.set_state_dict({g: {k: v.to(env.device) for k, v in e.items()} for g, e in state.items()})
        loaded[d] = env.get_obs().cpu().numpy()
        np.testing.assert_allclose(loaded[d], loaded["cpu"], atol=1e-5)  # the CPU env's, before it steps
        action = torch.tensor([[0.3, -0.2, -0.5, 1.0]], device=env.device).expand(8, 4)
        o, r, *_ = env.step(action)
        obs[d] = (o.cpu().numpy(), r.cpu().numpy())
    np.testing.assert_allclose(obs["cuda:0"][0], obs["cpu"][0], atol=2e-3)
    np.testing.assert_allclose(obs["cuda:0"][1], obs["cpu"][1], atol=2e-3)


def test_graph_replay_equals_eager_on_cuda():
    out = {}
    for graph in (True, False):
        env = T.make("PickCube-v1", num_envs=16, device="cuda:0", control_mode="pd_ee_delta_pos", graph=graph)
        obs, _ = env.reset(seed=1)
        for _ in range(3):
            obs, *_ = env.step(policy_for("PickCube-v1")(obs))
        out[graph] = obs.cpu().numpy()
    np.testing.assert_allclose(out[True], out[False], atol=1e-4)


@pytest.mark.parametrize("task", ["PushCube-v1", "PickCube-v1"])
def test_scripted_policy_solves_the_task_on_cuda(task):
    env = T.make(task, num_envs=256, device="cuda:0", control_mode="pd_ee_delta_pos", auto_reset=False,
                 ignore_terminations=True)  # fmt: skip
    obs, _ = env.reset(seed=0)
    policy = policy_for(task)
    for _ in range(env.max_episode_steps):
        obs, _, _, _, info = env.step(policy(obs))
    assert info["success"].float().mean().item() >= 0.9


def test_an_external_wrench_moves_the_cube_on_cuda_as_on_the_cpu():
    """The same lift (an upward force m (g + 2 m/s^2)) and, in env 1, a torque about z, given as a torch tensor on
    the env's device: the cube's pose after two steps is the CPU env's (measured agreement on the CPU against the
    closed form: tests/test_task_external_wrench.py)."""
    poses = {}
    for d in ("cpu", "cuda:0"):
        env = T.make("PickCube-v1", num_envs=2, device=d, control_mode="pd_joint_delta_pos")
        env.reset(seed=0)
        s = env.get_state_dict()
        s["actors"]["cube"][:] = torch.tensor([[0.1, 0.1, 0.02, 1.0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
                                               [0.1, -0.1, 0.02, 1.0, 0, 0, 0, 0, 0, 0, 0, 0, 0]])  # fmt: skip
        env.set_state_dict({g: dict(v) for g, v in s.items() if g in ("actors", "articulations")})
        for _ in range(4):
            env.step(torch.zeros(2, 8, device=env.device))
        m = float(env.model.body_mass.numpy()[env.scene.actor_body0["cube"]])
        force = torch.tensor([0.0, 0.0, m * 11.81], device=env.device)
        env.set_external_wrench("cube", force=force.expand(2, 3))
        env.set_external_wrench("cube", force=force, torque=torch.tensor([0.0, 0.0, 1e-3], device=env.device),
                                env_idx=[1])  # fmt: skip
        for _ in range(2):
            env.step(torch.zeros(2, 8, device=env.device))
        poses[d] = env.get_state_dict()["actors"]["cube"][:, :7].cpu().numpy()
    assert poses["cpu"][:, 2].min() > 0.028  # lifted about 1 cm
    np.testing.assert_allclose(poses["cuda:0"], poses["cpu"], atol=1e-4)
