"""What replaying ManiSkill's motion-planning demos needs, and the replay itself.

The demos (``<Task>__pd_joint_pos.json.gz``: ManiSkill 3.0.1's own motion-planning solutions on PhysX CPU, stepped in
``pd_joint_pos``, see the folder's README) run longer than the tasks' registered 50 / 100 steps, follow a main object
(``header.main_object``: ``cube``, ``cubeA``, ``peg``, ...) and hold episodes of different lengths in one file. Here:
``make(max_episode_steps=N)`` (``gym.make``'s override), ``reset(seed=[...])`` with one seed per env (an env's draw a
function of its own seed), and every demo file of a registered task replayed on Newton against ManiSkill's outcome:
success in >= 90 % of ManiSkill's successful episodes, the main object's final position within 1 cm of PhysX's in the
median (2 cm for a peg, whose pose hangs on a grasp of a long thin body).

The demos are read from ``$WPCTRL_MANISKILL_DEMOS`` (default ``/work/shared/tasks``); without them the replay tests
skip.
"""

from __future__ import annotations

import gzip
import json
import os
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import wpctrl  # noqa: E402
import wpctrl.tasks as T  # noqa: E402
from wpctrl.tasks.names import TASK_ACTORS, main_object  # noqa: E402

DEMOS = Path(os.environ.get("WPCTRL_MANISKILL_DEMOS", "/work/shared/tasks"))
DEMO_FILES = sorted(DEMOS.glob("*__pd_joint_pos.json.gz")) if DEMOS.is_dir() else []
FAST = T.TaskPhysics(substeps=2)
"""The API's bookkeeping, not the physics' fidelity."""


def _demo(path: Path) -> dict:
    return json.loads(gzip.decompress(path.read_bytes()))


@pytest.fixture(scope="module")
def pull_env():
    return T.make("PullCube-v1", num_envs=4, control_mode="pd_joint_pos", physics=FAST, max_episode_steps=3)


# -- make(max_episode_steps=N) ----------------------------------------------------------------------------------------


def test_max_episode_steps_overrides_the_tasks_limit(pull_env):
    """``truncated`` turns True at step N (not the registered 50), the auto reset then starts a new episode; the
    default is the registered limit."""
    env = pull_env
    assert env.max_episode_steps == 3 and T.TASKS["PullCube-v1"].max_episode_steps == 50
    env.reset(seed=0)
    hold = torch.zeros(4, 8)
    hold[:, :7] = env.get_state_dict()["articulations"]["panda"][:, 13:20]
    truncated = [env.step(hold)[3] for _ in range(4)]
    assert [bool(t.all()) for t in truncated] == [False, False, True, False]
    assert env.elapsed_steps.tolist() == [1] * 4  # reset inside step 3, one step into the next episode


@pytest.mark.parametrize("bad", [0, -5, 2.5, True, "100"])
def test_a_bad_max_episode_steps_is_refused_naming_it(bad):
    with pytest.raises(wpctrl.ConfigError, match="max_episode_steps expected a positive int"):
        T.make("PullCube-v1", num_envs=1, max_episode_steps=bad)


# -- reset(seed=[...]) ------------------------------------------------------------------------------------------------


def _start(env) -> np.ndarray:
    """Each env's drawn initial state: arm qpos and the cube's pose."""
    s = env.get_state_dict()
    return np.hstack([s["articulations"]["panda"][:, 13:20].numpy(), s["actors"]["cube"][:, :7].numpy()])


def test_each_env_draws_from_its_own_seed_alone(pull_env):
    """ManiSkill's vectorised envs take one seed per env: an env's initial state is a function of its seed (and the
    episodes since), whichever env it is and whatever the others' seeds are."""
    env = pull_env
    env.reset(seed=[7, 8, 7, 9])
    a = _start(env)
    np.testing.assert_array_equal(a[0], a[2])
    assert not np.allclose(a[0], a[1]) and not np.allclose(a[1], a[3])
    env.reset(seed=[9, 7, 100, 8])
    b = _start(env)
    np.testing.assert_array_equal(b[1], a[0])
    np.testing.assert_array_equal(b[0], a[3])
    np.testing.assert_array_equal(b[3], a[1])
    env.reset(seed=[5, 5, 6, 6])
    env.reset()  # unseeded: every env's next episode from its own seed's stream
    c = _start(env)
    np.testing.assert_array_equal(c[0], c[1])
    np.testing.assert_array_equal(c[2], c[3])
    assert not np.allclose(c[0], c[2])
    env.reset(seed=[5, 11, 6, 6], options={"env_idx": [1]})  # only the reset env takes its seed
    d = _start(env)
    np.testing.assert_array_equal(d[[0, 2, 3]], c[[0, 2, 3]])
    env.reset(seed=[0, 11, 0, 0])
    np.testing.assert_array_equal(_start(env)[1], d[1])


def test_one_int_seed_is_expanded_as_maniskill_expands_it(pull_env):
    """``reset(seed=s)`` on n envs seeds them ``[s, *RandomState(s).randint(2**31, size=n - 1)]``
    (``BaseEnv._set_episode_rng``, mani_skill/envs/sapien_env.py): the same episodes as that list."""
    env = pull_env
    env.reset(seed=123)
    a = _start(env)
    env.reset(seed=[123, *np.random.RandomState(123).randint(2**31, size=3).tolist()])
    np.testing.assert_array_equal(_start(env), a)
    assert len({tuple(r) for r in a}) == 4


@pytest.mark.parametrize(
    "seed, match",
    [([1, 2, 3], r"seed expected one int or a list of num_envs = 4 ints"), ([1, 2, 3, 4.5], r"seed\[3\]"),
     ([True, 1, 2, 3], r"seed\[0\]"), ([[1, 2], [3, 4]], r"seed expected .* got shape")],
)  # fmt: skip
def test_a_seed_list_of_the_wrong_length_or_type_is_refused_naming_seed(pull_env, seed, match):
    with pytest.raises(wpctrl.ConfigError, match=match):
        pull_env.reset(seed=seed)


# -- the demos ---------------------------------------------------------------------------------------------------------


def _goals(report) -> tuple[float, float]:
    """(success kept, median final error of the main object) of a replay."""
    return report.success_agreement, report.median_final_cube_error


def assert_demo_replays(path: Path):
    """Replay one demo file and check the goals; returns the report."""
    data = _demo(path)
    task, main = data["header"]["task"], data["header"]["main_object"]
    report = T.replay(data)
    assert report.main_object == main == main_object(task)
    assert [len(e.success) for e in report.episodes] == [len(ep["actions"]) for ep in data["episodes"]]
    kept, median = _goals(report)
    bound = 0.02 if main == "peg" else 0.01
    assert kept >= 0.9 and median <= bound, report.format()
    return report


_DEMO_PARAMS = [pytest.param(p, id=p.name.split("__")[0]) for p in DEMO_FILES]


@pytest.mark.slow  # each file builds an env and replays 60-200 steps (15-60 s on a 2-core CPU)
@pytest.mark.parametrize("path", _DEMO_PARAMS)
def test_maniskills_motion_planning_demos_replay_to_their_outcome(path):
    """Every demo file of a registered task: ManiSkill's successes kept (>= 90 %), the main object's final position
    within 1 cm (2 cm for a peg) of PhysX's in the median; a task wpctrl does not build yet is skipped by name."""
    task = path.name.split("__")[0]
    if task not in T.TASKS:
        pytest.skip(f"{task} is not a registered task of wpctrl.tasks (no module in TASK_MODULES)")
    assert task in TASK_ACTORS, "names.TASK_ACTORS lists the task's recorded actors"
    assert_demo_replays(path)


@pytest.mark.slow
@pytest.mark.skipif(not (DEMOS / "PullCube-v1__pd_joint_pos.json.gz").is_file(), reason="no PullCube demo file")
def test_episodes_of_different_lengths_step_together_each_read_to_its_own_end():
    """The demo file's episodes (62-79 steps) replay in one env; each one is read to its own end (the steps after a
    short episode's end are not read) and matches its replay alone, and the env runs past the registered 50 steps.

    Alone and in the batch are not bitwise equal: MuJoCo-Warp's result for one world moves with the other worlds of
    the batch once contacts start (measured on this file: the shortest episode's cube 1.9 mm apart at most, the same
    success at every step), so the positions are compared within 3 mm; reading another step than the episode's own
    would change the number of results and the success steps."""
    data = _demo(DEMOS / "PullCube-v1__pd_joint_pos.json.gz")
    lengths = [len(ep["actions"]) for ep in data["episodes"]]
    assert len(set(lengths)) > 1 and max(lengths) > 50
    together = T.replay(data)
    shortest = int(np.argmin(lengths))
    alone = T.replay({**data, "episodes": [data["episodes"][shortest]]})
    (one,) = alone.episodes
    mixed = together.episodes[shortest]
    assert (one.seed, one.success, one.success_recorded) == (mixed.seed, mixed.success, mixed.success_recorded)
    assert len(mixed.success) == lengths[shortest]
    np.testing.assert_allclose(one.cube_error, mixed.cube_error, atol=3e-3)
    np.testing.assert_allclose(one.cube_error[:30], mixed.cube_error[:30], atol=1e-6)  # before the arm meets the cube
