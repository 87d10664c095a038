"""The tasks' MuJoCo-Warp steps as device loops (``wpctrl.tasks.stepping``) against the same steps written out: the
same observations, rewards, contact-sensor flags and controller state, bitwise on the CPU (captured and eager) and
within float noise on CUDA; which loop ``"auto"`` picks and what ``"device"`` refuses."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

torch = pytest.importorskip("torch", reason="torch is not installed")  # a dev dependency

import wpctrl.tasks as T  # noqa: E402
from wpctrl.config import ConfigError  # noqa: E402
from wpctrl.tasks.scripted import policy_for  # noqa: E402
from wpctrl.tasks.stepping import resolve_substep_loop  # noqa: E402


def _trajectory(device: str, loop: str, graph: bool, substeps: int, steps: int = 12) -> dict:
    """A PickCube episode's first ``steps`` steps under the scripted grasp (contacts, a grasp flag that needs the
    contact sensor) from a fixed reset: everything the step returns, stacked."""
    env = T.make("PickCube-v1", num_envs=3, device=device, control_mode="pd_ee_delta_pos", seed=7, graph=graph,
                 physics=T.TaskPhysics(substeps=substeps), substep_loop=loop)  # fmt: skip
    assert env.substep_loop == loop
    obs, _ = env.reset(seed=7)
    policy = policy_for("PickCube-v1")
    out = {"obs": [], "reward": [], "is_grasped": [], "q": []}
    for _ in range(steps):
        obs, reward, _, _, info = env.step(policy(obs))
        out["obs"].append(obs.cpu().numpy())
        out["reward"].append(reward.cpu().numpy())
        out["is_grasped"].append(info["is_grasped"].cpu().numpy())
        out["q"].append(env.state.joint_q.numpy().copy())
    return {k: np.stack(v) for k, v in out.items()}


@pytest.mark.parametrize("graph", [True, False])
def test_device_loop_is_the_written_out_step_on_the_cpu(graph):
    ref = _trajectory("cpu", "unrolled", graph, substeps=4)
    ours = _trajectory("cpu", "device", graph, substeps=4)
    assert np.abs(np.diff(ref["q"], axis=0)).max() > 1e-3  # the arm moved
    assert ref["is_grasped"].any()  # and grasped: the contact sensor read the loop's last step
    for k in ref:
        np.testing.assert_array_equal(ours[k], ref[k], err_msg=k)


def test_auto_picks_the_device_loop_only_where_it_shortens_a_captured_cuda_graph():
    cpu = wp.get_device("cpu")
    assert resolve_substep_loop("auto", cpu, True, 8) == "unrolled"
    assert resolve_substep_loop("device", cpu, True, 8) == "device"  # runs (from the host's replay): tested above
    assert resolve_substep_loop("unrolled", cpu, True, 8) == "unrolled"
    if wp.get_cuda_device_count():
        cuda = wp.get_device("cuda:0")
        conditional = wp.is_conditional_graph_supported()
        assert resolve_substep_loop("auto", cuda, True, 8) == ("device" if conditional else "unrolled")
        assert resolve_substep_loop("auto", cuda, True, 7) == "unrolled"  # odd: no round trips of the state pair
        assert resolve_substep_loop("auto", cuda, False, 8) == "unrolled"  # eager: the loop would read back a counter


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(substep_loop="gpu"), "substep_loop expected one of ('auto', 'unrolled', 'device'), got 'gpu'"),
        (dict(substep_loop="device", physics=T.TaskPhysics(substeps=3)), "an even TaskPhysics.substeps >= 2, got 3"),
        (dict(substep_loop="device", physics=T.TaskPhysics(substeps=1)), "got 1"),
    ],
)
def test_make_refuses_a_substep_loop_it_cannot_run(kwargs, message):
    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace(")", r"\)").replace(".", r"\.")):
        T.make("PushCube-v1", num_envs=1, **kwargs)


@pytest.mark.skipif(
    not wp.get_cuda_device_count() or not torch.cuda.is_available() or not wp.is_conditional_graph_supported(),
    reason="needs a CUDA device with conditional graph nodes (driver and toolkit 12.4+): the captured device loop",
)
def test_captured_device_loop_is_the_written_out_step_on_cuda():
    ref = _trajectory("cuda:0", "unrolled", True, substeps=8)
    ours = _trajectory("cuda:0", "device", True, substeps=8)
    assert np.abs(np.diff(ref["q"], axis=0)).max() > 1e-3 and ref["is_grasped"].any()
    for k in ("obs", "reward", "q"):
        np.testing.assert_allclose(ours[k], ref[k], atol=1e-5, err_msg=k)
    np.testing.assert_array_equal(ours["is_grasped"], ref["is_grasped"])
