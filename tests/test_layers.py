"""The layers with the controller families in them: every import runs down config -> binding -> kernels -> engine ->
controllers, the modules of a family's own package (``wpctrl.impedance``) counted in the layer they belong to, and a
control mode is built from the families' declarations alone.

The import graph is parsed, not imported (:mod:`test_imports`), so a module counts as imported wherever its import
statement stands, in a function body too.
"""

from __future__ import annotations

import subprocess
import sys

import pytest
import test_imports
from conftest import build_panda
from harness import ARM, FINGERS
from test_imports import LAYERS, graph

import wpctrl
from wpctrl.config.family import ControllerConfig, Family

# The modules of a family package, by the layer each belongs to (a module not listed here belongs to no layer).
FAMILY_MODULES = {
    "wpctrl.impedance": "wpctrl.config",  # exports the configs only
    "wpctrl.impedance.config": "wpctrl.config",
    "wpctrl.impedance.spec": "wpctrl.config",
    "wpctrl.impedance.warp_kernels": "wpctrl.kernels",
    "wpctrl.impedance.engine_part": "wpctrl.engine",
    "wpctrl.impedance.controllers": "wpctrl.controllers",
}
BESIDE = ("wpctrl.robots", "wpctrl.maniskill", "wpctrl.tasks", "wpctrl.train", "wpctrl.demo", "wpctrl.distributed")


def _layer(module: str) -> str | None:
    if module in FAMILY_MODULES:
        return FAMILY_MODULES[module]
    for layer in LAYERS:
        if module == layer or module.startswith(layer + "."):
            return layer
    return None


def test_every_family_module_is_placed():
    """A new module in a family package is given its layer here, so that its imports are checked."""
    found = {m for m in test_imports.modules() if m == "wpctrl.impedance" or m.startswith("wpctrl.impedance.")}
    assert found == set(FAMILY_MODULES), f"place these in FAMILY_MODULES: {sorted(found - set(FAMILY_MODULES))}"


def test_imports_run_down_the_layers_with_the_families_in_them():
    bad = []
    for name, targets in graph(module_level=False).items():
        layer = _layer(name)
        if layer is None:
            continue
        for t in sorted(targets):
            t_layer = _layer(t)
            if t_layer is not None and LAYERS.index(t_layer) > LAYERS.index(layer):
                bad.append(f"{name} ({layer}) imports {t} ({t_layer})")
    assert not bad, "imports against the layers:\n" + "\n".join(bad)


@pytest.mark.parametrize("package", ["wpctrl.config", "wpctrl.engine"])
def test_config_and_engine_import_nothing_beside_the_library(package):
    """Neither the configs nor the engine imports the robots, ManiSkill, tasks, training or the demo."""
    bad = [
        f"{name} imports {t}"
        for name, targets in graph(module_level=False).items()
        if name == package or name.startswith(package + ".")
        for t in targets
        if t.startswith(BESIDE)
    ]
    assert not bad, "\n".join(bad)


def test_the_engine_reads_no_robot_description():
    """The engine takes its frames from Newton's model and, for links the model lacks, from the descriptions the
    config layer read (:mod:`wpctrl.config.robot_description`): no module of it parses a URDF or names a robot."""
    root = test_imports.ROOT / "engine"
    for path in sorted(root.rglob("*.py")):
        text = path.read_text()
        assert "xml.etree" not in text and "ElementTree" not in text, f"{path} parses XML"
        assert "panda" not in text.lower(), f"{path} names a robot"


def test_importing_the_configs_loads_no_engine():
    """``wpctrl.config`` (and the family packages' configs it exports) loads neither the engine, the kernels, the
    controllers nor Warp / Newton."""
    code = """
import sys
import wpctrl.config
loaded = sorted(m for m in sys.modules if m.split(".")[0] in ("warp", "newton") or m.startswith((
    "wpctrl.engine", "wpctrl.kernels", "wpctrl.controllers", "wpctrl.impedance.warp_kernels",
    "wpctrl.impedance.engine_part", "wpctrl.impedance.controllers")))
print("loaded:", loaded)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "loaded: []" in out.stdout, out.stdout


def _config_classes() -> list[type]:
    return [getattr(wpctrl, n) for n in wpctrl.__all__ if n.endswith("ControllerConfig") and n != "ControllerConfig"]


def test_every_config_declares_its_family():
    """Each exported config class declares a family; a family with a part names a module that registers a part with
    the engine when it is imported."""
    from wpctrl.engine.parts import PARTS

    classes = _config_classes()
    assert len(classes) >= 12, classes
    assert ControllerConfig.family is None
    for cls in classes:
        family = cls.family
        assert isinstance(family, Family), cls
        if family.part is not None:
            family.load_part()
            assert any(p.__module__ == family.part for p in PARTS.values()), (cls, family.part)


def test_a_new_family_is_built_from_its_declaration():
    """A config class outside wpctrl, with its own family and controller class, builds through ``build_controller``
    and mixes with wpctrl's configs in a mode dict: no dispatch to edit."""
    from dataclasses import dataclass

    from wpctrl.config.family import ControllerClass
    from wpctrl.config.joint_rows import effort_rows

    @dataclass
    class HoldStillConfig(ControllerConfig):  # effort rows with a zero action range: a family of one row function
        controller_cls = ControllerClass("wpctrl.controllers.joint", "JointEffortController")
        family = Family(lambda config, qlimits: effort_rows(_as_effort(config), qlimits))

    def _as_effort(c):
        return wpctrl.JointEffortControllerConfig(c.joint_names, 0.0, 0.0, normalize_action=False)

    ctrl = wpctrl.build_controller(
        {"arm": HoldStillConfig(ARM), "gripper": wpctrl.PDJointPosControllerConfig(FINGERS, 0.0, 0.04, 100, 10)},
        build_panda(2),
    )
    assert type(ctrl["arm"]) is wpctrl.JointEffortController
    assert ctrl.action_mapping == {"arm": (0, len(ARM)), "gripper": (len(ARM), len(ARM) + len(FINGERS))}
