"""The README's example runs as written and does what the README says it does.

The Python block of the README's "Example" section is read from README.md and run in a fresh interpreter on Warp's
CPU device (CUDA hidden), so the test runs the text a reader copies. Its printed line is parsed: 16 Pandas under
ManiSkill's ``pd_joint_pos`` with gravity off the robot (``balance_passive_force``, MuJoCo's gravcomp) reach their
joint targets. The same block with the switch set to False must show gravity acting (the arm sags below its targets
by the amount the README states), so the README's claim about gravity is checked against a real solver, and the line
the README quotes must match the measured one.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("mujoco_warp", reason="the example needs the [sim] extra (newton[sim]: MuJoCo-Warp)")

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
LINE = re.compile(
    r"^(\d+) envs on (\S+): max arm tracking error after (\d+) control steps: ([0-9.eE+-]+) rad$", re.MULTILINE
)
SWITCH = 'mode["balance_passive_force"] = True'


def example_code() -> str:
    text = README.read_text()
    section = text[text.index("\n## Example\n") :]
    section = section[: section.index("\n## ", 1)]
    blocks = re.findall(r"```python\n(.*?)```", section, re.DOTALL)
    assert len(blocks) == 1, f"README's Example section: expected one python block, found {len(blocks)}"
    return blocks[0]


def run(code: str) -> tuple[int, str, int, float]:
    env = dict(os.environ, CUDA_VISIBLE_DEVICES="")  # the CPU, as CI runs it (device chosen by the example)
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=900, check=False
    )
    assert out.returncode == 0, f"the README example failed:\n{out.stdout[-3000:]}\n{out.stderr[-3000:]}"
    found = LINE.findall(out.stdout)
    assert len(found) == 1, f"expected one result line, got:\n{out.stdout[-3000:]}"
    envs, device, steps, err = found[0]
    return int(envs), device, int(steps), float(err)


def test_readme_example_tracks_without_gravity_on_the_robot():
    code = example_code()
    assert SWITCH in code, "the example must set balance_passive_force explicitly"
    envs, device, steps, err = run(code)
    assert (envs, device, steps) == (16, "cpu", 40)
    assert err < 1e-4, f"with gravity off the robot the arm must reach its targets, error {err} rad"
    quoted = LINE.findall(README.read_text())
    assert len(quoted) == 1, "the README quotes the example's printed line once"
    q_envs, q_device, q_steps, q_err = quoted[0]
    assert (int(q_envs), q_device, int(q_steps)) == (envs, device, steps)
    assert float(q_err) < 1e-4, "the quoted error must be of the measured kind"


def test_readme_example_with_gravity_sags_as_stated():
    code = example_code().replace(SWITCH, SWITCH.replace("True", "False"))
    _, _, _, err = run(code)
    prose = " ".join(README.read_text().split())  # the sentence may wrap
    stated = re.search(r"With `False`, gravity acts and the same PD gains leave the arm ([0-9.eE+-]+) rad", prose)
    assert stated, "the README states the sag with balance_passive_force=False"
    assert err > 1e-2, f"gravity must act on the arm when balance_passive_force is False, error {err} rad"
    assert err == pytest.approx(float(stated.group(1)), rel=0.1), "the README's number must be the measured one"
