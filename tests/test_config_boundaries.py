"""Every field of every public config dataclass, validated at its boundary: a value just inside is accepted, one just
outside is refused, a value of the wrong type is refused (a :class:`wpctrl.ConfigError` naming the field, raised by
``build_controller`` before anything reaches the device).

The cases are generated from ``dataclasses.fields`` of the dataclasses ``wpctrl`` exports, so a new field cannot be
forgotten: a field without an entry in :data:`BOUNDS` (looked up along the class's MRO, so a subclass inherits its
base's entries) fails :func:`test_every_config_field_declares_its_boundary`. Whoever adds a field declares its
boundary here.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
import pytest
from conftest import PANDA_URDF, build_panda
from user_models import indices, put

import wpctrl
from wpctrl.robots import PANDA_ARM_JOINTS, PANDA_GRIPPER_JOINTS, panda_control_modes

torch = pytest.importorskip("torch", reason="torch is a dev dependency (actuator networks are read from torch)")

F32_MAX = float(np.finfo(np.float32).max)
N_ARM = len(PANDA_ARM_JOINTS)


def up(x: float) -> float:
    """The next float32 above ``x`` (as a Python float): the smallest step a float32 config value can take."""
    return float(np.nextafter(np.float32(x), np.float32(np.inf)))


def down(x: float) -> float:
    return float(np.nextafter(np.float32(x), np.float32(-np.inf)))


@dataclass(frozen=True)
class V:
    """A value for a field, with the other fields it needs (``fields``: the same config; ``build``:
    ``build_controller``'s options)."""

    value: object
    fields: dict = field(default_factory=dict)
    build: dict = field(default_factory=dict)
    label: str = ""


@dataclass(frozen=True)
class Bound:
    """A field's boundary: values accepted just inside it, values refused just outside, values of a wrong type."""

    inside: tuple
    outside: tuple = ()
    wrong_type: tuple = ()


@dataclass(frozen=True)
class Make:
    """A value made when the case runs (a torch module, the path of a TorchScript file)."""

    fn: object
    label: str = ""

    def __call__(self, ctx):
        return self.fn(ctx) if self.fn is _torchscript else self.fn()


def _mlp(n_in: int = 6, n_out: int = 1) -> Make:
    return Make(lambda: torch.nn.Sequential(torch.nn.Linear(n_in, 4), torch.nn.Tanh(), torch.nn.Linear(4, n_out)))


def _torchscript(path):
    return path


def _lstm():
    class Net(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.lstm = torch.nn.LSTM(2, 4, 1, batch_first=True)
            self.linear = torch.nn.Linear(4, 1)

        def forward(self, x, hc: tuple[torch.Tensor, torch.Tensor]):
            out, (h, c) = self.lstm(x, hc)
            return self.linear(out), (h, c)

    return Net()


def _lstm_net(input_size=2, bias=True, proj_size=0, head_first=False):
    """An LSTM actuator module of an unsupported shape."""

    class Net(torch.nn.Module):
        def __init__(self):
            super().__init__()
            if head_first:
                self.pre = torch.nn.Linear(6, 2)
            self.lstm = torch.nn.LSTM(input_size, 4, 1, bias=bias, proj_size=proj_size, batch_first=True)
            self.linear = torch.nn.Linear(proj_size or 4, 1)

    return Net()


LSTM = Make(_lstm)
TORCHSCRIPT = Make(_torchscript)


# Shared boundaries -------------------------------------------------------------------------------------------------

BOOL = Bound(inside=(True, False), wrong_type=(1, "True", None))


def nonneg(n: int, *, infinite_ok: bool = False, required: bool = True) -> Bound:
    """A per-joint value >= 0 (a scalar, one value, or one per joint), used in float32 (1e39 would become inf)."""
    inside = [0.0, F32_MAX, [0.0] * n, [1.0]]
    outside = [down(0.0), -1.0, math.nan, [1.0] * (n + 1), [[1.0] * n]]
    if infinite_ok:  # a force limit: inf (or beyond float32) means no limit
        inside += [math.inf, 1e39]
    else:
        outside += [math.inf, 1e39]
    return Bound(tuple(inside), tuple(outside), ("1.0", True) + ((None,) if required else ()))


def ordered_pair(other: str, lo_side: bool, n: int, other_value: float, none_ok: bool) -> Bound:
    """A lower (``lo_side``) or upper bound against ``other`` = ``other_value``: equal is accepted, one float32 step
    past it refused."""
    edge = other_value
    past = up(edge) if lo_side else down(edge)
    inside = [edge, [edge] * n, [edge]]
    if none_ok:
        inside.append(None)
    outside = [past, [past] * n, [edge] * (n + 1), math.nan]
    return Bound(tuple(inside), tuple(outside), ("0.5", True) + (() if none_ok else (None,)))


def drive_mode(n: int) -> Bound:
    return Bound(
        inside=("force", "acceleration", ["force"] * n, ["acceleration"] + ["force"] * (n - 1)),
        outside=("Force", "velocity", ["force"] * (n + 1), ["force"] * (n - 1) + ["accel"]),
        wrong_type=(3, None, [3] * n),
    )


def joint_names(names: list[str], *, fewer_ok: bool = True, extra_outside=()) -> Bound:
    inside = [list(names), tuple(names)]
    if fewer_ok:
        inside.append(list(names[:1]))
    return Bound(
        inside=tuple(inside),
        outside=(list(names) + [names[0]], ["no_such_joint"] + list(names[1:])) + tuple(extra_outside),
        wrong_type=(names[0], [1] * len(names), None),
    )


_DC = dict(actuation="explicit")
_DELTA = {"type": "levenberg_marquardt", "alpha": 1.0}


def _solver(**kw) -> dict:
    return dict(_DELTA, **kw)


BOUNDS: dict[str, dict[str, Bound]] = {
    "ControllerConfig": {"joint_names": joint_names(list(PANDA_ARM_JOINTS))},
    "PDJointPosControllerConfig": {
        # base: lower=-0.5, upper=0.5 over the 7 arm joints
        "lower": ordered_pair("upper", True, N_ARM, 0.5, none_ok=True),
        "upper": ordered_pair("lower", False, N_ARM, -0.5, none_ok=True),
        "stiffness": nonneg(N_ARM),
        "damping": nonneg(N_ARM),
        "force_limit": nonneg(N_ARM, infinite_ok=True),
        "friction": nonneg(N_ARM),
        "use_delta": BOOL,
        "use_target": BOOL,
        "interpolate": BOOL,
        "normalize_action": Bound(
            inside=(True, False, V(False, {"lower": -math.inf})),
            outside=(V(True, {"lower": -math.inf}),),  # normalising needs finite bounds
            wrong_type=(1, "True", None),
        ),
        "drive_mode": drive_mode(N_ARM),
        "actuator": Bound(
            inside=(
                None,
                V(wpctrl.DCMotor(50.0, 2.0), build=_DC),
                V(wpctrl.PositionBasedEffortLimit([0.0], [1.0]), build=_DC),
            ),
            outside=(wpctrl.DCMotor(50.0, 2.0),),  # an actuator model with the solver's implicit drive
            wrong_type=("dc", 50.0, {"saturation_effort": 1.0, "velocity_limit": 1.0}),
        ),
        "ema": Bound(
            inside=(None, 1.0, 0.5, 1e-6, 1, up(0.0)),  # up(0.0): the smallest positive float32
            outside=(0.0, -0.0, -0.1, up(1.0), 2, math.nan, math.inf, 1e-46),  # 1e-46: 0 in float32
            wrong_type=(True, "0.5", [0.5]),
        ),
        "binary": Bound(
            inside=(True, False),
            outside=(V(True, {"use_delta": True}),),  # a binary command is absolute
            wrong_type=(1, "yes", None),
        ),
    },
    "PDJointPosMimicControllerConfig": {
        # base: the Panda's gripper, finger 2 follows finger 1
        "joint_names": joint_names(list(PANDA_GRIPPER_JOINTS), fewer_ok=False),
        "lower": ordered_pair("upper", True, 2, 0.04, none_ok=True),
        "upper": ordered_pair("lower", False, 2, -0.01, none_ok=True),
        "stiffness": nonneg(2),
        "damping": nonneg(2),
        "force_limit": nonneg(2, infinite_ok=True),
        "friction": nonneg(2),
        "drive_mode": drive_mode(2),
        "mimic": Bound(
            inside=(
                {},
                None,
                {"panda_finger_joint1": {"joint": "panda_finger_joint2"}},
                {"panda_finger_joint2": {"joint": "panda_finger_joint1", "multiplier": -F32_MAX, "offset": F32_MAX}},
                {"panda_finger_joint2": {"joint": "panda_finger_joint1", "multiplier": 0, "offset": -2}},
            ),
            outside=(
                {"panda_finger_joint2": {"joint": "panda_finger_joint2"}},  # itself
                {"panda_finger_joint2": {"joint": "no_such_joint"}},
                {"no_such_joint": {"joint": "panda_finger_joint1"}},
                {"panda_finger_joint2": {"joint": "panda_finger_joint1", "multiplier": math.inf}},
                {"panda_finger_joint2": {"joint": "panda_finger_joint1", "offset": math.nan}},
                {"panda_finger_joint2": {"joint": "panda_finger_joint1", "multiplier": 1e39}},
                {"panda_finger_joint2": {"multiplier": 1.0}},  # no "joint"
            ),
            wrong_type=(
                [("panda_finger_joint2", "panda_finger_joint1")],
                [("panda_finger_joint2", {"joint": "panda_finger_joint1"})],  # dict() of it would be a valid map
                [],  # dict() of it would be the default map
                "panda_finger_joint1",
                {"panda_finger_joint2": "panda_finger_joint1"},
                {"panda_finger_joint2": {"joint": "panda_finger_joint1", "multiplier": "2"}},
                {"panda_finger_joint2": {"joint": "panda_finger_joint1", "offset": True}},
            ),
        ),
    },
    "PDJointPosVelControllerConfig": {
        # base: vel_lower=-1, vel_upper=1
        "vel_lower": ordered_pair("vel_upper", True, N_ARM, 1.0, none_ok=False),
        "vel_upper": ordered_pair("vel_lower", False, N_ARM, -1.0, none_ok=False),
        "binary": Bound(inside=(False,), outside=(True,), wrong_type=(1,)),  # a binary command sets no velocity
    },
    "PDJointVelControllerConfig": {
        "lower": ordered_pair("upper", True, N_ARM, 1.0, none_ok=False),
        "upper": ordered_pair("lower", False, N_ARM, -1.0, none_ok=False),
        "damping": nonneg(N_ARM),
        "force_limit": nonneg(N_ARM, infinite_ok=True),
        "friction": nonneg(N_ARM),
        "normalize_action": Bound(
            inside=(True, False, V(False, {"lower": -math.inf})),
            outside=(V(True, {"lower": -math.inf}),),
            wrong_type=(1, "True", None),
        ),
        "drive_mode": drive_mode(N_ARM),
        "actuator": Bound(
            inside=(None, V(wpctrl.DCMotor(50.0, 2.0), build=_DC)),
            outside=(wpctrl.DCMotor(50.0, 2.0), V(Make(lambda: wpctrl.ActuatorNet(_mlp().fn())), build=_DC)),
            wrong_type=("dc",),
        ),
    },
    "PDBaseVelControllerConfig": {
        "joint_names": Bound(
            inside=(["bx", "by", "yaw"], ["bx", "by", "yaw", "arm_1"]),
            outside=(["bx", "by"], ["bx", "by", "bx"], ["bx", "by", "nope"]),
            wrong_type=("bx", None),
        ),
        "lower": ordered_pair("upper", True, 3, 1.0, none_ok=False),
        "upper": ordered_pair("lower", False, 3, -1.0, none_ok=False),
        "damping": nonneg(3),
        "force_limit": nonneg(3, infinite_ok=True),
        "friction": nonneg(3),
        "drive_mode": drive_mode(3),
    },
    "PDBaseForwardVelControllerConfig": {
        "joint_names": Bound(
            inside=(["bx", "by", "yaw"],),
            outside=(["bx", "by"], ["bx", "by", "yaw", "arm_1"]),  # exactly the base's three joints
            wrong_type=("bx", None),
        ),
        # action [v, w]: bounds broadcast to 2 values, not one per joint
        "lower": Bound(
            inside=(1.0, [1.0, 1.0], [1.0]),
            outside=(up(1.0), [1.0, 1.0, 1.0], math.nan),
            wrong_type=("0.5", None),
        ),
        "upper": Bound(
            inside=(-1.0, [-1.0, -1.0], [-1.0]),
            outside=(down(-1.0), [-1.0, -1.0, -1.0], math.nan),
            wrong_type=("0.5", None),
        ),
        "damping": nonneg(3),
        "force_limit": nonneg(3, infinite_ok=True),
        "friction": nonneg(3),
        "drive_mode": drive_mode(3),
    },
    "JointEffortControllerConfig": {
        "lower": ordered_pair("upper", True, N_ARM, 10.0, none_ok=False),
        "upper": ordered_pair("lower", False, N_ARM, -10.0, none_ok=False),
        "normalize_action": Bound(
            inside=(True, False, V(False, {"lower": -math.inf})),
            outside=(V(True, {"lower": -math.inf}),),
            wrong_type=(1, "True", None),
        ),
        "force_limit": nonneg(N_ARM, infinite_ok=True),
        "friction": nonneg(N_ARM),
    },
    "PassiveControllerConfig": {
        "damping": nonneg(N_ARM),
        "force_limit": nonneg(N_ARM, infinite_ok=True),
        "friction": nonneg(N_ARM),
    },
    "PDEEPosControllerConfig": {
        "joint_names": joint_names(
            list(PANDA_ARM_JOINTS), fewer_ok=True, extra_outside=(list(PANDA_ARM_JOINTS) + ["panda_finger_joint1"],)
        ),
        # base: pos_lower=-0.1, pos_upper=0.1
        "pos_lower": Bound(
            inside=(0.1, [0.1] * 3, [0.1], V(None, {"normalize_action": False})),
            outside=(up(0.1), [0.0] * 2, [0.0] * 4, math.nan, None),
            wrong_type=("0.1",),
        ),
        "pos_upper": Bound(
            inside=(-0.1, [-0.1] * 3, V(None, {"normalize_action": False})),
            outside=(down(-0.1), [0.0] * 4, math.nan, None),
            wrong_type=("0.1",),
        ),
        "stiffness": nonneg(N_ARM),
        "damping": nonneg(N_ARM),
        "force_limit": nonneg(N_ARM, infinite_ok=True),
        "friction": nonneg(N_ARM),
        "ee_link": Bound(
            inside=("panda_hand_tcp", "panda_link7", "panda_hand"),
            outside=("", "no_such_link", "panda_link0"),
            wrong_type=(3, None),
        ),
        "urdf_path": Bound(
            # a link absent from the model is found in the URDF, as an offset from a kept ancestor body
            inside=(None, str(PANDA_URDF), PANDA_URDF, V(str(PANDA_URDF), {"ee_link": "panda_hand"})),
            outside=(V("/no/such/robot.urdf", {"ee_link": "tool0"}), V(str(PANDA_URDF), {"ee_link": "tool0"})),
            wrong_type=(3, ["a.urdf"]),
        ),
        "frame": Bound(
            inside=("root_translation", "body_translation"),
            outside=("world", "root_translation:root_aligned_body_rotation"),
            wrong_type=(3, None),
        ),
        "root_link_name": Bound(
            inside=(None, "panda_link0", V("panda_link1", {"joint_names": list(PANDA_ARM_JOINTS[1:])})),
            outside=("no_such_link", "panda_hand"),  # panda_hand is not an ancestor of the TCP
            wrong_type=(3,),
        ),
        "use_delta": BOOL,
        "use_target": BOOL,
        "interpolate": BOOL,
        "normalize_action": BOOL,
        "delta_solver_config": Bound(
            inside=(
                _DELTA,
                None,
                {},
                {"type": "pseudo_inverse"},
                _solver(solver_iterations=1),
                _solver(solver_iterations=10000),
                _solver(tolerance=1e-30, clik_dt=1e-30, clik_damping=1e-30, lm_lambda=1e-30),
                _solver(alpha=0.0),
                _solver(rotation_sign="corrected"),
                _solver(rotation_sign="maniskill"),
            ),
            outside=(
                _solver(type="gauss_newton"),
                _solver(iterations=3),  # an unknown key
                _solver(solver_iterations=0),
                _solver(solver_iterations=10001),
                _solver(tolerance=0.0),
                _solver(clik_dt=0.0),
                _solver(clik_damping=-1e-30),
                _solver(lm_lambda=0.0),
                _solver(alpha=math.inf),
                _solver(alpha=math.nan),
                _solver(rotation_sign="flipped"),
            ),
            wrong_type=(
                "levenberg_marquardt",
                [("type", "pseudo_inverse")],
                _solver(solver_iterations=2.0),
                _solver(solver_iterations=True),
                _solver(alpha="1"),
                _solver(tolerance=True),
            ),
        ),
        "drive_mode": drive_mode(N_ARM),
    },
    "PDEEPoseControllerConfig": {
        "frame": Bound(
            inside=(
                "body_translation:root_aligned_body_rotation",
                "root_translation:root_aligned_body_rotation",
                "body_translation:body_aligned_body_rotation",
                "root_translation:body_aligned_body_rotation",
            ),
            outside=("root_translation", "root_translation:world_aligned_body_rotation"),
            wrong_type=(3, None),
        ),
        # base: rot_lower=-0.1, rot_upper=0.1
        "rot_lower": Bound(
            inside=(0.1, [0.1] * 3, V(None, {"normalize_action": False})),
            outside=(up(0.1), [0.0] * 2, math.nan, None),
            wrong_type=("0.1",),
        ),
        "rot_upper": Bound(
            inside=(-0.1, [-0.1] * 3, V(None, {"normalize_action": False})),
            outside=(down(-0.1), [0.0] * 4, math.nan, None),
            wrong_type=("0.1",),
        ),
    },
    # Impedance controllers: base osc_ee_delta_pose / joint_impedance_delta_pos of the Panda (gains per unit inertia)
    "OperationalSpaceControllerConfig": {
        "joint_names": Bound(
            inside=(list(PANDA_ARM_JOINTS), tuple(PANDA_ARM_JOINTS)),
            outside=(
                list(PANDA_ARM_JOINTS) + [PANDA_ARM_JOINTS[0]],
                ["no_such_joint"] + list(PANDA_ARM_JOINTS[1:]),
                list(PANDA_ARM_JOINTS) + ["panda_finger_joint1"],  # not on the chain to the TCP
                list(PANDA_ARM_JOINTS[:6]),  # a null-space posture needs more than 6 joints
                V(list(PANDA_ARM_JOINTS[:5]), {"nullspace_control": "none"}),  # Λ of a 6-D task needs 6
            ),
            wrong_type=(PANDA_ARM_JOINTS[0], [1] * N_ARM, None),
        ),
        "pos_lower": Bound(
            inside=(0.1, [0.1] * 3, [0.1], V(None, {"normalize_action": False})),
            outside=(up(0.1), [0.0] * 2, [0.0] * 4, math.nan, None),
            wrong_type=("0.1", True),
        ),
        "pos_upper": Bound(
            inside=(-0.1, [-0.1] * 3, V(None, {"normalize_action": False})),
            outside=(down(-0.1), [0.0] * 4, math.nan, None),
            wrong_type=("0.1",),
        ),
        "rot_lower": Bound(
            inside=(0.1, [0.1] * 3, V(None, {"normalize_action": False})),
            outside=(up(0.1), [0.0] * 2, math.nan, None),
            wrong_type=("0.1",),
        ),
        "rot_upper": Bound(
            inside=(-0.1, [-0.1] * 3, V(None, {"normalize_action": False})),
            outside=(down(-0.1), [0.0] * 4, math.nan, None),
            wrong_type=("0.1",),
        ),
        "stiffness": nonneg(6),
        "damping": Bound(nonneg(6).inside + (None,), nonneg(6).outside, ("1.0", True)),
        "damping_ratio": Bound(
            inside=(0.0, 1.0, [0.5] * 6, 1e30),
            outside=(down(0.0), -1.0, math.nan, math.inf, 1e39, [1.0] * 7, F32_MAX),  # F32_MAX: the damping overflows
            wrong_type=("1.0", True, None),
        ),
        "force_limit": nonneg(N_ARM, infinite_ok=True),
        "friction": nonneg(N_ARM),
        "ee_link": Bound(
            inside=("panda_hand_tcp", "panda_link7", "panda_hand"),
            outside=("", "no_such_link", "panda_link0"),
            wrong_type=(3, None),
        ),
        "urdf_path": Bound(
            inside=(None, str(PANDA_URDF), V(str(PANDA_URDF), {"ee_link": "panda_hand"})),
            outside=(V("/no/such/robot.urdf", {"ee_link": "tool0"}), V(str(PANDA_URDF), {"ee_link": "tool0"})),
            wrong_type=(3, ["a.urdf"]),
        ),
        "frame": Bound(
            inside=(
                "body_translation:root_aligned_body_rotation",
                "root_translation:root_aligned_body_rotation",
                "body_translation:body_aligned_body_rotation",
                "root_translation:body_aligned_body_rotation",
            ),
            outside=("root_translation", "world"),
            wrong_type=(3, None),
        ),
        "root_link_name": Bound(
            inside=(
                None,
                "panda_link0",
                V("panda_link1", {"joint_names": list(PANDA_ARM_JOINTS[1:]), "nullspace_control": "none"}),
            ),
            outside=("no_such_link", "panda_hand"),
            wrong_type=(3,),
        ),
        "use_delta": BOOL,
        "use_target": BOOL,
        "normalize_action": BOOL,
        "impedance_mode": Bound(
            inside=("fixed", "variable_kp", "variable"),
            outside=("Fixed", "variable_kd", V("variable_kp", {"damping": 10.0})),  # the ratio sets the damping
            wrong_type=(3, None),
        ),
        "stiffness_limits": Bound(
            inside=((0.0, 1000.0), (0.0, 0.0), [0, F32_MAX], V((5.0, 5.0), {"impedance_mode": "variable"})),
            outside=((1.0, down(1.0)), (down(0.0), 1.0), (0.0, math.inf), (math.nan, 1.0)),
            wrong_type=("0,1", None, (0.0,), (True, 1.0), ("0", "1")),
        ),
        "damping_ratio_limits": Bound(
            inside=((0.0, 2.0), (1.0, 1.0)),
            outside=((1.0, down(1.0)), (-1.0, 1.0), (0.0, math.inf)),
            wrong_type=(None, (0.5,), (0.5, False)),
        ),
        "inertial_dynamics_decoupling": BOOL,
        "partial_inertial_dynamics_decoupling": Bound(
            inside=(True, False),
            outside=(V(True, {"inertial_dynamics_decoupling": False}),),  # partial decoupling needs decoupling
            wrong_type=(1, "True", None),
        ),
        "gravity_compensation": BOOL,
        "nullspace_control": Bound(
            inside=("none", "position"),
            outside=("velocity", V("position", {"joint_names": list(PANDA_ARM_JOINTS[:6])})),
            wrong_type=(3, None, True),
        ),
        "nullspace_stiffness": nonneg(N_ARM),
        "nullspace_damping": Bound(nonneg(N_ARM).inside + (None,), nonneg(N_ARM).outside, ("1.0", True)),
        "nullspace_damping_ratio": Bound(
            inside=(0.0, 1.0, [0.5] * N_ARM, 1e30),
            outside=(down(0.0), math.nan, math.inf, [1.0] * (N_ARM + 1), F32_MAX),  # F32_MAX: the damping overflows
            wrong_type=("1.0", True, None),
        ),
        "nullspace_target": Bound(
            inside=(None, [0.0] * N_ARM, 0.5, [1.0]),
            outside=([0.0] * (N_ARM + 1), [[0.0] * N_ARM], math.nan, math.inf),
            wrong_type=("0", True, [None] * N_ARM),
        ),
        "singularity_damping": Bound(
            inside=(0.0, 1e-3, down(1.0)),
            outside=(1.0, down(0.0), math.nan, math.inf),
            wrong_type=("0.001", True, None),
        ),
    },
    "JointImpedanceControllerConfig": {
        "lower": ordered_pair("upper", True, N_ARM, 0.1, none_ok=True),
        "upper": ordered_pair("lower", False, N_ARM, -0.1, none_ok=True),
        "stiffness": nonneg(N_ARM),
        "damping": Bound(nonneg(N_ARM).inside + (None,), nonneg(N_ARM).outside, ("1.0", True)),
        "damping_ratio": Bound(
            inside=(0.0, 1.0, [0.5] * N_ARM, 1e30),
            outside=(down(0.0), math.nan, math.inf, [1.0] * (N_ARM + 1), F32_MAX),
            wrong_type=("1.0", True, None),
        ),
        "force_limit": nonneg(N_ARM, infinite_ok=True),
        "friction": nonneg(N_ARM),
        "use_delta": BOOL,
        "use_target": BOOL,
        "normalize_action": Bound(
            inside=(True, False, V(False, {"lower": -math.inf})),
            outside=(V(True, {"lower": -math.inf}),),
            wrong_type=(1, "True", None),
        ),
        "impedance_mode": Bound(
            inside=("fixed", "variable_kp", "variable"),
            outside=("variable_kd", V("variable", {"damping": 10.0})),
            wrong_type=(3, None),
        ),
        "stiffness_limits": Bound(inside=((0.0, 1000.0),), outside=((2.0, 1.0),), wrong_type=(None, "01")),
        "damping_ratio_limits": Bound(inside=((0.0, 2.0),), outside=((2.0, 1.0),), wrong_type=(None, 1.0)),
        "inertial_compensation": BOOL,
        "gravity_compensation": BOOL,
    },
    # Actuator models (on the arm of a PDJointPos config, explicit actuation).
    "DCMotor": {
        # base: DCMotor(50.0, 2.0); the kernels read float32 (1e39 is inf there, 1e-46 is 0)
        "saturation_effort": Bound(
            inside=(0.0, [0.0] * N_ARM, F32_MAX, [50.0] * (N_ARM - 1) + [F32_MAX], 1e-46),
            outside=(
                down(0.0),
                math.inf,
                math.nan,
                [1.0] * (N_ARM + 1),
                V(1e39, label="inf in float32"),
                V([50.0] * (N_ARM - 1) + [down(0.0)], label="one joint below 0"),
                V([50.0] * (N_ARM - 1) + [1e39], label="one joint inf in float32"),
            ),
            wrong_type=("1.0", None, True),
        ),
        "velocity_limit": Bound(
            inside=(1e-6, [1e-6] * N_ARM, F32_MAX, up(0.0)),
            outside=(
                0.0,
                -0.0,
                -1.0,
                math.inf,
                math.nan,
                [1.0] * 2,
                V(1e39, label="inf in float32"),
                V(1e-46, label="0 in float32"),
                V([2.0] * (N_ARM - 1) + [0.0], label="one joint at 0"),
            ),
            wrong_type=("1.0", None, True),
        ),
    },
    "PositionBasedEffortLimit": {
        # base: positions [0, 1], efforts [1, 2]
        "positions": Bound(
            inside=([1.0, 1.0], [-math.pi, math.pi], V(list(np.linspace(-3, 3, 64)), {"efforts": [1.0] * 64})),
            outside=(
                [1.0, down(1.0)],
                [0.0],  # one entry, two efforts
                [0.0, math.nan],
                [0.0, math.inf],
                V(list(np.linspace(-3, 3, 65)), {"efforts": [1.0] * 65}),
                V([], {"efforts": []}),
                V([-1e39, 0.0], label="-inf in float32"),
                V([0.0, 1e39], label="inf in float32"),
            ),
            wrong_type=(["a", "b"], None, [[0.0, 1.0], [2.0]]),
        ),
        "efforts": Bound(
            inside=([0.0, 0.0], [F32_MAX, 0.0], [1e-46, 1.0]),
            outside=(
                [down(0.0), 1.0],
                [1.0, 2.0, 3.0],
                [1.0, math.inf],
                [1.0, math.nan],
                V([1.0, 1e39], label="inf in float32"),
            ),
            wrong_type=(["a", "b"], None),
        ),
    },
    "ActuatorNet": {
        # base: an MLP of 2 x 3 inputs, input_idx (0, 1, 2)
        "network": Bound(
            inside=(V(_mlp(), label="mlp"), V(TORCHSCRIPT, label="torchscript"), V(LSTM, label="lstm")),
            outside=(
                V(_mlp(4), label="4 inputs"),
                V(_mlp(6, 2), label="2 outputs"),
                V("/no/such/net.pt", label="missing file"),
                V(Make(lambda: torch.nn.Sequential(torch.nn.Tanh(), torch.nn.Linear(6, 1))), label="activation first"),
                V(Make(lambda: torch.nn.Sequential(torch.nn.Conv1d(1, 1, 1))), label="a conv layer"),
                V(Make(lambda: torch.nn.Sequential(torch.nn.Linear(6, 4), torch.nn.Linear(5, 1))), label="no chain"),
                V(Make(lambda: torch.nn.Sequential(torch.nn.Tanh())), label="no linear layer"),
                V(Make(lambda: _lstm_net(input_size=3)), label="lstm of 3 inputs"),
                V(Make(lambda: _lstm_net(bias=False)), label="lstm without biases"),
                V(Make(lambda: _lstm_net(proj_size=2)), label="projected lstm"),
                V(Make(lambda: _lstm_net(head_first=True)), label="lstm after a linear layer"),
            ),
            wrong_type=(3, None),
        ),
        "input_idx": Bound(
            inside=((0, 1, 63), [5, 5, 0], (np.int64(2), 0, 1)),
            outside=((0, 1, 64), (0, 1, -1), (), (0, 1)),  # (0, 1): 4 inputs for a 6-input network
            wrong_type=((0, 1, True), (0, 1, 2.0), ("0", 1, 2)),
        ),
        # the scales are float32 in the kernels: up to +-F32_MAX, 1e39 would be inf
        "pos_scale": Bound(
            inside=(0.0, -2.5, 1e30, 3, F32_MAX, -F32_MAX),
            outside=(math.inf, math.nan, 1e39, -1e39),
            wrong_type=(True, "1", None),
        ),
        "vel_scale": Bound(
            inside=(0.0, -2.5, 1e30, 3, F32_MAX),
            outside=(math.inf, math.nan, 1e39, -1e39),
            wrong_type=(True, "1", None),
        ),
        "torque_scale": Bound(
            inside=(0.0, -2.5, 1e30, 3, -F32_MAX),
            outside=(-math.inf, math.nan, 1e39, -1e39),
            wrong_type=(True, "1"),
        ),
        "input_order": Bound(inside=("pos_vel", "vel_pos"), outside=("pos", "velpos"), wrong_type=(1, None)),
        "saturation_effort": Bound(
            # 1e39: inf in float32, as the (default) speed: no envelope
            inside=(math.inf, 0.0, V(5.0, {"velocity_limit": 2.0}), [math.inf] * N_ARM, 1e39),
            outside=(
                down(0.0),
                math.nan,
                V(math.inf, {"velocity_limit": 2.0}),  # inf stall effort at finite speed
                V(1e39, {"velocity_limit": 2.0}, label="inf in float32 at finite speed"),
            ),
            wrong_type=("1.0", None),
        ),
        "velocity_limit": Bound(
            inside=(math.inf, V(1e-6, {"saturation_effort": 5.0}), V(1e39, {"saturation_effort": 5.0})),
            outside=(
                V(0.0, {"saturation_effort": 5.0}),
                -1.0,
                math.nan,
                V(1e-46, {"saturation_effort": 5.0}, label="0 in float32"),
                V(2.0, label="finite speed, inf stall effort"),
            ),
            wrong_type=("1.0", None),
        ),
        "kind": Bound(
            inside=("auto", "mlp", V("lstm", {"network": LSTM})),
            outside=("lstm", "gru"),
            wrong_type=(3, None),
        ),
        "kernel": Bound(
            inside=("auto", "unrolled", "3xtf32", "tiled"),
            outside=("fast", "Tiled", "split", "split2", "split4"),
            wrong_type=(3, None),
        ),
        "launch": Bound(
            inside=("auto", "fused", "separate", V("auto", {"kernel": "tiled"}, label="auto, tiled: separate")),
            outside=(
                "one",
                "Fused",
                V("fused", {"kernel": "tiled"}, label="fused with the tiled kernel"),
                V("fused", {"kernel": "3xtf32"}, label="fused with the tensor-core kernel"),
            ),
            wrong_type=(1, None),
        ),
    },
    # The option groups, passed to build_controller with the base arm config (a position controller, force drives).
    "Actuation": {
        # base: Actuation() (implicit)
        "mode": Bound(inside=("implicit", "explicit"), outside=("Implicit", "physx"), wrong_type=(1, None)),
        "explicit_pd": Bound(
            inside=(None, V("naive", {"mode": "explicit"}), V("coupled", {"mode": "explicit"})),
            outside=(V("stable", label="with implicit"), V("fast", {"mode": "explicit"})),
            wrong_type=(V(1, {"mode": "explicit"}),),
        ),
        "inertia_update": Bound(
            inside=(
                None,
                V("substep", {"mode": "explicit", "explicit_pd": "stable"}),
                V("control", {"mode": "explicit", "explicit_pd": "stable"}),
                V("control", {"mode": "explicit", "explicit_pd": "coupled"}),
            ),
            outside=(
                V("control", label="no inertia computed"),
                V("often", {"mode": "explicit", "explicit_pd": "stable"}),
            ),
            wrong_type=(V(2, {"mode": "explicit", "explicit_pd": "stable"}),),
        ),
    },
    "Delay": {
        # base: Delay(2)
        # substeps: 0 <= min <= max <= 1024, each edge of a fixed delay and of a range
        "substeps": Bound(
            inside=(0, 1024, (0, 1024), np.int64(3), (3, 3), (1024, 1024), (1023, 1024), (0, 0), [0, 2]),
            outside=(
                -1,
                1025,
                (3, 1),
                (0, 1, 2),
                V((0, 1025), label="max past the bound"),
                V((-1, 2), label="min below 0"),
                V((-1, -1), label="a range of -1"),
                V((4, 3), label="max one below min"),
                V((1025, 1025), label="a range of 1025"),
                V((1025, 1024), label="min past the bound"),
                V((0, 2**40), label="max far past the bound"),
                V((), label="no value"),
                V((2,), label="one value"),
            ),
            wrong_type=(1.5, "1", True, None, (1.0, 2), (0, True), (0, None), "12", {0: 1, 1: 2}),
        ),
        "seed": Bound(
            inside=(
                None,
                V(2**31 - 1, {"substeps": (0, 2)}),
                V(-(2**31), {"substeps": (0, 2)}),
                V(np.int64(7), {"substeps": (3, 4)}),
            ),
            outside=(
                V(2**31, {"substeps": (0, 2)}),
                V(-(2**31) - 1, {"substeps": (0, 2)}),
                V(3, label="fixed delay"),
                V(3, {"substeps": (2, 2)}, label="a range of one value"),
            ),
            wrong_type=(V("a", {"substeps": (0, 2)}), V(True, {"substeps": (0, 2)}), V(1.5, {"substeps": (0, 2)})),
        ),
    },
    "Diagnostics": {
        "track_effort": Bound(inside=(True, False, np.bool_(True)), wrong_type=(1, "True", None, 0.0)),
        "nan_policy": Bound(inside=("hold", "raise"), outside=("ignore",), wrong_type=(1, None)),
        "clip_targets": Bound(inside=("none", "joint_limits"), outside=("limits",), wrong_type=(True, None)),
    },
}


def config_classes() -> list[type]:
    """Every dataclass the package exports (the config layer's public surface)."""
    out = []
    for name in wpctrl.__all__:
        obj = getattr(wpctrl, name)
        if isinstance(obj, type) and dataclasses.is_dataclass(obj):
            out.append(obj)
    return out


def bound_for(cls: type, name: str) -> Bound | None:
    for klass in cls.__mro__:
        entry = BOUNDS.get(klass.__name__, {}).get(name)
        if entry is not None:
            return entry
    return None


def _cases():
    for cls in config_classes():
        for f in dataclasses.fields(cls):
            b = bound_for(cls, f.name)
            if b is None:
                continue
            for kind in ("inside", "outside", "wrong_type"):
                for i, v in enumerate(getattr(b, kind)):
                    label = v.label if isinstance(v, V) and v.label else str(i)
                    yield pytest.param(cls, f.name, kind, v, id=f"{cls.__name__}.{f.name}-{kind}-{label}")


# Valid configs to start from, and the models they bind to ---------------------------------------------------------


@pytest.fixture(scope="module")
def models():
    import newton
    import warp as wp

    panda = build_panda(1)
    b = newton.ModelBuilder()
    inertia = wp.mat33(np.eye(3) * 0.05)
    bx, by, base, arm = (b.add_link(mass=2.0, inertia=inertia) for _ in range(4))
    joints = [
        b.add_joint_prismatic(-1, bx, axis=(1, 0, 0), label="bx"),
        b.add_joint_prismatic(bx, by, axis=(0, 1, 0), label="by"),
        b.add_joint_revolute(by, base, axis=(0, 0, 1), label="yaw"),
        b.add_joint_revolute(base, arm, axis=(0, 1, 0), limit_lower=-1.0, limit_upper=1.0, label="arm_1"),
    ]
    b.add_articulation(joints)
    mobile = newton.ModelBuilder()
    mobile.replicate(b, 1)
    return {"panda": panda, "mobile": mobile.finalize(device="cpu")}


@pytest.fixture(scope="module")
def torchscript(tmp_path_factory):
    path = tmp_path_factory.mktemp("net") / "mlp.pt"
    torch.jit.script(_mlp().fn()).save(str(path))
    return str(path)


def _arm_pos(**kw):
    d = dict(joint_names=list(PANDA_ARM_JOINTS), lower=-0.5, upper=0.5, stiffness=100.0, damping=10.0)
    return wpctrl.PDJointPosControllerConfig(**dict(d, **kw))


BASES = {
    # class name -> (model, a valid config) ; actuator dataclasses go on _arm_pos(actuator=...) with explicit actuation
    "PDJointPosControllerConfig": ("panda", lambda: _arm_pos()),
    "PDJointPosMimicControllerConfig": (
        "panda",
        lambda: wpctrl.PDJointPosMimicControllerConfig(
            list(PANDA_GRIPPER_JOINTS),
            -0.01,
            0.04,
            100.0,
            10.0,
            mimic={"panda_finger_joint2": {"joint": "panda_finger_joint1"}},
        ),
    ),
    "PDJointPosVelControllerConfig": (
        "panda",
        lambda: wpctrl.PDJointPosVelControllerConfig(list(PANDA_ARM_JOINTS), -0.5, 0.5, 100.0, 10.0),
    ),
    "PDJointVelControllerConfig": (
        "panda",
        lambda: wpctrl.PDJointVelControllerConfig(list(PANDA_ARM_JOINTS), -1.0, 1.0, 10.0),
    ),
    "PDBaseVelControllerConfig": (
        "mobile",
        lambda: wpctrl.PDBaseVelControllerConfig(["bx", "by", "yaw"], -1.0, 1.0, 10.0),
    ),
    "PDBaseForwardVelControllerConfig": (
        "mobile",
        lambda: wpctrl.PDBaseForwardVelControllerConfig(["bx", "by", "yaw"], -1.0, 1.0, 10.0),
    ),
    "JointEffortControllerConfig": (
        "panda",
        lambda: wpctrl.JointEffortControllerConfig(list(PANDA_ARM_JOINTS), -10.0, 10.0),
    ),
    "PassiveControllerConfig": ("panda", lambda: wpctrl.PassiveControllerConfig(list(PANDA_ARM_JOINTS), 10.0)),
    "PDEEPosControllerConfig": ("panda", lambda: _copy_mode("pd_ee_delta_pos")),
    "PDEEPoseControllerConfig": ("panda", lambda: _copy_mode("pd_ee_delta_pose")),
    "OperationalSpaceControllerConfig": ("panda", lambda: _copy_mode("osc_ee_delta_pose")),
    "JointImpedanceControllerConfig": ("panda", lambda: _copy_mode("joint_impedance_delta_pos")),
    "DCMotor": ("panda", lambda: wpctrl.DCMotor(50.0, 2.0)),
    "PositionBasedEffortLimit": ("panda", lambda: wpctrl.PositionBasedEffortLimit([0.0, 1.0], [1.0, 2.0])),
    "ActuatorNet": ("panda", lambda: wpctrl.ActuatorNet(_mlp().fn())),
    "Actuation": ("panda", lambda: wpctrl.Actuation()),
    "Delay": ("panda", lambda: wpctrl.Delay(2)),
    "Diagnostics": ("panda", lambda: wpctrl.Diagnostics()),
}
ACTUATORS = ("DCMotor", "PositionBasedEffortLimit", "ActuatorNet")
OPTION_GROUPS = {"Actuation": "actuation", "Delay": "delay", "Diagnostics": "diagnostics"}  # build_controller keyword


def _copy_mode(name):
    import copy

    return copy.deepcopy(panda_control_modes()[name]["arm"])


def _resolve(value, torchscript):
    return value(torchscript) if isinstance(value, Make) else value


def _build(cls, name, v, models, torchscript):
    spec = v if isinstance(v, V) else V(v)
    key = cls.__name__ if cls.__name__ in BASES else "PDJointPosControllerConfig"  # ControllerConfig: a position one
    model_key, make = BASES[key]
    base = make()
    updates = {k: _resolve(x, torchscript) for k, x in spec.fields.items()}
    updates[name] = _resolve(spec.value, torchscript)
    build = dict(spec.build)
    if key in ACTUATORS:
        actuator = dataclasses.replace(base, **updates)
        config = _arm_pos(actuator=actuator)
        build.setdefault("actuation", "explicit")
    elif key in OPTION_GROUPS:  # an option group: made (it checks itself), then checked against the arm's rows
        build[OPTION_GROUPS[key]] = dataclasses.replace(base, **updates)
        config = _arm_pos()
    else:
        config = dataclasses.replace(base, **updates)
    return wpctrl.build_controller(config, models[model_key], **build)


@pytest.mark.filterwarnings("ignore")
@pytest.mark.parametrize("cls, name, kind, value", list(_cases()))
def test_field_boundary(cls, name, kind, value, models, torchscript):
    if kind == "inside":
        ctrl = _build(cls, name, value, models, torchscript)
        assert ctrl.num_envs == 1
        return
    with pytest.raises(wpctrl.ConfigError) as info:
        _build(cls, name, value, models, torchscript)
    # the message names the field (a mimic entry names its joint; the binding names the joint it did not find)
    msg = str(info.value)
    assert name in msg or (name == "joint_names" and "joint" in msg), msg


def test_every_config_field_declares_its_boundary():
    """A field of an exported config dataclass without a boundary in BOUNDS fails here: declare what is accepted just
    inside its range, what is refused just outside, and which wrong types are refused."""
    missing = []
    weak = []
    for cls in config_classes():
        for f in dataclasses.fields(cls):
            b = bound_for(cls, f.name)
            if b is None:
                missing.append(f"{cls.__name__}.{f.name}")
            elif not b.inside or not (b.outside or b.wrong_type):
                weak.append(f"{cls.__name__}.{f.name}")
    assert not missing, f"config fields without a boundary spec in tests/test_config_boundaries.py: {missing}"
    assert not weak, f"boundary specs that refuse nothing or accept nothing: {weak}"
    # the generator sees every config the package exports (a guard against a narrowed search)
    names = {c.__name__ for c in config_classes()}
    assert {"PDJointPosControllerConfig", "PDEEPoseControllerConfig", "DCMotor", "ActuatorNet"} <= names
    assert set(BOUNDS) - {"ControllerConfig"} <= names, "BOUNDS names a class the package no longer exports"


# -- Delay: each edge of its range, named in the message, and a delay of the maximum at work -------------------------

_MOST = r"delay\.substeps: expected at most 1024 substeps \(the history holds max \+ 1 targets\), got 1025"
_ORDER = r"delay\.substeps: expected 0 <= min_substeps <= max_substeps, got \({}\)"
_FIXED_SEED = r"delay\.seed: expected None for a fixed delay of 3 substeps \(nothing is drawn\), got 1"

DELAY_REFUSED = [
    # (substeps, seed, the message: the field, what is expected, what was given)
    pytest.param((0, 1025), None, _MOST, id="max past the bound"),
    pytest.param(1025, None, _MOST, id="fixed past the bound"),
    pytest.param((1025, 1025), None, _MOST, id="range of one value past the bound"),
    pytest.param((-1, 2), None, _ORDER.format("-1, 2"), id="min below 0"),
    pytest.param(-1, None, _ORDER.format("-1, -1"), id="fixed below 0"),
    pytest.param((4, 3), None, _ORDER.format("4, 3"), id="max one below min"),
    pytest.param((1025, 1024), None, _ORDER.format("1025, 1024"), id="min past the bound, above max"),
    pytest.param((3, 3), 1, _FIXED_SEED, id="seed for a range of one value"),
    pytest.param(3, 1, _FIXED_SEED, id="seed for a fixed delay"),
    pytest.param((0, 2), 2**31, r"delay\.seed: expected an int32, got 2147483648", id="seed past int32"),
    pytest.param((0, 2), -(2**31) - 1, r"delay\.seed: expected an int32, got -2147483649", id="seed below int32"),
]


@pytest.mark.parametrize(("substeps", "seed", "message"), DELAY_REFUSED)
def test_delay_refuses_each_edge_naming_expected_and_received(substeps, seed, message, models):
    """Just outside each edge of ``Delay`` (0 <= min <= max <= 1024, a seed only for a range that draws, int32): the
    error names the field, the rule and the value given, for the object and for build_controller's keywords."""
    with pytest.raises(wpctrl.ConfigError, match=message):
        wpctrl.Delay(substeps, seed)
    with pytest.raises(wpctrl.ConfigError, match=message):
        wpctrl.build_controller(_arm_pos(), models["panda"], delay=substeps, delay_seed=seed)


DELAY_ACCEPTED = [
    # (substeps, seed, its (min, max))
    pytest.param(0, None, (0, 0), id="fixed 0"),
    pytest.param(1024, None, (1024, 1024), id="fixed at the bound"),
    pytest.param((1024, 1024), None, (1024, 1024), id="range of one value at the bound"),
    pytest.param((0, 1024), -(2**31), (0, 1024), id="the widest range, the lowest seed"),
    pytest.param((1023, 1024), 2**31 - 1, (1023, 1024), id="the highest range, the highest seed"),
    pytest.param((3, 3), None, (3, 3), id="range of one value"),
]


@pytest.mark.parametrize(("substeps", "seed", "want"), DELAY_ACCEPTED)
def test_delay_accepts_each_edge_and_runs_its_range(substeps, seed, want, models):
    """Just inside each edge: the Delay reports its range, the controller keeps it, each env's drawn delay lies in it,
    and ``ctrl.delay`` takes the range's max (and refuses max + 1 and -1, naming them)."""
    d = wpctrl.Delay(substeps, seed)
    assert d.range == (d.min, d.max) == want and d.drawn == (want[1] > want[0])
    ctrl = wpctrl.build_controller(_arm_pos(), build_panda(4), delay=substeps, delay_seed=seed)
    assert ctrl.options.delay.range == want
    drawn = ctrl.delay.numpy()
    assert ((drawn >= want[0]) & (drawn <= want[1])).all(), drawn
    ctrl.delay = np.full(4, want[1], np.int32)
    np.testing.assert_array_equal(ctrl.delay.numpy(), want[1])
    for bad in (want[1] + 1, -1):
        with pytest.raises(wpctrl.ConfigError, match=rf"delay: expected 4 ints in \[0, {want[1]}\] .*got"):
            ctrl.delay = np.full(4, bad, np.int32)
    np.testing.assert_array_equal(ctrl.delay.numpy(), want[1])  # a refused value changes nothing


def test_a_delay_of_1024_substeps_holds_the_reset_pose_for_exactly_that_many():
    """The longest delay at work, per env: with a history of 1024 + 1 targets, env 0 delayed 1023 substeps and env 1
    1024, the drive targets (implicit: ``Control.joint_target_q``) stay at each env's reset pose until substep 1023
    (env 0) / 1024 (env 1) and are the commanded targets from the next substep on."""
    model = build_panda(2)
    cfg = wpctrl.PDJointPosControllerConfig(list(PANDA_ARM_JOINTS), None, None, 100.0, 10.0, normalize_action=False)
    ctrl = wpctrl.build_controller(cfg, model, 100, 100, delay=(0, 1024), delay_seed=3)
    rng = np.random.default_rng(0)
    s, c = model.state(), model.control()
    q0 = rng.uniform(-1.0, 1.0, (2, N_ARM)).astype(np.float32)
    put(s, model, PANDA_ARM_JOINTS, q0)
    ctrl.reset(s, control=c)
    ctrl.delay = np.array([1023, 1024], np.int32)
    target = rng.uniform(-1.0, 1.0, (2, N_ARM)).astype(np.float32)
    ctrl.set_action(target, s)
    coord, _ = indices(model, PANDA_ARM_JOINTS)
    seen = {}
    for k in range(1, 1026):
        ctrl.before_simulation_step(s, c)
        if k in (1, 1023, 1024, 1025):
            seen[k] = c.joint_target_q.numpy()[coord]
    np.testing.assert_array_equal(seen[1], q0)
    np.testing.assert_array_equal(seen[1023], q0)
    np.testing.assert_array_equal(seen[1024], np.stack([target[0], q0[1]]))
    np.testing.assert_array_equal(seen[1025], target)
