"""Command line: ``python -m wpctrl demo [options]`` (also the ``wpctrl`` console script; under
``torchrun --nproc-per-node=N -m wpctrl demo ...`` one process per rank)."""

from __future__ import annotations

import sys


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print("usage: wpctrl demo [options]   (wpctrl demo --help for the options)")
        return 0 if argv else 2
    if argv[0] != "demo":
        print(f"wpctrl: error: unknown command {argv[0]!r}; expected 'demo'", file=sys.stderr)
        return 2
    from .demo import main as demo_main  # light: warp (~1-3 s to import) loads after the demo's first line

    try:
        return demo_main(argv[1:])
    except SystemExit as e:  # argparse and the demo's checks exit 2 with a one-line message
        return e.code if isinstance(e.code, int) else 1


if __name__ == "__main__":
    raise SystemExit(main())
