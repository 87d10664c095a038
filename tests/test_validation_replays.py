"""A validation sample of real ManiSkill episodes, larger than the public one and of the same kinds, replayed open-loop
on Newton with each task's own physics (``tests/data/validation``, README there):

- ManiSkill's motion-planning demos of PegInsertionSide-v1 (26), PlaceSphere-v1 (32), LiftPegUpright-v1 (21),
  StackCube-v1 (24) and PullCube-v1 (24), recorded in the real ManiSkill by ``bench/tasks/record_demos.py`` from seeds
  200 onwards, as ManiSkill's trajectory files;
- the public PushCube-v1 (``pd_joint_delta_pos``, 40) and PickCube-v1 (``pd_ee_delta_pos``, 30) policies run in the
  real ManiSkill from seed 20010 (``wpctrl evaluate --sim maniskill --record``).

Each replay's success once must agree with ManiSkill's on at least the measured number of episodes less two (the
outcomes sit near thresholds: a different CPU's rounding can flip one), and its main object end within the measured
median error plus a margin. The issues' goal, 90 % episode by episode, is asserted where it holds and a strict
expected failure, with the measured numbers in its reason, where it does not.
"""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("torch")

import wpctrl.tasks as T  # noqa: E402

DATA = Path(__file__).parent / "data" / "validation"

# measured 2026-11-30, CPU, each task's own physics (16 substeps; the arm under PhysX's TGS pass but in
# PegInsertionSide, whose physics keeps MuJoCo's drive): episodes, success once agreeing, median final error of the
# main object [m]
MEASURED = {
    "LiftPegUpright-v1.h5": (21, 21, 0.0043),
    "PegInsertionSide-v1.h5": (26, 24, 0.0107),
    "PullCube-v1.h5": (24, 24, 0.0031),
    "StackCube-v1.h5": (24, 24, 0.0006),
    "PlaceSphere-v1.h5": (32, 30, 0.0027),
    "PushCube-v1__pd_joint_delta_pos__policy_20010.json.gz": (40, 36, 0.080),
    "PickCube-v1__pd_ee_delta_pos__policy_20010.json.gz": (30, 30, 0.0015),
}
GOAL = 0.9
"""Success once agreeing with ManiSkill's in this share of the episodes (the issues' goal)."""
SHORT_OF_GOAL = {name for name, (n, agree, _) in MEASURED.items() if agree < GOAL * n}

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def reports():
    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = T.replay(DATA / name)
        return cache[name]

    return get


@pytest.mark.parametrize("name", sorted(MEASURED))
def test_the_replays_agree_as_measured(reports, name):
    n, agree, median = MEASURED[name]
    report = reports(name)
    assert len(report.episodes) == n
    got = round(report.once_agreement * n)
    misses = [(e.seed, e.success_once_recorded, round(e.final_cube_error, 4)) for e in report.episodes
              if e.success_once != e.success_once_recorded]  # fmt: skip
    assert got >= agree - 2, (got, misses)
    assert report.median_final_cube_error <= 1.5 * median + 0.002, report.median_final_cube_error


@pytest.mark.parametrize(
    "name",
    [pytest.param(name, marks=pytest.mark.xfail(strict=True, reason=(
        f"measured {MEASURED[name][1]} / {MEASURED[name][0]} episodes agree (2026-11-30); the rest part where "
        "PhysX's and MuJoCo's contacts differ (docs/tasks.md)"))) if name in SHORT_OF_GOAL else name
     for name in sorted(MEASURED)],
)  # fmt: skip
def test_the_replays_reach_the_goal(reports, name):
    report = reports(name)
    assert report.once_agreement >= GOAL, report.once_agreement
