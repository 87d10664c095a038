"""What a new user meets first: a task env's repr, reset options, a batch too small for PPO's mini-batches, a device
the machine lacks, export / evaluate without torch, explicit naive PD past its stability bound, the delay's seed."""

from __future__ import annotations

import subprocess
import sys
import warnings

import newton
import numpy as np
import pytest
import warp as wp
from conftest import build_panda

import wpctrl
from wpctrl.__main__ import main as cli_main
from wpctrl.robots import PANDA_ARM_JOINTS, PANDA_GRIPPER_JOINTS, panda_control_modes

torch = pytest.importorskip("torch", reason="torch is not installed")  # a dev dependency


# -- the task env: repr, reset options, device ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def push_env():
    pytest.importorskip("mujoco_warp", reason="the tasks need the [sim] extra")
    import wpctrl.tasks as T

    env = T.make("PushCube-v1", num_envs=2, device="cpu", physics=T.TaskPhysics(substeps=2))
    yield env
    env.close()


def test_task_env_repr_names_the_task_and_reset_refuses_unknown_options(push_env):
    env = push_env
    for text in (repr(env), str(env)):
        for part in ("PushCube-v1", "num_envs=2", "device=cpu", "control_mode=pd_joint_delta_pos"):
            assert part in text, (part, text)
    assert env.task_spec.env_id == "PushCube-v1" and env.spec is None  # gymnasium's: not registered there
    env.reset(seed=1)
    env.step(torch.zeros(2, env.single_action_space.shape[0]))
    env.step(torch.zeros(2, env.single_action_space.shape[0]))
    assert env.elapsed_steps.tolist() == [2, 2]
    with pytest.raises(wpctrl.ConfigError) as e:
        env.reset(options={"env_ids": [0], "seed": 3})
    assert "['env_ids', 'seed']" in str(e.value) and "['env_idx', 'reconfigure']" in str(e.value)
    assert env.elapsed_steps.tolist() == [2, 2]  # refused before any reset
    with pytest.raises(wpctrl.ConfigError, match=r"options expected a dict"):
        env.reset(options=[0])
    env.reset(options={"env_idx": [1]})  # the known key: a partial reset
    assert env.elapsed_steps.tolist() == [2, 0]


def test_unknown_device_is_refused_with_the_available_ones():
    from wpctrl.devices import available_devices, check_device

    if wp.is_cuda_available():
        pytest.skip("cuda:0 exists on this machine: the no-GPU refusal cannot be shown")
    import wpctrl.tasks as T

    assert available_devices() == ["cpu"]
    with pytest.raises(wpctrl.ConfigError) as e:
        T.make("PushCube-v1", num_envs=2, device="cuda:0")
    assert "make: device: 'cuda:0'" in str(e.value) and "available devices: ['cpu']" in str(e.value)
    with pytest.raises(wpctrl.ConfigError, match=r"--device: 'gpu' is not a device of this machine"):
        check_device("gpu", "--device")
    assert check_device(torch.device("cpu")) == wp.get_device("cpu")


def test_cli_device_refusals(capsys, tmp_path):
    if wp.is_cuda_available():
        pytest.skip("cuda:0 exists on this machine: the no-GPU refusal cannot be shown")
    policy = tmp_path / "policy.ts"
    policy.write_text("not read: the device is refused first")
    for argv in (["train", "--task", "PushCube-v1", "--device", "cuda:0"],
                 ["evaluate", "--policy", str(policy), "--sim", "newton", "--device", "cuda:0"]):  # fmt: skip
        assert cli_main(argv) == 2
        captured = capsys.readouterr()
        assert "--device: 'cuda:0' is not a device of this machine" in captured.err, captured.err
        assert "available devices: ['cpu']" in captured.err and captured.out == ""


# -- a training batch too small for its mini-batches --------------------------------------------------------------


def test_batch_too_small_for_the_minibatches_is_refused_before_building(capsys):
    pytest.importorskip("rsl_rl", reason="the train extra (rsl-rl-lib) is not installed")
    from wpctrl.train.cli import parse

    # the reason: the std of one advantage is undefined, of two it is not
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # torch's own note on the one-sample std
        assert torch.isnan(torch.tensor([0.3]).std()) and torch.isfinite(torch.tensor([0.3, 0.5]).std())
    assert cli_main(["train", "--task", "PushCube-v1", "--device", "cpu", "--envs", "8"]) == 2
    captured = capsys.readouterr()
    err = " ".join(captured.err.split())
    for part in ("--envs 8 x --steps-per-env 4 = a batch of 32 samples", "--minibatches 32 mini-batches",
                 "leaves 1 sample per mini-batch", "at least 2 samples per mini-batch", ">= 2 x mini-batches = 64",
                 "raise --envs to 16", "--steps-per-env to 8", "lower --minibatches to 16"):  # fmt: skip
        assert part in err, (part, err)
    assert captured.out == ""  # nothing announced or built
    with pytest.raises(SystemExit):
        parse(["--task", "PickCube-v1", "--device", "cpu", "--envs", "15"])  # 60 samples: 1 per mini-batch
    assert "leaves 1 sample per mini-batch" in capsys.readouterr().err
    assert parse(["--task", "PickCube-v1", "--device", "cpu", "--envs", "16"]).envs == 16  # 2 per mini-batch
    assert parse(["--task", "PushCube-v1", "--device", "cpu", "--envs", "2", "--minibatches", "4"]).envs == 2
    # the reach task: 4 mini-batches of a whole-batch normalised advantage, one sample each at least
    with pytest.raises(SystemExit):
        parse(["--device", "cpu", "--envs", "1", "--steps-per-env", "3"])
    err = " ".join(capsys.readouterr().err.split())
    assert "a batch of 3 samples" in err and "4 mini-batches (fixed), leaves 0 samples" in err, err
    assert parse(["--device", "cpu", "--envs", "1", "--steps-per-env", "4"]).steps_per_env == 4


# -- export / evaluate without torch --------------------------------------------------------------------------------

_NO_TORCH = """
import sys
sys.modules["torch"] = None  # a base install: torch does not import
from wpctrl.__main__ import main
sys.exit(main(sys.argv[1:]))
"""


def test_make_without_torch_names_the_tasks_extra(tmp_path):
    """A base install (no torch): ``wpctrl.tasks.make`` says which extra it needs and how to install it, after the
    torch build of one's choice."""
    code = ("import sys\nsys.modules['torch'] = None\nimport wpctrl.tasks as T\n"
            "try:\n    T.make('PushCube-v1')\nexcept ImportError as e:\n    print(e)\n")  # fmt: skip
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert done.stdout.startswith("wpctrl.tasks.make needs the tasks extra: install the torch build you want first")
    assert 'pip install -e ".[tasks]" in a source checkout, or pip install "wpctrl[tasks]"' in done.stdout


@pytest.mark.parametrize("command, argv", [("export", ["run"]), ("evaluate", ["--policy", "p.ts", "--sim", "newton"]),
                                           ("train", ["--task", "reach", "--device", "cpu"])])  # fmt: skip
def test_commands_without_torch_print_the_install_line(command, argv, tmp_path):
    def run(args):
        return subprocess.run([sys.executable, "-c", _NO_TORCH, command, *args], capture_output=True, text=True,
                              cwd=tmp_path, timeout=120)  # fmt: skip

    helped = run(["--help"])
    assert helped.returncode == 0 and "usage:" in helped.stdout and "Traceback" not in helped.stderr, helped.stderr
    done = run(argv)
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert f"wpctrl {command} needs the train extra: install the torch build you want first" in done.stderr, done.stderr
    assert 'pip install -e ".[train]" in a source checkout, or pip install "wpctrl[train]"' in done.stderr
    assert "Traceback" not in done.stderr


# -- explicit naive PD past its stability bound ------------------------------------------------------------------


def _build(model, sim_freq=100, **kw):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ctrl = wpctrl.build_controller(panda_control_modes()["pd_joint_delta_pos"], model, 20, sim_freq, **kw)
    return ctrl, [w for w in caught if issubclass(w.category, UserWarning)]


def test_explicit_naive_pd_past_the_bound_warns():
    model = build_panda(2)
    _, caught = _build(model, actuation="explicit")
    assert len(caught) == 1
    text = str(caught[0].message)
    assert "panda_joint7 (Kp*dt^2/m = " in text and "explicit_pd='stable'" in text and "explicit_pd='coupled'" in text
    assert "Kp*dt^2/m + 2*Kd*dt/m < 4" in text and "panda_joint2" not in text  # joint 2 (m = 1.1) is inside
    assert caught[0].filename == __file__  # points at the caller's line
    for kw in ({"actuation": "explicit", "explicit_pd": "stable"}, {"actuation": "implicit"}):
        assert _build(model, **kw)[1] == [], kw
    assert _build(model, sim_freq=20000, actuation="explicit")[1] == []  # dt small enough for every joint


def _one_dof(inertia: float) -> newton.Model:
    """One revolute joint about z carrying a body of moment of inertia ``inertia`` about it; no gravity."""
    b = newton.ModelBuilder()
    link = b.add_link(mass=1.0, com=wp.vec3(0.0), inertia=wp.mat33(*np.diag([inertia] * 3).reshape(-1).tolist()))
    b.add_articulation([b.add_joint_revolute(-1, link, axis=(0.0, 0.0, 1.0), label="hinge", armature=0.0)])
    model = b.finalize(device="cpu")
    model.set_gravity((0.0, 0.0, 0.0))
    return model


@pytest.mark.parametrize("margin", [0.95, 1.05])
def test_one_dof_diverges_just_past_the_bound_and_not_below(margin):
    """A PD spring-damper on one joint of inertia m at sim_freq 100: Kd dt/m = 1, Kp dt^2/m = 4 margin - 2. MuJoCo's
    semi-implicit Euler step settles it below the bound and blows it up above; the warning says which."""
    pytest.importorskip("mujoco_warp", reason="needs the [sim] extra")
    m, dt = 0.01, 0.01
    a, b = 4.0 * margin - 2.0, 1.0
    model = _one_dof(m)
    cfg = wpctrl.PDJointPosControllerConfig(["hinge"], None, None, a * m / dt**2, b * m / dt, 1e9,
                                            normalize_action=False)  # fmt: skip
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ctrl = wpctrl.build_controller(cfg, model, 100, 100, actuation="explicit")
    warned = [w for w in caught if issubclass(w.category, UserWarning)]
    assert bool(warned) == (margin > 1.0)
    if warned:
        assert "hinge (Kp*dt^2/m = 2.2, Kd*dt/m = 1, m = 0.01)" in str(warned[0].message)
    solver = newton.solvers.SolverMuJoCo(model, disable_contacts=True, integrator="euler")
    s0, s1, control = model.state(), model.state(), model.control()
    ctrl.reset(s0)
    errors = []
    for _ in range(60):
        ctrl.set_action(np.array([[0.1]], np.float32), s0)
        ctrl.before_simulation_step(s0, control)
        solver.step(s0, s1, control, None, dt)
        s0, s1 = s1, s0
        errors.append(abs(float(s0.joint_q.numpy()[0]) - 0.1))
    if margin < 1.0:
        assert errors[-1] < 1e-4, errors[-5:]  # |z| = 0.8 per step: settled
    else:
        assert not np.isfinite(errors[-1]) or errors[-1] > 10.0, errors[-5:]  # |z| = 1.2 per step: 1.2^60 ~ 6e4


# -- the delay's seed -------------------------------------------------------------------------------------------


def test_delay_seed_names_the_delay_and_seed_is_its_deprecated_alias():
    model = build_panda(64)
    cfg = wpctrl.PDJointPosControllerConfig(PANDA_ARM_JOINTS + PANDA_GRIPPER_JOINTS, None, None, 1e3, 1e2, 1e3,
                                            normalize_action=False)  # fmt: skip

    def draws(**kw):
        return wpctrl.build_controller(cfg, model, delay=(0, 7), **kw).delay.numpy()

    a = draws(delay_seed=3)
    with pytest.warns(DeprecationWarning, match=r"seed= is deprecated, use delay_seed="):
        old = draws(seed=3)
    np.testing.assert_array_equal(a, old)  # the same draws
    assert not np.array_equal(a, draws(delay_seed=4))  # the seed keys them
    with pytest.raises(wpctrl.ConfigError, match=r"seed: expected None when delay_seed is given"):
        draws(seed=3, delay_seed=3)
    with pytest.raises(wpctrl.ConfigError, match=r"delay_seed: expected None without a delay"):
        wpctrl.build_controller(cfg, model, delay_seed=3)
    with pytest.raises(wpctrl.ConfigError, match=r"delay_seed: expected None when delay is given as Delay"):
        wpctrl.build_controller(cfg, model, delay=wpctrl.Delay((0, 2), seed=1), delay_seed=3)
