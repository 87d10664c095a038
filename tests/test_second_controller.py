"""A robot on a floating base (ManiSkill's Panda on a free joint: 16 coordinates and 15 DOFs per env, so a joint's
``joint_q`` / ``joint_target_q`` index and its ``joint_qd`` / ``joint_target_qd`` / ``joint_f`` index differ, and
by more in every later env) with more than one controller in the mode:

- actuator networks (MLP and LSTM) on the mode's second (and third) controller, on every network kernel that runs on
  the CPU (unrolled in a launch of its own and in the substep's launch, tiled, the tensor-core kernel's CPU
  emulation): the whole ``Control.joint_f`` of every env against torch
  evaluating the same network on the position errors and velocities gathered at the model's own indices, the other
  controller's explicit PD re-derived in numpy and the base's DOFs untouched;
- the elided substep launch (implicit actuation, nothing to do per substep): ``set_action`` writes each controller's
  drive targets straight into ``Control.joint_target_q`` (at coordinates) and ``joint_target_qd`` (at DOFs); every
  env's against a numpy re-derivation of ManiSkill's PD joint-position semantics, and against the same mode run
  with a substep launch.

The joints' indices come from the model's own tables (``user_models.indices``), never from wpctrl's binding."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from user_models import indices, panda_envs, put

import wpctrl
from wpctrl.robots import PANDA_ARM_JOINTS, PANDA_GRIPPER_JOINTS

torch = pytest.importorskip("torch", reason="torch is a dev dependency (the networks' reference)")

from actuator_nets import LSTMNet  # noqa: E402

pytestmark = pytest.mark.filterwarnings("ignore:`torch.jit:DeprecationWarning")

f32 = np.float32
E = 3
ARM = list(PANDA_ARM_JOINTS)
WRIST = list(PANDA_ARM_JOINTS[3:])[::-1]  # not in the model's order: the kernels read index tables
SHOULDER = list(PANDA_ARM_JOINTS[:3])
FINGERS = list(PANDA_GRIPPER_JOINTS)
MIMIC = {"panda_finger_joint2": {"joint": "panda_finger_joint1"}}
FINGER_KP, FINGER_KD = 20.0, 0.2


def _floating(num_envs: int = E):
    model = panda_envs(num_envs, floating=True)
    # the premise: a free joint's 7 coordinates and 6 DOFs make the two strides differ
    assert model.joint_coord_count // num_envs == 16 and model.joint_dof_count // num_envs == 15
    return model


# -- actuator networks on a floating base ----------------------------------------------------------------------------

# (kernel setting, launch setting): every network kernel that runs on the CPU
KERNELS = {
    "unrolled": ("unrolled", "separate"),
    "fused": ("unrolled", "fused"),  # the substep kernel and the network in one launch
    "tiled": ("tiled", "auto"),
    "3xtf32": ("3xtf32", "auto"),
}


def _net(kind: str, seed: int):
    torch.manual_seed(seed)
    if kind == "mlp":
        net = torch.nn.Sequential(torch.nn.Linear(6, 12), torch.nn.Tanh(), torch.nn.Linear(12, 8), torch.nn.ELU(0.6),
                                  torch.nn.Linear(8, 1))  # fmt: skip
    else:
        net = LSTMNet(hidden=5, layers=2)
    for p in net.parameters():
        torch.nn.init.uniform_(p, -0.7, 0.7)
    return net.eval()


class _TorchActuator:
    """One ActuatorNet's rows in torch as Isaac Lab runs them: an MLP over the history of position errors and
    velocities (newest first, zeroed at a reset), or an LSTM with its (h, c) per (env, joint)."""

    def __init__(self, net, act: wpctrl.ActuatorNet, kind: str, n: int):
        self.net, self.act, self.kind, self.n = net, act, kind, n
        if kind == "mlp":
            self.hist_e = np.zeros((E, max(act.input_idx) + 1, n), f32)
            self.hist_v = np.zeros_like(self.hist_e)
        else:
            self.h = torch.zeros(2, E * n, 5)
            self.c = torch.zeros(2, E * n, 5)

    def reset(self, mask: np.ndarray) -> None:
        if self.kind == "mlp":
            self.hist_e[mask] = 0.0
            self.hist_v[mask] = 0.0
        else:
            m = torch.from_numpy(mask)
            self.h.view(2, E, self.n, -1)[:, m] = 0.0
            self.c.view(2, E, self.n, -1)[:, m] = 0.0

    def step(self, err: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """The computed efforts (E, n) for position errors ``err`` and velocities ``qd`` (E, n)."""
        a, n = self.act, self.n
        with torch.no_grad():
            if self.kind == "mlp":
                self.hist_e = np.roll(self.hist_e, 1, axis=1)
                self.hist_v = np.roll(self.hist_v, 1, axis=1)
                self.hist_e[:, 0], self.hist_v[:, 0] = err, qd
                idx = list(a.input_idx)
                pos = self.hist_e[:, idx].transpose(0, 2, 1).reshape(E * n, -1) * f32(a.pos_scale)
                vel = self.hist_v[:, idx].transpose(0, 2, 1).reshape(E * n, -1) * f32(a.vel_scale)
                x = np.concatenate([pos, vel] if a.input_order == "pos_vel" else [vel, pos], axis=1)
                u = self.net(torch.from_numpy(x)).numpy()
            else:
                pos, vel = err * f32(a.pos_scale), qd * f32(a.vel_scale)
                x = np.stack([pos, vel] if a.input_order == "pos_vel" else [vel, pos], axis=2).reshape(E * n, 1, 2)
                u, (self.h, self.c) = self.net(torch.from_numpy(x), (self.h, self.c))
                u = u.numpy()
        return u.reshape(E, n) * f32(a.torque_scale)


def _fingers():
    return wpctrl.PDJointPosControllerConfig(FINGERS, None, None, FINGER_KP, FINGER_KD, 1e9, normalize_action=False)


def _network_mode(layout: str, kind: str, kernel: str, launch: str):
    """The mode and its networks ``{controller: (joint names, torch module, ActuatorNet, force limit)}``: the fingers
    first (explicit PD), then one network on the arm (``"second"``) or one network on each half of the arm, the
    wrist's joints in reverse order (``"two"``: the second and third controllers)."""
    scales = {"input_idx": (0, 1, 3)} if kind == "mlp" else {}
    ts = 20.0 if kind == "mlp" else 60.0  # the LSTM's outputs are smaller
    nets = {}
    if layout == "second":
        net = _net(kind, 1)
        act = wpctrl.ActuatorNet(net, pos_scale=1.5, vel_scale=0.3, torque_scale=ts, kernel=kernel, launch=launch,
                                 **scales)  # fmt: skip
        nets["arm"] = (ARM, net, act, 18.0)
    else:
        for name, joints, seed, order, lim in (("wrist", WRIST, 2, "vel_pos", 15.0), ("shoulder", SHOULDER, 3,
                                                                                         "pos_vel", 30.0)):  # fmt: skip
            net = _net(kind, seed)
            act = wpctrl.ActuatorNet(net, pos_scale=1.2, vel_scale=0.4, torque_scale=ts, input_order=order,
                                     kernel=kernel, launch=launch, **scales)  # fmt: skip
            nets[name] = (joints, net, act, lim)
    mode = {"fingers": _fingers()}
    for name, (joints, _, act, lim) in nets.items():
        mode[name] = wpctrl.PDJointPosControllerConfig(joints, None, None, 0.0, 0.0, lim, normalize_action=False,
                                                       actuator=act)  # fmt: skip
    return mode, nets


CASES = [
    pytest.param(layout, kind, k, id=f"{layout}-{kind}-{k}")
    for layout in ("second", "two")
    for kind in ("mlp", "lstm")
    for k in KERNELS
    if not (kind == "lstm" and k == "3xtf32")  # the tensor-core kernel runs MLPs (its refusal is tested elsewhere)
    and not (layout == "two" and k == "fused")  # the substep's launch takes one network (tested below)
]


@pytest.mark.parametrize(("layout", "kind", "k"), CASES)
def test_networks_on_a_floating_base_equal_torch_per_env_and_dof(layout, kind, k):
    """Per env and per DOF, the whole ``Control.joint_f`` after every substep: each network's rows are torch's
    network on the position errors ``q* - q`` (at the joints' coordinates) and velocities (at their DOFs) of that
    env, times torque_scale, clamped to the controller's force limit; the fingers are the explicit PD of their
    targets; the floating base's 6 DOFs stay 0. Random, per-env different states and targets, a partial reset."""
    kernel, launch = KERNELS[k]
    model = _floating()
    mode, nets = _network_mode(layout, kind, kernel, launch)
    ctrl = wpctrl.build_controller(mode, model, 100, 100, actuation="explicit", track_effort=True)
    groups = ctrl._engine.part("actuator_models")  # private: the variant that runs, and the launch
    assert [g.kernel_kind for g in groups.nets] == [kernel] * len(nets)
    assert (groups.fused is not None) == (launch == "fused")
    refs = {name: _TorchActuator(net, act, kind, len(j)) for name, (j, net, act, _) in nets.items()}
    finger_q, finger_d = indices(model, FINGERS)
    all_joints = FINGERS + [j for (joints, *_) in nets.values() for j in joints]
    _, dof = indices(model, all_joints)
    base_dofs = (np.arange(E) * 15)[:, None] + np.arange(6)
    assert not np.isin(base_dofs, dof).any()
    rng = np.random.default_rng(11)
    s, c = model.state(), model.control()
    ctrl.reset(s, control=c)
    worst, binds = 0.0, False
    for step in range(4):
        q = rng.uniform(-1.0, 1.0, (E, len(all_joints))).astype(f32)
        qd = rng.uniform(-3.0, 3.0, (E, len(all_joints))).astype(f32)
        put(s, model, all_joints, q, qd)
        if step == 2:  # env 1 resets: its histories / hidden states start again from zero
            mask = np.arange(E) == 1
            ctrl.reset(s, wp.array(mask, dtype=wp.bool), control=c)
            for ref in refs.values():
                ref.reset(mask)
        action = rng.uniform(-1.0, 1.0, (E, ctrl.action_dim)).astype(f32)
        ctrl.set_action(action, s)
        ctrl.before_simulation_step(s, c)
        # the expected joint_f of every DOF of every env
        want = np.zeros(model.joint_dof_count, f32)
        sq, sqd = s.joint_q.numpy(), s.joint_qd.numpy()
        fq, fqd = sq[finger_q], sqd[finger_d]
        want[finger_d] = f32(FINGER_KP) * (action[:, :2] - fq) + f32(FINGER_KD) * (f32(0.0) - fqd)
        col = 2
        computed = [want[finger_d]]
        for name, (joints, _, _, lim) in nets.items():
            jq, jd = indices(model, joints)
            n = len(joints)
            u = refs[name].step(action[:, col : col + n] - sq[jq], sqd[jd])
            want[jd] = np.clip(u, -lim, lim)
            computed.append(u)
            col += n
            worst, binds = max(worst, float(np.abs(u).max())), binds or bool((np.abs(u) > lim).any())
        np.testing.assert_allclose(c.joint_f.numpy(), want, rtol=1e-5, atol=2e-5, err_msg=f"substep {step}")
        np.testing.assert_allclose(ctrl.computed_effort.numpy(), np.hstack(computed), rtol=1e-5, atol=2e-5)
    assert worst > 5.0 and binds  # the networks produce real torques, and the force limits bind on some


def test_the_substeps_launch_takes_one_network_of_a_floating_base_mode():
    """Two networks in one mode (the second and third controllers): ``launch="fused"`` is refused with the reason,
    ``"auto"`` runs each in a launch of its own (the equality with torch is the test above)."""
    model = _floating(1)
    mode, _ = _network_mode("two", "mlp", "unrolled", "fused")
    with pytest.raises(wpctrl.ConfigError, match=r"actuator.launch: .*the substep's launch takes one network, this "
                       r"mode has 2\), got 'fused'"):  # fmt: skip
        wpctrl.build_controller(mode, model, 100, 100, actuation="explicit")


# -- the elided substep launch with three controllers ----------------------------------------------------------------

GRIP_LO, GRIP_HI = -0.01, 0.04
WRIST_D = 0.2  # delta bounds of the wrist (a virtual target: use_delta and use_target)
SHOULDER_D, SHOULDER_V = 0.3, 2.0  # delta bounds of the shoulder's positions (from the measured q), its velocities


def _three_controllers():
    """A mimic gripper, the wrist (its joints in reverse order) on a virtual target, the shoulder on position deltas
    from the measured position plus velocity targets: every action normalised (clipped to [-1, 1], then scaled)."""
    return {
        "gripper": wpctrl.PDJointPosMimicControllerConfig(FINGERS, GRIP_LO, GRIP_HI, 1e3, 1e2, mimic=MIMIC),
        "wrist": wpctrl.PDJointPosControllerConfig(
            WRIST, -WRIST_D, WRIST_D, 400.0, 40.0, use_delta=True, use_target=True
        ),
        "shoulder": wpctrl.PDJointPosVelControllerConfig(
            SHOULDER, -SHOULDER_D, SHOULDER_D, 300.0, 30.0, use_delta=True, vel_lower=-SHOULDER_V, vel_upper=SHOULDER_V
        ),
    }


def _scale(a, lo, hi):
    """ManiSkill's ``_preprocess_action``: clip to [-1, 1], then ``0.5 (h + l) + 0.5 (h - l) a`` in float32."""
    lo, hi = f32(lo), f32(hi)
    return f32(0.5) * (hi + lo) + (f32(0.5) * (hi - lo)) * np.clip(a, f32(-1.0), f32(1.0))


class _ManiSkillTargets:
    """The three controllers' drive targets as ManiSkill computes them (numpy, float32), written over a Control's
    initial ``joint_target_q`` (coordinates) / ``joint_target_qd`` (DOFs) at the model's own indices."""

    def __init__(self, model):
        self.gq, _ = indices(model, FINGERS)
        self.wq, _ = indices(model, WRIST)
        self.sq, self.sd = indices(model, SHOULDER)
        fresh = model.control()
        self.tq, self.tqd = fresh.joint_target_q.numpy().copy(), fresh.joint_target_qd.numpy().copy()
        self.virtual = None

    def reset(self, joint_q, mask=None):
        """ManiSkill's reset: the wrist's virtual target restarts at the measured position of the reset envs."""
        q = joint_q[self.wq]
        self.virtual = q.copy() if mask is None else np.where(mask[:, None], q, self.virtual)

    def set_action(self, a, joint_q):
        finger = _scale(a[:, 0], GRIP_LO, GRIP_HI)
        self.tq[self.gq[:, 0]] = finger
        self.tq[self.gq[:, 1]] = finger * f32(1.0) + f32(0.0)  # the follower: target * multiplier + offset
        self.virtual = self.virtual + _scale(a[:, 1:5], -WRIST_D, WRIST_D)
        self.tq[self.wq] = self.virtual
        self.tq[self.sq] = joint_q[self.sq] + _scale(a[:, 5:8], -SHOULDER_D, SHOULDER_D)
        self.tqd[self.sd] = _scale(a[:, 8:11], -SHOULDER_V, SHOULDER_V)


def _check(control, ref, what):
    """The whole Control, every env: the controlled joints' targets, and every other entry (the floating base's
    coordinates with its quaternion, the DOFs without a velocity target) as a fresh Control holds them."""
    np.testing.assert_allclose(control.joint_target_q.numpy(), ref.tq, rtol=0, atol=1e-6, err_msg=f"{what}: q")
    np.testing.assert_allclose(control.joint_target_qd.numpy(), ref.tqd, rtol=0, atol=1e-6, err_msg=f"{what}: qd")


def test_elided_substeps_write_each_controllers_targets_at_its_own_coordinates_and_dofs():
    """Implicit actuation with nothing to do per substep (the substep launch elided, ``set_action`` writes the drive
    targets itself) against a numpy re-derivation of ManiSkill's controllers, per env, over three control steps of 5
    substeps: right after ``set_action``, after every substep, after a partial reset (the wrist's virtual target of
    the reset env restarts at its measured position), and in a second Control handed in mid-step (it gets every
    env's targets, and the next ``set_action`` writes there). The same mode with a substep launch (the effort
    readout on) writes the same targets."""
    rng = np.random.default_rng(5)
    models = {"elided": _floating(), "per_substep": _floating()}
    ctrls = {k: wpctrl.build_controller(_three_controllers(), m, 20, 100, track_effort=k == "per_substep")
             for k, m in models.items()}  # fmt: skip
    assert "per-substep launch: no (elided)" in ctrls["elided"].describe()
    assert "per-substep launch: yes" in ctrls["per_substep"].describe()
    assert ctrls["elided"].action_dim == 1 + 4 + 6
    joints = FINGERS + WRIST + SHOULDER
    refs = {k: _ManiSkillTargets(m) for k, m in models.items()}
    states = {k: m.state() for k, m in models.items()}
    controls = {k: m.control() for k, m in models.items()}

    def new_state():
        q = rng.uniform(-1.0, 1.0, (E, len(joints))).astype(f32)
        qd = rng.uniform(-2.0, 2.0, (E, len(joints))).astype(f32)
        for k, m in models.items():
            put(states[k], m, joints, q, qd)

    new_state()
    for k in models:
        ctrls[k].reset(states[k], control=controls[k])
        refs[k].reset(states[k].joint_q.numpy())
    for step in range(3):
        new_state()
        if step == 1:  # env 1 resets at a new pose
            mask = np.arange(E) == 1
            for k in models:
                ctrls[k].reset(states[k], wp.array(mask, dtype=wp.bool), control=controls[k])
                refs[k].reset(states[k].joint_q.numpy(), mask)
        action = rng.uniform(-1.3, 1.3, (E, 11)).astype(f32)  # some past the bounds: clipped
        for k in models:
            ctrls[k].set_action(action, states[k])
            refs[k].set_action(action, states[k].joint_q.numpy())
        _check(controls["elided"], refs["elided"], f"step {step}, set_action")  # written by set_action itself
        for sub in range(5):
            if step == 1 and sub == 2:  # a fresh Control mid-step: it gets every env's targets
                controls = {k: m.control() for k, m in models.items()}
            for k in models:
                ctrls[k].before_simulation_step(states[k], controls[k])
                _check(controls[k], refs[k], f"{k}, step {step}, substep {sub}")
        np.testing.assert_array_equal(controls["elided"].joint_target_q.numpy(),
                                      controls["per_substep"].joint_target_q.numpy())  # fmt: skip
        np.testing.assert_array_equal(controls["elided"].joint_target_qd.numpy(),
                                      controls["per_substep"].joint_target_qd.numpy())  # fmt: skip
    # the envs' targets differ (a per-env check of something)
    t = controls["elided"].joint_target_q.numpy()[refs["elided"].sq]
    assert np.ptp(t, axis=0).min() > 0.05
