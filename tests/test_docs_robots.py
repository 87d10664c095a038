"""docs/robots.md's table of ManiSkill agents x control modes says what the tests show: every agent the differential
tests run, each mode the agent class defines, ✓ exactly where ``test_against_maniskill`` runs it and ✗ exactly where
ManiSkill itself cannot run it (``test_modes_maniskill_cannot_run_are_refused``)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

pytest.importorskip("mani_skill", reason="the maniskill extra (mani-skill) is not installed")  # a dev dependency

from maniskill_side import AGENTS, CANNOT_RUN  # noqa: E402

from wpctrl.maniskill import control_modes  # noqa: E402

DOC = Path(__file__).resolve().parents[1] / "docs" / "robots.md"


def _table() -> dict[str, tuple[set[str], set[str]]]:
    """{agent: (✓ modes, ✗ modes)} from the "Agents and modes" table."""
    text = DOC.read_text()
    section = text[text.index("## Agents and modes") :]
    section = section[: section.index("\n## ", 1)]
    out = {}
    for line in section.splitlines():
        if not line.startswith("| `"):
            continue
        agents_cell, modes_cell = (c.strip() for c in line.strip().strip("|").split("|"))
        modes_cell = re.sub(r"\([^()]*\)", "", modes_cell)  # reasons and remarks
        ok, bad = set(), set()
        for item in re.split(r"[;,]", modes_cell):
            m = re.fullmatch(r"\s*([a-z0-9_]+)\s*(✗)?\s*", item)
            assert m, f"docs/robots.md: cannot read {item!r} in {line!r}"
            (bad if m.group(2) else ok).add(m.group(1))
        for agent in re.findall(r"`([^`]+)`", agents_cell):
            out[agent] = (ok, bad)
    return out


def test_robots_doc_table_matches_the_tests():
    table = _table()
    assert set(table) == set(AGENTS), "agents in docs/robots.md vs the differential tests"
    for agent in AGENTS:
        modes = set(control_modes(agent))
        cannot = {m for (a, m) in CANNOT_RUN if a == agent}
        ok, bad = table[agent]
        assert ok == modes - cannot, f"{agent}: ✓ modes in docs/robots.md"
        assert bad == cannot, f"{agent}: ✗ modes in docs/robots.md"
