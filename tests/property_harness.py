"""The harness of the property tests (test_properties.py): wpctrl and the numpy reference side by side, driven by
operations that hypothesis draws one by one (``draw``: hypothesis' ``data.draw``), so that a failure shrinks to a short
stream of simple operations.

After every operation the controller's buffers, the model's drive properties and the whole of Newton's control arrays
(entries the controller must not write included) are compared with the reference. What the reference takes as an
input is checked against an independent computation first:

- the joint-space response r = (H^-1)_ii that acceleration drives and stable / coupled PD read: Newton's own
  ``JointSpaceResponse`` at the state of the call that refreshed it (set_action, or each substep);
- the coupled drive's block of H^-1: Newton's ``JointSpaceResponse`` at the substep's state;
- the Jacobian of an end-effector chain: Newton's ``eval_fk`` body poses and the model's joint frames and axes;
- randomised drive properties and per-env delays: Warp's RNG draws of the seed and the draw counter (numpy port).

Models: ``"replicated"`` (``build_panda(n)``: the index tables are env 0's plus a stride), ``"spaced"`` (the same,
replicated 1 m x 2 m apart: the grid is centred, no env sits at the origin), ``"floating"`` (ManiSkill's Panda URDF
on a free joint, spaced: 16 coordinates and 15 DOFs per env, so coordinate and DOF strides differ) or ``"flat"``
(three worlds, the second with a free-jointed box before its Panda: per-env index tables), built once per layout and
shared (each controller rewrites the drive arrays of its own joints only; comparisons never read other joints').
"""

from __future__ import annotations

import warnings

import newton
import numpy as np
import pytest
import warp as wp
from conftest import build_panda
from hypothesis import strategies as st
from reference_actuators import TABLE_TOL
from reference_ee import EE_CONFIGS
from reference_np import WRITE_KEYS, RefCombined, RefRobot, delay_draws, drawn_value, drive_draws, param_draws

import wpctrl
from wpctrl.robots import PANDA_INITIAL_Q, PANDA_JOINTS

torch = pytest.importorskip("torch", reason="torch is a dev dependency (torch inputs are drawn here)")

TOL = 1e-6
EE_TOL = 2e-4  # [rad, m] EE targets: float32 forward kinematics through a damped solve
DRIVE = ("stiffness", "damping", "force_limit", "friction")
ACT = ("saturation_effort", "velocity_limit")  # per-env DC-motor parameters (children with a DCMotor)
_MODELS: dict = {}


# ----------------------------------------------------------------------------------------------------------------------
# Models and an index layout computed here (independently of wpctrl's binding).


def _flat_model() -> newton.Model:
    from wpctrl.robots import panda

    b = newton.ModelBuilder()
    for w in range(3):
        b.begin_world()
        if w == 1:  # an extra articulation before the robot in world 1 only: no constant stride
            link = b.add_link(mass=1.0, inertia=wp.mat33(np.eye(3) * 0.01))
            b.add_articulation([b.add_joint_free(link, label="box/free")])
        b.add_builder(panda())
        b.end_world()
    return b.finalize(device="cpu")


class Layout:
    """(N, J) joint, coordinate and DOF indices of the Panda's joints in every world, each Panda's articulation and
    its DOFs' order in it, the robot's joint limits, and where its TCP site is."""

    def __init__(self, model: newton.Model):
        labels = list(model.joint_label)
        world = model.joint_world.numpy()
        q_start = model.joint_q_start.numpy()
        qd_start = model.joint_qd_start.numpy()
        N = int(model.world_count)
        J = len(PANDA_JOINTS)
        self.joint = np.zeros((N, J), np.int64)
        for j, label in enumerate(labels):
            short = label.rsplit("/", 1)[-1]
            if short in PANDA_JOINTS:
                self.joint[world[j], PANDA_JOINTS.index(short)] = j
        self.coord = q_start[self.joint]
        self.dof = qd_start[self.joint]
        d0 = self.dof[0]
        self.limits = np.stack([model.joint_limit_lower.numpy()[d0], model.joint_limit_upper.numpy()[d0]], axis=1)
        self.q0 = model.joint_q.numpy()[self.coord].astype(np.float32)
        self.art = model.joint_articulation.numpy()[self.joint[:, 0]]
        art_dof0 = qd_start[model.articulation_start.numpy()[self.art]]
        self.local = self.dof - art_dof0[:, None]  # each joint's DOF inside its articulation
        # The TCP: a site (a shape) on panda_link7 in wpctrl's Panda, a body of its own in the URDF's
        shape_world = model.shape_world.numpy()
        tcp = [i for i, s in enumerate(model.shape_label) if s.rsplit("/", 1)[-1] == "panda_hand_tcp"]
        if tcp:
            self.tcp_shape = np.array([next(i for i in tcp if shape_world[i] == w) for w in range(N)])
            self.tcp_body = model.shape_body.numpy()[self.tcp_shape]
            st = model.shape_transform.numpy().astype(np.float64)
            self.tcp_offset = [(st[i, :3], st[i, 3:]) for i in self.tcp_shape]
        else:
            body_world = model.body_world.numpy()
            bodies = [i for i, b in enumerate(model.body_label) if b.rsplit("/", 1)[-1] == "panda_hand_tcp"]
            self.tcp_body = np.array([next(i for i in bodies if body_world[i] == w) for w in range(N)])
            self.tcp_offset = [(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]))] * N


def model_for(kind: str, num_envs: int):
    key = (kind, num_envs)
    if key not in _MODELS:
        if kind == "replicated":
            m = build_panda(num_envs)
        elif kind in ("spaced", "floating"):
            from user_models import panda_envs

            m = panda_envs(num_envs, spacing=(1.0, 2.0, 0.0), floating=kind == "floating")
        else:
            m = _flat_model()
        _MODELS[key] = (m, Layout(m))
    return _MODELS[key]


# ----------------------------------------------------------------------------------------------------------------------
# Independent references for the reference's inputs: Newton's inverse inertia and forward kinematics.


def _qrot(q, v):
    """Rotate v by the (x, y, z, w) quaternion q."""
    u, w = q[:3], q[3]
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


def _qmul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )


def _compose(x, y):
    """Transform product x * y of (p, q) pairs."""
    return x[0] + _qrot(x[1], y[0]), _qmul(x[1], y[1])


class Physics:
    """Newton's own H^-1 (``JointSpaceResponse``) and forward kinematics (``eval_fk``) at given joint positions."""

    def __init__(self, model: newton.Model, layout: Layout):
        from newton.actuators import JointSpaceResponse

        self.model, self.layout = model, layout
        self.jsr = JointSpaceResponse(model)
        self.scratch = model.state()
        self._x_c = model.joint_X_c.numpy().astype(np.float64)
        self._axis = model.joint_axis.numpy().astype(np.float64)
        self._child = model.joint_child.numpy()
        self._type = model.joint_type.numpy()
        self._qd_start = model.joint_qd_start.numpy()
        self._tcp = layout.tcp_offset
        self._tcp_body = layout.tcp_body

    def _put(self, joint_q: np.ndarray):
        self.scratch.joint_q.assign(np.asarray(joint_q, np.float32))

    def inverse(self, joint_q: np.ndarray) -> np.ndarray:
        """(N, J, J) H^-1 of each env's Panda in PANDA_JOINTS order, float64, for a full joint_q array."""
        self._put(joint_q)
        self.jsr.refresh(self.scratch)
        inv = self.jsr.inverse_blocks.numpy().astype(np.float64)
        L = self.layout
        return np.stack([inv[L.art[e]][np.ix_(L.local[e], L.local[e])] for e in range(len(L.art))])

    def jacobian(self, joint_q: np.ndarray, names, ee_link: str) -> np.ndarray:
        """(N, 6, n) geometric Jacobian [v; w] about the TCP, in the world frame (every layout's Panda bases are
        unrotated: the root frame's axes; the Jacobian does not depend on where the base is), from eval_fk's body
        poses."""
        assert ee_link == "panda_hand_tcp"
        self._put(joint_q)
        newton.eval_fk(self.model, self.scratch.joint_q, self.scratch.joint_qd, self.scratch)
        body_q = self.scratch.body_q.numpy().astype(np.float64)
        L = self.layout
        cols = [PANDA_JOINTS.index(n) for n in names]
        out = np.zeros((len(L.art), 6, len(cols)))
        for e in range(len(L.art)):
            b = body_q[self._tcp_body[e]]
            p_ee = _compose((b[:3], b[3:]), self._tcp[e])[0]
            for c, col in enumerate(cols):
                j = L.joint[e, col]
                bc = body_q[self._child[j]]
                xc = self._x_c[j]
                o, rot = _compose((bc[:3], bc[3:]), (xc[:3], xc[3:]))
                a = _qrot(rot, self._axis[self._qd_start[j]])
                if self._type[j] == int(newton.JointType.REVOLUTE):
                    out[e, :3, c] = np.cross(a, p_ee - o)
                    out[e, 3:, c] = a
                else:
                    out[e, :3, c] = a
        return out


# ----------------------------------------------------------------------------------------------------------------------
# The harness.


def _ranged(delay):
    if delay is None:
        return None
    return (delay, delay) if isinstance(delay, int) else tuple(delay)


def _effective(children: dict, actuation, explicit_pd, nan_policy, inertia_update, opts: dict):
    """The drawn options as build_controller takes them: those this mode would ignore are left out (it refuses them,
    tests/test_options.py): an explicit law with implicit actuation, an inertia update where no inertia is computed
    (no acceleration drive, neither stable nor coupled PD), a seed where no delay is drawn, target clipping without a
    position target, a delay or the NaN check where no action is taken. What runs is the same either way."""

    def drive_modes(c):
        m = getattr(c, "drive_mode", "force")
        return [m] if isinstance(m, str) else list(m)

    opts = dict(opts)
    law = explicit_pd if actuation == "explicit" else None
    accel = any("acceleration" in drive_modes(c) for c in children.values())
    inertia = inertia_update if (accel or law in ("stable", "coupled")) else None
    rng = _ranged(opts.get("delay"))
    if rng is None or rng[0] == rng[1]:
        opts.pop("delay_seed", None)
    if not any(isinstance(c, (wpctrl.PDJointPosControllerConfig, *EE_CONFIGS)) for c in children.values()):
        opts.pop("clip_targets", None)
    if all(isinstance(c, wpctrl.PassiveControllerConfig) for c in children.values()):
        opts.pop("delay", None)
        opts.pop("delay_seed", None)
        nan_policy = "hold"
    return law, nan_policy, inertia, opts


class Harness:
    def __init__(self, mode, layout, num_substeps, actuation, explicit_pd, nan_policy, inertia_update, draw, opts=None):
        children = {"": mode} if not isinstance(mode, dict) else mode
        law, nan_policy, inertia, opts = _effective(
            children, actuation, explicit_pd, nan_policy, inertia_update, opts or {}
        )
        self.opts = opts
        self.draw = draw
        kind, num_envs = layout
        self.model, self.layout = model_for(kind, num_envs)
        self.physics = Physics(self.model, self.layout)
        self.N = num_envs
        self.K = num_substeps
        self.single = not isinstance(mode, dict)
        self.explicit = actuation == "explicit"
        self.coupled = self.explicit and explicit_pd == "coupled"
        if self.coupled:  # H every substep (its default): H once per control step has its own test in test_coupled.py
            inertia_update = inertia = "substep"
        children = {"": mode} if self.single else mode
        self.ee_cols = [
            PANDA_JOINTS.index(n) for c in children.values() if isinstance(c, EE_CONFIGS) for n in c.joint_names
        ]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            self.ctrl = wpctrl.build_controller(
                mode,
                self.model,
                control_freq=20,
                sim_freq=20 * num_substeps,
                actuation=actuation,
                nan_policy=nan_policy,
                explicit_pd=law,
                inertia_update=inertia,
                **opts,
            )
        self.inertia_update = inertia_update
        self.needs_response = self.ctrl.response is not None
        robot = RefRobot(PANDA_JOINTS, self.layout.limits)
        self.delay_range = _ranged(opts.get("delay"))
        self.ref = RefCombined(
            mode,
            robot,
            num_envs,
            num_substeps,
            self.layout.q0,
            actuation,
            explicit_pd,
            1.0 / (20 * num_substeps),
            inertia_update=inertia_update,
            delay=self.delay_range,
            track_effort=opts.get("track_effort", False),
            clip_targets=opts.get("clip_targets", "none"),
            kinematics=self._kinematics,
        )
        self.nominal = {
            uid: {f: getattr(self.child(uid), f).numpy()[0].copy() for f in DRIVE + self.act_fields(uid)}
            for uid in self.ref.children
        }
        self.row0 = {}
        r = 0
        for uid, rc in self.ref.children.items():
            self.row0[uid] = r
            r += rc.n
        self.rows = r
        # The device RNG's draw counter: the build's own reset draws the delays of a range (draw 0).
        self.seed = int(opts.get("delay_seed", 0))
        self.rng_counter = 0
        self.expect_delays(np.ones(num_envs, bool))
        self.nan_policy = nan_policy
        self.state = self.model.state()
        self.control = self.model.control()
        self.response_q = self.model.joint_q.numpy().copy()  # r was computed at build, for the initial pose
        # The expected control arrays: everything the controller must not write keeps its value.
        self.expect = {
            "target_q": self.control.joint_target_q.numpy().copy(),
            "target_qd": self.control.joint_target_qd.numpy().copy(),
            "f": self.control.joint_f.numpy().copy(),
        }
        self.apply(self.ref.initial_control_targets(self.layout.q0), check_only=True)
        self.q = self.layout.q0.copy()
        self.qd = np.zeros_like(self.q)

    # -- inputs the reference takes, computed by Newton ------------------------------------------------------------

    def _full_q(self, q):
        full = self.state.joint_q.numpy().copy()
        full[self.layout.coord] = q
        return full

    def _kinematics(self, q, names, ee_link):
        return self.physics.jacobian(self._full_q(q), names, ee_link)

    def expect_delays(self, mask):
        """The delays a reset of ``mask`` draws (Warp's RNG of the build's seed and the draw counter)."""
        rng = self.delay_range
        if rng is None:
            assert self.ctrl.delay is None
            return
        d = self.ctrl.delay.numpy()
        if rng[1] > rng[0]:
            want = delay_draws(self.seed, self.rng_counter, self.N, *rng)
            self.rng_counter += 1
        else:
            want = np.full(self.N, rng[0])
        if not hasattr(self, "delays"):
            self.delays = np.zeros(self.N, np.int64)
        self.delays[mask] = want[mask]
        np.testing.assert_array_equal(d, self.delays, err_msg="per-env delays drawn at reset")
        self.ref.delay = self.delays.copy()

    # -- Newton arrays ----------------------------------------------------------------------------------------------

    def put_state(self):
        rng = np.random.default_rng(self.draw(st.integers(0, 2**32 - 1), label="state seed"))
        if self.ee_cols:  # near the Panda's rest pose, away from singular arm configurations
            self.q = (np.asarray(PANDA_INITIAL_Q, np.float32) + rng.uniform(-0.4, 0.4, self.q.shape)).astype(np.float32)
            self.q = np.clip(self.q, self.layout.limits[:, 0], self.layout.limits[:, 1]).astype(np.float32)
        else:
            self.q = rng.uniform(-3.0, 3.0, self.q.shape).astype(np.float32)
        self.qd = rng.uniform(-5.0, 5.0, self.q.shape).astype(np.float32)
        q = self.state.joint_q.numpy()
        qd = self.state.joint_qd.numpy()
        q[self.layout.coord] = self.q
        qd[self.layout.dof] = self.qd
        self.state.joint_q.assign(q)
        self.state.joint_qd.assign(qd)

    def _index(self, key):
        return self.layout.coord if key == "target_q" else self.layout.dof

    def apply(self, writes: dict, check_only: bool = False):
        """Fold the reference's writes into the expected control arrays (check_only: just compare those entries)."""
        for key in WRITE_KEYS:
            written, values = writes[key]
            if key == "f" and not self.explicit:
                assert not written.any()
            idx = self._index(key)[written]
            if check_only:
                got = self._control_array(key)[idx]
                np.testing.assert_allclose(got, values[written], atol=TOL, rtol=0, err_msg=f"initial control {key}")
            else:
                self.expect[key][idx] = values[written]

    def _control_array(self, key):
        return {
            "target_q": self.control.joint_target_q,
            "target_qd": self.control.joint_target_qd,
            "f": self.control.joint_f,
        }[key].numpy()

    def child(self, uid):
        return self.ctrl if self.single else self.ctrl[uid]

    def act_fields(self, uid) -> tuple[str, ...]:
        """The per-env actuator-model parameters of child ``uid`` (a DCMotor's), or ()."""
        return ACT if self.ref.children[uid].actuator.kind == "dc" else ()

    def response(self) -> dict:
        """{uid: (N, n) r} as wpctrl last computed it (an input of the reference, checked in :meth:`check`)."""
        out = {}
        for uid in self.ref.children:
            r = self.child(uid).response
            if r is not None:
                out[uid] = r.numpy().copy()
        return out

    def check_drive_properties(self, where: str):
        m = self.model
        arrays = {
            "ke": m.joint_target_ke,
            "kd": m.joint_target_kd,
            "effort": m.joint_effort_limit,
            "friction": m.joint_friction,
        }
        response = self.response()
        for uid, rc in self.ref.children.items():
            props = rc.drive_properties(self.explicit, response.get(uid))
            dof = self.layout.dof[:, rc.cols]
            for key, arr in arrays.items():
                np.testing.assert_allclose(arr.numpy()[dof], props[key], rtol=1e-6, atol=0, err_msg=f"{where}: {key}")
            modes = np.vectorize(lambda s: int(newton.JointTargetMode[s]))(props["mode"])
            np.testing.assert_array_equal(m.joint_target_mode.numpy()[dof], modes, err_msg=f"{where}: mode")

    # -- comparisons ------------------------------------------------------------------------------------------------

    def _tolerance(self, key: str, exp: np.ndarray) -> np.ndarray:
        """Per-entry tolerance of a Newton control array: TOL, float32 rounding of the torques' products; the coupled
        drive's float64 solve against a float32 H^-1 (1e-4 relative); the EE rows' forward kinematics."""
        tol = np.full(exp.shape, TOL)
        if key == "f":
            tol += 1e-6 * np.abs(exp)
            if self.coupled and hasattr(self.ref, "coupled_scale"):
                # tau solves (I + D A) tau = b up to its clamps: relative to |b| + D |A| |tau|, not to tau
                cols, scale = self.ref.coupled_scale
                tol[self.layout.dof[:, cols]] += 1e-4 * np.abs(exp[self.layout.dof[:, cols]]) + 1e-5 * scale
        if key == "f":
            for rc in self.ref.children.values():
                if rc.actuator.kind == "table":
                    tol[self.layout.dof[:, rc.cols]] += TABLE_TOL
        if self.ee_cols:
            idx = self._index(key)[:, self.ee_cols]
            if key == "target_q":
                tol[idx] = EE_TOL
            elif key == "f":
                kp = max(float(rc.kp.max()) for rc in self.ref.children.values())
                tol[idx] += EE_TOL * (kp + 1.0)
        return tol

    def check_response(self, where: str):
        """wpctrl's r against Newton's JointSpaceResponse at the state of its last refresh."""
        if not self.needs_response:
            return
        want = np.diagonal(self.physics.inverse(self.response_q), axis1=1, axis2=2)
        for uid, rc in self.ref.children.items():
            got = self.child(uid).response.numpy()
            np.testing.assert_allclose(got, want[:, rc.cols], rtol=1e-4, err_msg=f"{where}: {uid or 'ctrl'}.response")

    def check(self, where: str):
        ctrl, ref = self.ctrl, self.ref
        for key in WRITE_KEYS:
            got = self._control_array(key)
            exp = self.expect[key]
            bad = np.abs(got.astype(np.float64) - exp) > self._tolerance(key, exp)
            if bad.any():
                i = np.nonzero(bad)[0][:5]
                raise AssertionError(f"{where}: control.{key} at {i.tolist()}: got {got[i]}, expected {exp[i]}")
        np.testing.assert_array_equal(ctrl.step_counter.numpy(), ref.step_counter, err_msg=f"{where}: step")
        np.testing.assert_array_equal(ctrl.bad_action_count.numpy(), ref.bad_action_count, err_msg=f"{where}: bad")
        self.check_response(where)
        for uid, rc in ref.children.items():
            c = self.child(uid)
            w = f"{where}: {uid or 'ctrl'}"
            np.testing.assert_allclose(
                c.processed_action.numpy(), rc.processed_action, atol=TOL, rtol=0, err_msg=f"{w}.processed_action"
            )
            if rc.has_qpos:
                tol = EE_TOL if isinstance(rc.config, EE_CONFIGS) else TOL
                np.testing.assert_allclose(
                    c.target_qpos.numpy(), rc.target_qpos, atol=tol, rtol=0, err_msg=f"{w}.target_qpos"
                )
                np.testing.assert_allclose(
                    c.start_qpos.numpy(), rc.start_qpos, atol=TOL, rtol=0, err_msg=f"{w}.start_qpos"
                )
            if rc.has_vel_target:
                np.testing.assert_allclose(
                    c.target_qvel.numpy(), rc.target_qvel, atol=TOL, rtol=0, err_msg=f"{w}.target_qvel"
                )
        self.check_drive_properties(where)
        for uid, rc in ref.children.items():
            c = self.child(uid)
            w = f"{where}: {uid or 'ctrl'}"
            for f, a in zip(DRIVE, (rc.kp, rc.kd, rc.force_limit, rc.friction)):
                np.testing.assert_array_equal(getattr(c, f).numpy(), a, err_msg=f"{w}.{f}")
            for f, a in zip(ACT, (rc.actuator.sat_effort, rc.actuator.vel_limit)):
                got = getattr(c, f)
                if rc.actuator.kind is not None or got is not None:  # a mode with actuator models has them per row
                    np.testing.assert_array_equal(got.numpy(), a, err_msg=f"{w}.{f}")
            if ref.track_effort:
                for f in ("computed_effort", "applied_effort"):
                    exp = getattr(rc, f)
                    atol = np.full(exp.shape, TOL)
                    if self.coupled:  # b - D A tau: large terms cancel (a float32 H^-1 against the kernel's float64)
                        atol += 1e-4 * np.abs(exp) + 1e-5 * getattr(rc, "effort_scale", 0.0)
                    if isinstance(rc.config, EE_CONFIGS):
                        kp = max(float(rc.kp.max()), getattr(self, "effort_kp", {}).get(uid, 0.0))
                        atol += EE_TOL * (kp + 1.0)
                    if rc.actuator.kind == "table" and f == "applied_effort":
                        atol += TABLE_TOL
                    got = getattr(c, f).numpy()
                    ok = np.abs(got - exp) <= atol + 1e-6 * np.abs(exp)
                    assert ok.all(), f"{w}.{f}: got {got[~ok]}, expected {exp[~ok]}"
                sat = c.saturation_count.numpy()
                # |law| vs the limit: exact for the float32 laws; the coupled drive's float64 law may sit within
                # 1e-5 of the limit (sat_margin), where either count is right.
                ok = (sat >= rc.saturation_count) & (sat <= rc.saturation_count + rc.sat_margin)
                assert ok.all(), f"{w}.saturation_count: {sat} vs {rc.saturation_count} (+{rc.sat_margin})"
            else:
                assert c.computed_effort is None
        got_state = ctrl.get_state()
        exp_state = ref.get_state(self.single)
        assert _keys(got_state) == _keys(exp_state), where
        for path, arr in _leaves(exp_state):
            np.testing.assert_allclose(_get(got_state, path).numpy(), arr, atol=TOL, rtol=0, err_msg=f"{where} {path}")

    # -- operations, every choice drawn by hypothesis -------------------------------------------------------------

    def random_action(self):
        N, D = self.N, self.ref.action_dim
        rng = np.random.default_rng(self.draw(st.integers(0, 2**32 - 1), label="action seed"))
        a = rng.uniform(-1.5, 1.5, (N, D))
        if D:
            a *= self.draw(st.sampled_from([1.0, 1.0, 1.0, 0.01, 10.0, 1e3]), label="action scale")
            bad = self.draw(
                st.lists(
                    st.tuples(st.integers(0, N - 1), st.integers(0, D - 1), st.sampled_from([np.nan, np.inf, -np.inf])),
                    max_size=3,
                ),
                label="non-finite entries",
            )
            for e, c, v in bad:
                a[e, c] = v
        return a

    def as_input(self, a: np.ndarray):
        """The same action as one of the accepted input kinds."""
        kinds = ["f32", "f64", "fortran", "torch", "torch64", "torch_strided", "wp"] + (["1-D"] if self.N == 1 else [])
        kind = self.draw(st.sampled_from(kinds), label="input kind")
        if kind == "1-D":  # one env: a (D,) action means the (1, D) one
            return a[0].astype(np.float32)
        if kind == "f64":
            return a.astype(np.float64)
        if kind == "fortran":
            return np.asfortranarray(a.astype(np.float32))
        if kind == "torch":
            return torch.from_numpy(a.astype(np.float32))
        if kind == "torch64":
            return torch.from_numpy(a.astype(np.float64))
        if kind == "torch_strided":
            return torch.from_numpy(np.ascontiguousarray(a.astype(np.float32).T)).t()
        if kind == "wp":
            return wp.array(a.astype(np.float32), dtype=wp.float32, device="cpu")
        return a.astype(np.float32)

    def random_env_ids(self, allow_duplicates: bool = True):
        """(env_ids as passed, its (N,) mask, whether it selects no env at all)."""
        N = self.N
        kinds = ["none", "int", "list", "mask", "torch_mask", "torch_ids", "wp_mask", "wp_ids"]
        kind = self.draw(st.sampled_from(kinds), label="env selection")
        mask_s = st.lists(st.booleans(), min_size=N, max_size=N).map(lambda m: np.array(m, bool))
        ids_s = st.lists(st.integers(0, N - 1), min_size=1, max_size=N, unique=True)
        if kind == "none":
            return None
        if kind == "int":
            return self.draw(st.integers(0, N - 1), label="env id")
        if kind == "list":
            elems = st.integers(0, N - 1)
            ids = st.lists(elems, max_size=N + 1) if allow_duplicates else st.lists(elems, max_size=N, unique=True)
            return self.draw(ids, label="env ids")
        if kind in ("mask", "torch_mask", "wp_mask"):
            m = self.draw(mask_s, label="env mask")
            if kind == "torch_mask":
                return torch.from_numpy(m)
            return wp.array(m, dtype=wp.bool, device="cpu") if kind == "wp_mask" else m
        ids = np.array(self.draw(ids_s, label="env ids"))
        if kind == "torch_ids":
            return torch.from_numpy(ids)
        return wp.array(ids.astype(np.int32), dtype=wp.int32, device="cpu")

    def op_reset(self):
        from reference_np import env_mask

        self.put_state()
        env_ids = self.random_env_ids()
        with_control = self.draw(st.booleans(), label="reset with the control")
        first = self.ref.num_resets == 0
        self.ctrl.reset(self.state, env_ids, control=self.control if with_control else None)
        self.apply(self.ref.reset(self.q, self.qd, env_ids, with_control))
        empty = isinstance(env_ids, list) and not env_ids
        if not empty or first:  # an empty selection launches nothing (the first reset always takes every env)
            self.expect_delays(np.ones(self.N, bool) if first else env_mask(env_ids, self.N))
        self.check(f"reset({env_ids!r}, control={with_control})")

    def op_step(self, with_action: bool):
        self.put_state()
        if with_action:
            a = self.random_action()
            if self.nan_policy == "raise" and not np.isfinite(a.astype(np.float32)).all():
                with pytest.raises(ValueError, match="non-finite"):
                    self.ctrl.set_action(self.as_input(a), self.state)
            else:
                self.ctrl.set_action(self.as_input(a), self.state)
                self.apply(self.ref.set_action(a, self.q))
                if self.inertia_update == "control" and not self.coupled:
                    self.response_q = self.state.joint_q.numpy().copy()
            self.check("set_action")
        extra = self.draw(st.booleans(), label="step past K")
        for k in range(self.K * (2 if extra else 1)):
            if self.draw(st.booleans(), label="new state before the substep"):
                self.put_state()
            self.ctrl.before_simulation_step(self.state, self.control)
            inverse = None
            if self.coupled or (self.inertia_update == "substep" and self.ctrl.substep_launch):
                self.response_q = self.state.joint_q.numpy().copy()
            if self.coupled:
                inverse = self.physics.inverse(self.response_q)
            self.apply(self.ref.before_simulation_step(self.q, self.qd, self.response(), inverse))
            # the efforts now held were computed with these gains; a later randomisation changes the gains, not them
            self.effort_kp = {uid: float(rc.kp.max()) for uid, rc in self.ref.children.items()}
            self.check(f"substep {k + 1}")

    def op_drive(self):
        """set_drive_properties or randomize_drive_properties on a drawn child and env selection (no duplicates)."""
        from reference_np import env_mask

        N = self.N
        uid = self.draw(st.sampled_from(list(self.ref.children)), label="child")
        c, rc = self.child(uid), self.ref.children[uid]
        n = rc.n
        env_ids = self.random_env_ids(allow_duplicates=False)
        if isinstance(env_ids, list) and not env_ids:
            env_ids = None
        mask = env_mask(env_ids, N)
        fields = sorted(
            self.draw(st.sets(st.sampled_from(DRIVE + self.act_fields(uid)), min_size=1), label="properties")
        )
        is_mask = isinstance(env_ids, np.ndarray | torch.Tensor) and env_ids.dtype in (np.bool_, torch.bool)
        is_mask = is_mask or (isinstance(env_ids, wp.array) and env_ids.dtype == wp.bool)
        if self.draw(st.booleans(), label="set (or randomise)"):
            sel = N if env_ids is None or is_mask else int(mask.sum()) if not isinstance(env_ids, int) else 1
            rng = np.random.default_rng(self.draw(st.integers(0, 2**32 - 1), label="values seed"))
            vals = {}
            for f in fields:
                shape = (n,) if self.draw(st.booleans(), label=f"{f} broadcast") else (sel, n)
                lo, hi = {"saturation_effort": (0.0, 200.0), "velocity_limit": (0.1, 10.0)}.get(f, (0.0, 500.0))
                v = rng.uniform(lo, hi, shape).astype(np.float32)
                vals[f] = torch.from_numpy(v) if self.draw(st.booleans(), label=f"{f} as torch") else v
            c.set_drive_properties(env_ids=env_ids, **vals)
            ids = None if env_ids is None or is_mask or isinstance(env_ids, int) else _ids(env_ids)
            for f, v in vals.items():
                v = np.asarray(v, np.float32)
                full = np.zeros((N, n), np.float32)
                if v.ndim == 1 or ids is None:
                    full[:] = v
                else:
                    full[ids] = v
                rc.set_drive(f, full, mask)
            self.check(f"set_drive_properties({fields}, {env_ids!r})")
            return
        mode = self.draw(st.sampled_from(["scale", "scale", "abs"]), label="randomise mode")
        top = 2.0 if mode == "scale" else 100.0
        ranges = {}
        for f in fields:
            least = (0.05 if mode == "scale" else 0.1) if f == "velocity_limit" else 0.0  # a no-load speed > 0
            lo = self.draw(st.floats(least, top), label=f"{f} lo")
            width = self.draw(st.sampled_from([0.0, 0.5 * top, top]), label=f"{f} width")
            ranges[f] = (lo, lo + width)
        seed = self.draw(st.integers(-(2**31), 2**31 - 1), label="randomise seed")
        before = {f: getattr(c, f).numpy().copy() for f in DRIVE + self.act_fields(uid)}
        c.randomize_drive_properties(env_ids=env_ids, mode=mode, seed=seed, **ranges)
        if any(f in ranges for f in ACT):  # the actuator parameters draw first, at their own counter value
            for p, f in enumerate(ACT):
                got = getattr(c, f).numpy().copy()
                if f not in ranges:
                    np.testing.assert_array_equal(got, before[f], err_msg=f"randomize {f}: not drawn")
                    continue
                u = param_draws(seed, self.rng_counter, N, self.rows, self.row0[uid], n, 4 + p)
                nominal = self.nominal[uid][f] if mode == "scale" else None
                want = np.where(mask[:, None], drawn_value(u, *ranges[f], nominal), before[f])
                np.testing.assert_allclose(got, want, rtol=1e-6, atol=0, err_msg=f"randomize {f}: Warp's draws")
                rc.set_drive(f, got, mask)
            self.rng_counter += 1
        if not any(f in ranges for f in DRIVE):
            self.check(f"randomize_drive_properties({ranges}, {mode}, {seed}, {env_ids!r})")
            return
        u = drive_draws(seed, self.rng_counter, N, self.rows, self.row0[uid], n)
        self.rng_counter += 1
        for p, f in enumerate(DRIVE):
            got = getattr(c, f).numpy().copy()
            if f not in ranges:
                np.testing.assert_array_equal(got, before[f], err_msg=f"randomize {f}: not drawn")
                continue
            nominal = self.nominal[uid][f] if mode == "scale" else None
            want = np.where(mask[:, None], drawn_value(u[..., p], *ranges[f], nominal), before[f])
            np.testing.assert_allclose(got, want, rtol=1e-6, atol=0, err_msg=f"randomize {f}: Warp's draws")
            rc.set_drive(f, got, mask)
        self.check(f"randomize_drive_properties({ranges}, {mode}, {seed}, {env_ids!r})")

    def op_set_state(self):
        exp = self.ref.get_state(self.single)
        if not exp:
            self.ctrl.set_state(None)
            return
        rng = np.random.default_rng(self.draw(st.integers(0, 2**32 - 1), label="state values seed"))
        new = _map(exp, lambda x: rng.uniform(-2, 2, x.shape).astype(np.float32))
        self.ctrl.set_state(new)
        self.ref.set_state(new, self.single)
        self.check("set_state")


def _ids(env_ids):
    if isinstance(env_ids, wp.array):
        return env_ids.numpy().astype(np.int64)
    if isinstance(env_ids, torch.Tensor):
        return env_ids.numpy().astype(np.int64)
    return np.asarray(env_ids, np.int64).reshape(-1)


def _keys(d):
    return {k: _keys(v) for k, v in d.items()} if isinstance(d, dict) else None


def _leaves(d, path=()):
    for k, v in d.items():
        if isinstance(v, dict):
            yield from _leaves(v, path + (k,))
        else:
            yield path + (k,), v


def _get(d, path):
    for k in path:
        d = d[k]
    return d


def _map(d, fn):
    return {k: _map(v, fn) if isinstance(v, dict) else fn(v) for k, v in d.items()}


OPERATIONS = ["reset", "step", "step", "step", "step", "step_no_action", "drive", "set_state"]


def run_stream(h: Harness, draw, min_ops: int = 6, max_ops: int = 14) -> None:
    """Metadata checks, then a stream of operations drawn one at a time."""
    ref, ctrl = h.ref, h.ctrl
    assert ctrl.single_action_space.shape == (ref.action_dim,)
    np.testing.assert_array_equal(ctrl.single_action_space.low, ref.action_low)
    np.testing.assert_array_equal(ctrl.single_action_space.high, ref.action_high)
    assert ctrl.action_space.shape == ((h.N, ref.action_dim) if h.N > 1 else (ref.action_dim,))
    if not h.single:
        assert ctrl.action_mapping == ref.action_mapping
    for uid, rc in ref.children.items():
        c = h.child(uid)
        if rc.normalize:
            np.testing.assert_array_equal(c._original_single_action_space.low, rc.low)
            np.testing.assert_array_equal(c._original_single_action_space.high, rc.high)
    h.check("construction")
    # The first reset may come late (buffers start at the model's initial pose).
    for i in range(draw(st.integers(min_ops, max_ops), label="operations")):
        op = draw(st.sampled_from(OPERATIONS), label=f"operation {i}")
        if op == "reset":
            h.op_reset()
        elif op == "step":
            h.op_step(with_action=True)
        elif op == "step_no_action":
            h.op_step(with_action=False)
        elif op == "drive":
            h.op_drive()
        else:
            h.op_set_state()
