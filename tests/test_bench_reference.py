"""The torch baseline of the benchmarks (bench/step/reference_torch.py) computes what wpctrl computes.

Both run the same Panda control modes on the same random measured states and actions (explicit actuation, a handful
of envs, a few control steps, CPU), each writing into its own Control; we compare the targets after set_action and
the drive targets and torques written at every substep. This is what makes the benchmark a comparison of equal work.
The synthetic large-N layout that bench/step/controller_step.py uses above its real-model limit is checked against a
real replicated model too.
"""

from __future__ import annotations

import sys

import numpy as np
import pytest
from conftest import ROOT, build_panda

if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

torch = pytest.importorskip("torch", reason="the benchmarks' baseline is written in torch (a dev dependency)")

import wpctrl  # noqa: E402
from bench.common import panda_mode, synthetic_setup  # noqa: E402
from bench.step.reference_torch import TorchCombinedController, layout_from_model, tile_layout  # noqa: E402

NUM_ENVS = 5
STEPS = 3
TOL = 1e-5
MODES = ["pd_joint_target_delta_pos", "pd_joint_delta_pos", "pd_joint_pos"]


def _random_action(rng, ctrl, num_envs):
    """Actions that also exercise the clip: normalized columns in [-1.5, 1.5], raw ones beyond their bounds."""
    low = ctrl.single_action_space.low
    high = ctrl.single_action_space.high
    span = high - low
    a = rng.uniform(low - 0.25 * span, high + 0.25 * span, size=(num_envs, low.shape[0]))
    return a.astype(np.float32)


def _perturb_state(rng, state, layout, base_q):
    """A measured state near the rest pose (as if the solver had moved the robot)."""
    q = state.joint_q.numpy()
    qd = state.joint_qd.numpy()
    q[layout.coord_index] = base_q + rng.normal(0.0, 0.05, size=layout.coord_index.shape).astype(np.float32)
    qd[layout.dof_index] = rng.normal(0.0, 0.5, size=layout.dof_index.shape).astype(np.float32)
    state.joint_q.assign(q)
    state.joint_qd.assign(qd)


@pytest.mark.parametrize("interpolate", [False, True], ids=["hold", "interp"])
@pytest.mark.parametrize("mode_name", MODES)
def test_reference_matches_wpctrl(mode_name, interpolate):
    rng = np.random.default_rng(1234)
    model = build_panda(NUM_ENVS)
    ctrl = wpctrl.build_controller(panda_mode(mode_name, interpolate), model, actuation="explicit")
    state = model.state()
    control_w = model.control()
    control_t = model.control()
    layout = layout_from_model(model, list(ctrl.joint_names))
    ref = TorchCombinedController(
        panda_mode(mode_name, interpolate), layout, state, control_t, actuation="explicit", device="cpu"
    )
    assert ref.action_dim == ctrl.action_dim
    assert ref.action_mapping == ctrl.action_mapping
    K = ctrl.num_substeps
    coord, dof = layout.coord_index, layout.dof_index
    base_q = state.joint_q.numpy()[coord]

    _perturb_state(rng, state, layout, base_q)
    ctrl.reset(state)
    ref.reset()
    for step in range(STEPS):
        _perturb_state(rng, state, layout, base_q)
        action = torch.from_numpy(_random_action(rng, ctrl, NUM_ENVS))
        ctrl.set_action(action, state)
        ref.set_action(action)
        where = f"{mode_name} interpolate={interpolate} step {step}"
        np.testing.assert_allclose(ctrl.target_qpos.numpy(), ref.target_qpos.numpy(), atol=TOL, rtol=0, err_msg=where)
        np.testing.assert_allclose(ctrl.start_qpos.numpy(), ref.start_qpos.numpy(), atol=TOL, rtol=0, err_msg=where)
        for k in range(K):
            if k:
                _perturb_state(rng, state, layout, base_q)
            ctrl.before_simulation_step(state, control_w)
            ref.before_simulation_step()
            sub = f"{where} substep {k + 1}"
            tq_w = control_w.joint_target_q.numpy()[coord]
            tq_t = control_t.joint_target_q.numpy()[coord]
            np.testing.assert_allclose(tq_w, tq_t, atol=TOL, rtol=0, err_msg=f"{sub} joint_target_q")
            f_w = control_w.joint_f.numpy()[dof]
            f_t = control_t.joint_f.numpy()[dof]
            # Torques reach the 100 N·m limit, where float32 spacing is 7.6e-6: compare relative to 1e-5.
            np.testing.assert_allclose(f_w, f_t, rtol=TOL, atol=TOL, err_msg=f"{sub} joint_f")
            assert np.abs(f_w).max() > 1.0, "the PD torques should not be trivially zero"
            np.testing.assert_array_equal(
                control_w.joint_target_qd.numpy()[dof], control_t.joint_target_qd.numpy()[dof]
            )


def test_synthetic_layout_matches_real_model():
    """The bench's synthetic N-env layout (a 2-world model tiled) drives the same values as a real N-world model."""
    n = 6
    mode = "pd_joint_target_delta_pos"
    real_model = build_panda(n)
    real = wpctrl.build_controller(panda_mode(mode, True), real_model, actuation="explicit")
    syn = synthetic_setup(
        panda_mode(mode, True), build_panda(2), n, actuation="explicit", control_freq=20, sim_freq=100
    )
    assert syn.ctrl.num_envs == n
    real_layout = layout_from_model(real_model, list(real.joint_names))
    np.testing.assert_array_equal(syn.layout.coord_index, real_layout.coord_index)
    np.testing.assert_array_equal(syn.layout.dof_index, real_layout.dof_index)
    np.testing.assert_array_equal(tile_layout(real_layout, n).coord_index, real_layout.coord_index)

    real_state, real_control = real_model.state(), real_model.control()
    np.testing.assert_array_equal(syn.state.joint_q.numpy(), real_state.joint_q.numpy())
    np.testing.assert_array_equal(syn.control.joint_target_q.numpy(), real_control.joint_target_q.numpy())
    rng = np.random.default_rng(7)
    q = real_state.joint_q.numpy() + rng.normal(0, 0.05, real_model.joint_coord_count).astype(np.float32)
    qd = rng.normal(0, 0.5, real_model.joint_dof_count).astype(np.float32)
    for st in (real_state, syn.state):
        st.joint_q.assign(q)
        st.joint_qd.assign(qd)
    real.reset(real_state)
    syn.ctrl.reset(syn.state)
    action = torch.from_numpy(rng.uniform(-1, 1, (n, real.action_dim)).astype(np.float32))
    for _ in range(2):
        real.set_action(action, real_state)
        syn.ctrl.set_action(action, syn.state)
        for _ in range(real.num_substeps):
            real.before_simulation_step(real_state, real_control)
            syn.ctrl.before_simulation_step(syn.state, syn.control)
            for name in ("joint_target_q", "joint_target_qd", "joint_f"):
                np.testing.assert_array_equal(
                    getattr(syn.control, name).numpy(), getattr(real_control, name).numpy(), err_msg=name
                )
