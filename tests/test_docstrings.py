"""Every module path, symbol and docs link named in a docstring of the package exists.

The codebase is navigated by its docstrings, so a pointer in one must lead somewhere. Every docstring of every module
of ``wpctrl`` (the module's, its classes', functions' and methods', and the string under an assignment) is read with
``ast``, and what it names is resolved:

- Sphinx roles (``:mod:``, ``:class:``, ``:func:``, ``:meth:``, ``:attr:``, ``:data:``, ``:exc:``, ``:obj:``): a
  target ``.x.y`` is relative to the module's package, a bare ``Name`` / ``Name.attr`` to the module (or the class
  the docstring belongs to), ``wpctrl.a.b`` / ``newton.X`` absolute; each resolves by import and attribute lookup;
- dotted names ``wpctrl.a.b`` anywhere in the text: the same;
- repository paths (``wpctrl/..``, ``tests/..``, ``bench/..``, ``docs/..``, ``tools/..`` and ``README.md``) and
  package-relative paths (``kernels/pd.py``, ``engine/parts/ee.py``): the file exists; a docs page followed by a quoted
  section title (``docs/actuation.md, "The coupled drive"``) has a heading that starts with that title;
- Markdown links ``[text](target)`` in the docs pages and the README: the target file exists.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import re
from pathlib import Path

import pytest
from test_imports import ROOT as PKG_ROOT
from test_imports import modules

REPO = PKG_ROOT.parent

ROLE = re.compile(r":(?:mod|class|func|meth|attr|data|exc|obj):`~?([^`<>]+?)`")
DOTTED = re.compile(r"(?<![\w.])wpctrl(?:\.[A-Za-z_]\w*)+")
REPO_PATH = re.compile(r"(?<![\w./-])((?:wpctrl|tests|bench|docs|tools)/[\w./-]*\w|README\.md)")
PKG_PATH = re.compile(r"(?<![\w./-])((?:kernels|engine|config|controllers|parts)/[\w/]+\.py)")
SECTION = re.compile(r"(docs/[\w-]+\.md),\s*\"([^\"]+)\"")
MD_LINK = re.compile(r"\]\(([^)\s#]+)(?:#[^)]*)?\)")


def _docstrings(tree: ast.Module):
    """(docstring, enclosing class name or None) of the module, its classes and functions, and attribute strings."""
    out = []

    def visit(body, cls):
        prev = None
        for node in body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                doc = ast.get_docstring(node, clean=False)
                inner = node.name if isinstance(node, ast.ClassDef) else cls
                if doc:
                    out.append((doc, inner))
                visit(node.body, inner)
            elif (
                isinstance(node, ast.Expr)
                and isinstance(node.value, ast.Constant)
                and isinstance(node.value.value, str)
                and isinstance(prev, (ast.Assign, ast.AnnAssign))
            ):
                out.append((node.value.value, cls))
            prev = node

    doc = ast.get_docstring(tree, clean=False)
    if doc:
        out.append((doc, None))
    visit(tree.body, None)
    return out


def _has(obj, attr: str) -> bool:
    """``obj.attr`` exists: an attribute, a dataclass / annotated field, or (for a class) ``self.attr = ...`` in it."""
    if hasattr(obj, attr) or attr in getattr(obj, "__annotations__", {}):
        return True
    if isinstance(obj, type):
        for klass in obj.__mro__[:-1]:
            try:
                if re.search(rf"self\.{attr}\b\s*(:[^=]*)?=", inspect.getsource(klass)):
                    return True
            except (OSError, TypeError):
                continue
    return False


def _lookup(obj, dotted: str) -> bool:
    for attr in dotted.split("."):
        if not _has(obj, attr):
            return False
        obj = getattr(obj, attr, None)
    return True


def _resolve_absolute(target: str) -> bool:
    parts = target.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        return _lookup(obj, ".".join(parts[i:])) if parts[i:] else True
    return False


def _package(module: str) -> str:
    is_pkg = (PKG_ROOT.joinpath(*module.split(".")[1:]) / "__init__.py").exists()
    return module if is_pkg else module.rpartition(".")[0]


def _resolve(target: str, module: str, cls: str | None) -> bool:
    """A Sphinx role's target, seen from ``module`` (and the class ``cls`` whose docstring names it)."""
    target = target.strip().removesuffix("()")
    if target.startswith("."):
        return _resolve_absolute(_package(module) + target)
    mod = importlib.import_module(module)
    first = target.partition(".")[0]
    scopes = ([getattr(mod, cls)] if cls and hasattr(mod, cls) else []) + [mod]
    for scope in scopes:
        if _has(scope, first):
            return _lookup(scope, target)
    return _resolve_absolute(target)


def _headings(page: Path) -> list[str]:
    return [line.lstrip("#").strip() for line in page.read_text().splitlines() if line.startswith("#")]


def _pointers():
    """(module, what, ok) for every pointer in the package's docstrings."""
    for name, path in sorted(modules().items()):
        tree = ast.parse(path.read_text(), str(path))
        for doc, cls in _docstrings(tree):
            for t in ROLE.findall(doc):
                yield name, f"role {t!r}", _resolve(t, name, cls)
            for t in DOTTED.findall(doc):
                yield name, f"name {t!r}", _resolve_absolute(t)
            for t in REPO_PATH.findall(doc):
                yield name, f"path {t!r}", (REPO / t.rstrip(".")).exists()
            for t in PKG_PATH.findall(doc):
                ok = (PKG_ROOT / t).exists() or (PKG_ROOT / "engine" / t).exists()
                yield name, f"path {t!r}", ok
            for page, title in SECTION.findall(doc):
                ok = (REPO / page).exists() and any(h.startswith(title) for h in _headings(REPO / page))
                yield name, f"section {page}, {title!r}", ok


def test_every_docstring_pointer_exists():
    bad = [f"{m}: {what}" for m, what, ok in _pointers() if not ok]
    assert not bad, "docstrings name what does not exist:\n" + "\n".join(bad)


def test_the_resolver_finds_and_rejects():
    """The checks can fail: a real pointer of each kind passes, a stale one does not."""
    assert _resolve(".pd_step", "wpctrl.kernels.pd", None)
    assert not _resolve(".drive", "wpctrl.kernels.pd", None)
    assert _resolve("_Engine", "wpctrl.engine.core", None)
    assert _resolve("Part.kernel_args", "wpctrl.engine.parts", None)
    assert not _resolve("Part.no_such_hook", "wpctrl.engine.parts", None)
    assert _resolve_absolute("wpctrl.engine.parts.coupled_drive.CoupledDrive")
    assert not _resolve_absolute("wpctrl.engine.parts.response.CoupledDrive")
    assert REPO_PATH.findall("see bench/README.md and ``kernels/pd.py``") == ["bench/README.md"]
    assert PKG_PATH.findall("see bench/README.md and ``kernels/pd.py``") == ["kernels/pd.py"]
    pointers = list(_pointers())
    assert len(pointers) > 100, len(pointers)


@pytest.mark.parametrize("page", sorted([*REPO.glob("docs/*.md"), REPO / "README.md"]), ids=lambda p: p.name)
def test_docs_links_exist(page: Path):
    bad = []
    for target in MD_LINK.findall(page.read_text()):
        if "://" in target or target.startswith("mailto:"):
            continue
        if not (page.parent / target).exists():
            bad.append(target)
    assert not bad, f"{page.name} links to missing files: {bad}"
