"""Every error wpctrl raises on bad input: the exception type, and a message that names the field and shows what was
expected and what was received. Also the inputs that must be *accepted* (float64 actions) and what a rejected call
must leave untouched (nan_policy="raise" launches nothing).
"""

from __future__ import annotations

import re

import newton
import numpy as np
import pytest
import warp as wp
from conftest import HAS_CUDA, build_panda

import wpctrl
from wpctrl import config as C
from wpctrl.robots import PANDA_ARM_JOINTS

try:
    import torch
except ImportError:  # a dev dependency: without it only the torch cases skip
    torch = None

NEEDS_TORCH = pytest.mark.skipif(torch is None, reason="torch is not installed (a dev dependency)")


def with_torch(make, *rest, id=None):
    """A parametrize case whose first value is built from torch when the test runs (skipped without torch)."""
    return pytest.param(make, *rest, marks=NEEDS_TORCH, id=id)


def _value(x):
    return x() if callable(x) else x


ARM3 = PANDA_ARM_JOINTS[:3]
N = 3


@pytest.fixture(scope="module")
def model():
    return build_panda(N)


def pos(**kw) -> C.PDJointPosControllerConfig:
    d = dict(joint_names=list(ARM3), lower=-1.0, upper=1.0, stiffness=100.0, damping=10.0)
    d.update(kw)
    return C.PDJointPosControllerConfig(**d)


def mimic(**kw) -> C.PDJointPosMimicControllerConfig:
    d = dict(joint_names=list(ARM3), lower=-1.0, upper=1.0, stiffness=100.0, damping=10.0)
    d.update(kw)
    return C.PDJointPosMimicControllerConfig(**d)


def posvel(**kw) -> C.PDJointPosVelControllerConfig:
    d = dict(joint_names=list(ARM3), lower=-1.0, upper=1.0, stiffness=100.0, damping=10.0)
    d.update(kw)
    return C.PDJointPosVelControllerConfig(**d)


def vel(**kw) -> C.PDJointVelControllerConfig:
    d = dict(joint_names=list(ARM3), lower=-1.0, upper=1.0, damping=10.0)
    d.update(kw)
    return C.PDJointVelControllerConfig(**d)


def passive(**kw) -> C.PassiveControllerConfig:
    d = dict(joint_names=list(ARM3), damping=1.0)
    d.update(kw)
    return C.PassiveControllerConfig(**d)


def raises(exc, *fragments: str):
    """pytest.raises that also checks every fragment occurs (literally) in the message."""
    return pytest.raises(exc, match="".join(f"(?=.*{re.escape(f)})" for f in fragments) + "(?s:.*)")


# ----------------------------------------------------------------------------------------------------------------------
# Joint names.


def test_unknown_joint_lists_close_matches(model):
    with raises(C.ConfigError, "joint_names", "'panda_jiont2'", "close matches", "'panda_joint2'"):
        wpctrl.build_controller(pos(joint_names=["panda_joint1", "panda_jiont2", "panda_joint3"]), model)


def test_unknown_joint_without_close_match_lists_the_models_joints(model):
    with raises(C.ConfigError, "joint_names", "'wheel'", "the model's joints", "'panda_joint1'"):
        wpctrl.build_controller(pos(joint_names=["wheel", "panda_joint2", "panda_joint3"]), model)


def test_duplicate_joints(model):
    with raises(C.ConfigError, "PDJointPosControllerConfig.joint_names", "duplicates", "'panda_joint1'"):
        wpctrl.build_controller(pos(joint_names=["panda_joint1", "panda_joint2", "panda_joint1"]), model)


@pytest.mark.parametrize("names", ["panda_joint1", [1, 2], None])
def test_joint_names_not_a_list_of_strings(model, names):
    with raises(C.ConfigError, "joint_names", "expected a sequence of joint-name strings", repr(names)):
        wpctrl.build_controller(pos(joint_names=names), model)


def _one_ball_one_free_one_hinge() -> newton.Model:
    b = newton.ModelBuilder()
    ball = b.add_link(mass=1.0, label="ball_link")
    b.add_shape_sphere(ball, radius=0.1)
    j_ball = b.add_joint_ball(-1, ball, label="ball")
    hinge = b.add_link(mass=1.0, label="hinge_link")
    b.add_shape_sphere(hinge, radius=0.1)
    j_hinge = b.add_joint_revolute(ball, hinge, axis=(0.0, 0.0, 1.0), label="hinge")
    b.add_articulation([j_ball, j_hinge])
    free = b.add_link(mass=1.0, label="free_link")
    b.add_shape_sphere(free, radius=0.1)
    j_free = b.add_joint_free(free, label="free")
    b.add_articulation([j_free])
    return b.finalize(device="cpu")


@pytest.mark.parametrize("joint, type_name", [("ball", "BALL"), ("free", "FREE")])
def test_non_one_dof_joint(joint, type_name):
    m = _one_ball_one_free_one_hinge()
    wpctrl.build_controller(passive(joint_names=["hinge"]), m)  # the 1-DOF joint of the same model is fine
    with raises(C.ConfigError, "joint_names", f"'{joint}'", f"a {type_name} joint", "1-DOF revolute or prismatic"):
        wpctrl.build_controller(passive(joint_names=["hinge", joint]), m)


# ----------------------------------------------------------------------------------------------------------------------
# Per-joint parameters.

_LENGTH_CASES = [
    (pos, "lower", [0.0, 0.0]),
    (pos, "upper", [1.0, 1.0, 1.0, 1.0]),
    (pos, "stiffness", [1.0, 2.0]),
    (pos, "damping", [1.0, 2.0, 3.0, 4.0]),
    (pos, "force_limit", [1.0, 2.0]),
    (pos, "friction", [0.0, 0.0]),
    (posvel, "vel_lower", [0.0, 0.0]),
    (posvel, "vel_upper", [1.0, 1.0, 1.0, 1.0]),
    (vel, "lower", [0.0, 0.0]),
    (vel, "damping", [1.0, 2.0]),
    (passive, "friction", [0.0, 0.0, 0.0, 0.0]),
    (mimic, "stiffness", [1.0, 2.0]),
    (pos, "lower", [[0.0, 0.0, 0.0]]),
]


@pytest.mark.parametrize("make, field, value", _LENGTH_CASES)
def test_wrong_sequence_length(model, make, field, value):
    cfg = make(**{field: value})
    shape = str(np.shape(value))
    with raises(C.ConfigError, f"{type(cfg).__name__}.{field}", "expected a scalar or 3 values", f"got shape {shape}"):
        wpctrl.build_controller(cfg, model)


@pytest.mark.parametrize("make", [pos, vel])
def test_wrong_drive_mode_length(model, make):
    with raises(C.ConfigError, "drive_mode", "a sequence of 3", "got 2 values", "['force', 'force']"):
        wpctrl.build_controller(make(drive_mode=["force", "force"]), model)


def test_unknown_drive_mode(model):
    with raises(
        C.ConfigError,
        "PDJointPosControllerConfig.drive_mode",
        "expected one of ('force', 'acceleration')",
        "got 'torque'",
    ):
        wpctrl.build_controller(pos(drive_mode=["force", "torque", "force"]), model)


@pytest.mark.parametrize(
    "make, kw, field, low, high",
    [
        (pos, dict(lower=1.0, upper=0.5), "lower/upper", "1.0", "0.5"),
        (pos, dict(lower=[0.0, 0.2, 0.0], upper=[1.0, 0.1, 1.0]), "lower/upper", "0.2", "0.1"),
        (pos, dict(lower=None, upper=-2.0), "lower/upper", "-1.7628", "-2.0"),  # joint limit vs config
        (posvel, dict(vel_lower=1.0, vel_upper=-1.0), "vel_lower/vel_upper", "1.0", "-1.0"),
        (vel, dict(lower=2.0, upper=1.0), "lower/upper", "2.0", "1.0"),
    ],
)
def test_lower_above_upper(model, make, kw, field, low, high):
    with raises(C.ConfigError, f".{field}", "lower must be <= upper", f"lower={low}", f"upper={high}", "joint"):
        wpctrl.build_controller(make(**kw), model)


@pytest.mark.parametrize(
    "make, field, value, shown",
    [
        (pos, "stiffness", float("nan"), "nan"),
        (pos, "damping", [1.0, float("nan"), 1.0], "nan"),
        (pos, "force_limit", float("nan"), "nan"),
        (pos, "friction", float("nan"), "nan"),
        (pos, "lower", float("nan"), "nan"),
        (pos, "upper", [1.0, 1.0, float("nan")], "nan"),
        (posvel, "vel_upper", float("nan"), "nan"),
        (vel, "upper", float("nan"), "nan"),
        (passive, "damping", float("nan"), "nan"),
        (pos, "stiffness", float("inf"), "inf"),
        (pos, "damping", [1.0, float("inf"), 1.0], "inf"),
        (pos, "friction", float("inf"), "inf"),
        (vel, "damping", float("inf"), "inf"),
        (pos, "stiffness", 1e39, "1e+39"),  # finite in float64, inf in float32
    ],
)
def test_non_finite_parameter(model, make, field, value, shown):
    cfg = make(**{field: value})
    with raises(C.ConfigError, f"{type(cfg).__name__}.{field}", "expected finite numbers", f"got {shown}", "joint"):
        wpctrl.build_controller(cfg, model)


@pytest.mark.parametrize(
    "make, kw, field",
    [
        (pos, dict(lower=-np.inf), "lower/upper"),
        (pos, dict(upper=[1.0, np.inf, 1.0]), "lower/upper"),
        (posvel, dict(vel_lower=-np.inf), "vel_lower/vel_upper"),
        (vel, dict(upper=np.inf), "lower/upper"),
    ],
)
def test_normalize_with_infinite_bounds(model, make, kw, field):
    with raises(C.ConfigError, f".{field}", "normalize_action needs finite bounds", "inf", "joint"):
        wpctrl.build_controller(make(**kw), model)
    wpctrl.build_controller(make(**kw, normalize_action=False), model)  # raw infinite bounds are fine (ManiSkill)


def test_infinite_force_limit_means_no_limit(model):
    ctrl = wpctrl.build_controller(pos(force_limit=[np.inf, 1e39, 5.0]), model)
    assert np.isinf(model.joint_effort_limit.numpy()[ctrl.dof_index[0, :2]]).all()


@pytest.mark.parametrize(
    "make, field, value, shown",
    [
        (pos, "stiffness", -1.0, "-1.0"),
        (pos, "damping", [1.0, -2.0, 1.0], "-2.0"),
        (pos, "force_limit", -np.inf, "-inf"),
        (pos, "friction", [0.0, 0.0, -0.5], "-0.5"),
        (vel, "damping", -1.0, "-1.0"),
        (passive, "force_limit", -3.0, "-3.0"),
    ],
)
def test_negative_parameter(model, make, field, value, shown):
    cfg = make(**{field: value})
    with raises(C.ConfigError, f"{type(cfg).__name__}.{field}", ">= 0", f"got {shown}", "joint 'panda_joint"):
        wpctrl.build_controller(cfg, model)


def test_velocity_bounds_must_be_numbers(model):
    with raises(C.ConfigError, "PDJointVelControllerConfig.lower", "expected a number or a sequence of 3", "got None"):
        wpctrl.build_controller(vel(lower=None), model)


def test_unparsable_parameter(model):
    with raises(C.ConfigError, "PDJointPosControllerConfig.stiffness", "expected a number", "'stiff'"):
        wpctrl.build_controller(pos(stiffness="stiff"), model)


def test_mode_flag_not_a_bool(model):
    with raises(C.ConfigError, "PDJointPosControllerConfig.use_delta", "expected a bool", "'yes'"):
        wpctrl.build_controller(pos(use_delta="yes"), model)


# ----------------------------------------------------------------------------------------------------------------------
# Mimic maps.


@pytest.mark.parametrize(
    "mm, role, name",
    [
        ({"panda_joint1": {"joint": "panda_joint5"}}, "control joint", "'panda_joint5'"),
        ({"panda_joint6": {"joint": "panda_joint1"}}, "mimic joint", "'panda_joint6'"),
    ],
)
def test_mimic_joint_outside_joint_names(model, mm, role, name):
    with raises(
        wpctrl.MimicJointError,
        "PDJointPosMimicControllerConfig.mimic",
        role,
        name,
        "not in joint_names",
        "'panda_joint1', 'panda_joint2', 'panda_joint3'",
    ) as info:
        wpctrl.build_controller(mimic(mimic=mm), model)
    # ManiSkill raises TypeError there; wpctrl's error is also a ValueError and a ConfigError.
    assert isinstance(info.value, TypeError) and isinstance(info.value, ValueError)
    assert isinstance(info.value, wpctrl.ConfigError)


def test_mimic_chain(model):
    mm = {"panda_joint1": {"joint": "panda_joint2"}, "panda_joint2": {"joint": "panda_joint3"}}
    with raises(
        C.ConfigError,
        "PDJointPosMimicControllerConfig.mimic",
        "mimic a commanded joint directly",
        "chain 'panda_joint1' -> 'panda_joint2' -> 'panda_joint3'",
    ):
        wpctrl.build_controller(mimic(mimic=mm), model)


@pytest.mark.parametrize(
    "mm, shown",
    [
        (
            {"panda_joint1": {"joint": "panda_joint2"}, "panda_joint2": {"joint": "panda_joint1"}},
            "cycle 'panda_joint1' -> 'panda_joint2' -> 'panda_joint1'",
        ),
        (
            {
                "panda_joint1": {"joint": "panda_joint2"},
                "panda_joint2": {"joint": "panda_joint3"},
                "panda_joint3": {"joint": "panda_joint1"},
            },
            "cycle 'panda_joint1' -> 'panda_joint2' -> 'panda_joint3' -> 'panda_joint1'",
        ),
    ],
)
def test_mimic_cycle(model, mm, shown):
    with raises(C.ConfigError, "PDJointPosMimicControllerConfig.mimic", "commanded joint directly", shown):
        wpctrl.build_controller(mimic(mimic=mm), model)


def test_mimic_self(model):
    with raises(C.ConfigError, "mimic['panda_joint1']", "cannot mimic itself"):
        wpctrl.build_controller(mimic(mimic={"panda_joint1": {"joint": "panda_joint1"}}), model)


def test_empty_mimic_with_three_joints(model):
    with raises(C.ConfigError, "PDJointPosMimicControllerConfig.mimic", "exactly 2 joints", "got 3 joints"):
        wpctrl.build_controller(mimic(mimic={}), model)


@pytest.mark.parametrize(
    "entry, fragments",
    [
        ({"joint": "panda_joint2", "multiplier": float("nan")}, ("finite multiplier", "multiplier=nan")),
        ({"joint": "panda_joint2", "offset": float("inf")}, ("finite multiplier", "offset=inf")),
        ({"joint": "panda_joint2", "multiplier": 1e39}, ("float32", "multiplier=1e+39")),
        ({"joint": "panda_joint2", "offset": "x"}, ("expected numbers", "'x'")),
        ({"multiplier": 2.0}, ("expected {'joint'", "{'multiplier': 2.0}")),
        ("panda_joint2", ("expected {'joint'", "'panda_joint2'")),
    ],
)
def test_bad_mimic_entry(model, entry, fragments):
    with raises(C.ConfigError, "mimic['panda_joint1']", *fragments):
        wpctrl.build_controller(mimic(mimic={"panda_joint1": entry}), model)


# ----------------------------------------------------------------------------------------------------------------------
# Frequencies, options, dicts.


def test_control_freq_must_divide_sim_freq(model):
    with raises(C.ConfigError, "sim_freq", "multiple of control_freq=30", "got sim_freq=100"):
        wpctrl.build_controller(pos(), model, control_freq=30, sim_freq=100)


@pytest.mark.parametrize(
    "kw, field, shown",
    [
        (dict(control_freq=0), "control_freq", "0"),
        (dict(control_freq=-20), "control_freq", "-20"),
        (dict(sim_freq=0), "sim_freq", "0"),
        (dict(sim_freq=-100), "sim_freq", "-100"),
        (dict(control_freq=20.0), "control_freq", "20.0"),
        (dict(sim_freq=True), "sim_freq", "True"),
    ],
)
def test_bad_freqs(model, kw, field, shown):
    with raises(C.ConfigError, f"{field}: expected a positive int", f"got {shown}"):
        wpctrl.build_controller(pos(), model, **kw)


@pytest.mark.parametrize(
    "kw, fragments",
    [
        (dict(actuation="torque"), ("actuation", "'implicit', 'explicit'", "got 'torque'")),
        (dict(nan_policy="ignore"), ("nan_policy", "'hold', 'raise'", "got 'ignore'")),
        (dict(explicit_pd="exact"), ("explicit_pd", "'naive', 'stable'", "got 'exact'")),
        (dict(inertia_update="never"), ("inertia_update", "'control', 'substep'", "got 'never'")),
    ],
)
def test_unknown_options(model, kw, fragments):
    with raises(ValueError, *fragments):
        wpctrl.build_controller(pos(), model, **kw)


def test_dict_children_share_a_joint(model):
    mode = {"arm": pos(), "wrist": passive(joint_names=["panda_joint3", "panda_joint4"])}
    with raises(C.ConfigError, "joint 'panda_joint3'", "both 'arm' and 'wrist'", "one controller"):
        wpctrl.build_controller(mode, model)


def test_bad_dicts_and_configs(model):
    with raises(C.ConfigError, "at least one", "empty dict"):
        wpctrl.build_controller({}, model)
    with raises(C.ConfigError, "control mode['arm']", "expected a controller config", "dict"):
        wpctrl.build_controller({"arm": {"joint_names": ARM3}}, model)
    with raises(C.ConfigError, "keys must be strings", "got 0"):
        wpctrl.build_controller({0: pos()}, model)
    with raises(C.ConfigError, "config", "expected a controller config", "got str"):
        wpctrl.build_controller("pd_joint_pos", model)


# ----------------------------------------------------------------------------------------------------------------------
# States and controls.


def test_state_and_control_from_another_model(model):
    ctrl = wpctrl.build_controller(pos(), model)
    other = build_panda(N + 1)
    s_other, c_other = other.state(), other.control()
    s, c = model.state(), model.control()
    action = np.zeros((N, 3), np.float32)
    coords, dofs = f"{model.joint_coord_count}", f"{model.joint_dof_count}"
    got = f"state has {other.joint_coord_count} coordinates / {other.joint_dof_count} DOFs"
    with raises(ValueError, "set_action", got, f"the controller's model {coords} / {dofs}"):
        ctrl.set_action(action, s_other)
    with raises(ValueError, "reset", got):
        ctrl.reset(s_other)
    with raises(ValueError, "before_simulation_step", got):
        ctrl.before_simulation_step(s_other, c)
    with raises(ValueError, "before_simulation_step", f"control has {other.joint_dof_count} DOFs", dofs):
        ctrl.before_simulation_step(s, c_other)
    with raises(ValueError, "reset", f"control has {other.joint_dof_count} DOFs"):
        ctrl.reset(s, control=c_other)
    with raises(TypeError, "expected a newton.State", "got NoneType"):
        ctrl.set_action(action, None)
    with raises(TypeError, "expected a newton.Control", "got State"):
        ctrl.before_simulation_step(s, s)


def test_model_without_the_robot_in_every_world():
    b = newton.ModelBuilder()
    from wpctrl.robots import panda

    b.add_world(panda())
    b.add_world(newton.ModelBuilder())
    m = b.finalize(device="cpu")
    with raises(C.ConfigError, "joint_names", "'panda_joint1'", "not in world 1"):
        wpctrl.build_controller(pos(), m)


# ----------------------------------------------------------------------------------------------------------------------
# Actions.


@pytest.fixture
def setup(model):
    ctrl = wpctrl.build_controller(pos(use_delta=True, use_target=True, lower=-0.1, upper=0.1), model)
    state, control = model.state(), model.control()
    ctrl.reset(state)
    return ctrl, state, control


def _snapshot(ctrl, control):
    return {
        "target_qpos": ctrl.target_qpos.numpy().copy(),
        "target_qvel": ctrl.target_qvel.numpy().copy(),
        "start_qpos": ctrl.start_qpos.numpy().copy(),
        "processed_action": ctrl.processed_action.numpy().copy(),
        "step": ctrl.step_counter.numpy().copy(),
        "bad": ctrl.bad_action_count.numpy().copy(),
        "target_q": control.joint_target_q.numpy().copy(),
        "target_qd": control.joint_target_qd.numpy().copy(),
        "f": control.joint_f.numpy().copy(),
    }


def _assert_same(a, b):
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


@pytest.mark.parametrize(
    "action, shown",
    [
        (np.zeros((N, 4), np.float32), f"({N}, 4)"),
        (np.zeros((N + 1, 3), np.float32), f"({N + 1}, 3)"),
        (np.zeros(3, np.float32), "(3,)"),  # unbatched with N > 1
        (np.zeros((1, N, 3), np.float32), f"(1, {N}, 3)"),
        with_torch(lambda: torch.zeros((N, 2)), f"({N}, 2)", id="torch"),
        (wp.zeros((N, 5), dtype=wp.float32, device="cpu"), f"({N}, 5)"),
    ],
)
def test_action_wrong_shape(setup, action, shown):
    ctrl, state, control = setup
    action = _value(action)
    before = _snapshot(ctrl, control)
    with raises(ValueError, "action", f"expected shape ({N}, 3)", f"got {shown}"):
        ctrl.set_action(action, state)
    _assert_same(before, _snapshot(ctrl, control))


@pytest.mark.parametrize(
    "action, shown",
    [
        (np.zeros((N, 3), np.int64), "int64"),
        (np.zeros((N, 3), np.int32), "int32"),
        (np.zeros((N, 3), bool), "bool"),
        with_torch(lambda: torch.zeros((N, 3), dtype=torch.int32), "torch.int32", id="torch-int32"),
        with_torch(lambda: torch.zeros((N, 3), dtype=torch.float16), "torch.float16", id="torch-float16"),
        (wp.zeros((N, 3), dtype=wp.int32, device="cpu"), "int32"),
    ],
)
def test_action_wrong_dtype(setup, action, shown):
    ctrl, state, control = setup
    action = _value(action)
    before = _snapshot(ctrl, control)
    with raises(TypeError, "action", "expected a float32 (or float64)", shown):
        ctrl.set_action(action, state)
    _assert_same(before, _snapshot(ctrl, control))


_A64 = np.random.default_rng(0).uniform(-1.5, 1.5, (N, 3))


@pytest.mark.parametrize(
    "make",
    [
        pytest.param(lambda: _A64.copy(), id="numpy"),
        pytest.param(lambda: np.asfortranarray(_A64), id="numpy-strided"),
        pytest.param(lambda: wp.array(_A64, dtype=wp.float64, device="cpu"), id="wp"),
        with_torch(lambda: torch.from_numpy(_A64.copy()), id="torch"),
        with_torch(lambda: torch.from_numpy(np.asfortranarray(_A64)), id="torch-strided"),
    ],
)
def test_float64_action_same_as_float32(model, make):
    results = []
    for action in (_A64.astype(np.float32), make()):
        ctrl = wpctrl.build_controller(pos(use_delta=True, lower=-0.1, upper=0.1), model)
        state = model.state()
        ctrl.reset(state)
        ctrl.set_action(action, state)
        del action
        _churn_allocator()
        results.append((ctrl.processed_action.numpy().copy(), ctrl.target_qpos.numpy().copy()))
    for x, y in zip(results[0], results[1]):
        np.testing.assert_array_equal(y, x)


def _churn_allocator():
    """Allocate and fill a few small tensors, so that freed memory read after the fact holds other values."""
    if torch is None:
        return
    for _ in range(4):
        torch.full((N, 3), 123.0, dtype=torch.float32)


@pytest.mark.filterwarnings("ignore:overflow encountered in cast:RuntimeWarning")
def test_nonfinite_action_raises_and_launches_nothing(model):
    ctrl = wpctrl.build_controller(
        pos(use_delta=True, lower=-0.1, upper=0.1, interpolate=True), model, nan_policy="raise"
    )
    state, control = model.state(), model.control()
    ctrl.reset(state)
    ctrl.set_action(np.full((N, 3), 0.5, np.float32), state)
    ctrl.before_simulation_step(state, control)
    before = _snapshot(ctrl, control)
    for bad in (np.nan, np.inf, -np.inf):
        a = np.full((N, 3), 0.25, np.float32)
        a[1, 2] = bad
        actions = [a, a.astype(np.float64), wp.array(a, dtype=wp.float32, device="cpu")]
        if torch is not None:
            actions.append(torch.from_numpy(a))
        for action in actions:
            with raises(ValueError, "action", "non-finite values in 1 env(s)", "env 1", "nan_policy='raise'"):
                ctrl.set_action(action, state)
            _assert_same(before, _snapshot(ctrl, control))
    # float64 values beyond float32's range become inf in the float32 action: rejected too.
    big = np.full((N, 3), 0.25)
    big[0, 0] = 1e300
    with raises(ValueError, "non-finite", "env 0"):
        ctrl.set_action(big, state)
    _assert_same(before, _snapshot(ctrl, control))


def test_nonfinite_action_hold_policy_counts(setup):
    ctrl, state, control = setup
    before = _snapshot(ctrl, control)
    a = np.full((N, 3), 0.5, np.float32)
    a[0, 1] = np.nan
    ctrl.set_action(a, state)
    assert ctrl.bad_action_count.numpy().tolist() == [1, 0, 0]
    after = _snapshot(ctrl, control)
    for k in ("target_qpos", "start_qpos", "processed_action"):
        np.testing.assert_array_equal(after[k][0], before[k][0], err_msg=k)
        assert not np.array_equal(after[k][1:], before[k][1:]) or k == "start_qpos", k


@pytest.mark.skipif(not HAS_CUDA, reason="needs a CUDA device to put the action on another device")
@NEEDS_TORCH
def test_action_on_another_device(model):
    ctrl = wpctrl.build_controller(pos(), model)
    state = model.state()
    with raises(ValueError, "action", "expected a tensor on cpu", "cuda"):
        ctrl.set_action(torch.zeros((N, 3), device="cuda"), state)
    with raises(ValueError, "action", "expected a wp.array on cpu", "cuda"):
        ctrl.set_action(wp.zeros((N, 3), dtype=wp.float32, device="cuda:0"), state)


def test_child_controller_is_not_driven_directly(model):
    ctrl = wpctrl.build_controller({"arm": pos(), "hand": passive(joint_names=["panda_finger_joint1"])}, model)
    state, control = model.state(), model.control()
    with raises(RuntimeError, "set_action", "child of a combined controller", "parent"):
        ctrl["arm"].set_action(np.zeros((N, 3), np.float32), state)
    with raises(RuntimeError, "before_simulation_step", "parent"):
        ctrl["arm"].before_simulation_step(state, control)
    with raises(RuntimeError, "reset", "parent"):
        ctrl["hand"].reset(state)
    with raises(KeyError, "no child controller 'gripper'", "['arm', 'hand']"):
        ctrl["gripper"]


def test_set_state_wrong_shape(setup):
    ctrl, _, _ = setup
    with raises(ValueError, "target_qpos", f"expected shape ({N}, 3)", f"got ({N}, 2)"):
        ctrl.set_state({"target_qpos": np.zeros((N, 2), np.float32)})


# ----------------------------------------------------------------------------------------------------------------------
# env_ids.


@pytest.mark.parametrize(
    "env_ids, exc, fragments",
    [
        ([0, N], ValueError, ("env_ids", f"indices in [0, {N})", f"got [0, {N}]")),
        ([-1], ValueError, ("env_ids", f"indices in [0, {N})", "got [-1]")),
        (N + 2, ValueError, ("env_ids", f"got [{N + 2}]")),
        (np.array([1, 7]), ValueError, ("env_ids", "got [1, 7]")),
        with_torch(lambda: torch.tensor([0, 9]), ValueError, ("env_ids", f"indices in [0, {N})", "[0, 9]"), id="t-ids"),
        (np.ones(N + 1, bool), ValueError, ("env_ids", f"bool mask must have shape ({N},)", f"got ({N + 1},)")),
        (np.ones((1, N), bool), ValueError, ("env_ids", f"shape ({N},)", f"got (1, {N})")),
        with_torch(
            lambda: torch.ones(N - 1, dtype=torch.bool),
            ValueError,
            ("env_ids", f"shape ({N},)", f"got ({N - 1},)"),
            id="t-mask",
        ),
        (wp.ones(N + 1, dtype=wp.bool, device="cpu"), ValueError, ("env_ids", f"shape ({N},)", f"({N + 1},)")),
        (True, ValueError, ("env_ids", f"shape ({N},)", "got ()")),
        ([0.0, 1.0], TypeError, ("env_ids", "expected env indices (ints) or a bool mask", "float64")),
        (np.array([0.5], np.float32), TypeError, ("env_ids", "float32")),
        with_torch(
            lambda: torch.tensor([0.0]),
            TypeError,
            ("env_ids", "expected an int or bool tensor", "torch.float32"),
            id="t-float",
        ),
        (wp.zeros(2, dtype=wp.float32, device="cpu"), TypeError, ("env_ids", "int32 or bool wp.array", "float32")),
    ],
)
def test_bad_env_ids(setup, env_ids, exc, fragments):
    ctrl, state, control = setup
    env_ids = _value(env_ids)  # after the first reset (which initialises every env whatever env_ids says)
    before = _snapshot(ctrl, control)
    with raises(exc, *fragments):
        ctrl.reset(state, env_ids, control=control)
    _assert_same(before, _snapshot(ctrl, control))


def test_device_env_ids_out_of_range_are_skipped(setup):
    """Device index arrays are not read back (graph capture): out-of-range entries are skipped by the kernel."""
    ctrl, state, control = setup
    ctrl.set_action(np.full((N, 3), 0.5, np.float32), state)
    before = ctrl.target_qpos.numpy().copy()
    ctrl.reset(state, wp.array([N + 5, 1, -3], dtype=wp.int32, device="cpu"))
    after = ctrl.target_qpos.numpy()
    np.testing.assert_array_equal(after[[0, 2]], before[[0, 2]])
    q = state.joint_q.numpy()[ctrl.coord_index[1]]
    np.testing.assert_array_equal(after[1], q)


def test_bad_env_ids_rejected_on_the_first_reset(model):
    ctrl = wpctrl.build_controller(pos(), model)
    with pytest.raises((ValueError, TypeError)):
        ctrl.reset(model.state(), [0.5, 99.0])


# ----------------------------------------------------------------------------------------------------------------------
# Wrong kinds of objects, and States/Controls of another model with the same sizes.


def test_state_and_control_rejected_by_type(setup):
    ctrl, state, control = setup
    model = ctrl.model
    action = np.zeros((N, 3), np.float32)
    before = _snapshot(ctrl, control)
    # A Model has joint_q / joint_qd of the right sizes: only its type tells it apart.
    with raises(TypeError, "set_action", "expected a newton.State", "got Model"):
        ctrl.set_action(action, model)
    with raises(TypeError, "set_action", "expected a newton.State", "got Control"):
        ctrl.set_action(action, control)
    with raises(TypeError, "reset", "expected a newton.State", "got Model"):
        ctrl.reset(model)
    with raises(TypeError, "before_simulation_step", "expected a newton.Control", "got Model"):
        ctrl.before_simulation_step(state, model)
    with raises(TypeError, "reset", "expected a newton.Control", "got State"):
        ctrl.reset(state, control=state)
    _assert_same(before, _snapshot(ctrl, control))


def test_state_of_another_model_with_the_same_sizes(model):
    other = build_panda(N)  # same joint counts: shapes cannot tell the States apart
    assert other.joint_coord_count == model.joint_coord_count
    ctrl = wpctrl.build_controller(pos(), model)
    ctrl_other = wpctrl.build_controller(pos(), other)
    s, c = model.state(), model.control()
    s_other, c_other = other.state(), other.control()
    action = np.zeros((N, 3), np.float32)
    ctrl.reset(s, control=c)
    ctrl_other.reset(s_other, control=c_other)  # binds s_other / c_other to `other`
    before = _snapshot(ctrl, c)
    with raises(ValueError, "set_action", "this state belongs to another newton.Model", "model.state()"):
        ctrl.set_action(action, s_other)
    with raises(ValueError, "before_simulation_step", "this state belongs to another newton.Model"):
        ctrl.before_simulation_step(s_other, c)
    with raises(ValueError, "before_simulation_step", "this control belongs to another newton.Model"):
        ctrl.before_simulation_step(s, c_other)
    with raises(ValueError, "reset", "this state belongs to another newton.Model"):
        ctrl.reset(s_other)
    _assert_same(before, _snapshot(ctrl, c))
    # Each model's own objects keep working, also with a second controller of the same model.
    ctrl.set_action(action, s)
    ctrl.before_simulation_step(s, c)
    wpctrl.build_controller(pos(), model).reset(s, control=c)
    ctrl_other.set_action(action, s_other)


@pytest.mark.parametrize(
    "field, value, shown",
    [
        ("stiffness", "1e3", "'1e3' (str)"),
        ("damping", [1.0, "2", 3.0], "[1.0, '2', 3.0] (list)"),
        ("force_limit", True, "True (bool)"),
        ("stiffness", {"a": 1.0}, "{'a': 1.0} (dict)"),
    ],
)
def test_non_numeric_parameter(model, field, value, shown):
    with raises(C.ConfigError, f"PDJointPosControllerConfig.{field}", "expected a number or a sequence of 3", shown):
        wpctrl.build_controller(pos(**{field: value}), model)


@pytest.mark.parametrize(
    "action, shown",
    [
        ({"arm": np.zeros(3)}, "got dict"),
        (None, "got NoneType"),
        ("0.1 0.2 0.3", "got str"),
        ([["a", "b", "c"]] * N, "got list holding dtype <U1"),
        (np.array([object()] * (N * 3), dtype=object).reshape(N, 3), "got ndarray holding dtype object"),
    ],
)
def test_action_not_an_array_names_the_type(setup, action, shown):
    ctrl, state, control = setup
    before = _snapshot(ctrl, control)
    with raises(TypeError, "action", f"expected an array of shape ({N}, 3)", shown):
        ctrl.set_action(action, state)
    _assert_same(before, _snapshot(ctrl, control))
