"""No allocation and no host sync in the per-step calls (the README's promise for float32 device input).

Every allocation of a Warp array (``wp.array`` built from data or new: ``wp.empty`` / ``wp.zeros`` / ``wp.full`` /
``wp.clone`` / ``wp.array(numpy)``) and every call that waits for or reads back the device (``wp.synchronize*``,
``wp.array.numpy`` / ``.list``, torch's ``.cpu`` / ``.item`` / ``.numpy`` / ``.tolist``) is counted while a warm
controller runs control steps (``set_action`` + K ``before_simulation_step``) with a float32 ``wp.array`` and a float32
torch tensor as the action, resets and randomises with device env selections, and while such a step is captured in a
graph and replayed. The counters themselves are checked first: they see what a per-step call would do wrong.

Warm: the first step records the launches (and the first torch action builds its cached wrapper); what follows must
not allocate or sync. CPU device: the same Python path runs on CUDA, where a sync would also break graph capture.
"""

from __future__ import annotations

import copy

import newton
import numpy as np
import pytest
import warp as wp
from conftest import build_panda
from harness import delta_arm, gripper

import wpctrl
from wpctrl.robots import PANDA_ARM_JOINTS, PANDA_GRIPPER_JOINTS, panda_control_modes

torch = pytest.importorskip("torch", reason="torch is a dev dependency (the torch action input is checked here)")

N = 3
A = wp.array


class Counter:
    """Counts array allocations and host syncs (see the module docstring) while active."""

    def __init__(self, monkeypatch):
        self.allocs: list[str] = []
        self.syncs: list[str] = []
        self.active = False

        def wrap(owner, name, log):
            original = getattr(owner, name)

            def counted(*args, **kwargs):
                if self.active:
                    log.append(name)
                return original(*args, **kwargs)

            monkeypatch.setattr(owner, name, counted)

        wrap(A, "_init_new", self.allocs)  # every allocating constructor ends here (zero-copy wraps do not)
        for name in ("numpy", "list"):
            wrap(A, name, self.syncs)
        import warp._src.context as ctx

        for name in ("synchronize", "synchronize_device", "synchronize_stream", "synchronize_event"):
            wrap(wp, name, self.syncs)
            if hasattr(ctx, name):
                wrap(ctx, name, self.syncs)
        for name in ("cpu", "item", "numpy", "tolist"):
            wrap(torch.Tensor, name, self.syncs)

    def __enter__(self):
        self.allocs.clear()
        self.syncs.clear()
        self.active = True
        return self

    def __exit__(self, *exc):
        self.active = False


def _modes():
    arm = wpctrl.PDJointPosControllerConfig(
        PANDA_ARM_JOINTS, None, None, 400.0, 40.0, 50.0, normalize_action=False, drive_mode="acceleration"
    )
    fingers = wpctrl.PDJointPosControllerConfig(
        PANDA_GRIPPER_JOINTS, None, None, 200.0, 20.0, 30.0, normalize_action=False
    )
    interp = {"arm": delta_arm(use_target=True, interpolate=True), "gripper": gripper()}
    return {
        "pd_joint_delta_pos implicit (substep elided)": (panda_control_modes()["pd_joint_delta_pos"], {}),
        "interpolated, explicit naive, delay, effort, clip": (
            interp,
            dict(actuation="explicit", delay=(1, 3), track_effort=True, clip_targets="joint_limits"),
        ),
        "acceleration, explicit stable, r per substep": (
            {"arm": arm, "fingers": fingers},
            dict(actuation="explicit", explicit_pd="stable", inertia_update="substep"),
        ),
        "implicit acceleration, r per control step": ({"arm": arm, "fingers": fingers}, {}),
        "coupled": ({"arm": arm, "fingers": fingers}, dict(actuation="explicit", explicit_pd="coupled")),
        "pd_ee_delta_pose": (panda_control_modes()["pd_ee_delta_pose"], {}),
        "osc_ee_delta_pose, delay, effort": (
            dict(panda_control_modes()["osc_ee_delta_pose"], balance_passive_force=False),
            dict(actuation="explicit", delay=(1, 3), track_effort=True),
        ),
    }


MODES = _modes()


def test_the_counters_see_allocations_and_syncs(monkeypatch):
    c = Counter(monkeypatch)
    a = wp.zeros(3, dtype=wp.float32)
    with c:
        a[1:]  # a view is not an allocation
        assert c.allocs == [] and c.syncs == []
        wp.zeros(3, dtype=wp.float32)
        wp.array(np.ones(2, np.float32), dtype=wp.float32)
        wp.clone(a)
        a.numpy()
        wp.synchronize_device()
        torch.ones(2).sum().item()
    assert len(c.allocs) == 3 and c.syncs.count("numpy") == 1 and "item" in c.syncs and len(c.syncs) >= 2


@pytest.mark.parametrize("name", list(MODES))
def test_per_step_calls_do_not_allocate_or_sync(monkeypatch, name):
    mode, options = MODES[name]
    model = build_panda(N)
    ctrl = wpctrl.build_controller(copy.deepcopy(mode), model, 20, 100, **options)
    if name.startswith("implicit acceleration"):  # r per control step writes Kp/r and notifies the solver
        ctrl.attach_solver(newton.solvers.SolverMuJoCo(model, disable_contacts=True))
    state, control = model.state(), model.control()
    rng = np.random.default_rng(0)
    a_np = rng.uniform(-1, 1, (N, ctrl.action_dim)).astype(np.float32)
    a_wp = wp.array(a_np, dtype=wp.float32)
    a_torch = torch.from_numpy(a_np.copy())
    mask = wp.array(np.array([True, False, True]), dtype=wp.bool)
    ids = wp.array(np.array([1], np.int32), dtype=wp.int32)

    def control_step(action):
        ctrl.set_action(action, state)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(state, control)

    ctrl.reset(state, control=control)
    for action in (a_wp, a_torch):  # warm: launches recorded, the torch wrapper cached
        control_step(action)
    ctrl.reset(state, env_ids=mask)
    ctrl.reset(state, env_ids=ids)
    ctrl.randomize_drive_properties(env_ids=mask, stiffness=(0.9, 1.1))
    counter = Counter(monkeypatch)
    with counter:
        for _ in range(2):
            control_step(a_wp)
            control_step(a_torch)
    assert counter.allocs == [] and counter.syncs == [], (counter.allocs, counter.syncs)
    with counter:
        ctrl.reset(state, env_ids=mask)
        ctrl.reset(state, env_ids=ids)
        ctrl.randomize_drive_properties(env_ids=mask, stiffness=(0.9, 1.1), seed=3)
    assert counter.allocs == [] and counter.syncs == [], ("reset / randomize", counter.allocs, counter.syncs)

    # A captured control step: capture and replay allocate nothing and never sync (the graph's own bookkeeping
    # aside, which is Warp's), and the replay computes what the eager step did.
    def reset_all():
        ctrl.reset(state, control=control)
        if ctrl.delay is not None:  # the same delays for the eager and the captured step
            ctrl.delay = np.array([1, 2, 3], np.int32)

    reset_all()
    control_step(a_wp)
    eager = (control.joint_target_q.numpy().copy(), control.joint_f.numpy().copy(), ctrl.target_qpos.numpy().copy())
    reset_all()
    with counter:
        with wp.ScopedCapture(device="cpu") as cap:
            control_step(a_wp)
        wp.capture_launch(cap.graph)
    assert counter.allocs == [] and counter.syncs == [], ("graph", counter.allocs, counter.syncs)
    replayed = (control.joint_target_q.numpy(), control.joint_f.numpy(), ctrl.target_qpos.numpy())
    for x, y in zip(eager, replayed):
        np.testing.assert_array_equal(x, y)
