"""Property tests: wpctrl against the independent numpy reference (``reference_np.py``, ``reference_ee.py``), operation
by operation (``property_harness.py`` says what is compared after each one and how the reference's inputs are checked).

Hypothesis draws the build and then every operation of the stream itself (``st.data()``), so a failure shrinks to a
short stream of simple operations:

- ``test_matches_reference``: a random control mode (1-3 children on disjoint subsets of the Panda's 9 joints, every
  joint config type and flag, scalar or per-joint parameters, mimic maps, force/acceleration drive modes, and on any
  child an actuator model (DC motor, position table; kept with the explicit naive / stable law), EMA smoothing or a
  binary command), the model layout (replicated worlds with 1, 3 or 5 envs, 3 worlds that differ: per-env index
  tables, 3 envs spaced apart, 3 Pandas on floating bases: coordinate and DOF strides differ), a substep count, the
  actuation (implicit; explicit with the naive, stable or coupled PD law), when r = (H^-1)_ii is refreshed, a NaN
  policy, and the actuation options (command delay, effort readout, target clamping, the RNG seed).
- ``test_panda_modes_match_reference``: ManiSkill's Panda modes, the end-effector ones included, on the same layouts,
  actuations and options (few modes: a mode compiles its kernels once, the cost of the random-mode test).
- ``test_mimic_matches_reference``: mimic maps with several control joints.

Operations: measured states written into the Newton state (also between substeps), actions (in range, out of range,
NaN/Inf entries; numpy / torch / wp, float32 / float64, strided, 1-D with one env), steps with and without an action
and past K substeps, resets (ids, masks, torch / wp selections; with or without the Control), ``set_drive_properties``
and ``randomize_drive_properties`` on a child and an env selection (a DC motor's per-env stall effort and no-load
speed included), and ``set_state``.

Cost: the random-mode test compiles the two step kernels of each mode it draws (about 0.2 s each on the CPU; Warp's
kernel cache keeps them for later runs); ``WPCTRL_PROPERTY_EXAMPLES`` sets the examples of the random-mode test (the
others take a fifth), default 250.
"""

from __future__ import annotations

import copy
import dataclasses
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from property_harness import Harness, model_for, run_stream

import wpctrl
from wpctrl import config as C
from wpctrl.robots import PANDA_JOINTS, panda_control_modes

torch = pytest.importorskip("torch", reason="torch is a dev dependency (torch inputs are drawn here)")

MAX_EXAMPLES = int(os.environ.get("WPCTRL_PROPERTY_EXAMPLES", "250"))  # raise it for a deeper search
LAYOUTS = [("replicated", 1), ("replicated", 3), ("replicated", 5), ("flat", 3), ("spaced", 3), ("floating", 3)]

# ----------------------------------------------------------------------------------------------------------------------
# Config strategies.

floats = st.floats


@st.composite
def per_joint(draw, n: int, elems, scalar_only: bool = False):
    """A scalar, a one-element list or a list of n values."""
    kind = draw(st.sampled_from(["scalar"] if scalar_only else ["scalar", "scalar", "list", "list1"]))
    if kind == "scalar":
        return draw(elems)
    if kind == "list1":
        return [draw(elems)]
    return [draw(elems) for _ in range(n)]


@st.composite
def bounds(draw, limits: np.ndarray):
    """(lower, upper) with lower <= upper per joint once None is replaced by the joint limit."""
    n = limits.shape[0]
    width = floats(0.0, 2.0)
    kind = draw(st.sampled_from(["none", "scalar", "list", "low_none", "high_none"]))
    if kind == "none":
        return None, None
    if kind == "scalar":
        lo = draw(floats(-2.0, 1.0))
        return lo, lo + draw(width)
    if kind == "list":
        lo = [draw(floats(-2.0, 1.0)) for _ in range(n)]
        return lo, [x + draw(width) for x in lo]
    if kind == "low_none":  # lower from the joint limits, a scalar upper above all of them
        return None, float(limits[:, 0].max()) + draw(width)
    return float(limits[:, 1].min()) - draw(width), None


gain = st.one_of(st.just(0.0), floats(1e-3, 1e4))
damp = st.one_of(st.just(0.0), floats(1e-3, 1e3))
flim = st.one_of(st.just(1e10), floats(0.1, 1e4))
fric = st.one_of(st.just(0.0), floats(0.0, 1.0))
vel_bound = floats(-3.0, 3.0)


@st.composite
def mimic_map(draw, names: list[str]):
    """A valid mimic map (no chains): followers mimic control joints directly; some joints may be neither."""
    n = len(names)
    if n == 2 and draw(st.booleans()):
        return {}  # ManiSkill's default: the second joint commands the first
    order = draw(st.permutations(names))
    n_ctrl = draw(st.integers(1, n // 2))
    ctrl, rest = order[:n_ctrl], order[n_ctrl:]
    n_follow = draw(st.integers(n_ctrl, len(rest)))  # every control joint gets a follower; the rest are neither
    # Dict order of the control joints against joint_names order (the action follows joint_names order).
    ctrl = sorted(ctrl, key=names.index, reverse=draw(st.booleans()))
    out = {}
    for i, f in enumerate(rest[:n_follow]):
        # The first followers take distinct control joints (so several action columns exist), later ones any.
        e = {"joint": ctrl[i] if i < len(ctrl) else draw(st.sampled_from(ctrl))}
        if draw(st.booleans()):
            e["multiplier"] = draw(floats(-2.0, 2.0))
        if draw(st.booleans()):
            e["offset"] = draw(floats(-0.05, 0.05))
        out[f] = e
    return out


@st.composite
def drive_modes(draw, n: int):
    """Mostly "force"; also "acceleration" and per-joint mixes."""
    kind = draw(st.sampled_from(["force", "force", "force_list", "acceleration", "mixed"]))
    if kind == "force_list":
        return ["force"] * n
    if kind == "mixed":
        return [draw(st.sampled_from(["force", "acceleration"])) for _ in range(n)]
    return kind


@st.composite
def actuator(draw, n: int):
    """Mostly none; a DC motor (per-joint or scalar parameters) or a position table (steps and ends included)."""
    kind = draw(st.sampled_from([None, None, None, "dc", "table"]))
    if kind == "dc":
        return C.DCMotor(draw(per_joint(n, floats(0.0, 200.0))), draw(per_joint(n, floats(0.1, 10.0))))
    if kind == "table":
        xs = sorted(draw(st.lists(floats(-3.0, 3.0), min_size=1, max_size=6)))
        if len(xs) > 1 and draw(st.booleans()):
            xs[1] = xs[0]  # a step
        ys = [draw(floats(0.0, 100.0)) for _ in xs]
        return C.PositionBasedEffortLimit(xs, ys)
    return None


@st.composite
def child_config(draw, names: list[str], limits: np.ndarray, kind: str | None = None):
    n = len(names)
    kinds = ["pos", "pos", "vel", "posvel", "passive"] + (["mimic", "mimic"] if n >= 2 else [])
    kind = kind or draw(st.sampled_from(kinds))
    pj = lambda elems: draw(per_joint(n, elems))  # noqa: E731
    if kind == "passive":
        return C.PassiveControllerConfig(names, damping=pj(damp), force_limit=pj(flim), friction=pj(fric))
    normalize = draw(st.booleans())
    if kind == "vel":
        lo = draw(per_joint(n, vel_bound))
        hi = np.asarray(lo, np.float64) + draw(floats(0.0, 2.0))
        hi = float(hi) if np.ndim(lo) == 0 else hi.tolist()
        return C.PDJointVelControllerConfig(
            names,
            lower=lo,
            upper=hi,
            damping=pj(damp),
            force_limit=pj(flim),
            friction=pj(fric),
            normalize_action=normalize,
            drive_mode=draw(drive_modes(n)),
            actuator=draw(actuator(n)),
        )
    delta = draw(st.booleans())
    lower, upper = draw(bounds(limits))
    common = dict(
        lower=lower,
        upper=upper,
        stiffness=pj(gain),
        damping=pj(damp),
        force_limit=pj(flim),
        friction=pj(fric),
        use_delta=delta,
        use_target=draw(st.booleans()),
        interpolate=draw(st.booleans()),
        normalize_action=normalize,
        drive_mode=draw(drive_modes(n)),
        actuator=draw(actuator(n)),
        ema=draw(st.one_of(st.none(), st.none(), st.just(1.0), floats(0.05, 1.0))),
    )
    if kind in ("pos", "mimic") and not delta and draw(st.integers(0, 3)) == 0:
        common["binary"] = True  # absolute targets only
    if kind == "pos":
        return C.PDJointPosControllerConfig(names, **common)
    if kind == "mimic":
        return C.PDJointPosMimicControllerConfig(names, **common, mimic=draw(mimic_map(names)))
    vl = draw(per_joint(n, vel_bound))
    vh = np.asarray(vl, np.float64) + draw(floats(0.0, 2.0))
    vh = float(vh) if np.ndim(vl) == 0 else vh.tolist()
    return C.PDJointPosVelControllerConfig(names, **common, vel_lower=vl, vel_upper=vh)


@st.composite
def control_mode(draw, limits_by_name: dict):
    """A single config or a dict of 1-3 children on disjoint joint subsets."""
    joints = draw(st.permutations(PANDA_JOINTS))
    n_children = draw(st.integers(1, 3))
    total = draw(st.integers(n_children, 9))
    cuts = []
    if n_children > 1:
        cuts = sorted(draw(st.sets(st.integers(1, total - 1), min_size=n_children - 1, max_size=n_children - 1)))
    parts = [joints[a:b] for a, b in zip([0] + cuts, cuts + [total])]
    children = {}
    for i, names in enumerate(parts):
        lim = np.array([limits_by_name[s] for s in names], np.float32)
        children[f"c{i}"] = draw(child_config(list(names), lim))
    if n_children == 1 and draw(st.booleans()):
        return children["c0"]
    return children


@st.composite
def big_mimic(draw, limits_by_name: dict):
    """One mimic config over 4-9 joints (several control joints, dict order against joint_names order)."""
    names = list(draw(st.permutations(PANDA_JOINTS)))[: draw(st.integers(4, 9))]
    lim = np.array([limits_by_name[s] for s in names], np.float32)
    return draw(child_config(names, lim, kind="mimic"))


@st.composite
def actuation_options(draw):
    """Issue 10's build options: mostly off (the default path stays covered), each on in a good share of examples."""
    opts = {}
    d = draw(st.sampled_from([None, None, 0, 2, (0, 3), (1, 2)]))
    if d is not None:
        opts["delay"] = d
    if draw(st.booleans()):
        opts["track_effort"] = True
    if draw(st.booleans()):
        opts["clip_targets"] = "joint_limits"
    if draw(st.booleans()):
        opts["delay_seed"] = draw(st.integers(-(2**31), 2**31 - 1))  # keys the per-env delay draws
    return opts


# ----------------------------------------------------------------------------------------------------------------------
# Tests.

_LIMITS = {s: tuple(map(float, lim)) for s, lim in zip(PANDA_JOINTS, model_for("replicated", 3)[1].limits)}
SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
EXPLICIT = st.sampled_from(
    [("implicit", "naive"), ("explicit", "naive"), ("explicit", "stable"), ("explicit", "coupled")]
)


@settings(max_examples=MAX_EXAMPLES, **SETTINGS)
@given(
    mode=control_mode(_LIMITS),
    layout=st.sampled_from(LAYOUTS),
    num_substeps=st.sampled_from([1, 2, 5]),
    actuation=EXPLICIT,
    inertia_update=st.sampled_from(["control", "substep"]),
    nan_policy=st.sampled_from(["hold", "hold", "raise"]),
    opts=actuation_options(),
    data=st.data(),
)
def test_matches_reference(mode, layout, num_substeps, actuation, inertia_update, nan_policy, opts, data):
    if actuation[0] == "implicit" or actuation[1] == "coupled":  # actuator models need the explicit naive/stable law
        mode = _without_actuators(mode)
    if not _builds(mode, layout, actuation):
        return
    h = Harness(mode, layout, num_substeps, *actuation, nan_policy, inertia_update, data.draw, opts)
    run_stream(h, data.draw)


def _without_actuators(mode):
    strip = lambda c: dataclasses.replace(c, actuator=None) if getattr(c, "actuator", None) is not None else c  # noqa: E731
    return {k: strip(c) for k, c in mode.items()} if isinstance(mode, dict) else strip(mode)


def _builds(mode, layout, actuation) -> bool:
    """Whether the build is one wpctrl accepts; the refusal (with its reason) is checked where it is not."""
    if layout[0] == "floating" and actuation == ("explicit", "coupled"):
        model, _ = model_for(*layout)
        with pytest.raises(wpctrl.ConfigError, match=r"'coupled' needs a fixed-base articulation"):
            wpctrl.build_controller(mode, model, actuation="explicit", explicit_pd="coupled")
        return False
    return True


PANDA_MODES = ["pd_joint_delta_pos", "pd_joint_target_delta_pos", "pd_joint_pos_vel", "pd_ee_delta_pos",
               "pd_ee_delta_pose"]  # fmt: skip


@settings(max_examples=max(MAX_EXAMPLES // 5, 10), **SETTINGS)
@given(
    name=st.sampled_from(PANDA_MODES),
    layout=st.sampled_from(LAYOUTS),
    num_substeps=st.sampled_from([1, 5]),
    actuation=EXPLICIT,
    inertia_update=st.sampled_from(["control", "substep"]),
    opts=actuation_options(),
    data=st.data(),
)
def test_panda_modes_match_reference(name, layout, num_substeps, actuation, inertia_update, opts, data):
    """ManiSkill's Panda modes, end-effector ones included (one DLS step at the measured state, the Jacobian from
    Newton's forward kinematics)."""
    mode = copy.deepcopy(panda_control_modes()[name])
    if not _builds(mode, layout, actuation):
        return
    if name.startswith("pd_ee") and layout[0] == "flat":  # the EE kernels compile one chain layout for all worlds
        with pytest.raises(wpctrl.ConfigError, match="laid out differently across worlds"):
            Harness(mode, layout, num_substeps, *actuation, "hold", inertia_update, data.draw, opts)
        return
    h = Harness(mode, layout, num_substeps, *actuation, "hold", inertia_update, data.draw, opts)
    run_stream(h, data.draw)


@settings(max_examples=max(MAX_EXAMPLES // 5, 10), **SETTINGS)
@given(
    mode=big_mimic(_LIMITS),
    num_substeps=st.sampled_from([1, 5]),
    actuation=st.sampled_from(["implicit", "explicit"]),
    data=st.data(),
)
def test_mimic_matches_reference(mode, num_substeps, actuation, data):
    """Mimic maps with several control joints, as the mixed stream above draws them rarely."""
    if actuation == "implicit":
        mode = _without_actuators(mode)
    h = Harness(mode, ("replicated", 3), num_substeps, actuation, "naive", "hold", "control", data.draw)
    run_stream(h, data.draw)


def test_strategies_cover_every_config_type():
    """The config strategy produces every config type and both mimic forms (a guard against a narrowed search)."""
    seen = set()

    @settings(max_examples=200, deadline=None, database=None, derandomize=True)
    @given(control_mode(_LIMITS))
    def collect(mode):
        for c in mode.values() if isinstance(mode, dict) else [mode]:
            name = type(c).__name__
            if isinstance(c, C.PDJointPosMimicControllerConfig):
                name += "(default)" if not c.mimic else "(map)"
            seen.add(name)

    collect()
    assert {
        "PDJointPosControllerConfig",
        "PDJointPosMimicControllerConfig(map)",
        "PDJointPosMimicControllerConfig(default)",
        "PDJointVelControllerConfig",
        "PDJointPosVelControllerConfig",
        "PassiveControllerConfig",
    } <= seen


def test_strategies_cover_the_actuator_options():
    """Some drawn children carry a DC motor, a position table, EMA smoothing or a binary command, also on a child
    that is not the first of its mode (a guard against a narrowed search)."""
    seen = set()

    @settings(max_examples=300, deadline=None, database=None, derandomize=True)
    @given(control_mode(_LIMITS))
    def collect(mode):
        children = list(mode.values()) if isinstance(mode, dict) else [mode]
        for i, c in enumerate(children):
            where = "later" if i else "first"
            act = getattr(c, "actuator", None)
            if act is not None:
                seen.add((type(act).__name__, where))
                seen.add((type(act).__name__, type(c).__name__))
            if getattr(c, "ema", None) is not None:
                seen.add(("ema", where))
            if getattr(c, "binary", False):
                seen.add(("binary", where))

    collect()
    want = {(k, w) for k in ("DCMotor", "PositionBasedEffortLimit", "ema", "binary") for w in ("first", "later")}
    want |= {("DCMotor", "PDJointVelControllerConfig"), ("PositionBasedEffortLimit", "PDJointPosMimicControllerConfig")}
    assert want <= seen, want - seen


# ----------------------------------------------------------------------------------------------------------------------
# Regression tests: minimal reproductions of bugs this file found (fixed).


def test_processed_action_of_a_child_without_action_columns():
    model, _ = model_for("replicated", 3)
    mode = {
        "arm": C.PDJointPosControllerConfig(["panda_joint1"], -1.0, 1.0, 100.0, 10.0),
        "knuckle": C.PassiveControllerConfig(["panda_joint2"], damping=1.0),
    }
    ctrl = wpctrl.build_controller(mode, model)
    assert ctrl["knuckle"].processed_action.shape == (3, 0)


def test_float64_torch_action_outlives_its_conversion(monkeypatch):
    """Deterministic: the float32 copy that ``Tensor.to`` returns is poisoned (NaN) the moment it is freed, so a
    kernel reading it afterwards sees NaN and rejects the action (bad_action_count 1) instead of using it."""
    import weakref

    to = torch.Tensor.to

    def poisoning_to(self, *args, **kwargs):
        out = to(self, *args, **kwargs)
        if self.dtype == torch.float64 and out.dtype == torch.float32:
            backing = out.clone().reshape(-1)
            view = backing.view(out.shape)
            weakref.finalize(view, backing.fill_, float("nan"))  # backing itself stays alive (closure)
            return view
        return out

    monkeypatch.setattr(torch.Tensor, "to", poisoning_to)
    model, _ = model_for("replicated", 3)
    cfg = C.PDJointVelControllerConfig(["panda_joint1"], 0.0, 0.0, 0.0, normalize_action=False)
    ctrl = wpctrl.build_controller(cfg, model)
    a = np.array([[0.1], [0.2], [0.3]])
    ctrl.set_action(torch.from_numpy(a), model.state())
    assert ctrl.bad_action_count.numpy().tolist() == [0, 0, 0]
    np.testing.assert_array_equal(ctrl.processed_action.numpy(), a.astype(np.float32))
