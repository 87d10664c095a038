"""The open-loop replay of ManiSkill's recorded episodes on Newton (``wpctrl.tasks.replay``, ``python -m wpctrl
replay``): the public sample (tests/data/tasks, a copy of real ManiSkill 3.0.1 / PhysX CPU episodes of both tasks and
both arm modes) against ManiSkill's outcomes and cube poses, the report's definitions, bad files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")

import wpctrl  # noqa: E402
import wpctrl.tasks as T  # noqa: E402

DATA = Path(__file__).parent / "data" / "tasks"


def _episodes(name: str) -> dict:
    return json.loads((DATA / name).read_text())


@pytest.mark.parametrize("task, max_median", [("PushCube-v1", 0.01), ("PickCube-v1", 0.02)])
def test_recorded_episodes_replay_to_maniskills_outcome(task, max_median):
    """ManiSkill's recorded episodes (every file of the public sample: both arm modes) replayed open-loop on Newton:
    every successful episode succeeds, the cube's final position within 1 cm (PushCube) / 2 cm (PickCube) of
    PhysX's in the median over the task's episodes, and (PickCube) the grasp flag agrees with ManiSkill's on most
    steps."""
    reports = [T.replay(DATA / f"{task}__{mode}.json") for mode in ("pd_joint_delta_pos", "pd_ee_delta_pos")]
    for report in reports:
        assert report.success_agreement == 1.0, report.format()
        for e in report.episodes:
            if "is_grasped" in e.flags:
                assert e.flag_agreement("is_grasped") >= 0.9, (e.seed, e.flag_agreement("is_grasped"))
    errors = [e.final_cube_error for r in reports for e in r.episodes]
    assert np.median(errors) <= max_median, "\n".join(r.format() for r in reports)


def test_replay_refuses_bad_files(tmp_path):
    with pytest.raises(FileNotFoundError):
        T.replay(tmp_path / "missing.json")
    data = _episodes("PushCube-v1__pd_joint_delta_pos.json")
    with pytest.raises(wpctrl.ConfigError, match="header"):
        T.replay({"episodes": data["episodes"]})
    broken = {"header": data["header"], "episodes": [dict(data["episodes"][0])]}
    broken["episodes"][0].pop("actions")
    with pytest.raises(wpctrl.ConfigError, match="'actions'"):
        T.replay(broken)


def test_the_main_object_is_the_headers_and_must_be_recorded():
    """The replay follows ``header.main_object`` (else the task's: the cube), read from ``actor_poses`` (else
    ``cube_pose``); a main object the start state lacks, or poses that are not one per step, are refused by name."""
    data = _episodes("PushCube-v1__pd_joint_delta_pos.json")
    assert T.load_episodes(data) is data
    data["header"]["main_object"] = "peg"
    with pytest.raises(wpctrl.ConfigError, match=r"episode 0: the main object 'peg' is not an actor"):
        T.load_episodes(data)
    data["header"]["main_object"] = "cube"
    ep = data["episodes"][0]
    ep["actor_poses"] = {"cube": ep.pop("cube_pose")[:-1]}
    with pytest.raises(wpctrl.ConfigError, match=r"episode 0 has 50 actions and 50 poses of 'cube'"):
        T.load_episodes(data)
    ep["actor_poses"] = {}
    with pytest.raises(wpctrl.ConfigError, match=r"neither 'actor_poses'\['cube'\] nor 'cube_pose'"):
        T.load_episodes(data)


def test_replay_agreement_counts_maniskills_successes_only():
    """success_agreement is over ManiSkill's successful episodes; outcome_agreement over all. A recorded success
    replayed as is, and the same start with the arm left still, recorded as ManiSkill's failure: both agree (2 of 2
    outcomes), and the one success counted succeeds (1 of 1)."""
    data = json.loads((DATA / "PickCube-v1__pd_ee_delta_pos.json").read_text())
    ok = data["episodes"][0]
    still = json.loads(json.dumps(ok))
    still["actions"] = [[0.0] * len(a) for a in ok["actions"]]
    still["info"] = {k: [False] * len(v) for k, v in ok["info"].items()}
    still["success_at_end"] = False
    data["episodes"] = [ok, still]
    report = T.replay(data)
    assert [e.success_at_end for e in report.episodes] == [True, False]
    assert report.success_agreement == 1.0
    assert report.outcome_agreement == 1.0


def test_replay_command_prints_and_writes_the_report_of_the_api(tmp_path, capsys):
    """``python -m wpctrl replay FILE --out OUT``: the printed table and the written JSON are ``replay(FILE)``'s; a
    missing file or one that is not ManiSkill's episode format exits 2 with the reason."""
    from wpctrl.tasks.replay import main

    data = json.loads((DATA / "PickCube-v1__pd_ee_delta_pos.json").read_text())
    data["episodes"] = data["episodes"][:2]
    src = tmp_path / "two.json"
    src.write_text(json.dumps(data))
    out = tmp_path / "report.json"
    assert main([str(src), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "PickCube-v1 pd_ee_delta_pos: 2 episodes replayed on Newton" in printed
    written = json.loads(out.read_text())
    assert written[0]["summary"] == T.replay(data).summary()
    assert len(written[0]["episodes"]) == 2
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"episodes": []}))
    for path, reason in ((tmp_path / "missing.json", "no episode file"), (bad, "'header' and 'episodes'")):
        assert main([str(path)]) == 2
        assert reason in capsys.readouterr().err
