"""What each optional feature needs installed, and the one install line every error about a missing package prints
(the same in a source checkout and for an installed wheel). Imports nothing heavy: the command lines use it before
warp or torch load.

torch is never pulled in silently by a hint: the line says to install the torch build first (a CPU or a CUDA build,
as PyTorch's own install page picks it), since pip otherwise takes PyPI's default build of torch, which on Linux is a
CUDA build of several GB.
"""

from __future__ import annotations

__all__ = ["EXTRAS", "TORCH_BUILDS", "TORCH_HINT", "install_hint", "missing"]

EXTRAS = {
    "sim": "MuJoCo-Warp, Newton's MuJoCo solver",
    "demo": "the demo (MuJoCo-Warp, tqdm, matplotlib)",
    "maniskill": "the real ManiSkill 3.0.1 and its robots' assets",
    "tasks": "ManiSkill's tasks on Newton (MuJoCo-Warp, Newton's mesh importer, ManiSkill's Panda asset, torch)",
    "train": "PPO training, export and evaluation (the tasks, rsl-rl-lib, torch, matplotlib)",
    "dev": "the tests and the docs (everything above)",
}
"""The extras of ``pyproject.toml`` and what each brings."""

TORCH_BUILDS = (
    "a CPU build: pip install torch with the CPU index URL that PyTorch's install page, pytorch.org/get-started, "
    "gives; a CUDA build: pip install torch"
)
"""How to pick torch's build, as PyTorch's own install page does."""
TORCH_HINT = f"install the torch build you want first ({TORCH_BUILDS}), then"


def install_hint(extra: str, torch: bool = False) -> str:
    """The install line for ``extra`` (one, or several joined by commas): ``pip install -e ".[extra]"`` in a source
    checkout, ``pip install "wpctrl[extra]"`` otherwise; with ``torch``, preceded by how to pick the torch build."""
    unknown = [e for e in extra.split(",") if e not in EXTRAS]
    if unknown:
        raise ValueError(f"extra: expected one of {sorted(EXTRAS)}, got {extra!r}")
    line = f'pip install -e ".[{extra}]" in a source checkout, or pip install "wpctrl[{extra}]"'
    return f"{TORCH_HINT} {line}" if torch else line


def missing(what: str, extra: str, error: BaseException, torch: bool = False) -> str:
    """A one-line message: ``what`` needs the ``extra`` extra, how to install it, and the import error itself."""
    return f"{what} needs the {extra} extra: {install_hint(extra, torch)} ({error})"
