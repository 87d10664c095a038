"""The compile notice: one line just before Warp compiles a kernel module, none when every module loads from Warp's
kernel cache.

Warp compiles a module on its first use and keeps the binary in its kernel cache (``wp.config.kernel_cache_dir``);
later runs load it in milliseconds. A cold first run of the demo spends a minute or two compiling with nothing else
to show, so it says so when, and only when, that happens. The hook wraps Warp's per-module compile step for the
duration of a ``with`` block; should a future Warp rename that step, the notice is printed up front instead.
"""

from __future__ import annotations

import os
from collections.abc import Callable


class CompileNotice:
    """``with CompileNotice(say, what):`` calls ``say(notice)`` once, before the first module that Warp has to
    compile (its binary is not in the kernel cache), and counts the modules compiled and loaded from the cache."""

    def __init__(self, say: Callable[[str], None], what: str, estimate: str = ""):
        self.say = say
        self.what = what
        self.estimate = estimate
        self.compiled: list[str] = []
        self.cached = 0
        self._original = None

    @property
    def message(self) -> str:
        estimate = f", {self.estimate}" if self.estimate else ""
        return f"compiling {self.what} (first run only{estimate}; later runs load them from Warp's kernel cache) ..."

    def __enter__(self) -> CompileNotice:
        import warp as wp

        module_cls = getattr(getattr(wp, "_src", None), "context", None)
        module_cls = getattr(module_cls, "Module", None)
        original = getattr(module_cls, "_compile", None)
        if original is None:  # an unknown Warp: say it up front rather than not at all
            self.say(self.message)
            return self
        notice = self

        def _compile(module, device=None, output_dir=None, output_name=None, *args, **kwargs):
            cold = not (output_dir and output_name and os.path.exists(os.path.join(output_dir, output_name)))
            if cold and not notice.compiled:
                notice.say(notice.message)
            if cold:
                notice.compiled.append(module.name)
            else:
                notice.cached += 1
            return original(module, device, output_dir, output_name, *args, **kwargs)

        self._original = (module_cls, original)
        module_cls._compile = _compile
        return self

    def __exit__(self, *exc) -> None:
        if self._original is not None:
            module_cls, original = self._original
            module_cls._compile = original
            self._original = None

    def summary(self) -> str:
        """``N modules compiled, M loaded from the cache`` (after the block)."""
        return f"{len(self.compiled)} kernel modules compiled, {self.cached} loaded from the cache"
