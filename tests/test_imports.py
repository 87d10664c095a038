"""The package's import structure: no import cycle between wpctrl's modules, and the layers import downward only.

Every module of the package is found with ``pkgutil.walk_packages`` and parsed with ``ast`` (nothing is imported, so
the test needs neither Newton nor a device). Relative imports are resolved against the importing module, and
``from pkg import name`` counts as an import of ``pkg.name`` when that is a module. Every import counts, those inside
functions too (only those under ``if TYPE_CHECKING:`` do not run): a cycle hidden in a function body is still a cycle,
so a module that needs another's name imports it one way (the config errors live in ``wpctrl.config.errors``, which
imports nothing of the package; the engine parts' base class in ``wpctrl.engine.parts.part``). The layer rule
config -> binding -> kernels -> engine -> controllers is checked on every import: a lower layer never imports a
higher one, and no layer imports the modules beside the library (robots, maniskill, distributed, demo, train, the
command line).
"""

from __future__ import annotations

import ast
import pkgutil
from pathlib import Path

import wpctrl

PACKAGE = "wpctrl"
ROOT = Path(wpctrl.__file__).resolve().parent

# The library's layers, lowest first; a module belongs to the first layer whose name is it or a parent of it.
LAYERS = ["wpctrl.config", "wpctrl.binding", "wpctrl.kernels", "wpctrl.engine", "wpctrl.controllers"]
# Beside the library: they may use it, it never uses them.
BESIDE = ["wpctrl.robots", "wpctrl.maniskill", "wpctrl.distributed", "wpctrl.demo", "wpctrl.train", "wpctrl.__main__"]
# Known exceptions to the "beside" rule, each with its reason; the test fails when one disappears, so that the list
# shrinks with the code.
KNOWN: dict[tuple[str, str], str] = {}


def modules() -> dict[str, Path]:
    """{module name: source file} for the package and every module under it."""
    out = {PACKAGE: ROOT / "__init__.py"}
    for info in pkgutil.walk_packages([str(ROOT)], prefix=PACKAGE + "."):
        base = ROOT.joinpath(*info.name.split(".")[1:])
        out[info.name] = base / "__init__.py" if info.ispkg else base.with_suffix(".py")
    return out


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _imports(body: list[ast.stmt], module_level: bool):
    """Import statements of ``body``; with ``module_level`` only those that run at import time."""
    for node in body:
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            if not module_level:
                yield from _imports(node.body, module_level)
        elif isinstance(node, ast.If) and module_level and _is_type_checking(node.test):
            yield from _imports(node.orelse, module_level)
        else:
            for field in ("body", "orelse", "finalbody", "handlers", "cases"):
                block = getattr(node, field, None)
                if isinstance(block, list):
                    yield from _imports([n for n in block if isinstance(n, ast.AST)], module_level)


def imported_modules(name: str, path: Path, known: set[str], module_level: bool) -> set[str]:
    """The package's modules that module ``name`` imports."""
    is_pkg = path.name == "__init__.py"
    found: set[str] = set()
    for node in _imports(ast.parse(path.read_text(), str(path)).body, module_level):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        else:
            if node.level:
                parts = name.split(".")
                anchor = parts if is_pkg else parts[:-1]
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            targets = []
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                targets.append(sub if sub in known else base)
        for t in targets:
            while t and t not in known:  # `import wpctrl.x.y as z` of a name that is not a module: its module
                t = t.rpartition(".")[0]
            if t and t != name and t.startswith(PACKAGE):
                found.add(t)
    return found


def graph(module_level: bool) -> dict[str, set[str]]:
    mods = modules()
    known = set(mods)
    return {name: imported_modules(name, path, known, module_level) for name, path in mods.items()}


def find_cycle(edges: dict[str, set[str]]) -> list[str] | None:
    """One cycle of the directed graph as a closed path [a, b, ..., a], or None."""
    WHITE, GREY, BLACK = 0, 1, 2
    color = dict.fromkeys(edges, WHITE)
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        color[node] = GREY
        stack.append(node)
        for nxt in sorted(edges.get(node, ())):
            if color.get(nxt, BLACK) == GREY:
                return stack[stack.index(nxt) :] + [nxt]
            if color.get(nxt) == WHITE:
                cycle = visit(nxt)
                if cycle:
                    return cycle
        stack.pop()
        color[node] = BLACK
        return None

    for node in sorted(edges):
        if color[node] == WHITE:
            cycle = visit(node)
            if cycle:
                return cycle
    return None


def _group(name: str, groups: list[str]) -> str | None:
    for g in groups:
        if name == g or name.startswith(g + "."):
            return g
    return None


def test_the_walk_finds_the_layers():
    mods = modules()
    assert len(mods) > 30, sorted(mods)
    for layer in LAYERS:
        assert layer in mods, f"{layer} not found by walk_packages"
    edges = graph(module_level=True)
    # spot checks against the source: the resolver reads relative, absolute and `from . import x` imports
    assert "wpctrl.engine.core" in edges["wpctrl.controllers.base_controller"]  # from ..engine.core import _Engine
    assert (
        "wpctrl.engine.parts.gravity" in edges["wpctrl.controllers.base_controller"]
    )  # from ..engine.parts import gravity
    assert "wpctrl.config" in edges["wpctrl"]  # from .config import (...)
    lazy = graph(module_level=False)  # function bodies too: wpctrl.__getattr__'s `from . import controllers`
    assert "wpctrl.controllers" in lazy["wpctrl"] and "wpctrl.controllers" not in edges["wpctrl"]


def test_no_import_cycle():
    """No cycle, counting the imports inside functions too (they run on first use)."""
    cycle = find_cycle(graph(module_level=False))
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_config_errors_import_nothing_of_the_package():
    """Every config module imports its errors from ``wpctrl.config.errors``, which imports none of the package."""
    edges = graph(module_level=False)
    assert edges["wpctrl.config.errors"] == set()
    users = {m for m, targets in edges.items() if "wpctrl.config.errors" in targets}
    assert {"wpctrl.config.rows", "wpctrl.config.validate", "wpctrl.config.actuator_models", "wpctrl.config"} <= users


def test_layers_import_downward_only():
    bad, seen = [], set()
    for name, targets in graph(module_level=False).items():
        layer = _group(name, LAYERS)
        if layer is None:
            continue
        rank = LAYERS.index(layer)
        for t in sorted(targets):
            t_layer = _group(t, LAYERS)
            if t_layer is not None and LAYERS.index(t_layer) > rank:
                bad.append(f"{name} ({layer}) imports {t} ({t_layer}, a higher layer)")
            elif _group(t, BESIDE) is not None:
                key = (name, _group(t, BESIDE))  # an exception covers the package beside, any module of it
                if key in KNOWN:
                    seen.add(key)
                else:
                    bad.append(f"{name} ({layer}) imports {t} (beside the library)")
    assert not bad, "layer rule config -> binding -> kernels -> engine -> controllers broken:\n" + "\n".join(bad)
    assert seen == set(KNOWN), f"no longer imported, remove from KNOWN: {sorted(set(KNOWN) - seen)}"


def test_find_cycle_names_the_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b", "d"}, "b": {"d"}, "d": set()}) is None  # a diamond is not a cycle


def test_controller_cls_resolves_on_first_use():
    """``Config.controller_cls`` is the controller class right after ``import wpctrl`` (before anything loaded the
    controllers, which import Newton), for every config class the package exports; reading it loads them."""
    import subprocess
    import sys

    code = """
import sys, dataclasses, wpctrl
assert "wpctrl.controllers" not in sys.modules, "import wpctrl loaded the controllers"
configs = [getattr(wpctrl, n) for n in wpctrl.__all__ if n.endswith("ControllerConfig") and n != "ControllerConfig"]
assert len(configs) >= 12, configs
for c in configs:
    cls = c.controller_cls
    assert isinstance(cls, type) and issubclass(cls, wpctrl.BaseController), (c, cls)
    assert cls.__name__ == c.__name__.removesuffix("Config"), (c, cls)
assert wpctrl.ControllerConfig.controller_cls is None
print("ok", len(configs))
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=ROOT.parent)
    assert out.returncode == 0 and out.stdout.startswith("ok"), out.stdout + out.stderr


SHARED_STEMS = {
    # a module name used in several packages, and the one concept it names in all of them
    "ee": "end-effector control (config, kernels, engine part, controller classes)",
    "actuator_models": "actuator models: DC motor, position table, networks (config, kernels, engine part)",
    "coupled_drive": "the coupled (PhysX) drive (its solve kernel, its engine part)",
    "drive_properties": "per-env drive properties (the engine part, the controllers' API)",
    "joint": "joint-space controllers (configs, controller classes)",
    "mobile_base": "mobile-base controllers (configs, controller classes)",
    "cli": "a command's command line (the demo's, the training's)",
}


def test_a_module_name_names_one_concept():
    """Two modules share a file name only when they are about the same thing (listed in SHARED_STEMS, with it): a new
    clash (``drive`` for drive properties and for the coupled drive, ``base`` for a mobile base and a base class,
    ``options`` for controller options and the demo's command line) fails here until it is renamed or declared."""
    stems: dict[str, list[str]] = {}
    for name, path in modules().items():
        if path.name != "__init__.py":
            stems.setdefault(path.stem, []).append(name)
    shared = {s: sorted(m) for s, m in stems.items() if len(m) > 1}
    undeclared = {s: m for s, m in shared.items() if s not in SHARED_STEMS}
    assert not undeclared, f"module names shared across packages without one concept declared: {undeclared}"
    assert set(SHARED_STEMS) <= set(shared), f"no longer shared, remove: {sorted(set(SHARED_STEMS) - set(shared))}"
