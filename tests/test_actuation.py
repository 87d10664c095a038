"""RL-grade actuation: per-env drive properties and their randomisation, command delay, effort readout,
target clamping. Closed-form checks on the CPU device, captured graphs, and MuJoCo-Warp rollouts of real Pandas.
"""

from __future__ import annotations

import newton
import numpy as np
import pytest
import warp as wp
from conftest import HAS_CUDA, build_panda
from harness import ARM, FINGERS, Harness, delta_arm

import wpctrl
from wpctrl.robots import PANDA_ARM_JOINTS, PANDA_INITIAL_Q

F32 = np.float32
N = 4


def arm_abs(kp=400.0, kd=40.0, fl=50.0, **kw):
    """The 7 arm joints, absolute targets in raw units."""
    return wpctrl.PDJointPosControllerConfig(ARM, None, None, kp, kd, fl, normalize_action=False, **kw)


def random_state(h: Harness, rng, scale=0.5):
    q = (np.asarray(PANDA_INITIAL_Q, F32)[None, : h.coord.shape[1]] + rng.uniform(-scale, scale, h.coord.shape)).astype(
        F32
    )
    qd = rng.uniform(-1.0, 1.0, h.coord.shape).astype(F32)
    h.put(q, qd)
    return q, qd


# ----------------------------------------------------------------------------------------------------------------------
# Per-env drive properties.


def test_drive_properties_start_at_the_config_per_env():
    h = Harness({"arm": arm_abs(kp=[float(i + 1) for i in range(7)], fl=7.0), "fingers": _fingers()}, num_envs=N)
    c = h.ctrl
    assert c.stiffness.shape == (N, 9) and c.damping.shape == (N, 9)
    np.testing.assert_array_equal(c.stiffness.numpy()[:, :7], np.tile(np.arange(1, 8, dtype=F32), (N, 1)))
    np.testing.assert_array_equal(c["fingers"].force_limit.numpy(), np.full((N, 2), 30.0, F32))
    np.testing.assert_array_equal(c["arm"].friction.numpy(), np.zeros((N, 7), F32))


def _fingers(**kw):
    return wpctrl.PDJointPosMimicControllerConfig(FINGERS, -0.01, 0.04, 200.0, 20.0, 30.0, **kw)


def test_per_env_gains_explicit_torque_closed_form():
    """set_drive_properties on envs 1 and 3 changes exactly their torques: clamp(Kp_e (q* - q) - Kd_e qd, +-lim_e)."""
    torch = pytest.importorskip("torch", reason="torch is a dev dependency (a torch value is passed here)")
    rng = np.random.default_rng(0)
    h = Harness(arm_abs(), num_envs=N, actuation="explicit")
    q, qd = random_state(h, rng)
    h.ctrl.reset(h.state)
    kp = rng.uniform(100, 900, (2, 7)).astype(F32)
    h.ctrl.set_drive_properties(
        stiffness=kp, damping=np.full(7, 5.0), force_limit=torch.full((2, 7), 20.0), env_ids=[1, 3]
    )
    target = (q + rng.uniform(-0.3, 0.3, q.shape)).astype(F32)
    h.act(target)
    h.substeps(1)
    KP = np.full((N, 7), 400.0, F32)
    KD = np.full((N, 7), 40.0, F32)
    LIM = np.full((N, 7), 50.0, F32)
    KP[[1, 3]], KD[[1, 3]], LIM[[1, 3]] = kp, 5.0, 20.0
    want = np.clip(KP * (target - q) + KD * (F32(0) - qd), -LIM, LIM)
    np.testing.assert_allclose(h.joint_f(), want, rtol=1e-6, atol=1e-5)
    np.testing.assert_array_equal(h.ctrl.stiffness.numpy(), KP)
    # explicit: the built-in drive stays off; effort limits are mirrored into the model
    m = h.model
    np.testing.assert_array_equal(m.joint_target_ke.numpy()[h.dof], 0.0)
    np.testing.assert_array_equal(m.joint_effort_limit.numpy()[h.dof], LIM)


def test_per_env_gains_implicit_write_the_model_for_those_envs_only():
    h = Harness({"arm": arm_abs(), "fingers": _fingers()}, num_envs=N)
    m = h.model
    before = {k: getattr(m, k).numpy().copy() for k in ("joint_target_ke", "joint_target_kd", "joint_friction")}
    mask = np.array([False, True, False, True])
    h.ctrl["fingers"].set_drive_properties(stiffness=[7.0, 8.0], friction=np.full((N, 2), 0.25), env_ids=mask)
    ke = m.joint_target_ke.numpy()
    fr = m.joint_friction.numpy()
    changed = np.zeros_like(ke, bool)
    fingers = h.dof[:, 7:]
    changed[fingers[mask]] = True
    np.testing.assert_array_equal(ke[fingers[mask]], np.tile([7.0, 8.0], (2, 1)).astype(F32))
    np.testing.assert_array_equal(fr[fingers[mask]], 0.25)
    np.testing.assert_array_equal(ke[~changed], before["joint_target_ke"][~changed])
    np.testing.assert_array_equal(fr[~changed], before["joint_friction"][~changed])
    np.testing.assert_array_equal(m.joint_target_kd.numpy(), before["joint_target_kd"])
    # the drive targets do not depend on the gains: arm targets are the raw action, the fingers' the scaled column
    a = np.random.default_rng(4).uniform(-1.2, 1.2, (N, 8)).astype(F32)
    h.act(a)
    lo, hi = F32(-0.01), F32(0.04)
    finger = F32(0.5) * (hi + lo) + F32(0.5) * (hi - lo) * np.clip(a[:, 7], F32(-1), F32(1))
    np.testing.assert_array_equal(h.substeps(1)[0], np.column_stack([a[:, :7], finger, finger]))


def test_acceleration_drive_uses_per_env_gains_over_r():
    h = Harness(arm_abs(drive_mode="acceleration"), num_envs=2)
    h.ctrl.set_drive_properties(stiffness=np.array([[100.0] * 7, [300.0] * 7]), damping=[10.0] * 7)
    h.ctrl.set_action(np.tile(np.asarray(PANDA_INITIAL_Q[:7], F32), (2, 1)), h.state)  # refreshes r and the gains
    r = h.ctrl.response.numpy()
    ke = h.model.joint_target_ke.numpy()[h.dof]
    kd = h.model.joint_target_kd.numpy()[h.dof]
    np.testing.assert_allclose(ke, np.array([[100.0], [300.0]], F32) / r, rtol=1e-6)
    np.testing.assert_allclose(kd, F32(10.0) / r, rtol=1e-6)


def test_zero_range_randomisation_is_bit_identical():
    """Scale (1, 1) and abs (x, x) draws reproduce the values exactly; a stream of explicit torques is bitwise equal."""
    rng = np.random.default_rng(1)
    hs = [
        Harness(arm_abs(kp=333.3, kd=33.3, fl=12.3, friction=0.1), num_envs=N, actuation="explicit") for _ in range(2)
    ]
    one = (1.0, 1.0)
    hs[1].ctrl.randomize_drive_properties(stiffness=one, damping=one, force_limit=one, friction=one, seed=7)
    for name in ("stiffness", "damping", "force_limit", "friction"):
        np.testing.assert_array_equal(getattr(hs[1].ctrl, name).numpy(), getattr(hs[0].ctrl, name).numpy(), name)
    for key in ("joint_target_ke", "joint_target_kd", "joint_effort_limit", "joint_friction"):
        np.testing.assert_array_equal(getattr(hs[1].model, key).numpy(), getattr(hs[0].model, key).numpy(), key)
    states = [rng.uniform(-1, 1, (N, 7)).astype(F32) for _ in range(6)]
    outs = []
    for h in hs:
        h.ctrl.reset(h.state)
        out = []
        for s in states:
            h.put(s, s)
            h.act(s + 0.1)
            for _ in range(2):
                h.substeps(1)
                out.append(h.joint_f().copy())
        outs.append(np.array(out))
    np.testing.assert_array_equal(outs[0], outs[1])
    hs[1].ctrl.randomize_drive_properties(damping=(12.5, 12.5), mode="abs")
    np.testing.assert_array_equal(hs[1].ctrl.damping.numpy(), 12.5)


def test_randomisation_in_a_captured_graph_draws_new_values_each_replay():
    h = Harness({"arm": arm_abs(), "fingers": _fingers()}, num_envs=8)
    c = h.ctrl
    mask = wp.zeros(8, dtype=wp.bool, device="cpu")
    with wp.ScopedCapture(device="cpu") as cap:
        c.randomize_drive_properties(env_ids=mask, stiffness=(0.5, 2.0), damping=(0.5, 2.0), seed=3)
    nominal_kp = np.concatenate([np.full(7, 400.0, F32), np.full(2, 200.0, F32)])
    nominal_kd = nominal_kp / 10
    prev = c.stiffness.numpy().copy()
    draws = []
    for i in range(4):
        m = np.random.default_rng(i).random(8) < 0.5
        m[i] = True
        mask.assign(m)
        wp.capture_launch(cap.graph)
        kp, kd = c.stiffness.numpy().copy(), c.damping.numpy().copy()
        np.testing.assert_array_equal(kp[~m], prev[~m])  # envs outside the mask keep their values
        assert (kp[m] >= 0.5 * nominal_kp - 1e-3).all() and (kp[m] <= 2.0 * nominal_kp + 1e-3).all()
        assert (kd[m] >= 0.5 * nominal_kd - 1e-4).all() and (kd[m] <= 2.0 * nominal_kd + 1e-4).all()
        assert not np.isin(kp[m], prev[m]).any()  # fresh draws on every replay
        np.testing.assert_array_equal(h.model.joint_target_ke.numpy()[h.dof], kp)  # mirrored (implicit)
        draws.append(kp[m] / nominal_kp[None, :].repeat(m.sum(), 0))
        prev = kp
    u = np.concatenate([d.ravel() for d in draws])
    assert u.min() < 0.7 and u.max() > 1.8  # spread over the range
    assert len(np.unique(u)) == u.size  # every joint and env draws independently


def test_randomisation_is_warps_rng_keyed_by_seed_and_draw_counter():
    """Each (env, row) draws from Warp's RNG keyed by the call's seed and the device draw counter (one per call):
    the values are the numpy port's (reference_np.drive_draws), another seed gives other values, the same seed on a
    fresh controller the same ones, and the next call (counter + 1) new ones."""
    from reference_np import drawn_value, drive_draws

    def fresh():
        return Harness({"arm": arm_abs(), "fingers": _fingers()}, num_envs=N)

    got = {}
    for seed in (7, 8):
        h = fresh()
        c = h.ctrl["fingers"]
        nom = {f: getattr(c, f).numpy()[0].copy() for f in ("stiffness", "force_limit")}
        c.randomize_drive_properties(stiffness=(0.5, 2.0), force_limit=(1.0, 3.0), mode="abs", seed=seed)
        u = drive_draws(seed, 0, N, 9, 7, 2)
        np.testing.assert_allclose(c.stiffness.numpy(), drawn_value(u[..., 0], 0.5, 2.0), rtol=1e-6)
        np.testing.assert_allclose(c.force_limit.numpy(), drawn_value(u[..., 2], 1.0, 3.0), rtol=1e-6)
        np.testing.assert_array_equal(h.ctrl["arm"].stiffness.numpy(), 400.0)  # other rows untouched
        got[seed] = c.stiffness.numpy().copy()
        c.randomize_drive_properties(stiffness=(0.5, 2.0), mode="scale", seed=seed)  # counter 1
        np.testing.assert_allclose(
            c.stiffness.numpy(), drawn_value(drive_draws(seed, 1, N, 9, 7, 2)[..., 0], 0.5, 2.0, nom["stiffness"]),
            rtol=1e-6,
        )  # fmt: skip
        np.testing.assert_array_equal(h.model.joint_target_ke.numpy()[h.dof[:, 7:]], c.stiffness.numpy())
    assert not np.isin(got[7], got[8]).any()  # another seed, other values
    h = fresh()
    h.ctrl["fingers"].randomize_drive_properties(stiffness=(0.5, 2.0), force_limit=(1.0, 3.0), mode="abs", seed=7)
    np.testing.assert_array_equal(h.ctrl["fingers"].stiffness.numpy(), got[7])  # the same seed, the same values


@pytest.mark.parametrize("seed", [0, 5])
def test_delays_are_warps_rng_of_the_build_seed(seed):
    """Each reset that draws delays (a range of more than one value) uses the build's seed and the draw counter
    (the build's own reset is draw 0): the values of the numpy port (reference_np.delay_draws)."""
    from reference_np import delay_draws

    h = Harness({"arm": delta_arm(use_target=True)}, num_envs=16, delay=(1, 4), delay_seed=seed)
    np.testing.assert_array_equal(h.ctrl.delay.numpy(), delay_draws(seed, 0, 16, 1, 4))
    h.ctrl.reset(h.state)
    np.testing.assert_array_equal(h.ctrl.delay.numpy(), delay_draws(seed, 1, 16, 1, 4))
    h.ctrl.randomize_drive_properties(damping=(1.0, 2.0), seed=seed)  # draw 2
    mask = np.arange(16) % 3 == 0
    before = h.ctrl.delay.numpy().copy()
    h.ctrl.reset(h.state, env_ids=mask)
    want = np.where(mask, delay_draws(seed, 3, 16, 1, 4), before)
    np.testing.assert_array_equal(h.ctrl.delay.numpy(), want)
    other = Harness({"arm": delta_arm(use_target=True)}, num_envs=16, delay=(1, 4), delay_seed=seed + 1)
    assert not np.array_equal(other.ctrl.delay.numpy(), delay_draws(seed, 0, 16, 1, 4))


def test_randomize_on_a_child_with_ids_and_abs_mode():
    torch = pytest.importorskip("torch", reason="torch is a dev dependency (torch env ids are passed here)")
    h = Harness({"arm": arm_abs(), "fingers": _fingers()}, num_envs=N)
    before = h.ctrl.force_limit.numpy().copy()
    h.ctrl["fingers"].randomize_drive_properties(env_ids=torch.tensor([2]), force_limit=(5.0, 6.0), mode="abs")
    after = h.ctrl.force_limit.numpy()
    assert ((after[2, 7:] >= 5.0) & (after[2, 7:] <= 6.0)).all()
    after[2, 7:] = before[2, 7:]
    np.testing.assert_array_equal(after, before)


# ----------------------------------------------------------------------------------------------------------------------
# Command delay.


def _delay_stream(actuation, delay, d_values=None, interpolate=True, steps=4, seed=0):
    """Drive targets (implicit) or torques (explicit) after every substep, with the measured state held fixed."""
    rng = np.random.default_rng(seed)
    h = Harness(
        {"arm": delta_arm(use_target=True, interpolate=interpolate)},
        num_envs=N,
        actuation=actuation,
        delay=delay,
    )
    q = (np.asarray(PANDA_INITIAL_Q[:7], F32) + rng.uniform(-0.2, 0.2, (N, 7))).astype(F32)
    h.put(q, rng.uniform(-0.5, 0.5, (N, 7)).astype(F32))
    h.ctrl.reset(h.state)
    if d_values is not None:
        h.ctrl.delay = np.asarray(d_values, np.int32)
    actions = np.random.default_rng(seed + 1).uniform(-1, 1, (steps, N, 7)).astype(F32)
    out = []
    for a in actions:
        h.act(a)
        for _ in range(h.ctrl.num_substeps):
            h.ctrl.before_simulation_step(h.state, h.control)
            out.append(h.joint_f().copy() if actuation == "explicit" else h.drive_q().copy())
    reset_out = h.joint_f().copy() * 0 if actuation == "explicit" else q
    return np.array(out), h, q, reset_out


@pytest.mark.parametrize("actuation", ["implicit", "explicit"])
def test_delay_shifts_the_command_sequence_per_env(actuation):
    d = [0, 1, 2, 3]
    base, *_ = _delay_stream(actuation, None)
    got, h, q, _ = _delay_stream(actuation, (0, 3), d_values=d)
    if actuation == "explicit":  # the law on the reset pose, measured state unchanged: Kd (0 - qd) only
        qd = h.state.joint_qd.numpy()[h.dof]
        first = np.clip(F32(1e3) * (q - q) + F32(1e2) * (F32(0) - qd), -100, 100)
    else:
        first = q
    for e, de in enumerate(d):
        np.testing.assert_array_equal(got[de:, e], base[: len(base) - de, e], err_msg=f"env {e}, d={de}")
        for t in range(de):
            np.testing.assert_array_equal(got[t, e], first[e], err_msg=f"env {e}: substep {t} is the reset pose")
    assert h.ctrl.delay.numpy().tolist() == d


def test_delay_drawn_per_env_at_reset_and_history_cleared():
    h = Harness({"arm": delta_arm(use_target=True)}, num_envs=64, delay=(1, 4), delay_seed=5)
    h.ctrl.reset(h.state)
    d0 = h.ctrl.delay.numpy().copy()
    assert d0.min() >= 1 and d0.max() <= 4 and len(np.unique(d0)) == 4
    for _ in range(3):  # fill the history with commands of this episode
        h.step(np.ones(7, F32))
    mask = np.zeros(64, bool)
    mask[::2] = True
    q_new = np.full((64, 7), 0.25, F32)
    h.put(q_new)
    with wp.ScopedCapture(device="cpu") as cap:  # a captured reset redraws the delays of the masked envs
        h.ctrl.reset(h.state, env_ids=wp.array(mask, dtype=wp.bool, device="cpu"))
    wp.capture_launch(cap.graph)
    d1 = h.ctrl.delay.numpy().copy()
    np.testing.assert_array_equal(d1[~mask], d0[~mask])
    assert (d1[mask] != d0[mask]).any() and d1.min() >= 1 and d1.max() <= 4
    h.act(np.ones((64, 7), F32))
    for t in range(4):
        h.ctrl.before_simulation_step(h.state, h.control)
        dq = h.drive_q()
        fresh = mask & (d1 > t)  # still inside the delay: the reset pose, no command of the old episode
        np.testing.assert_array_equal(dq[fresh], q_new[fresh])
        assert (dq[mask & (d1 <= t)] != q_new[mask & (d1 <= t)]).all()  # the new command arrived


# ----------------------------------------------------------------------------------------------------------------------
# Effort readout.


@pytest.mark.parametrize("actuation", ["implicit", "explicit"])
def test_effort_readout_and_saturation_counts(actuation):
    rng = np.random.default_rng(2)
    h = Harness(arm_abs(kp=300.0, kd=30.0, fl=40.0), num_envs=N, actuation=actuation, track_effort=True)
    c = h.ctrl
    c.set_drive_properties(force_limit=rng.uniform(10, 60, (N, 7)).astype(F32))
    lim = c.force_limit.numpy().copy()
    h.ctrl.reset(h.state)
    count = np.zeros((N, 7), np.int64)
    for _ in range(3):
        target = (np.asarray(PANDA_INITIAL_Q[:7], F32) + rng.uniform(-0.3, 0.3, (N, 7))).astype(F32)
        h.act(target)
        for _ in range(h.ctrl.num_substeps):
            q, qd = random_state(h, rng, 0.4)
            h.ctrl.before_simulation_step(h.state, h.control)
            u = F32(300.0) * (target - q) + F32(30.0) * (F32(0) - qd)
            np.testing.assert_allclose(c.computed_effort.numpy(), u, rtol=1e-6, atol=1e-4)
            np.testing.assert_allclose(c.applied_effort.numpy(), np.clip(u, -lim, lim), rtol=1e-6, atol=1e-4)
            if actuation == "explicit":
                np.testing.assert_array_equal(c.applied_effort.numpy(), h.joint_f())
            count += np.abs(u) > lim
    assert count.sum() > 10 and (count < 15).any()
    np.testing.assert_array_equal(c.saturation_count.numpy(), count)
    h.ctrl.reset(h.state, env_ids=[0, 2])
    count[[0, 2]] = 0
    np.testing.assert_array_equal(c.saturation_count.numpy(), count)


def test_effort_readout_is_off_by_default():
    c = Harness(arm_abs(), num_envs=1).ctrl
    assert c.computed_effort is None and c.applied_effort is None and c.saturation_count is None and c.delay is None
    assert c._engine.part("delay") is None  # private: no delay part, so no history buffer is allocated


# ----------------------------------------------------------------------------------------------------------------------
# Target clamping.


@pytest.mark.parametrize("clip", ["none", "joint_limits"])
def test_clip_targets_keeps_a_virtual_target_inside_the_limits(clip):
    mode = {
        "arm": delta_arm(use_target=True),
        "fingers": wpctrl.PDJointPosMimicControllerConfig(
            FINGERS,
            -0.01,
            0.04,
            1e3,
            1e2,
            100,
            mimic={"panda_finger_joint2": {"joint": "panda_finger_joint1", "multiplier": 2.0}},
        ),
    }
    h = Harness(mode, num_envs=2, clip_targets=clip)
    h.ctrl.reset(h.state)
    lim = h.ctrl.joint_limits
    for _ in range(60):  # +0.1 rad per step on the arm: 6 rad, past every limit
        h.act(np.ones(8, F32))
        h.substeps(1)
    t = h.ctrl.target_qpos.numpy()
    if clip == "none":
        assert (t[:, :7] > lim[:7, 1]).all()  # ManiSkill's behaviour: the virtual target runs away
        assert (t[:, 8] > lim[8, 1]).all()
    else:
        np.testing.assert_array_equal(
            t, np.broadcast_to(np.minimum(np.array([*lim[:7, 1], 0.04, 0.08]), lim[:, 1]), t.shape)
        )
        np.testing.assert_array_equal(h.drive_q(), t)
        for _ in range(3):  # one step back moves off the limit at once (no wind-up)
            h.act(-np.ones(8, F32))
        np.testing.assert_allclose(h.ctrl.target_qpos.numpy()[:, :7], np.tile(lim[:7, 1] - 0.3, (2, 1)), atol=1e-5)


# ----------------------------------------------------------------------------------------------------------------------
# Errors: the field, expected and received.


@pytest.mark.parametrize(
    "call, fragments",
    [
        (lambda c: c.set_drive_properties(stiffness=[-1.0] * 7), ["set_drive_properties.stiffness", ">= 0", "-1.0"]),
        (lambda c: c.set_drive_properties(damping=[np.nan] * 7), ["set_drive_properties.damping", "finite", "nan"]),
        (lambda c: c.set_drive_properties(friction=np.inf * np.ones(7)), ["set_drive_properties.friction", "inf"]),
        (lambda c: c.set_drive_properties(stiffness=[1.0] * 3), ["set_drive_properties.stiffness", "(7,)", "(3,)"]),
        (
            lambda c: c.set_drive_properties(stiffness=np.ones((2, 7)), env_ids=[0, 1, 2]),
            ["stiffness", "(3, 7)", "(2, 7)"],
        ),
        (
            lambda c: c.randomize_drive_properties(stiffness=(2.0, 1.0)),
            ["randomize_drive_properties.stiffness", "lo <= hi"],
        ),
        (
            lambda c: c.randomize_drive_properties(damping=(-1.0, 1.0)),
            ["randomize_drive_properties.damping", "(-1.0, 1.0)"],
        ),
        (lambda c: c.randomize_drive_properties(force_limit=5.0), ["force_limit", "(lo, hi)", "5.0"]),
        (lambda c: c.randomize_drive_properties(stiffness=(1, 2), mode="mul"), ["mode", "'scale'", "'mul'"]),
        (lambda c: c.randomize_drive_properties(stiffness=(1, 2), seed=1.5), ["seed", "int32", "1.5"]),
        (lambda c: setattr(c, "delay", np.zeros(N, np.int32)), ["delay", "without delay="]),
    ],
)
def test_bad_actuation_inputs(call, fragments):
    h = Harness(arm_abs(), num_envs=N)
    before = h.model.joint_target_ke.numpy().copy()
    with pytest.raises(ValueError) as e:
        call(h.ctrl)
    for f in fragments:
        assert f in str(e.value), (f, str(e.value))
    np.testing.assert_array_equal(h.model.joint_target_ke.numpy(), before)  # nothing reached the model


@pytest.mark.parametrize(
    "kw, fragments",
    [
        ({"delay": -1}, ["delay", "0 <= min_substeps", "(-1, -1)"]),
        ({"delay": (3, 1)}, ["delay", "(3, 1)"]),
        ({"delay": 1.5}, ["delay", "1.5"]),
        ({"clip_targets": "limits"}, ["clip_targets", "'joint_limits'", "'limits'"]),
        ({"track_effort": 1}, ["track_effort", "bool", "1"]),
        ({"delay_seed": "a"}, ["delay_seed", "'a'"]),
    ],
)
def test_bad_build_options(kw, fragments):
    model = build_panda(1)
    with pytest.raises(ValueError) as e:
        wpctrl.build_controller(arm_abs(), model, **kw)
    for f in fragments:
        assert f in str(e.value), (f, str(e.value))


def test_delay_setter_checks_range():
    h = Harness(arm_abs(), num_envs=N, delay=(0, 2))
    with pytest.raises(ValueError, match=r"delay: expected 4 ints in \[0, 2\]"):
        h.ctrl.delay = [0, 1, 2, 3]
    h.ctrl.delay = 2
    assert h.ctrl.delay.numpy().tolist() == [2] * N


# ----------------------------------------------------------------------------------------------------------------------
# MuJoCo-Warp: per-world gains after the notice, the notice inside a graph, and rollouts of 64 Pandas.


def _arm_rollout(ctrl, solver, model, goal, steps):
    s0, s1, c = model.state(), model.state(), model.control()
    ctrl.reset(s0, control=c)
    coord = ctrl.coord_index
    err = []
    for _ in range(steps):
        ctrl.set_action(np.broadcast_to(goal, (model.world_count, 7)).copy(), s0)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(s0, c)
            solver.step(s0, s1, c, None, 0.01)
            s0, s1 = s1, s0
            err.append(np.abs(s0.joint_q.numpy()[coord] - goal))
    return np.array(err), s0  # (substeps, envs, joints) [rad]


def test_mujoco_per_env_stiffness_and_delay_rollout():
    n = 64
    model = build_panda(n)
    cfg = wpctrl.PDJointPosControllerConfig(PANDA_ARM_JOINTS, None, None, 1000.0, 100.0, 100.0, normalize_action=False)
    ctrl = wpctrl.build_controller(cfg, model, 20, 100)
    solver = newton.solvers.SolverMuJoCo(model, disable_contacts=True)
    ctrl.attach_solver(solver)
    goal = (np.asarray(PANDA_INITIAL_Q[:7], F32) + F32(0.3)).astype(F32)
    steps = 4

    e_nom, s = _arm_rollout(ctrl, solver, model, goal, steps)
    assert np.isfinite(s.joint_q.numpy()).all()
    assert e_nom.mean(axis=2).std(axis=1).max() < 1e-5  # identical envs track identically

    # The notice reaches MuJoCo-Warp's per-world actuators: randomise inside a captured graph, replay.
    with wp.ScopedCapture(device="cpu") as cap:
        ctrl.randomize_drive_properties(stiffness=(0.5, 2.0), seed=11)
    wp.capture_launch(cap.graph)
    kp = ctrl.stiffness.numpy()
    gain = solver.mjw_model.actuator_gainprm.numpy()[:, :, 0]  # (worlds, actuators): position actuators first
    np.testing.assert_array_equal(gain[:, :7], kp)
    e_rand, s = _arm_rollout(ctrl, solver, model, goal, steps)
    assert np.isfinite(s.joint_q.numpy()).all()
    mid = e_rand[10]  # 0.1 s into the step response
    spread = mid.mean(axis=1)
    assert spread.max() > 1.15 * spread.min(), spread  # visibly different error per env
    for j in range(7):  # stiffer joints are closer to the goal
        rank = np.corrcoef(np.argsort(np.argsort(kp[:, j])), np.argsort(np.argsort(mid[:, j])))[0, 1]
        assert rank < -0.5, (j, rank)

    ctrl.set_drive_properties(stiffness=np.full(7, 1000.0))
    delayed = wpctrl.build_controller(cfg, model, 20, 100, delay=2, solver=solver)
    e_del, s = _arm_rollout(delayed, solver, model, goal, steps)
    assert np.isfinite(s.joint_q.numpy()).all()
    assert (e_del[:, 0, :].mean(axis=1)[2:12] > e_nom[:, 0, :].mean(axis=1)[2:12]).all()  # the response lags
    assert e_del.mean() > 1.05 * e_nom.mean()


@pytest.mark.skipif(not HAS_CUDA, reason="no CUDA device")
def test_cuda_captured_randomisation_reaches_mujoco():
    with wp.ScopedDevice("cuda:0"):
        model = build_panda(4, device="cuda:0")
        ctrl = wpctrl.build_controller(arm_abs(), model, 20, 100)
        solver = newton.solvers.SolverMuJoCo(model, disable_contacts=True)
        ctrl.attach_solver(solver)
        mask = wp.array([True, False, True, False], dtype=wp.bool)
        with wp.ScopedCapture() as cap:
            ctrl.randomize_drive_properties(env_ids=mask, stiffness=(0.5, 2.0))
        seen = []
        for _ in range(2):
            wp.capture_launch(cap.graph)
            kp = ctrl.stiffness.numpy()
            np.testing.assert_array_equal(solver.mjw_model.actuator_gainprm.numpy()[:, :7, 0], kp)
            seen.append(kp.copy())
        assert (seen[0][[0, 2]] != seen[1][[0, 2]]).all()
        np.testing.assert_array_equal(seen[1][[1, 3]], 400.0)
