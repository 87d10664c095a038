"""``python -m bench``, the benchmark session runner: its stage table points at files that exist, it lists its stages,
it keeps to its time budget, a small stage runs on the CPU, and the A/B summary computes new / old per round."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from bench import stages
from bench.__main__ import main
from bench.ab import summary

ROOT = Path(__file__).resolve().parents[1]


def test_stage_names_are_unique_and_groups_expand():
    names = [s.name for s in stages.STAGES]
    assert len(names) == len(set(names))
    assert not set(stages.GROUPS) & set(names), "a group may not share a stage's name"
    for group, members in stages.GROUPS.items():
        assert [s.name for s in stages.expand([group])] == members
    assert [s.name for s in stages.expand(["step-implicit", "step", "step-implicit"])][0] == "step-implicit"
    with pytest.raises(KeyError):
        stages.expand(["no-such-stage"])


def test_every_referenced_module_and_test_file_exists():
    for stage in stages.STAGES:
        assert stage.what and stage.outputs and stage.expected_s > 0, stage.name
        assert stage.expected_s < 600, f"{stage.name} must fit one 10-minute call"
        for path in stage.modules:
            assert (ROOT / path).is_file(), f"{stage.name}: {path}"
    source = (ROOT / "bench" / "stages.py").read_text()
    modules = set(re.findall(r'"(bench(?:\.\w+)+)"', source))
    assert "bench.step.controller_step" in modules
    for mod in modules:
        assert (ROOT / (mod.replace(".", "/") + ".py")).is_file(), mod
    for path in set(re.findall(r'"(tests/test_\w+\.py)', source)):
        assert (ROOT / path).is_file(), path


def test_list_names_every_stage(capsys):
    assert main(["--list"]) == 0
    listed = capsys.readouterr().out
    for stage in stages.STAGES:
        assert f"{stage.name} [{stage.group}, ~{stage.expected_s} s]" in listed


def test_the_budget_stops_the_session_before_a_stage_that_does_not_fit(tmp_path):
    # 30 s cannot hold step-explicit (~150 s): nothing starts, both stages are reported as not run
    assert main(["step-explicit", "step-implicit", "--device", "cpu", "--budget", "30", "--out", str(tmp_path)]) == 1
    results = json.loads((tmp_path / "session.json").read_text())
    assert [(r["stage"], r["status"]) for r in results] == [("step-explicit", "not run"), ("step-implicit", "not run")]
    assert "Not run: step-explicit, step-implicit" in (tmp_path / "session.md").read_text()


def test_a_cpu_stage_runs(tmp_path):
    pytest.importorskip("torch")
    args = ["step-implicit", "--device", "cpu", "--envs", "2", "--repeats", "1", "--budget", "0"]
    assert main([*args, "--out", str(tmp_path)]) == 0
    results = json.loads((tmp_path / "session.json").read_text())
    assert results[0]["status"] == "ok"
    rows = json.loads((tmp_path / "step-implicit" / "controller_step_cpu_implicit.json").read_text())["rows"]
    assert {r["envs"] for r in rows} == {2}
    assert (tmp_path / "step-implicit" / "step-implicit.log").is_file()


def _write(run_dir: Path, side: str, rnd: int, us: float, commit: str) -> None:
    rows = [{"envs": 4096, "variant": "wpctrl_graph", "interpolate": False, "us_per_step": us,
             "samples_us": [us * 0.99, us, us * 1.02]}]  # fmt: skip
    path = run_dir / f"controller_step_ab_{side}_explicit_{rnd}.json"
    path.write_text(json.dumps({"meta": {"wpctrl_commit": commit}, "rows": rows}))


def test_ab_summary_reports_new_over_old_and_its_spread(tmp_path):
    for rnd, (old, new) in enumerate([(10.0, 9.0), (10.0, 9.5), (12.0, 9.0)], start=1):
        _write(tmp_path, "A", rnd, old, "aaaaaaa")
        _write(tmp_path, "B", rnd, new, "bbbbbbb")
    text, records = summary.summarise(tmp_path)
    (rec,) = records
    assert rec["old_us"] == 10.0 and rec["new_us"] == 9.0
    assert rec["new_over_old"] == pytest.approx(0.9)
    assert rec["per_round_new_over_old"] == pytest.approx([0.9, 0.95, 0.75])
    assert rec["sample_spread_old"] == pytest.approx(0.03)
    assert "old = aaaaaaa, new = bbbbbbb" in text
    row = "| controller_step | explicit | 4k | wpctrl_graph | 10.00 | 9.00 | 0.900 | 0.750–0.950 | 3.0 % / 3.0 % |"
    assert row in text
