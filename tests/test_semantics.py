"""Every sentence of section 3 of tests/data/maniskill-controllers.md (ManiSkill 3.0.1 controller behaviour), numbered
as there.

Each test asserts ManiSkill's behaviour against closed-form values, or wpctrl's documented deliberate difference
(marked DIFFERENCE, listed in docs/semantics.md).
"""

from __future__ import annotations

import copy

import numpy as np
import pytest
import warp as wp
from harness import ARM, FINGERS, Harness, delta_arm, gripper

import wpctrl

f32 = np.float32
PANDA_LIMITS = np.array(
    [
        [-2.8973, 2.8973],
        [-1.7628, 1.7628],
        [-2.8973, 2.8973],
        [-3.0718, -0.0698],
        [-2.8973, 2.8973],
        [-0.0175, 3.7525],
        [-2.8973, 2.8973],
    ],
    np.float32,
)


# --- Action spaces and dtype ---------------------------------------------------------------------------------------


def test_01_float32_box_and_original_space():
    h = Harness(delta_arm())
    sp = h.ctrl.single_action_space
    assert sp.dtype == np.float32 and sp.shape == (7,)
    assert (sp.low == -1).all() and (sp.high == 1).all()
    assert np.array_equal(h.ctrl._original_single_action_space.low, np.full(7, f32(-0.1)))


def test_02_batched_space_and_unbatched_single_env():
    h = Harness({"arm": delta_arm(), "gripper": gripper()}, num_envs=3)
    assert h.ctrl.action_space.shape == (3, 8)
    h1 = Harness({"arm": delta_arm(), "gripper": gripper()}, num_envs=1)
    assert h1.ctrl.action_space.shape == (8,)
    # DIFFERENCE: with one env a (D,) action is accepted (as ManiSkill's env does before calling the controller),
    # and means what the (1, D) action means, for every input kind.
    a = np.array([0.5, -1.5, 0.25, 1.0, -0.2, 0.0, 0.9, 0.3], np.float32)
    q = np.linspace(-0.5, 0.5, 9).astype(np.float32)
    h1.put(q)
    h1.ctrl.reset(h1.state)
    c = np.clip(a, -1, 1)
    lo, hi = f32(-0.01), f32(0.04)
    finger = f32(0.5) * (hi + lo) + f32(0.5) * (hi - lo) * c[7]
    want = np.concatenate([q[:7] + f32(0.1) * c[:7], [finger, finger]])[None, :]
    torch = pytest.importorskip("torch", reason="torch is a dev dependency")
    for x in (a, wp.array(a, dtype=wp.float32), torch.from_numpy(a.copy()), a.astype(np.float64)):
        h1.ctrl.set_action(x, h1.state)
        np.testing.assert_allclose(h1.ctrl.target_qpos.numpy(), want, atol=1e-7)
        np.testing.assert_array_equal(h1.ctrl.processed_action.numpy()[0, :7], f32(0.1) * c[:7])
        assert h1.ctrl.bad_action_count.numpy().tolist() == [0]
    with pytest.raises(ValueError, match=r"expected shape \(3, 8\)"):
        h.ctrl.set_action(np.zeros(8, np.float32), h.state)


def test_03_none_bounds_take_joint_limits():
    h = Harness(wpctrl.PDJointPosControllerConfig(ARM, None, None, 1e3, 1e2, normalize_action=False))
    np.testing.assert_array_equal(h.ctrl.single_action_space.low, PANDA_LIMITS[:, 0])
    np.testing.assert_array_equal(h.ctrl.single_action_space.high, PANDA_LIMITS[:, 1])
    # each bound independently
    h = Harness(wpctrl.PDJointPosControllerConfig(ARM, -0.5, None, 1e3, 1e2, normalize_action=False))
    assert (h.ctrl.single_action_space.low == f32(-0.5)).all()
    np.testing.assert_array_equal(h.ctrl.single_action_space.high, PANDA_LIMITS[:, 1])


def test_04_scalar_or_per_joint_sequences():
    per = [0.1 * (i + 1) for i in range(7)]
    h = Harness(wpctrl.PDJointPosControllerConfig(ARM, -0.1, per, per, 50.0, force_limit=per, friction=0.5))
    np.testing.assert_array_equal(h.ctrl._original_single_action_space.high, np.array(per, np.float32))
    np.testing.assert_array_equal(h.model.joint_target_ke.numpy()[h.dof[0]], np.array(per, np.float32))
    np.testing.assert_array_equal(h.model.joint_target_kd.numpy()[h.dof[0]], np.full(7, 50.0, np.float32))
    np.testing.assert_array_equal(h.model.joint_friction.numpy()[h.dof[0]], np.full(7, 0.5, np.float32))
    with pytest.raises(ValueError, match="stiffness"):
        Harness(wpctrl.PDJointPosControllerConfig(ARM, -0.1, 0.1, [1.0, 2.0], 1.0))


def test_05_mimic_bounds_indexed_over_all_joints():
    f2, f1 = FINGERS[1], FINGERS[0]
    cfg = wpctrl.PDJointPosMimicControllerConfig(
        [f2, f1], [0.0, -0.5], None, 1e3, 1e2, normalize_action=False, mimic={f2: {"joint": f1}}
    )
    h = Harness(cfg)
    np.testing.assert_array_equal(h.ctrl.single_action_space.low, [f32(-0.5)])
    np.testing.assert_array_equal(h.ctrl.single_action_space.high, [f32(0.04)])


def test_06_vel_without_bounds_raises():
    with pytest.raises(ValueError, match="lower"):
        Harness(wpctrl.PDJointVelControllerConfig(ARM, None, 1.0, 1e2))


def test_07_passive_has_zero_width_action():
    h = Harness({"arm": delta_arm(), "fingers": wpctrl.PassiveControllerConfig(FINGERS, damping=5.0)})
    assert h.ctrl["fingers"].single_action_space.shape == (0,)
    assert h.ctrl.action_mapping == {"arm": (0, 7), "fingers": (7, 7)}
    assert h.ctrl.single_action_space.shape == (7,)


def test_08_combined_layout_is_insertion_order():
    h = Harness({"gripper": gripper(), "arm": delta_arm()})
    assert h.ctrl.action_mapping == {"gripper": (0, 1), "arm": (1, 8)}
    assert h.ctrl.joint_names == FINGERS + ARM


# --- Normalization -------------------------------------------------------------------------------------------------


def test_09_clip_then_scale_saturates():
    h = Harness(wpctrl.PDJointPosControllerConfig(ARM, -0.3, 0.7, 1e3, 1e2))
    h.ctrl.reset(h.state)
    h.act([5, -5, 0, 0.5, -1, 1, 0.25])
    lo, hi = f32(-0.3), f32(0.7)
    a = np.clip(np.array([5, -5, 0, 0.5, -1, 1, 0.25], np.float32), -1, 1)
    ref = f32(0.5) * (hi + lo) + f32(0.5) * (hi - lo) * a
    np.testing.assert_array_equal(h.ctrl.processed_action.numpy()[0], ref)
    assert h.ctrl.processed_action.numpy()[0, 0] == hi and h.ctrl.processed_action.numpy()[0, 1] == lo


def test_10_gripper_values():
    h = Harness(gripper())
    h.ctrl.reset(h.state)
    for a, want in [(-1, -0.00999999885), (0, 0.015), (0.5, 0.0275), (1, 0.04)]:
        h.act([a])
        np.testing.assert_allclose(h.ctrl.target_qpos.numpy()[0], [want, want], atol=1e-6)
        np.testing.assert_allclose(h.substeps(1)[0][0], [want, want], atol=1e-6)


def test_11_no_clip_without_normalization():
    h = Harness(wpctrl.PDJointPosControllerConfig(ARM, None, None, 1e3, 1e2, normalize_action=False))
    h.ctrl.reset(h.state)
    h.act([10, 0, 0, -1, 0, 1, 0])
    assert h.substeps(1)[0][0, 0] == f32(10)


def test_12_infinite_bounds_with_normalization_raise():
    # DIFFERENCE: ManiSkill produces NaN targets; wpctrl refuses at construction.
    import newton

    b = newton.ModelBuilder()
    link = b.add_link(mass=1.0, inertia=wp.mat33(np.eye(3) * 0.01))
    j = b.add_joint_revolute(-1, link, axis=(0, 0, 1), label="wheel")  # no limits
    b.add_articulation([j])
    model = b.finalize(device="cpu")
    with pytest.raises(ValueError, match="finite bounds"):
        wpctrl.build_controller(wpctrl.PDJointPosControllerConfig(["wheel"], None, None, 1.0, 1.0), model)
    ctrl = wpctrl.build_controller(
        wpctrl.PDJointPosControllerConfig(["wheel"], None, None, 1.0, 1.0, normalize_action=False), model
    )
    assert np.isinf(ctrl.single_action_space.low).all()


# --- Delta, target and absolute modes ------------------------------------------------------------------------------


def test_13_delta_from_measured_q_at_set_action():
    h = Harness(delta_arm())
    h.ctrl.reset(h.state)
    q = np.linspace(-0.5, 0.5, 7).astype(np.float32) + np.array([0, 0, 0, -2, 0, 2, 0], np.float32)
    h.put(q)
    h.act(np.full(7, 0.5))
    np.testing.assert_array_equal(h.ctrl.target_qpos.numpy()[0], q + f32(0.05))


def test_14_delta_on_virtual_target_accumulates():
    h = Harness(delta_arm(use_target=True))
    q0 = h.q()[0].copy()
    h.ctrl.reset(h.state)
    measured = [0.025, 0.079, 0.156]
    expect = q0.copy()
    for m in measured:
        h.act(np.ones(7))
        expect = expect + f32(0.1)
        np.testing.assert_allclose(h.ctrl.target_qpos.numpy()[0], expect, atol=1e-6)
        h.put(q0 + f32(m))  # the robot lags: the virtual target does not care
    h.put(q0 + f32(1.0))
    h.ctrl.reset(h.state)
    np.testing.assert_array_equal(h.ctrl.target_qpos.numpy()[0], q0 + f32(1.0))


@pytest.mark.parametrize("use_target", [False, True])
def test_15_absolute_ignores_use_target(use_target):
    h = Harness(wpctrl.PDJointPosControllerConfig(ARM, -1, 1, 1e3, 1e2, use_target=use_target))
    h.ctrl.reset(h.state)
    for _ in range(2):
        h.act(np.full(7, 0.5))
        np.testing.assert_array_equal(h.ctrl.target_qpos.numpy()[0], np.full(7, f32(0.5)))


def test_16_targets_never_clipped_to_joint_limits():
    h = Harness(delta_arm(use_target=True))
    h.ctrl.reset(h.state)
    q0 = h.q()[0]
    for _ in range(40):
        h.act(np.ones(7))
    t = h.ctrl.target_qpos.numpy()[0]
    np.testing.assert_allclose(t, q0 + 4.0, atol=1e-4)
    assert (t > PANDA_LIMITS[:, 1]).any()
    assert (h.substeps(1)[0][0] == t).all()


def test_17_set_state_then_delta():
    h = Harness(delta_arm(use_target=True))
    h.ctrl.reset(h.state)
    X = np.arange(7, dtype=np.float32)[None, :] * f32(0.1)
    h.ctrl.set_state({"target_qpos": X})
    h.act(np.full(7, -1.0))
    np.testing.assert_allclose(h.ctrl.target_qpos.numpy(), X - f32(0.1), atol=1e-7)


def test_18_get_state_is_live_and_empty_without_use_target():
    assert Harness(delta_arm()).ctrl.get_state() == {}
    h = Harness({"arm": delta_arm(use_target=True), "gripper": gripper()})
    st = h.ctrl.get_state()
    assert list(st) == ["arm"] and list(st["arm"]) == ["target_qpos"]
    h.ctrl.reset(h.state)
    view = st["arm"]["target_qpos"]
    h.act(np.ones(8))
    h.put(np.zeros(9))
    h.ctrl.reset(h.state)  # the live view sees the reset
    np.testing.assert_array_equal(view.numpy(), np.zeros((1, 7), np.float32))


# --- Interpolation -------------------------------------------------------------------------------------------------


def _interp_arm(**kw):
    return wpctrl.PDJointPosControllerConfig(ARM, -0.1, 0.1, 1e3, 1e2, use_delta=True, interpolate=True, **kw)


def test_19_interpolated_substeps():
    h = Harness(_interp_arm())
    q = np.array([0, 0, 0, -2, 0, 2, 0], np.float32)
    h.put(q)
    h.ctrl.reset(h.state)
    before = h.drive_q().copy()
    h.act(np.ones(7))
    np.testing.assert_array_equal(h.drive_q(), before)  # set_action writes no drive target
    subs = h.substeps()
    for k, d in enumerate(subs, 1):
        np.testing.assert_allclose(d[0], q + f32(0.02) * k, atol=1e-6)
    # ManiSkill's exact float32 rounding: start + ((target - start) / K) * k
    step = ((q + f32(0.1)) - q) / f32(5)
    np.testing.assert_array_equal(subs[2][0], q + step * f32(3))


def test_20_step_counter():
    h = Harness(delta_arm())
    h.ctrl.reset(h.state)
    h.substeps(3)
    assert h.ctrl.step_counter.numpy()[0] == 3
    h.act(np.zeros(7))
    assert h.ctrl.step_counter.numpy()[0] == 0
    h.substeps(2)
    h.ctrl.reset(h.state)
    assert h.ctrl.step_counter.numpy()[0] == 0


def test_21_stepping_past_k_holds_the_target():
    # DIFFERENCE: ManiSkill extrapolates (0.12 ... 0.20); wpctrl holds the last substep's value.
    h = Harness(_interp_arm())
    h.put(np.zeros(7))
    h.ctrl.reset(h.state)
    h.act(np.ones(7))
    last = h.substeps()[-1]
    for d in h.substeps():  # "env.step(None)": no set_action, K more substeps
        np.testing.assert_array_equal(d, last)
    np.testing.assert_allclose(last[0], np.full(7, 0.1), atol=1e-6)


def test_22_substep_before_any_action_holds_reset_target():
    # DIFFERENCE: ManiSkill raises AttributeError; wpctrl holds the reset pose.
    h = Harness(_interp_arm())
    q = np.array([0.1, 0.2, 0.3, -2, 0, 2, 0], np.float32)
    h.put(q)
    h.ctrl.reset(h.state)
    for d in h.substeps():
        np.testing.assert_array_equal(d[0], q)


def test_23_same_kernel_on_every_device():
    # DIFFERENCE: ManiSkill's GPU interpolation lags a control step (#1071). wpctrl's substep kernel writes the
    # Control directly on every device; the CPU/CUDA parity run is in tests/test_cuda.py.
    h = Harness(_interp_arm())
    h.put(np.zeros(7))
    h.ctrl.reset(h.state)
    h.act(np.ones(7))
    assert np.allclose(h.substeps(1)[0][0], 0.02)  # applied in the very substep it belongs to


# --- Reset ---------------------------------------------------------------------------------------------------------


def test_24_reset_sets_start_and_target_to_q_first_reset_all():
    h = Harness(delta_arm(use_target=True), num_envs=4)
    q = np.random.default_rng(0).uniform(-1, 1, (4, 7)).astype(np.float32)
    h.put(q)
    h.ctrl.reset(h.state, env_ids=[1])  # the first reset initialises every env, as ManiSkill's
    np.testing.assert_array_equal(h.ctrl.target_qpos.numpy(), q)
    np.testing.assert_array_equal(h.ctrl.start_qpos.numpy(), q)
    h.act(np.ones((4, 7)))
    h.put(q + 1)
    h.ctrl.reset(h.state, env_ids=[1, 3])
    t = h.ctrl.target_qpos.numpy()
    np.testing.assert_array_equal(t[[1, 3]], q[[1, 3]] + 1)
    np.testing.assert_array_equal(t[[0, 2]], q[[0, 2]] + f32(0.1))


def test_25_reset_writes_drive_targets():
    # DIFFERENCE: ManiSkill leaves the stale drive target until the next set_action; wpctrl's reset envs hold still.
    h = Harness(delta_arm(), num_envs=2)
    h.ctrl.reset(h.state)
    h.act(np.ones((2, 7)))
    h.substeps()
    q = np.full((2, 7), -0.5, np.float32)
    h.put(q)
    h.ctrl.reset(h.state, env_ids=[0], control=h.control)  # written at once with a control ...
    np.testing.assert_array_equal(h.drive_q()[0], q[0])
    assert not np.array_equal(h.drive_q()[1], q[1])
    h.ctrl.reset(h.state, env_ids=[1])  # ... or by the next substep without one
    np.testing.assert_array_equal(h.substeps(1)[0], q)


def test_26_partial_reset_leaves_other_envs_alone():
    # DIFFERENCE: ManiSkill re-initialises every env's buffers on any reset.
    h = Harness(delta_arm(use_target=True), num_envs=6)
    h.ctrl.reset(h.state)
    rng = np.random.default_rng(1)
    h.act(rng.uniform(-1, 1, (6, 7)))
    before = h.ctrl.target_qpos.numpy().copy()
    h.put(rng.uniform(-1, 1, (6, 7)))
    mask = np.array([True, False, False, True, False, False])
    h.ctrl.reset(h.state, env_ids=mask)
    after = h.ctrl.target_qpos.numpy()
    np.testing.assert_array_equal(after[~mask], before[~mask])
    np.testing.assert_array_equal(after[mask], h.q()[mask])


def test_27_posvel_reset_of_target_qvel():
    cfg = wpctrl.PDJointPosVelControllerConfig(ARM, -0.1, 0.1, 1e3, 1e2, use_delta=True)
    h = Harness(cfg, num_envs=2)
    qd = np.full((2, 7), 0.3, np.float32)
    h.put(qd=qd)
    h.ctrl.reset(h.state)  # first reset: the measured velocity
    np.testing.assert_array_equal(h.ctrl.target_qvel.numpy(), qd)
    h.act(np.ones((2, 14)))
    h.ctrl.reset(h.state, env_ids=[1])  # later resets: 0 for the reset envs
    np.testing.assert_array_equal(h.ctrl.target_qvel.numpy(), [np.full(7, 1.0, np.float32), np.zeros(7)])


def test_28_rebuilding_a_mode_reapplies_drive_properties():
    # ManiSkill's mode switch keeps stale drive properties; wpctrl has no agent: building a controller applies them.
    h = Harness(delta_arm())
    wpctrl.build_controller(wpctrl.PDJointVelControllerConfig(ARM, -1.0, 1.0, 1e2), h.model)
    assert not h.model.joint_target_ke.numpy()[h.dof[0]].any()
    wpctrl.build_controller(delta_arm(), h.model)
    assert (h.model.joint_target_ke.numpy()[h.dof[0]] == 1e3).all()


# --- Mimic ---------------------------------------------------------------------------------------------------------


def test_29_action_columns_follow_joint_order():
    names = [ARM[0], ARM[1], ARM[2], ARM[3]]
    # dict order: ARM[3]'s controller first, but columns follow ascending position in joint_names
    mimic = {ARM[0]: {"joint": ARM[3]}, ARM[2]: {"joint": ARM[1]}}
    cfg = wpctrl.PDJointPosMimicControllerConfig(names, -1, 1, 1.0, 1.0, normalize_action=False, mimic=mimic)
    h = Harness(cfg)
    h.ctrl.reset(h.state)
    assert h.ctrl.single_action_space.shape == (2,)
    h.act([0.25, -0.75])
    np.testing.assert_array_equal(h.ctrl.target_qpos.numpy()[0], f32([-0.75, 0.25, 0.25, -0.75]))


def test_30_mimic_formula_and_delta_target_offsets():
    f1, f2 = FINGERS
    cfg = wpctrl.PDJointPosMimicControllerConfig(
        FINGERS, -1, 1, 1.0, 1.0, normalize_action=False, mimic={f2: {"joint": f1, "multiplier": -2.0, "offset": 0.01}}
    )
    h = Harness(cfg)
    h.ctrl.reset(h.state)
    h.act([0.03])
    np.testing.assert_allclose(h.ctrl.target_qpos.numpy()[0], [0.03, -0.05], atol=1e-7)
    cfg = wpctrl.PDJointPosMimicControllerConfig(
        FINGERS, -1, 1, 1.0, 1.0, normalize_action=False, use_delta=True, use_target=True,
        mimic={f2: {"joint": f1, "offset": 0.002}},
    )  # fmt: skip
    h = Harness(cfg)
    h.put(np.zeros(2))
    h.ctrl.reset(h.state)
    for i in range(1, 4):
        h.act([0.01])
        np.testing.assert_allclose(h.ctrl.target_qpos.numpy()[0], [0.01 * i, 0.01 * i + 0.002], atol=1e-7)


def test_31_empty_mimic_defaults_and_errors(caplog):
    f1, f2 = FINGERS
    cfg = wpctrl.PDJointPosMimicControllerConfig(FINGERS, -1, 1, 1.0, 1.0, normalize_action=False)
    with caplog.at_level("WARNING", logger="wpctrl"):
        h = Harness(cfg)
    # DIFFERENCE (README): the config is not mutated, and the warning says which joint follows which
    assert [r.getMessage() for r in caplog.records if r.name == "wpctrl"] == [
        f"PDJointPosMimicControllerConfig.mimic is empty: {f1!r} follows {f2!r} (the second joint is commanded, as "
        "in ManiSkill)"
    ]
    h.ctrl.reset(h.state)
    h.act([0.02])  # the second joint is commanded, the first follows
    np.testing.assert_allclose(h.ctrl.target_qpos.numpy()[0], [0.02, 0.02])
    assert cfg.mimic == {}  # wpctrl does not mutate the user's config
    with pytest.raises(ValueError, match="empty mimic map"):
        Harness(wpctrl.PDJointPosMimicControllerConfig(ARM[:3], -1, 1, 1.0, 1.0))


def test_32_joints_outside_the_mimic_map_stay_frozen():
    names = [ARM[0], ARM[1], ARM[2]]
    cfg = wpctrl.PDJointPosMimicControllerConfig(
        names, -1, 1, 1.0, 1.0, normalize_action=False, mimic={ARM[1]: {"joint": ARM[0]}}
    )
    h = Harness(cfg)
    h.put([0.1, 0.2, 0.3])
    h.ctrl.reset(h.state)
    h.put([0.5, 0.5, 0.5])
    for a in (0.4, -0.4):
        h.act([a])
        d = h.substeps(1)[0][0]
        np.testing.assert_allclose(d, [a, a, 0.3], atol=1e-7)  # still written every step, frozen at reset q


def test_33_control_joint_missing_from_joint_names():
    cfg = wpctrl.PDJointPosMimicControllerConfig(FINGERS, -1, 1, 1.0, 1.0, mimic={FINGERS[1]: {"joint": ARM[0]}})
    with pytest.raises(TypeError, match="not in joint_names"):
        Harness(cfg)


# --- Drives --------------------------------------------------------------------------------------------------------


def test_34_drive_properties_written_per_joint():
    import newton

    mode = {
        "arm": wpctrl.PDJointPosControllerConfig(
            ARM, -0.1, 0.1, 1e3, 1e2, 87.0, friction=0.1, drive_mode=["force"] * 7
        ),
        "fingers": wpctrl.PassiveControllerConfig(FINGERS, damping=3.0, force_limit=20.0),
    }
    h = Harness(mode)
    m, dof = h.model, h.dof[0]
    np.testing.assert_array_equal(m.joint_target_ke.numpy()[dof], [1e3] * 7 + [0, 0])
    np.testing.assert_array_equal(m.joint_target_kd.numpy()[dof], [1e2] * 7 + [3, 3])
    np.testing.assert_array_equal(m.joint_effort_limit.numpy()[dof], [87] * 7 + [20, 20])
    np.testing.assert_array_equal(m.joint_friction.numpy()[dof], np.array([0.1] * 7 + [0, 0], np.float32))
    P, V = int(newton.JointTargetMode.POSITION), int(newton.JointTargetMode.VELOCITY)
    np.testing.assert_array_equal(m.joint_target_mode.numpy()[dof], [P] * 7 + [V, V])
    hv = Harness(wpctrl.PDJointVelControllerConfig(ARM, -1.0, 1.0, 1e2))
    assert not hv.model.joint_target_ke.numpy()[hv.dof[0]].any()
    # per-joint drive_mode sequence, indexed by joint order: only the acceleration joints get inertia-scaled gains
    ha = Harness(
        wpctrl.PDJointPosControllerConfig(ARM, -0.1, 0.1, 1e3, 1e2, drive_mode=["acceleration"] + ["force"] * 6)
    )
    ke = ha.model.joint_target_ke.numpy()[ha.dof[0]]
    assert ke[0] != 1e3 and (ke[1:] == 1e3).all()  # tests/test_acceleration.py checks the scaling itself


def test_35_velocity_targets_are_the_scaled_action():
    h = Harness(wpctrl.PDJointVelControllerConfig(ARM, -1.0, 1.0, 1e2))
    h.ctrl.reset(h.state)
    h.act([0.5, -2, 3, 0, 1, -1, 0.25])
    h.substeps(1)
    np.testing.assert_array_equal(h.drive_qd()[0], f32([0.5, -1, 1, 0, 1, -1, 0.25]))  # no URDF velocity limits


def test_36_posvel_velocity_half_written_once_never_interpolated():
    cfg = wpctrl.PDJointPosVelControllerConfig(ARM, -0.1, 0.1, 1e3, 1e2, use_delta=True, interpolate=True)
    h = Harness(cfg)
    h.put(np.zeros(7))
    h.ctrl.reset(h.state)
    h.act(np.concatenate([np.ones(7), np.full(7, 0.5)]))
    for k in range(1, 6):
        d = h.substeps(1)[0]
        np.testing.assert_allclose(d[0], np.full(7, 0.02 * k), atol=1e-6)
        np.testing.assert_array_equal(h.drive_qd()[0], np.full(7, 0.5, np.float32))


# --- Env plumbing --------------------------------------------------------------------------------------------------


def test_37_float64_accepted_and_nan_held():
    h = Harness(delta_arm(use_target=True), num_envs=2)
    h.ctrl.reset(h.state)
    a = np.random.default_rng(2).uniform(-1, 1, (2, 7))
    h.ctrl.set_action(a, h.state)  # float64 numpy
    t64 = h.ctrl.target_qpos.numpy().copy()
    h2 = Harness(delta_arm(use_target=True), num_envs=2)
    h2.ctrl.reset(h2.state)
    h2.ctrl.set_action(a.astype(np.float32), h2.state)
    np.testing.assert_array_equal(h2.ctrl.target_qpos.numpy(), t64)
    # DIFFERENCE: ManiSkill raises on any NaN (CPU sim only); wpctrl holds that env and counts it by default.
    bad = a.copy()
    bad[1, 3] = np.nan
    h.ctrl.set_action(bad, h.state)
    t = h.ctrl.target_qpos.numpy()
    np.testing.assert_array_equal(t[1], t64[1])
    assert not np.array_equal(t[0], t64[0])
    np.testing.assert_array_equal(h.ctrl.bad_action_count.numpy(), [0, 1])
    hr = Harness(delta_arm(), num_envs=2, nan_policy="raise")
    with pytest.raises(ValueError, match="non-finite"):
        hr.ctrl.set_action(bad, hr.state)
    # Any column: env c gets NaN, +Inf or -Inf in column c of the flat arm + gripper action; the last env none.
    n = 9
    hm = Harness({"arm": delta_arm(use_target=True), "gripper": gripper()}, num_envs=n)
    hm.ctrl.reset(hm.state)
    hm.act(np.zeros((n, 8), np.float32))
    before = hm.ctrl.target_qpos.numpy().copy()
    a = np.full((n, 8), 0.5, np.float32)
    for c in range(8):
        a[c, c] = (np.nan, np.inf, -np.inf)[c % 3]
    hm.act(a)
    t = hm.ctrl.target_qpos.numpy()
    np.testing.assert_array_equal(t[:8], before[:8])
    assert (t[8] != before[8]).all()
    np.testing.assert_array_equal(hm.ctrl.bad_action_count.numpy(), [1] * 8 + [0])


def test_38_from_qpos_not_provided():
    # ManiSkill's CombinedController.from_qpos / to_action_dict (1-D only) have no counterpart: wpctrl works on
    # batched arrays only, and action_mapping slices a flat batch the way to_action_dict splits one action.
    ms = pytest.importorskip("mani_skill.agents.controllers.base_controller", reason="mani-skill is a dev dependency")
    assert callable(ms.CombinedController.from_qpos) and callable(ms.CombinedController.to_action_dict)
    n = 3
    h = Harness({"arm": delta_arm(), "gripper": gripper()}, num_envs=n)
    assert not hasattr(h.ctrl, "from_qpos") and not hasattr(h.ctrl, "to_action_dict")
    a = np.random.default_rng(38).uniform(-1.5, 1.5, (n, 8)).astype(np.float32)
    h.ctrl.reset(h.state)
    h.act(a)
    lo, hi = f32(-0.01), f32(0.04)
    want = {"arm": f32(0.1) * np.clip(a[:, :7], -1, 1)}
    want["gripper"] = f32(0.5) * (hi + lo) + f32(0.5) * (hi - lo) * np.clip(a[:, 7:], -1, 1)
    assert h.ctrl.action_mapping == {"arm": (0, 7), "gripper": (7, 8)}
    for uid, (s, e) in h.ctrl.action_mapping.items():
        np.testing.assert_array_equal(h.ctrl[uid].processed_action.numpy(), want[uid])
        np.testing.assert_array_equal(h.ctrl.processed_action.numpy()[:, s:e], want[uid])


def test_reset_with_a_control_zeroes_the_explicit_torques_of_the_reset_envs():
    """Explicit actuation: a reset given the Control zeroes joint_f on the reset envs' controlled DOFs (and writes
    their drive targets); other envs and DOFs the controller does not drive keep theirs."""
    n = 3
    h = Harness({"arm": delta_arm(use_target=True)}, num_envs=n, actuation="explicit")
    rng = np.random.default_rng(8)
    h.put(rng.uniform(-1, 1, (n, 7)), rng.uniform(-1, 1, (n, 7)))
    h.ctrl.reset(h.state)
    h.step(rng.uniform(-1, 1, (n, 7)))
    f = h.control.joint_f.numpy()
    fingers = h.model.joint_qd_start.numpy()[[7, 8]]  # world 0's finger DOFs: not driven by this controller
    f[fingers] = 123.0
    h.control.joint_f.assign(f)
    before = h.control.joint_f.numpy().copy()
    assert (np.abs(before[h.dof]) > 1e-3).all()
    q_new = rng.uniform(-1, 1, (n, 7)).astype(np.float32)
    h.put(q_new)
    h.ctrl.reset(h.state, env_ids=[1], control=h.control)
    after = h.control.joint_f.numpy()
    np.testing.assert_array_equal(after[h.dof[1]], 0.0)
    keep = np.ones_like(after, bool)
    keep[h.dof[1]] = False
    np.testing.assert_array_equal(after[keep], before[keep])
    np.testing.assert_array_equal(h.drive_q()[1], q_new[1])


# --- README promises -----------------------------------------------------------------------------------------------


JOINT_CONFIGS = [
    "PDJointPosControllerConfig",
    "PDJointPosMimicControllerConfig",
    "PDJointVelControllerConfig",
    "PDJointPosVelControllerConfig",
    "PassiveControllerConfig",
]


@pytest.mark.parametrize("name", JOINT_CONFIGS)
def test_joint_configs_have_maniskills_fields_order_and_defaults(name):
    """The positional fields of wpctrl's joint configs are ManiSkill 3.0.1's, in its order, with its defaults (its
    own dataclasses, imported); wpctrl's additions are keyword-only and come with defaults."""
    import dataclasses

    controllers = pytest.importorskip("mani_skill.agents.controllers", reason="mani-skill is a dev dependency")
    theirs = dataclasses.fields(getattr(controllers, name))
    ours = dataclasses.fields(getattr(wpctrl, name))
    positional = [f for f in ours if not f.kw_only]
    assert [f.name for f in positional] == [f.name for f in theirs]

    def default(f):
        if f.default is not dataclasses.MISSING:
            return f.default
        if f.default_factory is not dataclasses.MISSING:
            return f.default_factory()
        return "required"

    assert [default(f) for f in positional] == [default(f) for f in theirs]
    for f in ours:
        if f.kw_only:
            assert default(f) != "required", f.name


def test_set_state_copies_its_input_and_get_state_is_live():
    """DIFFERENCE (README 8): set_state copies (changing the dict's arrays afterwards changes nothing), whatever the
    array kind; get_state returns the live arrays."""
    torch = pytest.importorskip("torch", reason="torch is a dev dependency")
    n = 2
    h = Harness({"arm": delta_arm(use_target=True), "gripper": gripper()}, num_envs=n)
    h.ctrl.reset(h.state)
    rng = np.random.default_rng(9)
    for kind in ("numpy", "torch", "warp"):
        v = rng.uniform(-1, 1, (n, 7)).astype(np.float32)
        if kind == "numpy":
            src = v.copy()
        elif kind == "torch":
            src = torch.from_numpy(v.copy())
        else:
            src = wp.array(v, dtype=wp.float32)
        h.ctrl.set_state({"arm": {"target_qpos": src}})
        if kind == "warp":
            src.fill_(7.0)
        else:
            src[:] = 7.0
        np.testing.assert_array_equal(h.ctrl["arm"].target_qpos.numpy(), v, err_msg=kind)
    live = h.ctrl.get_state()["arm"]["target_qpos"]
    h.act(np.ones((n, 8), np.float32))
    np.testing.assert_allclose(live.numpy(), v + f32(0.1), atol=1e-7)  # the same array, updated by the step


def test_a_controller_built_after_the_mujoco_solver_warns_what_to_do():
    """Changing joint_target_mode after SolverMuJoCo was built (it creates its actuators at construction) warns with
    the fix; building before the solver, or changing no mode, does not warn."""
    import warnings

    import newton
    from conftest import build_panda

    vel = wpctrl.PDJointVelControllerConfig(ARM, -1.0, 1.0, 10.0)
    model = build_panda(1)
    solver = newton.solvers.SolverMuJoCo(model, disable_contacts=True)
    with pytest.warns(UserWarning) as record:
        wpctrl.build_controller(vel, model, solver=solver)
    assert [str(w.message) for w in record] == [
        "wpctrl changed Model.joint_target_mode after the MuJoCo solver was built; MuJoCo creates its actuators at "
        "construction, so build the controller before the solver"
    ]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        wpctrl.build_controller(vel, model, solver=solver)  # the modes are VELOCITY already: nothing changes
        model = build_panda(1)
        ctrl = wpctrl.build_controller(vel, model)
        ctrl.attach_solver(newton.solvers.SolverMuJoCo(model, disable_contacts=True))


# --- Beyond section 3: many envs, inputs, state round trips ----------------------------------------------------------


def test_per_env_independence_64_envs():
    n = 64
    h = Harness({"arm": delta_arm(use_target=True), "gripper": gripper()}, num_envs=n)
    rng = np.random.default_rng(3)
    q = rng.uniform(-1, 1, (n, 9)).astype(np.float32)
    h.put(q)
    h.ctrl.reset(h.state)
    a = rng.uniform(-1.5, 1.5, (n, 8)).astype(np.float32)
    h.act(a)
    c = np.clip(a, -1, 1)
    arm = q[:, :7] + (f32(0.0) + f32(0.1) * c[:, :7])
    lo, hi = f32(-0.01), f32(0.04)
    fing = f32(0.5) * (hi + lo) + f32(0.5) * (hi - lo) * c[:, 7]
    np.testing.assert_allclose(h.ctrl.target_qpos.numpy(), np.column_stack([arm, fing, fing]), atol=1e-6)
    assert len({tuple(r) for r in h.ctrl.target_qpos.numpy()}) == n


def test_partial_reset_bit_identical_64_envs():
    n = 64
    mode = {"arm": delta_arm(use_target=True, interpolate=True), "gripper": gripper()}
    rng = np.random.default_rng(4)
    acts = rng.uniform(-1, 1, (5, n, 8)).astype(np.float32)
    qs = rng.uniform(-1, 1, (5, n, 9)).astype(np.float32)
    runs = []
    for with_reset in (False, True):
        h = Harness(copy.deepcopy(mode), num_envs=n, actuation="explicit")
        h.ctrl.reset(h.state)
        for i in range(5):
            h.put(qs[i], qs[i])
            if with_reset and i == 2:
                h.ctrl.reset(h.state, env_ids=np.arange(0, n, 7))
            h.act(acts[i])
            h.substeps(3)
        runs.append((h.ctrl.target_qpos.numpy(), h.ctrl.start_qpos.numpy(), h.joint_f(), h.drive_q()))
    keep = np.ones(n, bool)
    keep[np.arange(0, n, 7)] = False
    for a, b in zip(runs[0], runs[1]):
        np.testing.assert_array_equal(a[keep], b[keep])
    assert not np.array_equal(runs[0][0][~keep], runs[1][0][~keep])  # the reset envs' virtual targets restarted


def test_get_set_state_round_trip():
    n = 64
    h = Harness({"arm": delta_arm(use_target=True), "gripper": gripper()}, num_envs=n)
    h.ctrl.reset(h.state)
    h.act(np.random.default_rng(5).uniform(-1, 1, (n, 8)))
    saved = {k: {kk: vv.numpy().copy() for kk, vv in v.items()} for k, v in h.ctrl.get_state().items()}
    h.act(np.ones((n, 8)))
    h.ctrl.set_state(saved)
    np.testing.assert_array_equal(h.ctrl.get_state()["arm"]["target_qpos"].numpy(), saved["arm"]["target_qpos"])
    torch = pytest.importorskip("torch", reason="torch is a dev dependency")
    h.ctrl.set_state({"arm": {"target_qpos": torch.zeros(n, 7)}})
    assert not h.ctrl["arm"].target_qpos.numpy().any()


def test_torch_numpy_warp_inputs_identical_and_zero_copy():
    torch = pytest.importorskip("torch", reason="torch is a dev dependency")
    n = 8
    a = np.random.default_rng(6).uniform(-1.2, 1.2, (n, 8)).astype(np.float32)
    results = []
    for kind in ("numpy", "torch", "warp", "torch_strided"):
        h = Harness({"arm": delta_arm(use_target=True, interpolate=True), "gripper": gripper()}, num_envs=n)
        h.ctrl.reset(h.state)
        if kind == "numpy":
            x = a
        elif kind == "torch":
            x = torch.from_numpy(a.copy())
        elif kind == "warp":
            x = wp.array(a, dtype=wp.float32)
        else:
            x = torch.from_numpy(np.ascontiguousarray(a.T)).T  # a non-contiguous view
        for _ in range(3):
            h.ctrl.set_action(x, h.state)
            h.substeps()
        results.append((h.ctrl.target_qpos.numpy(), h.drive_q()))
    for r in results[1:]:
        np.testing.assert_array_equal(r[0], results[0][0])
        np.testing.assert_array_equal(r[1], results[0][1])
    from wpctrl.controllers.inputs import _action_array

    t = torch.from_numpy(a.copy())
    view = _action_array(t, n, 8, wp.get_device("cpu"), None)
    assert view.ptr == t.data_ptr()  # zero-copy
    t[0, 0] = 123.0
    assert view.numpy()[0, 0] == 123.0


def test_graph_capture_replay_is_bit_identical_on_cpu():
    n = 16
    mode = {"arm": delta_arm(use_target=True, interpolate=True), "gripper": gripper()}
    rng = np.random.default_rng(7)
    acts = rng.uniform(-1, 1, (4, n, 8)).astype(np.float32)
    out = []
    for captured in (False, True):
        h = Harness(copy.deepcopy(mode), num_envs=n, actuation="explicit")
        h.put(rng.uniform(-1, 1, (n, 9)) * 0 + 0.1)
        h.ctrl.reset(h.state)
        act = wp.zeros((n, 8), dtype=wp.float32)
        mask = wp.array(np.arange(n) % 5 == 0, dtype=wp.bool)

        def control_step(h=h, act=act):
            h.ctrl.set_action(act, h.state)
            for _ in range(h.ctrl.num_substeps):
                h.ctrl.before_simulation_step(h.state, h.control)

        graph = None
        if captured:
            with wp.ScopedCapture(device="cpu") as cap:
                control_step()
            graph = cap.graph
        for i in range(4):
            act.assign(acts[i])
            if graph is not None:
                wp.capture_launch(graph)
            else:
                control_step()
            if i == 1:
                h.ctrl.reset(h.state, env_ids=mask)
        out.append((h.ctrl.target_qpos.numpy(), h.joint_f(), h.drive_q(), h.ctrl.step_counter.numpy()))
    for a, b in zip(*out):
        np.testing.assert_array_equal(a, b)
