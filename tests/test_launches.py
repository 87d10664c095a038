"""Launches per control step, and the elided substep launch of modes without per-substep work.

Counts every kernel launch (``wp.launch`` and recorded ``wp.Launch`` objects) of a control step; checks that the
drive targets a solver reads at every substep are the ones the substep kernel wrote before the elision (the
controller's own targets, re-derived in numpy), with one Control, swapped Controls, resets with and without a
Control, ``set_state`` and graph capture; and ``step_counter`` against ManiSkill's ``_step`` rule.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest
import warp as wp
from harness import ARM, Harness, delta_arm, gripper

import wpctrl
from wpctrl.robots import panda_control_modes

f32 = np.float32


class LaunchCounter:
    """Counts kernel launches: ``wp.launch`` calls and ``wp.Launch.launch`` (recorded launches)."""

    def __init__(self, monkeypatch):
        self.kernels: list[str] = []
        launch, replay = wp.launch, wp.Launch.launch

        def counted_launch(kernel, *args, **kwargs):
            if not kwargs.get("record_cmd"):  # recording a launch runs nothing
                self.kernels.append(kernel.key)
            return launch(kernel, *args, **kwargs)

        def counted_replay(cmd, *args, **kwargs):
            self.kernels.append(cmd.kernel.key)
            return replay(cmd, *args, **kwargs)

        monkeypatch.setattr(wp, "launch", counted_launch)
        monkeypatch.setattr(wp.Launch, "launch", counted_replay)

    def take(self) -> list[str]:
        out, self.kernels = self.kernels, []
        return out


def _mode(interpolate=False):
    return {"arm": delta_arm(use_target=True, interpolate=interpolate), "gripper": gripper()}


def _control_step(h, action, control=None):
    h.ctrl.set_action(action, h.state)
    for _ in range(h.ctrl.num_substeps):
        h.ctrl.before_simulation_step(h.state, h.control if control is None else control)


@pytest.mark.parametrize(
    "mode, actuation, options, expected",
    [
        (delta_arm(), "implicit", {}, 1),  # pd_joint_delta_pos
        (_mode(), "implicit", {}, 1),  # pd_joint_target_delta_pos with the mimic gripper
        (wpctrl.PDJointVelControllerConfig(ARM, -1.0, 1.0, 1e2), "implicit", {}, 1),  # pd_joint_vel
        (_mode(), "implicit", {"clip_targets": "joint_limits"}, 1),  # clamped in set_action
        (_mode(interpolate=True), "implicit", {}, 1 + 5),  # interpolation: a substep launch each
        (_mode(), "explicit", {}, 1 + 5),  # explicit torques: a substep launch each
        (_mode(), "implicit", {"delay": (1, 2)}, 1 + 5),  # the delay ring shifts every substep
        (_mode(), "implicit", {"track_effort": True}, 1 + 5),  # the effort readout reads the measured state
        (panda_control_modes()["pd_ee_delta_pos"], "implicit", {}, 2),  # the EE launch, then the joint launch
    ],
)
def test_launches_per_control_step(monkeypatch, mode, actuation, options, expected):
    h = Harness(copy.deepcopy(mode), num_envs=3, actuation=actuation, **options)
    h.ctrl.reset(h.state)
    a = np.zeros((3, h.ctrl.action_dim), np.float32)
    act = wp.array(a, dtype=wp.float32)
    counter = LaunchCounter(monkeypatch)
    _control_step(h, act)  # the first Control seen: the elided mode writes it once, in the first substep
    first = counter.take()
    elided = not h.ctrl.substep_launch
    assert elided == (expected <= 2)
    for _ in range(3):
        _control_step(h, act)
        launched = counter.take()
        assert len(launched) == expected, launched
        assert launched[expected - 1 if elided else 0].startswith("wpctrl_set_action"), launched
    if elided:
        assert len(first) == expected + 1 and first[-1].startswith("_targets_kernel"), first
    # A second Control (double buffering): one small write when it first appears in a step, then nothing.
    other = h.model.control()
    _control_step(h, act, other)
    assert len(counter.take()) == (expected + 1 if elided else expected)
    _control_step(h, act, other)
    assert len(counter.take()) == expected


@pytest.mark.parametrize(
    ("launch", "options", "expected"),
    [
        ("auto", {}, 1 + 5),  # the network's rows in the substep kernel's launch
        ("separate", {}, 1 + 2 * 5),  # the substep kernel, then the network's own launch
        ("auto", {"delay": 1}, 1 + 2 * 5),  # a delay: the network reads the delayed target, after the substep kernel
    ],
)
def test_actuator_network_launches_per_control_step(monkeypatch, launch, options, expected):
    torch = pytest.importorskip("torch", reason="torch is a dev dependency (the network is a torch module)")
    torch.manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Linear(6, 8), torch.nn.Tanh(), torch.nn.Linear(8, 1))
    arm = delta_arm(actuator=wpctrl.ActuatorNet(net, launch=launch))
    h = Harness({"arm": arm, "gripper": gripper()}, num_envs=3, actuation="explicit", **options)
    h.ctrl.reset(h.state)
    act = wp.zeros((3, h.ctrl.action_dim), dtype=wp.float32)
    counter = LaunchCounter(monkeypatch)
    for _ in range(2):
        _control_step(h, act)
        launched = counter.take()
        assert len(launched) == expected, launched
        assert sum(k.startswith("wpctrl_substep_actuator_net") for k in launched) == (5 if expected == 6 else 0)


class Expected:
    """The drive position targets of ``_mode()`` re-derived in numpy (ManiSkill's rules, float32): the arm's virtual
    target accumulates ``0.1 clip(a)``; both fingers take the gripper's column scaled onto [-0.01, 0.04]; an env with
    a NaN/Inf action keeps its targets; a reset sets the reset envs' targets to the measured positions; set_state sets
    the arm's."""

    def __init__(self, q):
        self.t = np.asarray(q, f32).copy()

    def act(self, a):
        a = np.asarray(a, f32)
        good = np.isfinite(a).all(axis=1)
        c = np.clip(a, f32(-1), f32(1))
        lo, hi = f32(-0.01), f32(0.04)
        g = f32(0.5) * (hi + lo) + f32(0.5) * (hi - lo) * c[:, 7]
        t = self.t.copy()
        t[:, :7] = t[:, :7] + f32(0.1) * c[:, :7]
        t[:, 7] = t[:, 8] = g
        self.t[good] = t[good]

    def reset(self, q, envs):
        self.t[envs] = np.asarray(q, f32)[envs]


@pytest.mark.parametrize(
    "mode, actuation, options",
    [
        (delta_arm(), "implicit", {}),
        (_mode(), "implicit", {}),
        (_mode(interpolate=True), "explicit", {"track_effort": True, "clip_targets": "joint_limits"}),
        (_mode(), "implicit", {"delay": 2}),
    ],
)
def test_reset_is_one_launch(monkeypatch, mode, actuation, options):
    """reset is the reset kernel alone, whatever the env selection and with or without the (known) Control; the
    documented extras: a Control not known yet in a mode without per-substep work also gets every env's targets
    (one more launch), a delay range draws (the draw counter's bump), an EE controller resets its pose."""
    n = 4
    h = Harness(copy.deepcopy(mode), num_envs=n, actuation=actuation, **options)
    h.ctrl.reset(h.state, control=h.control)
    _control_step(h, np.zeros((n, h.ctrl.action_dim), np.float32))
    counter = LaunchCounter(monkeypatch)
    mask = wp.array(np.arange(n) % 2 == 0, dtype=wp.bool)
    for env_ids in (None, 1, [0, 3], np.arange(n) < 2, mask, wp.array(np.array([2], np.int32), dtype=wp.int32)):
        for control in (None, h.control):
            h.ctrl.reset(h.state, env_ids=env_ids, control=control)
            assert counter.take() == ["_reset_kernel"], (env_ids, control)
    elided = not h.ctrl.substep_launch
    h.ctrl.reset(h.state, env_ids=[1], control=h.model.control())
    assert counter.take() == ["_reset_kernel"] + (["_targets_kernel"] if elided else [])
    ranged = Harness(copy.deepcopy(mode), num_envs=n, actuation=actuation, delay=(0, 2))
    counter.take()
    ranged.ctrl.reset(ranged.state, env_ids=[1])
    assert counter.take() == ["_reset_kernel", "_bump_counter_kernel"]
    ee = Harness(copy.deepcopy(panda_control_modes()["pd_ee_delta_pos"]), num_envs=n)
    counter.take()
    ee.ctrl.reset(ee.state, env_ids=[1])
    assert len(counter.take()) == 2


def _check_drive(h, control, want, where):
    """The Control's position drive targets are ``want`` (n, 9); the velocity targets stay 0 (position rows)."""
    got_q = control.joint_target_q.numpy()[h.coord]
    np.testing.assert_allclose(got_q, want, atol=1e-6, rtol=0, err_msg=f"{where}: joint_target_q")
    np.testing.assert_array_equal(control.joint_target_qd.numpy()[h.dof], 0.0, err_msg=f"{where}: joint_target_qd")


def test_swapped_controls_get_the_targets():
    n = 4
    h = Harness(_mode(), num_envs=n)
    rng = np.random.default_rng(0)
    h.put(rng.uniform(-1, 1, (n, 9)))
    h.ctrl.reset(h.state)
    want = Expected(h.q())
    a, b = h.model.control(), h.model.control()
    schedule = [[a] * 5, [b] * 5, [a, b, a, b, a], [b, b, a, a, a]]
    for i, controls in enumerate(schedule):
        act = rng.uniform(-1.2, 1.2, (n, 8)).astype(np.float32)
        if i == 2:
            act[1, 7] = np.nan  # env 1 holds its targets this step
        h.ctrl.set_action(act, h.state)
        want.act(act)
        for k, c in enumerate(controls):
            h.ctrl.before_simulation_step(h.state, c)
            _check_drive(h, c, want.t, f"step {i} substep {k}")  # the Control the solver steps with holds them
    # A Control whose arrays were replaced in place counts as another Control.
    a.joint_target_q = wp.zeros_like(a.joint_target_q)
    h.ctrl.before_simulation_step(h.state, a)
    _check_drive(h, a, want.t, "replaced arrays")


def test_reset_set_state_and_invalidate_keep_the_known_control_current():
    n = 4
    h = Harness({"arm": delta_arm(use_target=True), "gripper": gripper()}, num_envs=n)
    rng = np.random.default_rng(1)
    h.ctrl.reset(h.state)
    want = Expected(h.q())
    act = rng.uniform(-1, 1, (n, 8)).astype(np.float32)
    _control_step(h, act)
    want.act(act)
    _check_drive(h, h.control, want.t, "control step")
    # A reset without a Control still updates the known one (the solver's next substep sees the reset pose) ...
    h.put(rng.uniform(-1, 1, (n, 9)))
    h.ctrl.reset(h.state, env_ids=[2])
    want.reset(h.q(), [2])
    _check_drive(h, h.control, want.t, "reset without control")
    # ... a reset with a new Control writes every env into it, not only the reset ones.
    other = h.model.control()
    h.ctrl.reset(h.state, env_ids=[1], control=other)
    want.reset(h.q(), [1])
    _check_drive(h, other, want.t, "reset with a new control")
    # set_state edits the targets on the host: the next substep writes them.
    arm = rng.uniform(-1, 1, (n, 7)).astype(np.float32)
    h.ctrl.set_state({"arm": {"target_qpos": arm}})
    want.t[:, :7] = arm
    h.ctrl.before_simulation_step(h.state, other)
    _check_drive(h, other, want.t, "set_state")
    # Someone else overwrote the targets: invalidate_control makes the next substep rewrite them.
    other.joint_target_q.zero_()
    h.ctrl.before_simulation_step(h.state, other)
    assert not other.joint_target_q.numpy().any()  # not detected (documented) ...
    h.ctrl.invalidate_control()
    h.ctrl.before_simulation_step(h.state, other)
    _check_drive(h, other, want.t, "invalidate_control")  # ... until invalidated
    act = rng.uniform(-1, 1, (n, 8)).astype(np.float32)
    _control_step(h, act, other)
    want.act(act)
    _check_drive(h, other, want.t, "the next control step")


def test_step_counter_follows_maniskill_step_without_substep_launches():
    # ManiSkill: _step = 0 at set_action and reset, += 1 per before_simulation_step; a rejected (NaN) action
    # leaves its env untouched, so that env keeps counting from its last accepted action.
    n = 3
    h = Harness(delta_arm(), num_envs=n)
    assert not h.ctrl.substep_launch
    h.ctrl.reset(h.state)
    expect = np.zeros(n, np.int64)

    def sub(k):
        nonlocal expect
        h.substeps(k)
        expect = expect + k
        np.testing.assert_array_equal(h.ctrl.step_counter.numpy(), expect)

    sub(3)
    a = np.zeros((n, 7), np.float32)
    a[1, 2] = np.nan
    h.act(a)
    expect[[0, 2]] = 0
    np.testing.assert_array_equal(h.ctrl.step_counter.numpy(), expect)
    sub(2)
    h.ctrl.reset(h.state, env_ids=[2])
    expect[2] = 0
    sub(1)
    h.act(np.zeros((n, 7), np.float32))
    expect[:] = 0
    sub(5)
    sub(4)  # past K: keeps counting
    assert h.ctrl.step_counter.numpy().tolist() == [9, 9, 9]


@pytest.mark.parametrize("known_before_capture", [False, True])
def test_graph_replay_bitwise_without_substep_launches(known_before_capture):
    n = 8
    rng = np.random.default_rng(2)
    acts = rng.uniform(-1, 1, (5, n, 8)).astype(np.float32)
    acts[2, 3, 4] = np.nan  # a held env during a replay
    acts[3, 3, 0] = np.inf
    out = []
    for captured in (False, True):
        h = Harness(_mode(), num_envs=n)
        h.put(np.full((n, 9), 0.1, np.float32))
        h.ctrl.reset(h.state, control=h.control if known_before_capture else None)
        act = wp.zeros((n, 8), dtype=wp.float32)
        mask = wp.array(np.arange(n) % 3 == 0, dtype=wp.bool)
        graph = None
        if captured:
            with wp.ScopedCapture(device="cpu") as cap:
                _control_step(h, act)
            graph = cap.graph
        steps = []
        for i in range(5):
            act.assign(acts[i])
            if graph is not None:
                wp.capture_launch(graph)
            else:
                _control_step(h, act)
            if i == 1:
                h.ctrl.reset(h.state, env_ids=mask)
            steps.append((h.drive_q().copy(), h.ctrl.step_counter.numpy().copy()))
        out.append((steps, h.ctrl.target_qpos.numpy(), h.ctrl.bad_action_count.numpy()))
    (eager, t0, b0), (replay, t1, b1) = out
    np.testing.assert_array_equal(t0, t1)
    np.testing.assert_array_equal(b0, b1)
    assert b0.tolist() == [0, 0, 0, 2, 0, 0, 0, 0]
    for i, ((d0, s0), (d1, s1)) in enumerate(zip(eager, replay)):
        np.testing.assert_array_equal(d0, d1, err_msg=f"step {i}: drive targets")
        np.testing.assert_array_equal(s0, s1, err_msg=f"step {i}: step_counter")
    assert eager[-1][1].tolist() == [5] * n
    assert eager[3][1][3] == 10  # env 3 held for two steps: counting since its reset after step 1


def _uneven_model():
    """3 Panda worlds, world 1 with an extra free-jointed box first: the robots are not at a constant stride."""
    import newton

    from wpctrl.robots import panda

    b = newton.ModelBuilder()
    for w in range(3):
        b.begin_world()
        if w == 1:
            link = b.add_link(mass=1.0, inertia=wp.mat33(np.eye(3) * 0.01))
            b.add_articulation([b.add_joint_free(link, label="box/free")])
        b.add_builder(panda())
        b.end_world()
    return b.finalize(device="cpu")


@pytest.mark.parametrize("actuation, interpolate", [("implicit", False), ("explicit", True)])
def test_strided_and_flat_index_tables_agree(actuation, interpolate):
    # Replicated worlds: env 0's indices + env * stride; uneven worlds: a flat (num_envs, rows) table. The same
    # per-env joint states and actions must give bit-identical targets, drive targets and torques at the robots'
    # coordinates / DOFs, and leave the box's free joint alone.
    from conftest import build_panda

    rng = np.random.default_rng(3)
    q = rng.uniform(-1, 1, (3, 9)).astype(np.float32)
    qd = rng.uniform(-1, 1, (3, 9)).astype(np.float32)
    acts = rng.uniform(-1.2, 1.2, (3, 3, 8)).astype(np.float32)
    results = []
    for model in (build_panda(3), _uneven_model()):
        ctrl = wpctrl.build_controller(_mode(interpolate), model, 20, 100, actuation=actuation)
        plan = ctrl._engine.plan  # private: the plan's index tables (a stride, or per-env tables)
        b = ctrl  # the controlled joints' coord_index / dof_index
        uneven = model.joint_coord_count != 3 * 9
        assert (plan.q_stride, plan.qd_stride) == ((0, 0) if uneven else (9, 9))
        assert plan.q_idx.shape == ((3, 9) if uneven else (1, 9))
        state, control = model.state(), model.control()
        tq0 = control.joint_target_q.numpy().copy()
        sq, sqd = state.joint_q.numpy(), state.joint_qd.numpy()
        sq[b.coord_index], sqd[b.dof_index] = q, qd
        state.joint_q.assign(sq)
        state.joint_qd.assign(sqd)
        ctrl.reset(state)
        steps = []
        for a in acts:
            ctrl.set_action(a, state)
            for _ in range(ctrl.num_substeps):
                ctrl.before_simulation_step(state, control)
                steps.append(
                    (
                        control.joint_target_q.numpy()[b.coord_index],
                        control.joint_f.numpy()[b.dof_index],
                        ctrl.target_qpos.numpy().copy(),
                    )
                )
        others = np.setdiff1d(np.arange(model.joint_coord_count), b.coord_index.reshape(-1))
        np.testing.assert_array_equal(control.joint_target_q.numpy()[others], tq0[others])
        results.append(steps)
    for k, (x, y) in enumerate(zip(*results)):
        for u, v in zip(x, y):
            np.testing.assert_array_equal(u, v, err_msg=f"substep {k}")
    assert not np.array_equal(results[0][0][0], results[0][-1][0])  # the targets moved
