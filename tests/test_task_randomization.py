"""Per-env physics drawn at every reset (:class:`wpctrl.tasks.TaskRandomization`).

The reference is Newton's own path: the same scale factors written into Newton's ``Model`` (every shape's friction
and ``solref`` time constant of the env's world, the cube's mass and inertia) and handed to the solver with
``notify_model_changed``, which converts them and recomputes what MuJoCo derives from them (the inverse weights, the
subtree masses). The randomised env's solver model and its motion from the same state must be that env's. Then: the
draws (ranges, one stream per env seed, only reset envs draw, inside the captured auto reset), a scene drawn again
(PegInsertionSide), off by default, and bad input.
"""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="torch is not installed")  # a dev dependency
wp = pytest.importorskip("warp")

import newton  # noqa: E402

import wpctrl.tasks as T  # noqa: E402
from wpctrl.config import ConfigError  # noqa: E402

N = 4
PHYSICS = T.TaskPhysics(substeps=8)
RANGES = T.TaskRandomization(friction=(0.5, 1.5), contact_time=(1.0, 2.0), mass=(0.5, 2.0))
ARRAYS = ("geom_friction", "geom_solref", "body_mass", "body_inertia", "body_invweight0", "body_subtreemass",
          "dof_invweight0")


def _make(randomization=RANGES, seed=3, task="PickCube-v1", **kw):
    return T.make(task, num_envs=N, device="cpu", physics=PHYSICS, randomization=randomization, seed=seed, **kw)


def _newton_reference(factors: np.ndarray, seed=3):
    """An env without randomisation whose Newton model holds, world by world, the factors' values, told to the solver
    through ``notify_model_changed``."""
    env = _make(None, seed=seed, graph=False)
    model, sc = env.model, env.scene
    world = model.shape_world.numpy() if hasattr(model, "shape_world") else None
    body = model.shape_body.numpy()
    if world is None:
        world = np.where(body >= 0, body // sc.bodies_per_env, -1)
    mu = model.shape_material_mu.numpy()
    solref = model.mujoco.solref.numpy()
    for e in range(N):
        mu[world == e] *= factors[e, 0]
        solref[world == e, 0] *= factors[e, 1]
    model.shape_material_mu.assign(mu)
    model.mujoco.solref.assign(solref)
    mass, inertia = model.body_mass.numpy(), model.body_inertia.numpy()
    for e in range(N):
        b = sc.actor_body0["cube"] + e * sc.bodies_per_env
        mass[b] *= factors[e, 2]
        inertia[b] *= factors[e, 2]
    model.body_mass.assign(mass)
    model.body_inertia.assign(inertia)
    env.solver.notify_model_changed(newton.ModelFlags.SHAPE_PROPERTIES | newton.ModelFlags.BODY_INERTIAL_PROPERTIES)
    return env


def _slide_state(env):
    """Every env's cube on the table away from the arm, sliding at 0.5 m/s, its gripper open above it."""
    s = env.get_state_dict()
    cube = s["actors"]["cube"]
    cube[:, 0:3] = torch.tensor([0.1, 0.25, 0.02])
    cube[:, 3:7] = torch.tensor([1.0, 0.0, 0.0, 0.0])
    cube[:, 7:] = 0.0
    cube[:, 7] = 0.5
    return s


def test_the_draws_are_what_newtons_own_model_update_makes_of_the_same_factors():
    """The randomised env's MuJoCo-Warp arrays are those Newton's ``notify_model_changed`` writes for the same factors
    (its inverse weights and subtree masses recomputed by MuJoCo-Warp's ``set_const``), and from the same state the
    two envs move the same way, where an env without the factors moves differently."""
    env = _make(graph=False)
    factors = env.randomization_factors.numpy().copy()
    ref = _newton_reference(factors)
    plain = _make(None, graph=False)
    m, r = env.solver.mjw_model, ref.solver.mjw_model
    for name in ARRAYS:
        np.testing.assert_allclose(getattr(m, name).numpy(), getattr(r, name).numpy(), rtol=2e-6, atol=0, err_msg=name)
    cube = ref.scene.actor_body0["cube"] + 1  # MuJoCo's body 0 is the world
    base = plain.solver.mjw_model
    assert not np.allclose(m.body_invweight0.numpy()[:, cube], base.body_invweight0.numpy()[:, cube], rtol=1e-2)
    state = _slide_state(env)
    hold = torch.zeros(N, 8)
    cubes = []
    for e in (env, ref, plain):  # one control step of sliding (a second lets env 1's cube settle, where noise grows)
        e.set_state_dict(state)
        e.step(hold)
        cubes.append(e.get_state_dict()["actors"]["cube"].numpy())
    np.testing.assert_allclose(cubes[0][:, :3], cubes[1][:, :3], atol=2e-6)  # measured <= 4e-8
    np.testing.assert_allclose(cubes[0][:, 7:10], cubes[1][:, 7:10], atol=1e-4)  # measured <= 2.4e-6
    assert np.abs(cubes[0][:, 7] - cubes[2][:, 7]).max() > 0.04  # the factors change the slide: 0.085 m/s


def test_every_reset_draws_each_envs_factors_from_its_own_seed_within_the_ranges():
    env = _make()
    f = env.randomization_factors.numpy().copy()
    lo, hi = RANGES.ranges()[:, 0], RANGES.ranges()[:, 1]
    assert (f >= lo).all() and (f <= hi).all()
    assert len({tuple(row) for row in f.round(6)}) == N  # each env its own
    # the same seed at another place among the envs draws the same factors (as its initial state)
    seeds_list = [11, 12, 13, 14]
    env.reset(seed=seeds_list)
    a = env.randomization_factors.numpy().copy()
    env.reset(seed=seeds_list[::-1])
    b = env.randomization_factors.numpy().copy()
    np.testing.assert_array_equal(a, b[::-1])
    # a partial reset draws only its envs' next factors
    env.reset(options={"env_idx": [2]})
    c = env.randomization_factors.numpy()
    np.testing.assert_array_equal(np.delete(c, 2, 0), np.delete(b, 2, 0))
    assert not np.allclose(c[2], b[2])


def test_the_captured_auto_reset_draws_new_factors_for_the_envs_it_restarts():
    """Envs 1 and 3 time out inside a captured step: their factors and their solver values change (drawn on the
    device, in the graph), the others' stay."""
    env = _make(graph=True)
    assert env.graph is not None
    before = env.randomization_factors.numpy().copy()
    lengths = env.elapsed_steps.clone()
    lengths[[1, 3]] = env.max_episode_steps - 1
    env.elapsed_steps.copy_(lengths)
    _, _, _, truncated, _ = env.step(torch.zeros(N, 8))
    assert truncated.numpy().tolist() == [False, True, False, True]
    after = env.randomization_factors.numpy()
    np.testing.assert_array_equal(after[[0, 2]], before[[0, 2]])
    assert not np.allclose(after[[1, 3]], before[[1, 3]])
    ref = _newton_reference(after)
    for name in ARRAYS:
        np.testing.assert_allclose(getattr(env.solver.mjw_model, name).numpy(),
                                   getattr(ref.solver.mjw_model, name).numpy(), rtol=2e-6, err_msg=name)  # fmt: skip


@pytest.mark.slow  # PegInsertionSide's scene (CI runs it)
def test_a_scene_drawn_again_is_what_the_factors_scale():
    """PegInsertionSide draws its peg from the seed: after a reconfiguring reset the peg's solver mass is the new
    peg's (Newton's model) times the env's factor."""
    env = T.make("PegInsertionSide-v1", num_envs=2, device="cpu", physics=PHYSICS, seed=1,
                 randomization=T.TaskRandomization(mass=(0.5, 2.0)))  # fmt: skip
    sc = env.scene
    peg = sc.actor_body0["peg"]
    to_newton = env.solver.mjc_body_to_newton.numpy()[0]
    mj = int(np.flatnonzero(to_newton == peg)[0])
    masses = []
    for seed in ([5, 6], [7, 8]):
        env.reset(seed=seed, options={"reconfigure": True})
        newton_mass = env.model.body_mass.numpy()[[peg, peg + sc.bodies_per_env]]
        f = env.randomization_factors.numpy()[:, 2]
        np.testing.assert_allclose(env.solver.mjw_model.body_mass.numpy()[:, mj], newton_mass * f, rtol=1e-6)
        masses.append(newton_mass)
    assert not np.allclose(masses[0], masses[1])  # the scene did change


def test_off_by_default():
    env = _make(None, graph=False)
    assert env.randomization is None and env.randomization_factors is None


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"friction": (0.0, 1.0)}, "TaskRandomization.friction: expected a range (low, high) of scale factors with "
                                   "0 < low <= high, got (0.0, 1.0)"),
        ({"mass": (2.0, 1.0)}, "TaskRandomization.mass: expected a range"),
        ({"contact_time": (1.0,)}, "TaskRandomization.contact_time: expected a range"),
        ({"friction": (0.5, float("nan"))}, "TaskRandomization.friction: expected a range"),
        ({"mass": (True, 2)}, "TaskRandomization.mass: expected a range"),
    ],
)  # fmt: skip
def test_bad_ranges_are_refused_naming_the_field(kwargs, message):
    with pytest.raises(ConfigError) as e:
        T.TaskRandomization(**kwargs)
    assert str(e.value).startswith(message), str(e.value)


def test_a_time_constant_under_two_solver_steps_is_refused_before_anything_is_simulated():
    """At 8 substeps a MuJoCo step is 1.25 ms and MuJoCo raises a time constant under 2.5 ms to 2.5 ms: the scene's
    5 ms times 0.4 would not be drawn as asked."""
    with pytest.raises(ConfigError, match=r"TaskRandomization.contact_time: expected low >= 0.5 .*got \(0.4, 1.0\)"):
        _make(T.TaskRandomization(contact_time=(0.4, 1.0)), graph=False)
    with pytest.raises(ConfigError, match="make: randomization expected a TaskRandomization"):
        T.make("PushCube-v1", randomization={"friction": (0.5, 1.5)})
