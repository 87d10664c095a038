"""External wrenches on a task's actors (``TaskEnv.set_external_wrench``): a lifting force and a torque move a free
cube as Newton's laws say, per env, through the env's captured step; removing the wrench lets the cube fall back;
resets keep it; bad input is refused before anything is written."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="the task envs return torch tensors")
pytest.importorskip("mujoco_warp", reason="the task envs run MuJoCo-Warp (newton[sim])")

from scipy.spatial.transform import Rotation  # noqa: E402

import wpctrl.tasks as T  # noqa: E402
from wpctrl import ConfigError  # noqa: E402

HALF = 0.02
"""PickCube's cube half size [m]."""
STEP = 0.05
"""One control step [s] (20 Hz)."""


@pytest.fixture(scope="module")
def env():
    e = T.make("PickCube-v1", num_envs=2, control_mode="pd_joint_delta_pos")
    e.reset(seed=0)
    return e


def _cube_at_rest(env):
    """Both cubes on the table, upright, away from the Panda; no wrench; settled for 4 steps."""
    env.set_external_wrench("cube")
    s = env.get_state_dict()
    s["actors"]["cube"][:] = torch.tensor([[0.1, 0.1, HALF, 1.0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
                                           [0.1, -0.1, HALF, 1.0, 0, 0, 0, 0, 0, 0, 0, 0, 0]])  # fmt: skip
    env.set_state_dict({g: dict(d) for g, d in s.items() if g in ("actors", "articulations")})
    for _ in range(4):
        env.step(torch.zeros(2, 8))
    return env.get_state_dict()["actors"]["cube"].clone()


def _yaw(pose) -> float:
    return float(Rotation.from_quat([*pose[4:7].tolist(), float(pose[3])]).as_euler("xyz")[2])


def test_a_lifting_force_and_a_torque_move_the_cube_as_newtons_laws_say(env):
    """Both envs: an upward force m (g + a) lifts the cube by a t^2 / 2; env 1 only: a torque I alpha about z turns
    it by alpha t^2 / 2 (I = m (2h)^2 / 6, a solid cube), env 0 does not turn. Measured 0.6 % over the closed form
    after 0.1 s (MuJoCo's integration and the contact letting go); bounds 2 %."""
    p0 = _cube_at_rest(env)
    body = env.scene.actor_body0["cube"]
    m = float(env.model.body_mass.numpy()[body])
    g = float(np.linalg.norm(np.asarray(env.model.gravity.numpy()).reshape(-1, 3)[0]))
    inertia = m * (2 * HALF) ** 2 / 6
    a, alpha = 2.0, 60.0
    env.set_external_wrench("cube", force=[0.0, 0.0, m * (g + a)])
    env.set_external_wrench("cube", force=[0.0, 0.0, m * (g + a)], torque=[0.0, 0.0, alpha * inertia], env_idx=[1])
    expected = np.array([[0, 0, m * (g + a), 0, 0, 0], [0, 0, m * (g + a), 0, 0, alpha * inertia]])
    np.testing.assert_allclose(env.get_external_wrench("cube").numpy(), expected, rtol=1e-6)
    for _ in range(2):
        env.step(torch.zeros(2, 8))
    t = 2 * STEP
    p = env.get_state_dict()["actors"]["cube"]
    np.testing.assert_allclose((p[:, 2] - p0[:, 2]).numpy(), a * t * t / 2, rtol=0.02)
    assert abs(_yaw(p[0])) < 1e-6
    assert _yaw(p[1]) == pytest.approx(alpha * t * t / 2, rel=0.02)
    np.testing.assert_allclose(p[:, :2].numpy(), p0[:, :2].numpy(), atol=1e-5)  # straight up


def test_removing_the_wrench_lets_the_cube_fall_back_and_a_reset_keeps_it(env):
    """Lifted for 0.1 s (1 cm), then released: after 0.3 s the cube rests on the table again. A wrench set before
    ``reset`` is still there after it."""
    p0 = _cube_at_rest(env)
    m = float(env.model.body_mass.numpy()[env.scene.actor_body0["cube"]])
    env.set_external_wrench("cube", force=[0.0, 0.0, m * 11.81])
    for _ in range(2):
        env.step(torch.zeros(2, 8))
    assert (env.get_state_dict()["actors"]["cube"][:, 2] - p0[:, 2] > 0.008).all()
    env.set_external_wrench("cube")
    assert not env.get_external_wrench("cube").any()
    for _ in range(6):
        env.step(torch.zeros(2, 8))
    np.testing.assert_allclose(env.get_state_dict()["actors"]["cube"][:, 2].numpy(), p0[:, 2].numpy(), atol=1e-3)
    env.set_external_wrench("cube", torque=[0.0, 0.0, 1e-3], env_idx=[0])
    env.reset(seed=1)
    np.testing.assert_array_equal(env.get_external_wrench("cube")[:, 5].numpy(), np.float32([1e-3, 0.0]))
    env.set_external_wrench("cube")


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"actor": "peg"}, "set_external_wrench: actor expected one of PickCube-v1's free bodies ['cube'], got 'peg'"),
        ({"actor": "goal_site"}, "got 'goal_site'"),  # a marker, not a body
        ({"force": [1.0, 2.0]}, "force expected shape (2, 3) or (3,), got (2,) (a row per env selected, or one for"),
        ({"force": np.ones((2, 3)), "env_idx": [1]}, "force expected shape (1, 3) or (3,), got (2, 3)"),
        ({"torque": [0.0, float("nan"), 0.0]}, "torque holds non-finite values"),
        ({"force": "up"}, "force expected an array of numbers, got str"),
        ({"force": [0.0, 0.0, 1.0], "env_idx": [2]}, "env_idx: indices must be in [0, 2), got [2]"),
    ],
)
def test_bad_input_is_refused_before_anything_is_written(env, kwargs, message):
    env.set_external_wrench("cube", force=[0.0, 0.0, 0.5])
    before = env.get_external_wrench("cube")
    kwargs = {"actor": "cube", **kwargs}
    with pytest.raises(ConfigError) as e:
        env.set_external_wrench(kwargs.pop("actor"), **kwargs)
    assert message in str(e.value)
    assert torch.equal(env.get_external_wrench("cube"), before)
    env.set_external_wrench("cube")
