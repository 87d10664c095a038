"""A new user's first hour with the command line and ``wpctrl.tasks.make``: quiet by default and loud on request
(no Warp banner, CUDA-driver line or module-load lines unless ``--verbose`` / ``verbose=True``; no warning at all
from ``--help``), every argument mistake refused in one line before Warp, torch, Newton or ManiSkill is imported, and
progress on long work (on stderr, none with ``--no-progress``).

Every command runs in a fresh subprocess: what it imports and prints is only visible there (this test process has
imported Warp already)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from wpctrl.config import ConfigError
from wpctrl.console import cuda_absent

DATA = Path(__file__).parent / "data" / "tasks"
HEAVY = ("warp", "torch", "newton", "mani_skill")

_CLI = f"""
import sys, wpctrl.__main__ as m
rc = m.main(sys.argv[1:])
print("HEAVY", sorted(k for k in {HEAVY!r} if k in sys.modules), file=sys.stderr)
sys.exit(rc)
"""

WARP_NOISE = ("Warp CUDA warning", "initialized:", "load on device", "took ")
"""What Warp prints unless told to be quiet: the native CUDA-driver line, the banner, the module-load lines."""


def _python(code: str, *args, cwd=None, timeout=300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True, text=True, cwd=cwd,
                          timeout=timeout)  # fmt: skip


def _cli(*argv, cwd=None, timeout=60):
    """Runs ``wpctrl <argv>`` in a subprocess: (exit code, stdout, stderr less the last line, heavy modules)."""
    done = _python(_CLI, *argv, cwd=cwd, timeout=timeout)
    *err, heavy = done.stderr.rstrip("\n").split("\n")
    assert heavy.startswith("HEAVY "), done.stderr
    return done.returncode, done.stdout, "\n".join(err), eval(heavy[len("HEAVY ") :])  # noqa: S307 (a printed list)


def _noise(text: str) -> list[str]:
    return [line for line in text.splitlines() if any(n in line for n in WARP_NOISE)]


# -- help ---------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("argv", [[], ["demo"], ["demo", "--task", "PushCube-v1"], ["train"], ["replay"], ["export"],
                                  ["evaluate"]])  # fmt: skip
def test_help_prints_no_warning_and_imports_nothing_heavy(argv):
    rc, out, err, heavy = _cli(*argv, "--help")
    assert rc == 0 and "usage:" in out
    assert err == "" and heavy == [], (err, heavy)
    if argv:
        assert "--verbose" in out, out
    if argv in (["replay"], ["evaluate"]):
        assert "--no-progress" in out, out


# -- refusals -----------------------------------------------------------------------------------------------------

POLICY = "policy.ts"  # written by the test: the refusals below come before it is read


def _refusals(tmp: Path):
    (tmp / POLICY).write_text("not read: the argument is refused first")
    (tmp / "run").mkdir()
    (tmp / "notes.json").write_text('{"some": "json"}')
    cases = [
        (["train", "--task", "PushCub-v1"], "argument --task: invalid choice: 'PushCub-v1'"),
        (["train", "--task", "PushCube-v1", "--control-mode", "pd_ee_pos"],
         "--control-mode: expected one of the Panda's modes"),
        (["train", "--task", "reach", "--control-mode", "pd_joint_pos"], "--control-mode: expected one of"),
        (["train", "--task", "PushCube-v1", "--envs", "8"], "--envs 8 x --steps-per-env 4 = a batch of 32"),
        (["evaluate", "--policy", "missing.ts", "--sim", "newton"], "--policy: no file 'missing.ts'"),
        (["evaluate", "--policy", POLICY, "--sim", "newton", "--task", "PickCube"],
         "argument --task: invalid choice: 'PickCube'"),
        (["evaluate", "--policy", POLICY, "--sim", "newton", "--episodes", "0"], "--episodes: expected a positive"),
        (["export", "missing"], "run dir 'missing' does not exist"),
        (["export", "run"], "run dir 'run' has no policy.pt"),
        (["replay", "missing.json"], "no episode file 'missing.json'"),
        (["replay", "notes.json"], "expected ManiSkill's episode format: a dict with 'header' and 'episodes'"),
        (["demo", "--control-mode", "pd_ee_pos"], "--control-mode: expected one of"),
        (["demo", "--task", "PushCub-v1"], "argument --task: invalid choice: 'PushCub-v1'"),
    ]  # fmt: skip
    if cuda_absent():  # the cheap check knows: no sign of an NVIDIA driver on this machine
        no_cuda = "--device: 'cuda:0' is not a device of this machine (it has no CUDA device); available devices"
        cases += [
            (["train", "--task", "PushCube-v1", "--device", "cuda:0"], no_cuda),
            (["evaluate", "--policy", POLICY, "--sim", "newton", "--device", "cuda:0"], no_cuda),
            (["replay", str(DATA / "PushCube-v1__pd_ee_delta_pos.json"), "--device", "cuda:0"], no_cuda),
            (["demo", "--task", "PushCube-v1", "--device", "cuda:0"], no_cuda),
            (["demo", "--device", "cuda:0"], "--device cuda:0: no CUDA device is available on this machine"),
        ]
    return cases


def test_every_refusal_is_one_line_before_the_heavy_imports(tmp_path):
    """Each mistake exits 2 with ``wpctrl <command>: error: <what>`` as the last line on stderr (argparse's usage
    line may come before it), nothing on stdout, and neither Warp, torch, Newton nor ManiSkill imported."""
    failures = []
    for argv, message in _refusals(tmp_path):
        rc, out, err, heavy = _cli(*argv, cwd=tmp_path)
        last = err.splitlines()[-1] if err else ""
        command = "demo --task" if argv[:2] == ["demo", "--task"] and "invalid choice" in message else argv[0]
        ok = (rc == 2 and out == "" and last.startswith(f"wpctrl {command}: error: ") and message in last
              and heavy == [] and "Traceback" not in err)  # fmt: skip
        if not ok:
            failures.append((argv, rc, out, err, heavy))
    assert not failures, "\n".join(map(repr, failures))


def test_replay_names_what_it_expected_of_a_file_that_is_no_recording(tmp_path):
    """``wpctrl replay README.md`` (a file that is not JSON), a broken .json.gz and a recording of a task wpctrl does
    not build: one line each, naming the file and what was expected."""
    import gzip

    (tmp_path / "bad.json.gz").write_bytes(b"\x1f\x8b not gzip")
    data = json.loads((DATA / "PushCube-v1__pd_ee_delta_pos.json").read_text())
    data["header"]["task"] = "PlugCharger-v1"
    (tmp_path / "stack.json.gz").write_bytes(gzip.compress(json.dumps(data).encode()))
    readme = Path(__file__).resolve().parents[1] / "README.md"
    expected = "expected ManiSkill's episode JSON (an object with 'header' and 'episodes'), plain or gzip-compressed"
    for name, message in (
        (str(readme), f"{str(readme)!r} is not a recording (not JSON text); {expected}"),
        ("bad.json.gz", f"'bad.json.gz' is not a recording (not a readable gzip file); {expected}"),
        ("stack.json.gz", "'stack.json.gz': task 'PlugCharger-v1' is not one wpctrl builds"),
    ):
        rc, out, err, heavy = _cli("replay", name, cwd=tmp_path)
        assert (rc, out, heavy) == (2, "", []), (name, rc, out, err, heavy)
        assert len(err.splitlines()) == 1 and err.startswith(f"wpctrl replay: error: {message}"), err


def test_a_gzipped_recording_loads_as_the_plain_one(tmp_path):
    import gzip

    from wpctrl.tasks import load_episodes

    src = DATA / "PickCube-v1__pd_ee_delta_pos.json"
    (tmp_path / "pick.json.gz").write_bytes(gzip.compress(src.read_bytes()))
    assert load_episodes(tmp_path / "pick.json.gz") == load_episodes(src)


def test_the_light_names_are_the_tasks_own():
    """The task ids and control modes the command lines check without importing Warp are the ones the tasks are
    built from, and ``import wpctrl.tasks`` imports nothing heavy."""
    from wpctrl.robots import panda_control_modes
    from wpctrl.tasks import CONTROL_MODES, OBS_MODES, TASKS, names
    from wpctrl.tasks.env import TaskEnv

    assert names.TASK_IDS == tuple(TASKS)
    from wpctrl.tasks.scripted import POLICIES, policy_for

    assert names.SCRIPTED_TASKS == tuple(POLICIES)  # what `wpctrl demo --task` offers is what it can solve
    with pytest.raises(ConfigError, match="no scripted policy for 'StackCube-v1'; the tasks with one are"):
        policy_for("StackCube-v1")
    assert names.CONTROL_MODES == tuple(m for m in panda_control_modes() if m.startswith("pd_")) == CONTROL_MODES
    assert names.CONTROL_MODES[0] == names.DEFAULT_CONTROL_MODE
    assert names.OBS_MODES == OBS_MODES
    assert TaskEnv  # the real env imports alongside
    done = _python(f"import sys, wpctrl.tasks; print(sorted(k for k in {HEAVY!r} if k in sys.modules))")
    assert done.returncode == 0 and done.stdout.strip() == "[]", (done.stdout, done.stderr)


# -- quiet / verbose ----------------------------------------------------------------------------------------------

_WARP_BLOCK = """
import sys, warp as wp
from wpctrl.console import quiet_warp

@wp.kernel
def first_hour_probe(x: wp.array(dtype=float)):
    x[wp.tid()] = 1.0

before = wp.config.log_level
with quiet_warp(verbose=sys.argv[1] == "verbose"):
    inside = wp.config.log_level
    wp.launch(first_hour_probe, 2, inputs=[wp.zeros(2, dtype=float, device="cpu")], device="cpu")
print("LEVELS", before, inside, wp.config.log_level, flush=True)
"""


def test_quiet_warp_hides_warps_start_up_and_module_loads_unless_verbose(tmp_path):
    """``quiet_warp()`` (what ``make`` runs in): no banner, no CUDA-driver line, no module-load line, and the user's
    log level back afterwards; ``quiet_warp(verbose=True)``: Warp's banner and the module-load line."""
    script = tmp_path / "probe.py"  # a file: Warp reads a kernel's source
    script.write_text(_WARP_BLOCK)
    quiet = _python(f"import runpy; runpy.run_path({str(script)!r}, run_name='__main__')", "quiet", cwd=tmp_path)
    assert quiet.returncode == 0, quiet.stderr
    import warp as wp

    info, warning = wp.LOG_INFO, wp.LOG_WARNING
    assert quiet.stdout.strip().splitlines() == [f"LEVELS {info} {warning} {info}"], quiet.stdout
    assert _noise(quiet.stdout + quiet.stderr) == [] and quiet.stderr == "", quiet.stderr
    loud = _python(f"import runpy; runpy.run_path({str(script)!r}, run_name='__main__')", "verbose", cwd=tmp_path)
    assert loud.returncode == 0, loud.stderr
    assert f"LEVELS {info} {info} {info}" in loud.stdout
    assert "initialized:" in loud.stdout and "load on device 'cpu'" in loud.stdout, loud.stdout
    if cuda_absent():
        assert "Warp CUDA warning: Could not find or load the NVIDIA CUDA driver" in loud.stderr, loud.stderr


def test_export_hides_torchs_known_notes_only():
    """The export's filter: TorchScript's deprecation (DeprecationWarning or FutureWarning, as torch versions differ)
    and the ONNX exporter's torchvision lines are not shown; any other warning or log line is."""
    import logging
    import warnings

    pytest.importorskip("torch")
    from wpctrl.train.export import known_third_party_notes_hidden

    logger = logging.getLogger("torch.onnx._internal.exporter._registration")
    records = []

    class Keep(logging.Handler):
        def emit(self, record):
            records.append(record.getMessage())

    handler = Keep()
    logger.addHandler(handler)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with known_third_party_notes_hidden():
                for message, category in (
                    ("`torch.jit.script` is deprecated. Please switch to `torch.compile`", DeprecationWarning),
                    ("`torch.jit.save` is deprecated. Please switch to `torch.export`.", FutureWarning),
                    ("something else is deprecated", DeprecationWarning),
                ):
                    warnings.warn(message, category, stacklevel=1)
                logger.warning("torchvision is not installed. Skipping %s", "torchvision::nms")
                logger.warning("another exporter note")
            after = "`torch.jit.load` is deprecated. Please switch to `torch.export`."
            warnings.warn(after, FutureWarning, stacklevel=1)
            logger.warning("torchvision is not installed. Skipping %s", "torchvision::roi_align")
    finally:
        logger.removeHandler(handler)
    shown = [str(w.message) for w in caught]
    assert shown == ["something else is deprecated", "`torch.jit.load` is deprecated. Please switch to `torch.export`."]
    assert records == ["another exporter note", "torchvision is not installed. Skipping torchvision::roi_align"]


# -- progress -----------------------------------------------------------------------------------------------------

_PROGRESS = """
import sys
if sys.argv[1] == "no-tqdm":
    sys.modules["tqdm"] = None  # tqdm not installed
from wpctrl.console import progress
bar = progress(3, "probe work", "episode", enabled=sys.argv[2] == "on")
for _ in range(3):
    bar.update(1)
bar.close()
"""


@pytest.mark.parametrize("tqdm", ["tqdm", "no-tqdm"])
def test_progress_goes_to_stderr_with_the_time_left_and_none_when_off(tqdm):
    on = _python(_PROGRESS, tqdm, "on")
    assert on.returncode == 0 and on.stdout == "", on.stderr
    assert "probe work" in on.stderr, on.stderr
    if tqdm == "no-tqdm":  # the plain line: count, elapsed and the estimate
        assert "probe work: 3/3 episodes" in on.stderr and "left" in on.stderr, on.stderr
    off = _python(_PROGRESS, tqdm, "off")
    assert off.returncode == 0 and (off.stdout, off.stderr) == ("", "")


_SESSION = """
import sys, json
import wpctrl.tasks as T
from wpctrl.__main__ import main

def mark(what):
    print("MARK " + what, flush=True)
    print("MARK " + what, file=sys.stderr, flush=True)

T.make("PushCube-v1", num_envs=1)  # a user's own script: the library, quietly
mark("replay --no-progress")
assert main(["replay", sys.argv[1], "--no-progress"]) == 0
mark("replay")
assert main(["replay", sys.argv[1]]) == 0
mark("end")
"""


def _segments(text: str) -> dict[str, str]:
    out, key = {}, "start"
    for line in text.splitlines():
        if line.startswith("MARK "):
            key = line[5:]
            continue
        out[key] = out.get(key, "") + line + "\n"
    return out


def test_a_first_session_is_quiet_and_shows_progress_on_stderr(tmp_path):
    """A fresh process: ``make`` prints nothing; ``wpctrl replay --no-progress`` prints its report and no bar;
    ``wpctrl replay`` the same report, and its bar (file name, episodes, steps) on stderr, which is no TTY here."""
    data = json.loads((DATA / "PushCube-v1__pd_ee_delta_pos.json").read_text())
    data["episodes"] = data["episodes"][:1]
    src = tmp_path / "one.json"
    src.write_text(json.dumps(data))
    done = _python(_SESSION, src, cwd=tmp_path, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    out, err = _segments(done.stdout), _segments(done.stderr)
    assert out.get("start", "") == "" and err.get("start", "") == "", (out, err)  # make: not a line
    for seg in ("replay --no-progress", "replay"):
        assert "PushCube-v1 pd_ee_delta_pos: 1 episodes replayed on Newton" in out[seg], out
        assert _noise(out[seg] + err.get(seg, "")) == [], (out[seg], err.get(seg))
    assert "one.json (1 episodes)" not in err.get("replay --no-progress", ""), err
    assert "one.json (1 episodes)" in err["replay"] and "step" in err["replay"], err


def test_evaluate_shows_episodes_done_on_both_simulators(tmp_path):
    """``wpctrl evaluate``: a bar of episodes on stderr with ``--sim maniskill`` and ``--sim newton``; with
    ``--no-progress`` none (the plain count lines on stdout instead)."""
    torch = pytest.importorskip("torch")
    pytest.importorskip("mani_skill")
    from wpctrl.train.export import known_third_party_notes_hidden

    policy = tmp_path / "policy.ts"
    with known_third_party_notes_hidden():  # torch's TorchScript deprecation notes
        torch.jit.save(torch.jit.script(torch.nn.Linear(35, 8)), str(policy))  # PushCube's observation width
    code = (
        _SESSION.split("T.make")[0]
        + """
args = [\"evaluate\", \"--policy\", sys.argv[1], \"--task\", \"PushCube-v1\", \"--episodes\", \"2\"]
mark("maniskill --no-progress")
assert main(args + ["--sim", "maniskill", "--no-progress"]) == 0
mark("maniskill")
assert main(args + ["--sim", "maniskill"]) == 0
mark("newton")
assert main(args + ["--sim", "newton", "--envs", "1"]) == 0
mark("end")
"""
    )
    done = _python(code, policy, cwd=tmp_path, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    out, err = _segments(done.stdout), _segments(done.stderr)
    assert "2 episodes: " in out["maniskill --no-progress"]
    assert "on ManiSkill" not in err.get("maniskill --no-progress", "")
    assert "PushCube-v1 on ManiSkill" in err["maniskill"] and "episode" in err["maniskill"], err
    assert "PushCube-v1 on Newton" in err["newton"] and "episode" in err["newton"], err
    assert "PushCube-v1 on newton: success" in out["newton"]
    for seg in ("maniskill", "newton"):
        assert _noise(out[seg] + err[seg]) == [] and "libvulkan" not in err[seg], err[seg]
