"""Every combination of ``build_controller``'s options: refused when the mode would ignore part of it, otherwise run
as ``ctrl.options`` says.

The combinations are generated (each option group's fields crossed with each other and with the joints they meet:
force and acceleration drives, velocity-only and passive-only configs, mode dicts with and without their own
``balance_passive_force``). For each one the expectation is derived here from what each option does, not from
wpctrl's checks: an explicit law needs explicit actuation; an inertia update needs a mode that computes inertia (an
acceleration drive, stable or coupled PD); a seed needs a delay that is drawn (a range); target clipping needs a
position target; a delay and the NaN check need an action; a group is given one way (its object or its keywords); the
gravity switch one value. A combination that breaks one of these is refused with a :class:`wpctrl.ConfigError` that
names the field; every other one builds, the same from the objects as from the keywords, and ``ctrl.options`` (and
``ctrl.explicit_pd``, ``ctrl.inertia_update``, ...) describe what the engine runs, checked against the engine's own
parts where nothing public shows it (the response part's update schedule, the coupled drive's block cache: private
parts, read here on purpose).
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from conftest import build_panda
from reference_np import delay_draws

import wpctrl
from wpctrl.robots import PANDA_ARM_JOINTS

N = 4  # envs: enough for the per-env delay draws to differ


@pytest.fixture(scope="module")
def model():
    return build_panda(N)


def _config(kind: str):
    names = list(PANDA_ARM_JOINTS)
    if kind in ("force", "acceleration"):
        return wpctrl.PDJointPosControllerConfig(names, -0.1, 0.1, 400.0, 40.0, use_delta=True, drive_mode=kind)
    if kind == "velocity":
        return wpctrl.PDJointVelControllerConfig(names, -1.0, 1.0, 40.0)
    return wpctrl.PassiveControllerConfig(names, 10.0)


def _build(model, kind, **kw):
    return wpctrl.build_controller(_config(kind), model, 20, 100, balance_passive_force=False, **kw)


def _refused(fn, field: str) -> None:
    with pytest.raises(wpctrl.ConfigError) as info:
        fn()
    assert field in str(info.value), str(info.value)


@pytest.mark.parametrize("law", ["naive", "stable", "coupled"])
def test_an_effort_controller_beside_an_explicit_drive_keeps_its_torque(model, law):
    """An effort gripper next to an explicitly driven arm: its torque (the action times the effort bound) reaches
    Control.joint_f with the naive and stable laws; the coupled drive solves every row's torque and would overwrite it,
    so that combination is refused."""
    from wpctrl.robots import PANDA_GRIPPER_JOINTS

    mode = {
        "arm": _config("force"),
        "gripper": wpctrl.JointEffortControllerConfig(list(PANDA_GRIPPER_JOINTS), -10.0, 10.0),
    }

    def build():
        return wpctrl.build_controller(mode, model, 20, 100, balance_passive_force=False,
                                       actuation=wpctrl.Actuation("explicit", law))  # fmt: skip

    if law == "coupled":
        with pytest.raises(wpctrl.ConfigError, match="would overwrite the torques of this mode's effort rows"):
            build()
        return
    ctrl = build()
    s, c = model.state(), model.control()
    ctrl.reset(s, control=c)
    a = np.zeros((N, ctrl.action_dim), np.float32)
    a[:, -2:] = [[0.5, -0.25]]
    ctrl.set_action(a, s)
    ctrl.before_simulation_step(s, c)
    f = c.joint_f.numpy().reshape(N, -1)
    np.testing.assert_allclose(f[:, 7:9], [[5.0, -2.5]] * N, atol=1e-6)


# -- Actuation: mode x explicit law x inertia update x drive mode -----------------------------------------------------

ACTUATION_CASES = list(
    itertools.product(
        ("implicit", "explicit"),
        (None, "naive", "stable", "coupled"),
        (None, "control", "substep"),
        ("force", "acceleration"),
    )
)


@pytest.mark.parametrize("mode, law, inertia, drive", ACTUATION_CASES)
def test_actuation_combinations(model, mode, law, inertia, drive):
    by_keywords = lambda: _build(model, drive, actuation=mode, explicit_pd=law, inertia_update=inertia)  # noqa: E731
    by_object = lambda: _build(model, drive, actuation=wpctrl.Actuation(mode, law, inertia))  # noqa: E731
    if law is not None and mode == "implicit":  # an explicit law with the solver's drive: it would not run
        _refused(by_keywords, "explicit_pd")
        _refused(by_object, "explicit_pd")
        return
    runs = (law or "naive") if mode == "explicit" else None
    computes = drive == "acceleration" or runs in ("stable", "coupled")
    if inertia is not None and not computes:  # nothing to recompute: the update would not run
        _refused(by_keywords, "inertia_update")
        _refused(by_object, "inertia_update")
        return
    ctrl, same = by_keywords(), by_object()
    assert ctrl.options == same.options
    update = (inertia or ("substep" if runs == "coupled" else "control")) if computes else None
    assert ctrl.options.actuation == wpctrl.Actuation(mode, runs, update)
    assert (ctrl.actuation, ctrl.explicit_pd, ctrl.inertia_update) == (mode, runs, update)
    # What the engine runs (its parts, private): r for acceleration drives and stable PD, on the reported schedule;
    # the coupled drive's block cached for the control step only with "control".
    assert (ctrl.response is not None) == (drive == "acceleration" or runs == "stable")
    eng = ctrl._engine  # private: the engine parts that run (nothing public shows the schedule)
    coupled = eng.part("coupled_drive")
    assert (coupled is not None) == (runs == "coupled")
    if coupled is not None:
        assert (coupled.h_cache is not None) == (update == "control")
    elif computes:
        assert eng.part("response").update_per_substep == (update == "substep")
    assert eng.layout.explicit == {None: 0, "naive": 1, "stable": 2, "coupled": 0}[runs]


# -- Delay: substeps x seed x an action to delay ----------------------------------------------------------------------

DELAY_CASES = list(itertools.product((None, 0, 2, (0, 3), (1, 1)), (None, 0, 5), ("force", "passive")))


@pytest.mark.parametrize("delay, seed, kind", DELAY_CASES)
def test_delay_combinations(model, delay, seed, kind):
    by_keywords = lambda: _build(model, kind, delay=delay, delay_seed=seed)  # noqa: E731
    rng = None if delay is None else ((delay, delay) if isinstance(delay, int) else delay)
    if seed is not None and (rng is None or rng[0] == rng[1]):  # nothing is drawn: the seed would not be used
        _refused(by_keywords, "seed")
        if rng is not None:
            _refused(lambda: _build(model, kind, delay=wpctrl.Delay(delay, seed)), "seed")
        return
    if rng is not None and kind == "passive":  # no action: nothing to delay
        _refused(by_keywords, "delay")
        return
    ctrl = by_keywords()
    if rng is None:
        assert ctrl.options.delay is None and ctrl.delay is None
        return
    assert ctrl.options == _build(model, kind, delay=wpctrl.Delay(delay, seed)).options
    assert ctrl.options.delay == wpctrl.Delay(delay, seed) and ctrl.options.delay.range == rng
    # the per-env delays the build's reset drew: Warp's RNG keyed by the seed (0 when none), draw 0
    want = delay_draws(0 if seed is None else seed, 0, N, *rng)
    np.testing.assert_array_equal(ctrl.delay.numpy(), want)


def test_the_seed_keys_the_draws(model):
    """Two seeds draw different per-env delays (so the case above cannot pass with the seed ignored)."""
    a = _build(model, "force", delay=(0, 7), delay_seed=1).delay.numpy()
    b = _build(model, "force", delay=(0, 7), delay_seed=2).delay.numpy()
    assert (a != b).any()


# -- Diagnostics: effort readout x NaN policy x target clipping x the targets there are ------------------------------

DIAGNOSTICS_CASES = list(
    itertools.product((False, True), ("hold", "raise"), ("none", "joint_limits"), ("force", "velocity", "passive"))
)


@pytest.mark.parametrize("track, nan, clip, kind", DIAGNOSTICS_CASES)
def test_diagnostics_combinations(model, track, nan, clip, kind):
    by_keywords = lambda: _build(model, kind, track_effort=track, nan_policy=nan, clip_targets=clip)  # noqa: E731
    diagnostics = wpctrl.Diagnostics(track, nan, clip)
    if clip != "none" and kind != "force":  # no position target to clamp
        _refused(by_keywords, "clip_targets")
        _refused(lambda: _build(model, kind, diagnostics=diagnostics), "clip_targets")
        return
    if nan != "hold" and kind == "passive":  # no action to check
        _refused(by_keywords, "nan_policy")
        return
    ctrl = by_keywords()
    assert ctrl.options == _build(model, kind, diagnostics=diagnostics).options
    assert ctrl.options.diagnostics == diagnostics
    assert (ctrl.track_effort, ctrl.nan_policy, ctrl.clip_targets) == (track, nan, clip)
    assert (ctrl.computed_effort is not None) == track
    assert ctrl._engine.layout.clip == (clip == "joint_limits")  # compiled into the step kernel (private)


# -- a group given both ways ------------------------------------------------------------------------------------------

BOTH_WAYS = [
    ({"actuation": wpctrl.Actuation("explicit")}, "explicit_pd", "stable"),
    ({"actuation": wpctrl.Actuation("explicit", "stable")}, "inertia_update", "substep"),
    ({"delay": wpctrl.Delay((0, 2))}, "delay_seed", 3),
    ({"diagnostics": wpctrl.Diagnostics()}, "track_effort", True),
    ({"diagnostics": wpctrl.Diagnostics()}, "nan_policy", "raise"),
    ({"diagnostics": wpctrl.Diagnostics()}, "clip_targets", "joint_limits"),
]


@pytest.mark.parametrize("group, keyword, value", BOTH_WAYS, ids=[k for _, k, _ in BOTH_WAYS])
def test_a_group_and_its_keyword_together_are_refused(model, group, keyword, value):
    """The keyword would be ignored (the object wins) or the object overridden: neither happens silently."""
    _refused(lambda: _build(model, "force", **group, **{keyword: value}), keyword)


@pytest.mark.parametrize(
    "value, field",
    [("Explicit", "actuation"), (3, "actuation"), (wpctrl.Diagnostics(), "actuation")],
)
def test_a_group_of_the_wrong_kind_is_refused(model, value, field):
    _refused(lambda: _build(model, "force", actuation=value), field)
    _refused(lambda: _build(model, "force", diagnostics=wpctrl.Delay(2)), "diagnostics")
    _refused(lambda: _build(model, "force", delay=wpctrl.Diagnostics()), "delay")


# -- the gravity switch: the mode dict's entry x the keyword ----------------------------------------------------------

BALANCE_CASES = list(itertools.product(("absent", True, False), (None, True, False)))


@pytest.mark.parametrize("entry, keyword", BALANCE_CASES)
def test_balance_passive_force_combinations(model, entry, keyword):
    mode = {"arm": _config("force")}
    if entry != "absent":
        mode["balance_passive_force"] = entry
    build = lambda: wpctrl.build_controller(mode, model, 20, 100, balance_passive_force=keyword)  # noqa: E731
    if entry != "absent" and keyword is not None and entry != keyword:  # one of the two would be ignored
        _refused(build, "balance_passive_force")
        return
    ctrl = build()
    want = keyword if keyword is not None else (True if entry == "absent" else entry)
    assert ctrl.balance_passive_force is want and ctrl.options.balance_passive_force is want
    assert (ctrl._engine.part("gravity") is not None) == want  # private: the gravity part is on


# -- the options of a child and of the direct constructor -------------------------------------------------------------


def test_children_report_the_parent_options(model):
    mode = {"arm": _config("acceleration"), "balance_passive_force": False}
    ctrl = wpctrl.build_controller(mode, model, actuation="explicit", explicit_pd="stable", delay=(0, 1), delay_seed=4)
    assert ctrl["arm"].options == ctrl.options
    assert ctrl["arm"].explicit_pd == "stable" and ctrl["arm"].inertia_update == "control"


def test_controller_cls_takes_the_groups_only(model):
    """``Config.controller_cls(config, model, ...)`` takes the groups as objects (the keywords are
    build_controller's convenience): the same controller, and a plain string is refused rather than guessed."""
    cfg = _config("force")
    direct = type(cfg).controller_cls(
        cfg, model, 20, 100, actuation=wpctrl.Actuation("explicit", "stable"), balance_passive_force=False
    )
    built = _build(model, "force", actuation="explicit", explicit_pd="stable")
    assert type(direct) is type(built) and direct.options == built.options
    _refused(lambda: type(cfg).controller_cls(cfg, model, 20, 100, actuation="explicit"), "actuation")


def test_every_option_is_keyword_only(model):
    with pytest.raises(TypeError):
        wpctrl.build_controller(_config("force"), model, 20, 100, "explicit")
