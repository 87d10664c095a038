"""wpctrl.tasks on Newton (CPU): the env API, ManiSkill's state dict, observations and rewards against numpy
re-derivations of ManiSkill's definitions (tests/reference_tasks.py) and ManiSkill's recorded observations, reset
draws, auto reset, bad input, joint limits on MuJoCo-Warp (the replay of ManiSkill's episodes:
tests/test_tasks_replay.py)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import reference_tasks as R  # noqa: E402

import wpctrl  # noqa: E402
import wpctrl.tasks as T  # noqa: E402
from wpctrl.tasks.definitions import PANDA_REST_QPOS  # noqa: E402

DATA = Path(__file__).parent / "data" / "tasks"
N = 4
FAST = T.TaskPhysics(substeps=2)
"""For the tests of the API (not of the physics' fidelity): 2 MuJoCo steps per physics step instead of 16."""


def _episodes(name: str) -> dict:
    return json.loads((DATA / name).read_text())


@pytest.fixture(scope="module")
def pick_env():
    return T.make("PickCube-v1", num_envs=N, control_mode="pd_ee_delta_pos", physics=FAST)


@pytest.fixture(scope="module")
def push_env():
    return T.make("PushCube-v1", num_envs=N, control_mode="pd_joint_delta_pos", physics=FAST)


def _random_state(env, rng, n=N) -> dict:
    """A valid ManiSkill state dict: the Panda near rest, the cube somewhere on the table (any yaw, small velocity)."""
    spec = env.task_spec
    qpos = np.asarray(PANDA_REST_QPOS) + rng.normal(0, 0.15, (n, 9))
    qpos[:, 7:] = rng.uniform(0.0, 0.04, (n, 2))
    qvel = rng.normal(0, 0.3, (n, 9))
    yaw = rng.uniform(0, 2 * np.pi, n)
    cube = np.column_stack([rng.uniform(-0.15, 0.15, (n, 2)), np.full(n, 0.02), np.cos(yaw / 2), np.zeros((n, 2)),
                            np.sin(yaw / 2), rng.normal(0, 0.05, (n, 6))])  # fmt: skip
    goal = np.column_stack([rng.uniform(-0.1, 0.1, (n, 2)), rng.uniform(0.0, 0.3, n),
                            np.tile(spec.markers[0].quat, (n, 1)), np.zeros((n, 6))])  # fmt: skip
    state = env.get_state_dict()
    state["actors"]["cube"] = torch.tensor(cube, dtype=torch.float32)
    state["actors"][spec.goal_name] = torch.tensor(goal, dtype=torch.float32)
    state["articulations"]["panda"][:, 13:22] = torch.tensor(qpos, dtype=torch.float32)
    state["articulations"]["panda"][:, 22:31] = torch.tensor(qvel, dtype=torch.float32)
    return state


# -- make() and the spaces ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs, field",
    [
        (dict(env_id="PlugCharger-v1"), "env_id"),
        (dict(control_mode="pd_ee_pose_quat"), "control_mode"),
        (dict(obs_mode="rgbd"), "obs_mode"),
        (dict(reward_mode="shaped"), "reward_mode"),
        (dict(sim_backend="physx_cuda"), "sim_backend"),
        (dict(controller_semantics="gpu"), "controller_semantics"),
        (dict(num_envs=0), "num_envs"),
        (dict(num_envs=True), "num_envs"),
        (dict(physics={"substeps": 2}), "physics"),
        (dict(seed=[1, 2]), "seed"),
    ],
)
def test_make_refuses_bad_input_naming_the_field(kwargs, field):
    args = dict(env_id="PushCube-v1")
    args.update(kwargs)
    with pytest.raises(wpctrl.ConfigError, match=field):
        T.make(args.pop("env_id"), **args)


@pytest.mark.parametrize(
    "field, value",
    [("substeps", 0), ("substeps", 1.5), ("integrator", "rk5"), ("cone", "round"), ("impratio", 0.5),
     ("contact_solref", (0.0, 1.0)), ("contact_solref", (0.01,)), ("contact_solimp", (0.9, 0.8, 0.001)),
     ("contact_solimp", (0.9, 1.0, 0.001)), ("limit_solref", (0.02, -1.0)), ("limit_solimp", (0.9, 0.95, 0.0)),
     ("friction_combine", "min"), ("iterations", 0), ("ls_iterations", 0), ("contact_gap", -0.001),
     ("contact_gap", float("inf")), ("contact_gap", "1cm"), ("contact_gap", True), ("finger_torsion", -0.01),
     ("finger_torsion", 5e-5), ("finger_torsion", float("nan")), ("finger_torsion", float("inf")),
     ("finger_torsion", "0.05"), ("finger_torsion", True), ("finger_solimp", (0.7, 0.6, 0.001)),
     ("finger_solimp", (0.0, 0.7, 0.001)), ("finger_solimp", (0.7, 0.7)), ("finger_solimp", 0.7),
     ("finger_solref", (0.005, 0.0)), ("finger_solref", (float("nan"), 1.0)), ("shape_solref", "cube"),
     ("shape_solref", (("cube", (0,), (0.0, 1.0)),)), ("shape_solref", (("cube", (), (0.01, 1.0)),)),
     ("shape_solref", (("cube", (-1,), (0.01, 1.0)),)), ("shape_solref", (("", (0,), (0.01, 1.0)),)),
     ("shape_solref", (("cube", 0, (0.01, 1.0)),))],
)  # fmt: skip
def test_task_physics_refuses_values_outside_their_range(field, value):
    with pytest.raises(wpctrl.ConfigError, match=f"TaskPhysics.{field}"):
        T.TaskPhysics(**{field: value})
    T.TaskPhysics()  # the defaults are valid


def test_a_tasks_physics_refuses_unknown_tasks_fields_and_values_naming_them(monkeypatch):
    """``task_physics`` names an unknown task (with the known ones), an unknown field, a bad value; a task declaring
    physics that TaskPhysics refuses is refused at registration, naming the task and the field."""
    from wpctrl.tasks import registry
    from wpctrl.tasks.push_cube import PushCube

    with pytest.raises(wpctrl.ConfigError, match=r"'PlugCharger-v1'.*known ones"):
        T.task_physics("PlugCharger-v1")
    with pytest.raises(wpctrl.ConfigError, match=r"\['finger_twist'\] are not TaskPhysics fields"):
        T.task_physics("PushCube-v1", finger_twist=0.1)
    with pytest.raises(wpctrl.ConfigError, match="TaskPhysics.substeps"):
        T.task_physics("PegInsertionSide-v1", substeps=0)
    monkeypatch.setattr(registry, "_REGISTERED", dict(registry._REGISTERED))
    for physics, match in (({"finger_twist": 0.1}, r"task Twisted-test: physics: \['finger_twist'\]"),
                           ({"finger_torsion": -1.0}, r"task Twisted-test: physics: TaskPhysics.finger_torsion"),
                           ([("substeps", 8)], r"task Twisted-test: physics expected a mapping")):  # fmt: skip
        twisted = type("Twisted", (PushCube,), {"physics": physics})
        with pytest.raises(wpctrl.ConfigError, match=match):
            T.register_task("Twisted-test", max_episode_steps=5)(twisted)
    assert "Twisted-test" not in T.TASKS


INSIDE = dict(substeps=1, integrator="implicit", cone="pyramidal", impratio=1.0, iterations=1, ls_iterations=1,
              contact_solref=(1e-4, 1e-3), contact_solimp=(0.5, 0.5, 1e-4), limit_solref=(1e-4, 1e-3),
              limit_solimp=(0.5, 0.5, 1e-4), friction_combine="max", contact_gap=0.0, finger_torsion=1e-4,
              finger_solref=(1e-4, 1e-3), finger_solimp=(0.5, 0.5, 1e-4))  # fmt: skip
"""Every TaskPhysics field at (or just inside) the edge of its range, none at its default."""


def test_task_physics_values_at_the_edge_reach_mujoco():
    """Each field just inside its range is accepted and lands where MuJoCo reads it, in every env's copy: the
    solver options, every geom's solref / solimp / gap / friction and every robot joint's limit solref / solimp."""
    physics = T.TaskPhysics(**INSIDE)
    assert all(getattr(physics, k) != getattr(T.TaskPhysics(), k) for k in INSIDE)
    env = T.make("PushCube-v1", num_envs=3, physics=physics, graph=False)
    m, mw = env.solver.mj_model, env.solver.mjw_model
    assert (m.opt.integrator, m.opt.cone) == (2, 0)  # mjINT_IMPLICIT, mjCONE_PYRAMIDAL
    assert (m.opt.impratio, m.opt.iterations, m.opt.ls_iterations) == (1.0, 1, 1)
    assert round(env.dt, 9) == 0.01
    solref, solimp = mw.geom_solref.numpy(), mw.geom_solimp.numpy()
    np.testing.assert_allclose(solref, np.broadcast_to(INSIDE["contact_solref"], solref.shape), rtol=1e-6)
    np.testing.assert_allclose(solimp[..., :3], np.broadcast_to(INSIDE["contact_solimp"], solimp[..., :3].shape))
    np.testing.assert_allclose(env.model.shape_gap.numpy(), 0.0)
    limited = m.jnt_limited.astype(bool)
    np.testing.assert_allclose(mw.jnt_solref.numpy()[:, limited], np.broadcast_to(INSIDE["limit_solref"],
                                                                                 (3, limited.sum(), 2)))  # fmt: skip
    np.testing.assert_allclose(mw.jnt_solimp.numpy()[:, limited, :3],
                               np.broadcast_to(INSIDE["limit_solimp"], (3, limited.sum(), 3)))  # fmt: skip
    # friction "max": the materials' own coefficients (finger pads 2.0, the rest 0.3), not PhysX's averages
    np.testing.assert_allclose(np.unique(mw.geom_friction.numpy()[..., 0]), [0.3, 2.0], rtol=1e-6)
    # finger_torsion: condim 4 and the coefficient on the finger geoms only (test_finger_torsion_... below)
    assert np.unique(mw.geom_condim.numpy()).tolist() == [3, 4]
    np.testing.assert_array_equal(np.unique(mw.geom_friction.numpy()[..., 1]), np.float32([0.0, 1e-4]))


def test_shape_solref_reaches_the_named_shapes_in_every_world_and_refuses_others():
    """``TaskPhysics.shape_solref`` sets MuJoCo's solref of the named actor's named shapes in every env's copy and of
    nothing else; a JSON record's lists are taken as tuples; an actor the task lacks or a shape index past its shapes
    is refused before anything is built, naming the entry."""
    physics = T.TaskPhysics(shape_solref=[["cube", [0], [0.02, 1.5]]])
    assert physics.shape_solref == (("cube", (0,), (0.02, 1.5)),)
    assert T.TaskPhysics(**physics.as_dict()) == physics
    env = T.make("PushCube-v1", num_envs=3, physics=physics, graph=False)
    solref = env.solver.mjw_model.geom_solref.numpy()  # (worlds, geoms, 2)
    to_shape = env.solver.mjc_geom_to_newton_shape.numpy()
    cube = {env.scene.actor_shapes0["cube"][0] + w * env.scene.shapes_per_env for w in range(3)}
    named = np.isin(to_shape, sorted(cube))
    assert named.sum() == 3 and named.any(axis=1).all()
    np.testing.assert_allclose(solref[named], np.broadcast_to((0.02, 1.5), (3, 2)), rtol=1e-6)
    np.testing.assert_allclose(solref[~named & (to_shape >= 0)], np.broadcast_to(
        physics.contact_solref, solref[~named & (to_shape >= 0)].shape), rtol=1e-6)  # fmt: skip
    for entry, match in ((("goal", (0,), (0.02, 1.0)), r"shape_solref\[0\]: actor expected one of \['cube'\]"),
                         (("cube", (1,), (0.02, 1.0)), r"shape_solref\[0\]: shape index expected < 1")):  # fmt: skip
        with pytest.raises(wpctrl.ConfigError, match=match):
            T.make("PushCube-v1", num_envs=1, physics=T.TaskPhysics(shape_solref=(entry,)), graph=False)


def _finger_geoms(env) -> np.ndarray:
    """(world, geom) True where MuJoCo-Warp's geom is a shape of a finger link (scene.FINGER_LINKS), found from the
    Newton shapes' bodies by name; the same geoms in every world, both fingers' and not every geom."""
    from wpctrl.tasks.scene import FINGER_LINKS

    labels = [lb.rsplit("/", 1)[-1] for lb in env.model.body_label]
    finger_shape = np.array([b >= 0 and labels[b] in FINGER_LINKS for b in env.model.shape_body.numpy()])
    shape_of_geom = env.solver.mjc_geom_to_newton_shape.numpy()  # (world, geom) -> Newton shape
    assert (shape_of_geom >= 0).all()
    finger = finger_shape[shape_of_geom]
    assert (finger == finger[0]).all() and 2 <= finger[0].sum() < finger.shape[1]  # both fingers, every world
    return finger


def test_finger_torsion_gives_the_finger_geoms_condim_4_and_that_coefficient():
    """TaskPhysics.finger_torsion > 0: in MuJoCo-Warp's model the geoms of the finger links (scene.FINGER_LINKS) have
    condim 4 and exactly that torsional coefficient, in every world; every other geom keeps condim 3 and gets a
    torsional coefficient of 0; sliding and rolling friction are the default build's everywhere. The default (0)
    gives no geom condim 4."""
    assert T.TaskPhysics().finger_torsion == 0.0
    models = {}
    for torsion in (0.0, 0.05):
        env = T.make("PushCube-v1", num_envs=2, physics=T.TaskPhysics(substeps=2, finger_torsion=torsion), graph=False)
        finger = _finger_geoms(env)
        mw = env.solver.mjw_model
        models[torsion] = (finger[0], mw.geom_condim.numpy(), mw.geom_friction.numpy())
    (finger, condim0, friction0), (finger1, condim, friction) = models[0.0], models[0.05]
    np.testing.assert_array_equal(finger1, finger)
    assert (condim0 == 3).all()
    assert (condim[finger] == 4).all() and (condim[~finger] == 3).all()
    assert (friction[..., finger, 1] == np.float32(0.05)).all()
    assert (friction[..., ~finger, 1] == 0.0).all()
    np.testing.assert_array_equal(friction[..., [0, 2]], friction0[..., [0, 2]])


def test_finger_solimp_and_solref_land_on_the_finger_geoms_only():
    """TaskPhysics.finger_solimp / finger_solref: in MuJoCo-Warp's model the geoms of the finger links carry them in
    every world and every other geom keeps contact_solimp / contact_solref; None gives the fingers the contact values
    too. The default softens the finger geoms only (dmin = dmax = 0.7)."""
    assert T.TaskPhysics().finger_solimp == (0.7, 0.7, 0.001) and T.TaskPhysics().finger_solref is None
    for physics in (T.TaskPhysics(substeps=2), T.TaskPhysics(substeps=2, finger_solimp=None),
                    T.TaskPhysics(substeps=2, finger_solimp=(0.6, 0.8, 0.002), finger_solref=(0.01, 0.5))):  # fmt: skip
        env = T.make("PushCube-v1", num_envs=2, physics=physics, graph=False)
        finger = _finger_geoms(env)
        mw = env.solver.mjw_model
        solimp, solref = mw.geom_solimp.numpy()[..., :3], mw.geom_solref.numpy()
        if solimp.ndim == 2:
            solimp, solref = np.broadcast_to(solimp, finger.shape + (3,)), np.broadcast_to(solref, finger.shape + (2,))
        want_imp = physics.finger_solimp or physics.contact_solimp
        want_ref = physics.finger_solref or physics.contact_solref
        np.testing.assert_allclose(solimp[finger], np.broadcast_to(want_imp, solimp[finger].shape), rtol=1e-6)
        np.testing.assert_allclose(solimp[~finger], np.broadcast_to(physics.contact_solimp, solimp[~finger].shape),
                                   rtol=1e-6)  # fmt: skip
        np.testing.assert_allclose(solref[finger], np.broadcast_to(want_ref, solref[finger].shape), rtol=1e-6)
        np.testing.assert_allclose(solref[~finger], np.broadcast_to(physics.contact_solref, solref[~finger].shape),
                                   rtol=1e-6)  # fmt: skip


def test_mujoco_warp_has_constraint_rows_for_every_contact_it_can_hold():
    """MuJoCo-Warp's per-world constraint rows (njmax) cover every contact its buffer holds at the cone's rows per
    contact (elliptic: condim, 3, or 4 with finger torsion; pyramidal: 2 (condim - 1)) plus a row per DOF: rows it has
    no room for would be dropped from the solve. Its own estimate for the tasks' scene counted about a third."""
    for physics, per_contact in ((T.TaskPhysics(substeps=2), 3), (T.TaskPhysics(substeps=2, cone="pyramidal"), 4),
                                 (T.TaskPhysics(substeps=2, finger_torsion=0.05), 4)):  # fmt: skip
        env = T.make("StackCube-v1", num_envs=3, physics=physics, graph=False)
        contacts = -(-env.solver.get_max_contact_count() // 3)
        assert env.solver.mjw_data.njmax >= contacts * per_contact + env.scene.dofs_per_env, (physics, contacts)


def test_a_contact_time_constant_under_two_mujoco_steps_acts_as_two_steps():
    """MuJoCo raises a contact's solref time constant to two of its steps where it is shorter (its ``refsafe``): at 2
    substeps (5 ms steps) a push with contact_solref 1.25 ms is bitwise the one with 10 ms; 20 ms pushes otherwise."""
    from wpctrl.tasks.scripted import policy_for

    runs = {}
    for tau in (0.00125, 0.01, 0.02):
        env = T.make("PushCube-v1", num_envs=1, control_mode="pd_ee_delta_pos", auto_reset=False,
                     physics=T.TaskPhysics(substeps=2, contact_solref=(tau, 1.0)))  # fmt: skip
        obs, _ = env.reset(seed=4)
        policy = policy_for("PushCube-v1")
        for _ in range(25):
            obs, *_ = env.step(policy(obs))
        runs[tau] = env.state.joint_q.numpy().copy()
    np.testing.assert_array_equal(runs[0.00125], runs[0.01])
    assert np.abs(runs[0.02] - runs[0.01]).max() > 1e-5


def test_contact_gap_changes_which_pairs_are_tracked_not_the_motion():
    """Every shape carries TaskPhysics.contact_gap; a narrower envelope tracks fewer pairs and moves nothing else: 25
    steps of a scripted push from the same state, the cube pushed, are bitwise equal under
    Newton's default gap (0.1 m) and the tasks' (0.01 m)."""
    from wpctrl.tasks.scripted import policy_for

    runs = {}
    for gap in (0.1, T.TaskPhysics().contact_gap):
        env = T.make("PushCube-v1", num_envs=2, control_mode="pd_ee_delta_pos", auto_reset=False,
                     physics=T.TaskPhysics(substeps=2, contact_gap=gap))  # fmt: skip
        assert np.allclose(env.model.shape_gap.numpy(), gap)
        obs, _ = env.reset(seed=4)
        cube0 = env.get_state_dict()["actors"]["cube"][:, :3].clone()
        policy = policy_for("PushCube-v1")
        for _ in range(25):
            obs, *_ = env.step(policy(obs))
        assert ((env.get_state_dict()["actors"]["cube"][:, :3] - cube0).norm(dim=1) > 0.005).all()  # pushed: in contact
        runs[gap] = (env.state.joint_q.numpy().copy(), int(env.solver.mjw_data.nacon.numpy()[0]))
    (q_wide, n_wide), (q_narrow, n_narrow) = runs.values()
    np.testing.assert_array_equal(q_narrow, q_wide)
    assert n_narrow < n_wide / 3, (n_narrow, n_wide)


def test_friction_rule_reproduces_physx_average():
    """MuJoCo takes the larger coefficient of a pair, PhysX the average: the per-material values returned give every
    pair of the scene PhysX's coefficient under MuJoCo's rule."""
    from wpctrl.tasks.physics import mujoco_friction

    mats = {"default": 0.3, "gripper": 2.0}
    mu = mujoco_friction(mats)
    for a in mats:
        for b in mats:
            if a == b == "gripper":
                continue  # no finger-finger pair in the scene (SRDF-filtered)
            assert max(mu[a], mu[b]) == pytest.approx(0.5 * (mats[a] + mats[b]))
    assert mujoco_friction(mats, "max") == mats
    with pytest.raises(wpctrl.ConfigError, match="two distinct"):
        mujoco_friction({"a": 0.1, "b": 0.2, "c": 0.3})


def test_spaces_are_maniskills(pick_env, push_env):
    for env, obs_dim in ((pick_env, 42), (push_env, 35)):
        assert env.single_observation_space.shape == (obs_dim,)
        assert env.observation_space.shape == (N, obs_dim)
        assert env.single_action_space.shape == (env.ctrl.action_dim,)
        assert env.action_space.shape == (N, env.ctrl.action_dim)
        np.testing.assert_array_equal(env.single_action_space.low, -1.0)
        np.testing.assert_array_equal(env.single_action_space.high, 1.0)
    assert pick_env.ctrl.action_dim == 4 and push_env.ctrl.action_dim == 8


# -- state dicts, observations, rewards --------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["PickCube-v1__pd_ee_delta_pos.json", "PushCube-v1__pd_joint_delta_pos.json"])
def test_recorded_initial_states_give_maniskills_observation(name, pick_env, push_env):
    """ManiSkill's own obs[0] of every recorded episode, from its initial state dict (TCP pose by Newton's FK of
    ManiSkill's URDF, quaternions wxyz with ManiSkill's sign)."""
    data = _episodes(name)
    env = pick_env if name.startswith("Pick") else push_env
    for ep in data["episodes"][:N]:
        state = {g: {k: torch.tensor(v) for k, v in d.items()} for g, d in ep["init_state_dict"].items()}
        env.set_state_dict(state, env_idx=[0])
        obs = env.get_obs()[0].numpy()
        np.testing.assert_allclose(obs, np.asarray(ep["obs"][0], np.float32), atol=1e-5)


@pytest.mark.parametrize("task", ["PushCube-v1", "PickCube-v1"])
def test_state_dict_round_trips_exactly_and_obs_reward_follow_maniskills_definitions(task, pick_env, push_env):
    env = pick_env if task == "PickCube-v1" else push_env
    rng = np.random.default_rng(3)
    for _ in range(3):
        state = _random_state(env, rng)
        env.set_state_dict(state)
        back = env.get_state_dict()
        for group in ("actors", "articulations"):
            for k, v in state[group].items():
                torch.testing.assert_close(back[group][k], v, rtol=0, atol=0)
        obs = env.get_obs().numpy()
        arrays = {g: {k: v.numpy() for k, v in d.items()} for g, d in state.items()}
        parts = R.state_parts(arrays, env.task_spec.goal_name)
        tcp_pose = obs[:, 19:26] if task == "PickCube-v1" else obs[:, 18:25]
        grasped = np.zeros(N, bool)  # a state just set has no contact force yet
        np.testing.assert_allclose(obs, R.flat_obs(task, parts, tcp_pose, grasped), atol=1e-6)
        info = env.evaluate()
        env_r = env.unwrapped  # noqa: F841  (the env is its own base env, as ManiSkill's vector env's unwrapped)
        if task == "PushCube-v1":
            ref = R.push_evaluate(parts["cube_p"], parts["goal_p"])
            dense = R.push_dense(tcp_pose[:, :3], parts["cube_p"], parts["goal_p"], ref["success"])
        else:
            ref = R.pick_evaluate(parts["cube_p"], parts["goal_p"], parts["qvel"], grasped)
            dense = R.pick_dense(tcp_pose[:, :3], parts["cube_p"], parts["goal_p"], parts["qvel"], ref)
        for k, v in ref.items():
            np.testing.assert_array_equal(info[k].numpy(), v, err_msg=k)
        np.testing.assert_allclose(env.reward_dense.numpy(), dense, rtol=1e-5, atol=1e-6)


def test_success_and_reward_on_known_cases(push_env):
    """Cases whose answer is known: a cube in the goal region on the table succeeds (dense reward 4, normalised
    1); lifted 6 mm above the table it does not; 10.5 cm from the goal's centre it does not."""
    state = push_env.get_state_dict()
    goal = torch.tensor([0.2, 0.0, 1e-3])
    state["actors"]["goal_region"][:, :3] = goal
    cube = state["actors"]["cube"]
    cube[:, :3] = torch.tensor([[0.25, 0.03, 0.02], [0.2, 0.0, 0.026], [0.305, 0.0, 0.02], [0.12, 0.04, 0.02]])
    cube[:, 3:] = torch.tensor([1.0, 0, 0, 0, 0, 0, 0, 0, 0, 0])
    push_env.set_state_dict(state)
    assert push_env.evaluate()["success"].tolist() == [True, False, False, True]
    np.testing.assert_allclose(push_env.reward_dense.numpy()[[0, 3]], 4.0)
    assert (push_env.reward_dense.numpy()[[1, 2]] < 4.0).all()


def test_push_place_reward_waits_until_the_tcp_reaches_the_push_point(push_env):
    """ManiSkill's PushCube: the place terms count only once the TCP is within 1 cm of the push point (behind the
    cube). The cube is put 3 cm (envs 0, 1) and 5 mm (envs 2, 3) from where the TCP pushes: the first pair earns the
    reaching term alone, the second the place terms too (numpy re-derivation of the dense reward)."""
    push_env.reset(seed=1)
    tcp = push_env.get_obs()[:, 18:21].clone()
    state = push_env.get_state_dict()
    state["actors"]["goal_region"][:, :3] = tcp + torch.tensor([0.4, 0.0, 0.0])
    offsets = torch.tensor([[0.0, 0.03, 0.0], [0.0, 0.0, -0.03], [0.0, 0.005, 0.0], [0.0, 0.0, 0.004]])
    cube = state["actors"]["cube"]
    cube[:, :3] = tcp + torch.tensor([0.02 + 0.005, 0.0, 0.0]) + offsets
    cube[:, 3:] = torch.tensor([1.0, 0, 0, 0, 0, 0, 0, 0, 0, 0])
    push_env.set_state_dict(state)
    tcp_p = push_env.get_obs()[:, 18:21].numpy().astype(np.float64)
    cube_p = cube[:, :3].numpy().astype(np.float64)
    goal_p = state["actors"]["goal_region"][:, :3].numpy().astype(np.float64)
    expected = R.push_dense(tcp_p, cube_p, goal_p, np.zeros(N, bool))
    np.testing.assert_allclose(push_env.reward_dense.numpy(), expected, atol=1e-4)
    reach_only = 1 - np.tanh(5 * 0.03)
    np.testing.assert_allclose(push_env.reward_dense.numpy()[:2], reach_only, atol=1e-4)
    assert (push_env.reward_dense.numpy()[2:] > 1.0).all()  # the place terms on top of reaching (at most 1)


def test_pick_success_needs_the_robot_static(pick_env):
    """ManiSkill's PickCube: success is the cube at the goal (within 2.5 cm) and the arm still (every arm joint
    slower than 0.2 rad/s); the cube on its goal with an arm joint moving at 0.5 rad/s (env 1) or 0.19 rad/s (env 2,
    still static) and the fingers alone moving (env 3: the fingers do not count)."""
    pick_env.reset(seed=1)
    state = pick_env.get_state_dict()
    goal = torch.tensor([0.05, -0.02, 0.15])
    state["actors"]["goal_site"][:, :3] = goal
    cube = state["actors"]["cube"]
    cube[:, :3] = goal + torch.tensor([0.0, 0.0, 0.01])
    cube[:, 3:] = torch.tensor([1.0, 0, 0, 0, 0, 0, 0, 0, 0, 0])
    qvel = state["articulations"]["panda"][:, 22:31]
    qvel[:] = 0.0
    qvel[1, 3] = 0.5
    qvel[2, 5] = 0.19
    qvel[3, 7:] = 0.5
    pick_env.set_state_dict(state)
    flags = pick_env.evaluate()
    assert flags["is_obj_placed"].tolist() == [True] * 4
    assert flags["is_robot_static"].tolist() == [True, False, True, True]
    assert flags["success"].tolist() == [True, False, True, True]


def test_pick_dense_reward_while_the_cube_is_held():
    """PickCube's dense reward with the cube in the gripper (the scripted pick, simulated until the contact sensor
    reports a grasp): reaching + grasped + place + static terms re-derived in numpy from the state and the flags. Then
    a state dict with the cube on the table: no grasp, the held cube's contact forces gone with the state."""
    from wpctrl.tasks.scripted import policy_for

    env = T.make("PickCube-v1", num_envs=N, control_mode="pd_ee_delta_pos", auto_reset=False,
                 ignore_terminations=True, physics=T.TaskPhysics(substeps=8))  # fmt: skip
    obs, _ = env.reset(seed=2)
    pick = policy_for("PickCube-v1")
    for _ in range(40):
        obs, *_ = env.step(pick(obs))
        if env.evaluate()["is_grasped"].all():
            break
    info = {k: v.numpy() for k, v in env.evaluate().items()}
    # every env holds its cube; those whose goal is not yet reached check the place term's partial value
    assert info["is_grasped"].all() and not info["success"].all()
    state = env.get_state_dict()
    cube_p = state["actors"]["cube"][:, :3].numpy().astype(np.float64)
    goal_p = state["actors"]["goal_site"][:, :3].numpy().astype(np.float64)
    qvel = state["articulations"]["panda"][:, 22:31].numpy().astype(np.float64)
    tcp_p = obs[:, env.task_spec.obs_slices()["extra"]["tcp_pose"]][:, :3].numpy().astype(np.float64)
    expected = R.pick_dense(tcp_p, cube_p, goal_p, qvel, info)
    np.testing.assert_allclose(env.reward_dense.numpy(), expected, atol=1e-4)
    assert (expected > 2.0).all()  # reaching, grasped and some of place
    # a state set from outside starts without contact forces: the held cube's forces do not carry over
    fresh = T.make("PickCube-v1", num_envs=N, physics=FAST)
    fresh.reset(seed=3)
    env.set_state_dict(fresh.get_state_dict())
    assert not env.evaluate()["is_grasped"].any()


def test_state_dict_obs_mode_is_the_flat_vector_split():
    env = T.make("PickCube-v1", num_envs=2, obs_mode="state_dict", physics=FAST)
    obs, _ = env.reset(seed=5)
    flat = T.make("PickCube-v1", num_envs=2, physics=FAST)
    flat_obs, _ = flat.reset(seed=5)
    s = env.task_spec.obs_slices()
    for group, fields in s.items():
        for name, sl in fields.items():
            got = obs[group][name]
            want = flat_obs[:, sl]
            if name == "is_grasped":
                assert got.dtype == torch.bool
                got = got[:, None].float()
            torch.testing.assert_close(got, want)


# -- bad input: refused before anything is written ---------------------------------------------------------------------


def _bad_states(env):
    good = env.get_state_dict()

    def edit(fn):
        s = {g: {k: v.clone() for k, v in d.items()} for g, d in good.items()}
        fn(s)
        return s

    return [
        (edit(lambda s: s["actors"].pop("cube")), "'cube'"),
        (edit(lambda s: s["articulations"].pop("panda")), "'panda'"),
        (edit(lambda s: s["actors"].__setitem__("cube", s["actors"]["cube"][:, :7])), r"expected shape \(4, 13\)"),
        (edit(lambda s: s["articulations"]["panda"].__setitem__((0, 15), float("nan"))), "non-finite"),
        (edit(lambda s: s["actors"]["table-workspace"].__setitem__((slice(None), 2), 0.1)), "table is fixed"),
        (edit(lambda s: s["articulations"]["panda"].__setitem__((slice(None), 0), -0.5)), "root is fixed"),
        ({"actors": {}}, "'actors' and 'articulations'"),
        ([1, 2], "expected a dict"),
    ]


def test_bad_state_dicts_are_refused_and_nothing_is_written(push_env):
    push_env.reset(seed=2)
    before_q = push_env.state.joint_q.numpy().copy()
    before_goal = push_env.marker_pos.numpy().copy()
    for state, match in _bad_states(push_env):
        with pytest.raises(wpctrl.ConfigError, match=match):
            push_env.set_state_dict(state)
        np.testing.assert_array_equal(push_env.state.joint_q.numpy(), before_q)
        np.testing.assert_array_equal(push_env.marker_pos.numpy(), before_goal)
    with pytest.raises(wpctrl.ConfigError, match="env_idx"):
        push_env.set_state_dict(push_env.get_state_dict(), env_idx=[0, N])


def test_bad_actions_are_refused_and_nan_actions_hold_the_targets(push_env):
    push_env.reset(seed=4)
    with pytest.raises(wpctrl.ConfigError, match=r"action expected shape \(4, 8\)"):
        push_env.step(torch.zeros(N, 7))
    with pytest.raises(wpctrl.ConfigError, match="dict"):
        push_env.step({"action": torch.zeros(N, 8)})
    zero = torch.zeros(N, 8)
    push_env.step(zero)
    targets = push_env.ctrl.target_qpos.numpy().copy()
    bad_before = push_env.ctrl.bad_action_count.numpy().copy()
    a = torch.full((N, 8), 0.7)
    a[1, 3] = float("nan")
    push_env.step(a)
    after = push_env.ctrl.target_qpos.numpy()
    np.testing.assert_array_equal(after[1], targets[1])  # env 1 held its targets (the controller's NaN policy)
    assert not np.allclose(after[0], targets[0])
    assert (push_env.ctrl.bad_action_count.numpy() - bad_before).tolist() == [0, 1, 0, 0]


# -- resets and episodes -----------------------------------------------------------------------------------------------


def test_reset_draws_follow_maniskills_distributions(pick_env, push_env):
    """ManiSkill's _initialize_episode: qpos = rest + N(0, 0.02) (fingers 0.04), cube xy ~ U[-0.1, 0.1]^2 on the
    table; PushCube's goal 0.2 m in +x at z = 1e-3, PickCube's anywhere in the box with z = 0.02 + U[0, 0.3] and a
    uniform cube yaw. 40 resets of 4 envs each."""
    for env in (push_env, pick_env):
        draws = []
        for seed in range(40):
            env.reset(seed=seed)
            s = env.get_state_dict()
            draws.append((s["articulations"]["panda"][:, 13:22].numpy(), s["actors"]["cube"].numpy(),
                          s["actors"][env.task_spec.goal_name][:, :3].numpy()))  # fmt: skip
        qpos = np.concatenate([d[0] for d in draws])
        cube = np.concatenate([d[1] for d in draws])
        goal = np.concatenate([d[2] for d in draws])
        noise = qpos[:, :7] - np.asarray(PANDA_REST_QPOS[:7])
        assert 0.017 < noise.std() < 0.023 and abs(noise.mean()) < 0.004
        np.testing.assert_allclose(qpos[:, 7:], 0.04, atol=1e-7)
        assert (np.abs(cube[:, :2]) <= 0.1).all() and cube[:, :2].std() > 0.05
        np.testing.assert_allclose(cube[:, 2], 0.02, atol=1e-7)
        yaw = 2 * np.arctan2(cube[:, 6], cube[:, 3])
        np.testing.assert_allclose(cube[:, 4:6], 0.0, atol=1e-7)
        if env.task_spec.env_id == "PushCube-v1":
            np.testing.assert_allclose(goal[:, :2], cube[:, :2] + [0.2, 0.0], atol=1e-6)
            np.testing.assert_allclose(goal[:, 2], 1e-3, atol=1e-7)
            np.testing.assert_allclose(yaw, 0.0, atol=1e-6)
        else:
            assert (np.abs(goal[:, :2]) <= 0.1).all() and (goal[:, 2] >= 0.02).all() and (goal[:, 2] <= 0.32).all()
            assert np.histogram(np.mod(yaw, 2 * np.pi), bins=4, range=(0, 2 * np.pi))[0].min() > 25
        # a seed gives the same draws again; another seed others
        env.reset(seed=7)
        a = env.get_state_dict()["actors"]["cube"].clone()
        env.reset(seed=8)
        env.reset(seed=7)
        torch.testing.assert_close(env.get_state_dict()["actors"]["cube"], a)


@pytest.mark.parametrize(
    "kwargs, message",
    [({"seed": [1, 2, 3]}, "a list of num_envs = 4 ints"), ({"seed": 1.5}, "seed expected an int"),
     ({"seed": True}, "seed expected an int"), ({"options": {"env_idx": [0, 4]}}, r"indices must be in \[0, 4\)"),
     ({"options": {"env_idx": [-1]}}, r"indices must be in \[0, 4\)"),
     ({"options": {"env_idx": np.array([0.0, 1.0])}}, "integers"),
     ({"options": {"env_idx": np.array([True, False])}}, r"bool mask must have shape \(4,\)"),
     ({"options": {"env_idx": torch.tensor([True, False, True])}}, r"bool mask must have shape \(4,\)")],
)  # fmt: skip
def test_bad_reset_arguments_are_refused_and_nothing_is_reset(push_env, kwargs, message):
    push_env.reset(seed=3)
    push_env.step(torch.full((N, 8), 0.5))
    before = push_env.get_state_dict()
    with pytest.raises(wpctrl.ConfigError, match=message):
        push_env.reset(**kwargs)
    after = push_env.get_state_dict()
    for group in ("actors", "articulations"):
        for name, v in before[group].items():
            torch.testing.assert_close(after[group][name], v, rtol=0, atol=0)
    assert push_env.elapsed_steps.tolist() == [1] * N


def test_partial_reset_touches_only_the_envs_named(push_env):
    push_env.reset(seed=11)
    for _ in range(2):
        push_env.step(torch.full((N, 8), 0.5))
    before = push_env.get_state_dict()
    obs, info = push_env.reset(options={"env_idx": torch.tensor([2])})
    after = push_env.get_state_dict()
    for k in ("cube",):
        torch.testing.assert_close(after["actors"][k][[0, 1, 3]], before["actors"][k][[0, 1, 3]])
        assert not torch.allclose(after["actors"][k][2], before["actors"][k][2])
    torch.testing.assert_close(after["articulations"]["panda"][[0, 1, 3]], before["articulations"]["panda"][[0, 1, 3]])
    assert info["elapsed_steps"].tolist() == [2, 2, 0, 2]
    assert obs.shape == (N, 35)


def test_episodes_truncate_at_50_steps_and_auto_reset_inside_the_step():
    env = T.make("PushCube-v1", num_envs=2, control_mode="pd_joint_delta_pos", reward_mode="dense", physics=FAST)
    obs, info = env.reset(seed=1)
    zero = torch.zeros(2, 8)
    for t in range(1, 51):
        prev = obs
        obs, reward, terminated, truncated, info = env.step(zero)
        if t < 50:
            assert not truncated.any() and info["elapsed_steps"].tolist() == [t, t]
            assert not info["_final_info"].any()
    assert truncated.all() and not terminated.any()
    assert info["_final_info"].all()
    assert info["final_info"]["elapsed_steps"].tolist() == [50, 50]
    assert info["elapsed_steps"].tolist() == [0, 0]  # the new episodes
    # the final observation is the old episode's last state (the arm held still), the returned one a new episode's
    torch.testing.assert_close(info["final_observation"][:, :9], prev[:, :9], atol=2e-3, rtol=0)
    assert not torch.allclose(obs[:, 18 + 7 : 18 + 10], info["final_observation"][:, 18 + 7 : 18 + 10])


def test_without_auto_reset_a_finished_episode_stays_until_reset():
    """auto_reset=False (ManiSkillVectorEnv's switch): at the time limit the envs report truncation and keep their
    state and step count; the next reset starts new episodes."""
    env = T.make("PushCube-v1", num_envs=2, control_mode="pd_joint_delta_pos", auto_reset=False, physics=FAST)
    env.reset(seed=1)
    zero = torch.zeros(2, 8)
    for _ in range(50):
        obs, _, _, truncated, info = env.step(zero)
    assert truncated.all() and info["elapsed_steps"].tolist() == [50, 50]
    before = env.get_state_dict()
    torch.testing.assert_close(env.get_obs(), obs)
    env.reset(seed=2)
    assert env.elapsed_steps.tolist() == [0, 0]
    assert not torch.allclose(env.get_state_dict()["actors"]["cube"], before["actors"]["cube"])


def test_success_terminates_unless_terminations_are_ignored():
    for ignore in (False, True):
        env = T.make("PushCube-v1", num_envs=1, control_mode="pd_joint_delta_pos", ignore_terminations=ignore,
                     auto_reset=False, physics=FAST)  # fmt: skip
        env.reset(seed=0)
        state = env.get_state_dict()
        state["actors"]["cube"][:, :3] = state["actors"]["goal_region"][:, :3] + torch.tensor([0.0, 0.0, 0.019])
        env.set_state_dict(state)
        _, reward, terminated, truncated, info = env.step(torch.zeros(1, 8))
        assert info["success"].item() and reward.item() == pytest.approx(1.0)
        assert terminated.item() is (not ignore)


# -- physics -----------------------------------------------------------------------------------------------------------


def test_joint_limits_hold_as_physx_does():
    """A saturated drive (100 N m) swinging joint 4 into its upper limit (-0.0698 rad) at ~16 rad/s and holding it
    there for a second: TaskPhysics' limit (two MuJoCo steps, critically damped) holds it within a milliradian;
    Newton's import (force-space gains ke 1e4, kd 10: a time constant of ~0.5 s for this joint) lets it through by
    more than 0.05 rad."""
    overshoot = {}
    for name, physics in (("tasks", T.TaskPhysics()), ("newton", T.TaskPhysics(limit_solref=None))):
        env = T.make("PushCube-v1", num_envs=1, control_mode="pd_joint_pos", physics=physics)
        env.reset(seed=0)
        target = torch.tensor([list(PANDA_REST_QPOS[:7]) + [0.04]])
        target[0, 3] = 0.8  # far past the upper limit -0.0698: the drive saturates at 100 N m
        worst = -math.inf
        for _ in range(20):
            env.step(target)
            worst = max(worst, float(env.get_state_dict()["articulations"]["panda"][0, 13 + 3]))
        overshoot[name] = worst - (-0.0698)
    assert overshoot["tasks"] < 1e-3, overshoot
    assert overshoot["newton"] > 0.05, overshoot
