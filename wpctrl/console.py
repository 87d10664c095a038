"""What wpctrl's command lines and :func:`wpctrl.tasks.make` print, and what they check before the heavy imports.

- **Quiet by default**: Warp prints a start-up banner, a ``Module ... load on device ...`` line for every kernel module
  it loads (60 and more for a task env), and on a machine without an NVIDIA driver the native line "Warp CUDA warning:
  Could not find or load the NVIDIA CUDA driver". None of it tells a user what to do. The commands
  (:func:`cli_output`) and ``make`` (:func:`quiet_warp`, for the duration of the call only) raise Warp's own switch,
  ``warp.config.log_level``, to ``warp.LOG_WARNING`` and initialise Warp without that one native line; Warp's
  warnings and errors still show. ``--verbose`` (``make(verbose=True)``) leaves Warp as loud as it is by default.
- **Cheap device check** (:func:`device_refusal`): a CUDA device asked for on a machine with no sign of an NVIDIA
  driver is refused without importing Warp; :func:`wpctrl.devices.check_device` stays the authoritative check after.
- **Progress** (:func:`progress`): a tqdm bar on stderr with the time left, or, without tqdm, a plain line every few
  seconds; and (:func:`compile_notice`) one line before Warp compiles kernels that are not in its cache yet.

Importing this module imports nothing heavy (no Warp, torch or Newton).
"""

from __future__ import annotations

import argparse
import contextlib
import glob
import os
import shutil
import sys
import tempfile
import time

__all__ = [
    "COMPILE_ESTIMATE",
    "add_output_options",
    "cli_output",
    "compile_notice",
    "cuda_absent",
    "device_refusal",
    "progress",
    "quiet_warp",
]

VERBOSE = False
"""Set by the command line's ``--verbose`` (:func:`cli_output`): :func:`wpctrl.tasks.make` is then verbose too."""

CUDA_DRIVER_NOTICE = "Warp CUDA warning: Could not find or load the NVIDIA CUDA driver"
"""The start of the native line Warp prints at initialisation on a machine without an NVIDIA driver."""

COMPILE_ESTIMATE = "about 2-3 min on a 2-core CPU, less on a GPU"
"""How long a task env's first build compiles Warp kernels (Newton's, MuJoCo-Warp's and wpctrl's)."""


def add_output_options(parser: argparse.ArgumentParser, progress: bool = False) -> None:
    """``--verbose`` (and, with ``progress``, ``--progress`` / ``--no-progress``) on a command's parser."""
    parser.add_argument(
        "--verbose",
        action="store_true",
        help="show Warp's start-up banner, its CUDA-driver warning and a line per kernel module it loads (default: "
        "quiet)",
    )
    if progress:
        parser.add_argument(
            "--progress",
            action=argparse.BooleanOptionalAction,
            default=True,
            help="progress bar with the time left, on stderr (default on; --no-progress for logs)",
        )


# -- Warp, quietly ------------------------------------------------------------------------------------------------


def _warp_initialised(wp) -> bool:
    context = getattr(getattr(wp, "_src", None), "context", None)
    return getattr(context, "runtime", None) is not None


def _init_warp_without_driver_notice(wp) -> None:
    """``wp.init()``, with the native CUDA-driver line (written by Warp's C++ core straight to file descriptor 2)
    dropped and anything else it writes there passed on."""
    if _warp_initialised(wp):
        return
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no usable stderr descriptor: nothing to filter
        wp.init()
        return
    with tempfile.TemporaryFile() as captured:
        try:
            os.dup2(captured.fileno(), 2)
            try:
                wp.init()
            finally:
                os.dup2(saved, 2)
                os.close(saved)
        finally:
            captured.seek(0)
            text = captured.read().decode(errors="replace")
    kept = [line for line in text.splitlines(keepends=True) if not line.startswith(CUDA_DRIVER_NOTICE)]
    if kept:
        sys.stderr.write("".join(kept))
        sys.stderr.flush()


@contextlib.contextmanager
def quiet_warp(verbose: bool = False):
    """Within the block, Warp prints warnings and errors only: ``warp.config.log_level`` raised to
    ``warp.LOG_WARNING`` (put back as it was on exit) and Warp initialised, if it is not yet, without the native
    CUDA-driver line. ``verbose`` (or the command line's ``--verbose``): ``log_level`` at most ``warp.LOG_INFO``
    within the block (Warp's default), everything shown."""
    import warp as wp

    before = wp.config.log_level
    loud = verbose or VERBOSE
    wp.config.log_level = min(before, wp.LOG_INFO) if loud else max(before, wp.LOG_WARNING)
    try:
        if not loud:
            _init_warp_without_driver_notice(wp)
        yield
    finally:
        wp.config.log_level = before


def cli_output(verbose: bool) -> None:
    """A command's Warp output for the rest of the process, once its arguments are checked: quiet (log level
    ``warp.LOG_WARNING``, Warp initialised without the CUDA-driver line), or, with ``--verbose``, Warp's defaults (and
    :func:`wpctrl.tasks.make` verbose too)."""
    global VERBOSE
    VERBOSE = bool(verbose)
    import warp as wp

    if verbose:
        wp.config.log_level = min(wp.config.log_level, wp.LOG_INFO)
        return
    wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)
    _init_warp_without_driver_notice(wp)


# -- devices, without Warp -------------------------------------------------------------------------------------


def cuda_absent() -> bool:
    """True when this machine shows no sign of an NVIDIA driver (Linux: no ``/dev/nvidia*`` or WSL's ``/dev/dxg``, no
    ``nvidia-smi`` on the PATH, no ``libcuda`` the loader knows; macOS: always), so that no CUDA device can exist.
    False when there may be one: Warp decides then."""
    if sys.platform == "darwin":
        return True
    if not sys.platform.startswith("linux"):
        return False
    if glob.glob("/dev/nvidia[0-9]*") or os.path.exists("/dev/dxg") or shutil.which("nvidia-smi"):
        return False
    import ctypes.util

    return ctypes.util.find_library("cuda") is None


def device_refusal(device: str | None, what: str = "--device") -> str | None:
    """The refusal of a device name that cannot exist on this machine, known without importing Warp (a non-CPU
    device where :func:`cuda_absent`), worded as :func:`wpctrl.devices.check_device`'s; None when Warp must decide."""
    if device is None or device == "cpu" or not cuda_absent():
        return None
    from .devices import not_a_device

    return not_a_device(what, device, True, ["cpu"])


# -- progress ----------------------------------------------------------------------------------------------------


class _Lines:
    """tqdm's stand-in without tqdm: a line on stderr every ``every`` seconds and at the end, with the time left."""

    def __init__(self, total: int, desc: str, unit: str, every: float = 10.0):
        self.total, self.desc, self.unit, self.every = total, desc, unit, every
        self.n = 0
        self.start = self.last = time.perf_counter()

    def update(self, n: int = 1) -> None:
        self.n += n
        now = time.perf_counter()
        if now - self.last >= self.every or self.n >= self.total:
            self.last = now
            done = max(self.n, 1)
            left = (now - self.start) / done * max(self.total - self.n, 0)
            print(f"{self.desc}: {self.n}/{self.total} {self.unit}s, {now - self.start:.0f} s, about {left:.0f} s "
                  "left", file=sys.stderr, flush=True)  # fmt: skip

    def close(self) -> None:
        pass


def progress(total: int, desc: str, unit: str = "step", enabled: bool = True):
    """A progress display for ``total`` ``unit``\\ s on stderr: a tqdm bar (elapsed and estimated time left) where
    tqdm is installed, else a plain line every 10 s; a do-nothing one when not ``enabled`` (``--no-progress``).
    Has ``update(n)`` and ``close()``."""
    if not enabled:
        return _Off()
    try:
        from tqdm import tqdm
    except ImportError:
        return _Lines(total, desc, unit)
    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, leave=False, dynamic_ncols=True, disable=False)


class _Off:
    def update(self, n: int = 1) -> None:
        pass

    def close(self) -> None:
        pass


@contextlib.contextmanager
def compile_notice(what: str, say=None):
    """Around a task env's first build: one line, on stderr, just before Warp compiles a kernel module its cache
    lacks (none when every module loads from the cache), then how long the build took."""
    from .demo.notice import CompileNotice

    def stderr(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    say = say or stderr
    t = time.perf_counter()
    with CompileNotice(say, what, COMPILE_ESTIMATE) as notice:
        yield notice
    if notice.compiled:
        say(f"  built in {time.perf_counter() - t:.0f} s ({notice.summary()})")
