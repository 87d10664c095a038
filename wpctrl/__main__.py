"""Command line: ``python -m wpctrl demo [options]`` (also the ``wpctrl`` console script)."""

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
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING
    from .demo import main as demo_main

    return demo_main(argv[1:])


if __name__ == "__main__":
    raise SystemExit(main())
