"""The mutation list (``tools/mutations/``) stays in step with the code it mutates.

A refactor that moves or rewrites a mutated line leaves the mutation stale: ``tools/mutate.py`` would refuse to run
it. These checks catch that in the ordinary suite, before anyone runs the (long) mutation check itself.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))

from mutations import AREAS, all_mutations  # noqa: E402

MUTATIONS = all_mutations()


def test_every_area_module_is_listed():
    modules = {p.stem for p in (ROOT / "tools" / "mutations").glob("*.py")} - {"__init__", "model"}
    assert modules == set(AREAS)


@pytest.mark.parametrize("m", MUTATIONS, ids=[m.name for m in MUTATIONS])
def test_mutation_applies_once_and_names_real_tests(m):
    assert m.old != m.new
    text = (ROOT / m.file).read_text()
    assert text.count(m.old) == 1, f"{m.name}: its text occurs {text.count(m.old)} times in {m.file}"
    for t in m.tests:
        path, _, name = t.partition("::")
        assert (ROOT / path).is_file(), f"{m.name}: no test file {path}"
        if name:
            func = name.split("[")[0].split("::")[-1]
            assert f"def {func}(" in (ROOT / path).read_text(), f"{m.name}: no test {t}"
