"""tools/test_report.py, which writes the suite's counts and times into docs/testing.md: its counts against a real
pytest run of a small file with a known outcome, the table it writes between the markers (the rest of the page kept),
and a page without the markers refused."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _tool():
    spec = importlib.util.spec_from_file_location("test_report_tool", ROOT / "tools" / "test_report.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_counts_and_table_of_a_real_run(tmp_path):
    tool = _tool()
    (tmp_path / "test_known.py").write_text(
        "import pytest\n"
        "def test_a(): pass\n"
        "def test_b(): pass\n"
        "def test_c(): pytest.skip('known')\n"
        "def test_d(): assert False\n"
    )
    xml = tmp_path / "run.xml"
    subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--no-cov", str(tmp_path),
                    f"--junitxml={xml}", "-o", "addopts="], cwd=tmp_path, capture_output=True, check=False)  # fmt: skip
    c = tool.counts(xml)
    assert (c["tests"], c["passed"], c["skipped"], c["failures"] + c["errors"]) == (4, 2, 1, 1)
    doc = tmp_path / "testing.md"
    doc.write_text(f"# Testing\n\nbefore\n\n{tool.BEGIN}\nold table\n{tool.END}\n\nafter\n")
    assert tool.main(["--run", "fast, warm cache", str(xml), "--wall", "90", "--doc", str(doc)]) == 0
    page = doc.read_text()
    assert "old table" not in page and "before" in page and "after" in page
    row = [line for line in page.splitlines() if line.startswith("| fast, warm cache |")]
    assert len(row) == 1 and "| 4 | 2 | 1 | 1 | 1.5 min |" in row[0], row


def test_a_page_without_the_markers_is_refused(tmp_path):
    tool = _tool()
    doc = tmp_path / "testing.md"
    doc.write_text("# Testing\n")
    with pytest.raises(SystemExit, match="markers"):
        tool.write(doc, "| table |")
    assert doc.read_text() == "# Testing\n"


def test_the_page_has_the_markers():
    tool = _tool()
    page = (ROOT / "docs" / "testing.md").read_text()
    assert page.count(tool.BEGIN) == 1 and page.count(tool.END) == 1
