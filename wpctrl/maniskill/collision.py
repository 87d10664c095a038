"""What ManiSkill's URDF loader sets on a robot's collision shapes, applied to a Newton builder where Newton has the
same knob. Host only, no ManiSkill import.

- ``urdf_config`` materials (a global ``material`` and per-link ``link: {name: {material: ...}}`` naming one of
  ``_materials``): Newton's shapes carry one Coulomb coefficient, ``shape_material_mu``, which gets PhysX's
  ``static_friction`` (the coefficient that decides whether a grasp holds); ``restitution`` maps one to one.
  ``dynamic_friction``, ``patch_radius``, ``min_patch_radius`` (PhysX's torsional patch) and ``density`` (used by
  SAPIEN only for links without an inertial) have no Newton counterpart and are left out.
- MJCF geoms as ManiSkill's MJCF loader makes them: ``condim="1"`` is frictionless (Newton's importer keeps the
  geom's ``friction``), ``condim="3"`` takes the sliding friction (as Newton's importer does).
- The SRDF beside the URDF (``<disable_collisions reason="Default">``, as SAPIEN reads it): every shape pair of the
  two links is filtered (``add_shape_collision_filter_pair``).
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET

import newton


def _link_shapes(builder: newton.ModelBuilder) -> dict[str, list[int]]:
    """Shapes by the link (body) name they are attached to (the label's last ``/`` part)."""
    names = [label.rsplit("/", 1)[-1] for label in builder.body_label]
    out: dict[str, list[int]] = {}
    for s, b in enumerate(builder.shape_body):
        if b >= 0:
            out.setdefault(names[b], []).append(s)
    return out


def apply_materials(builder: newton.ModelBuilder, urdf_config) -> dict[str, tuple[float, float]]:
    """Set ``shape_material_mu`` / ``shape_material_restitution`` from a ManiSkill ``urdf_config`` dict; returns
    ``{link: (mu, restitution)}`` for the links it set (every link when the config has a global ``material``)."""
    if not isinstance(urdf_config, dict) or not urdf_config:
        return {}
    shapes = _link_shapes(builder)
    chosen: dict[str, dict] = {}
    if "material" in urdf_config:
        for link in shapes:
            chosen[link] = urdf_config["material"]
    materials = urdf_config.get("_materials", {})
    for link, cfg in (urdf_config.get("link") or {}).items():
        if "material" not in cfg:
            continue
        mat = cfg["material"]
        if isinstance(mat, str):
            if mat not in materials:
                raise ValueError(f"urdf_config: link {link!r} names material {mat!r}, not in _materials {materials}")
            mat = materials[mat]
        chosen[link] = mat
    applied = {}
    for link, mat in chosen.items():
        mu = float(_get(mat, "static_friction"))
        rest = float(_get(mat, "restitution"))
        for s in shapes.get(link, []):
            builder.shape_material_mu[s] = mu
            builder.shape_material_restitution[s] = rest
        if link in shapes:
            applied[link] = (mu, rest)
    return applied


def mjcf_frictionless_geoms(mjcf_path: str) -> set[str]:
    """Names of the MJCF file's geoms whose resolved ``condim`` is 1 (default classes and ``childclass`` applied)."""
    root = ET.parse(mjcf_path).getroot()
    classes: dict[str, dict[str, str]] = {}

    def walk_defaults(node, inherited: dict[str, str], name: str) -> None:
        geom = dict(inherited)
        for g in node.findall("geom"):
            geom.update(g.attrib)
        classes[name] = geom
        for child in node.findall("default"):
            walk_defaults(child, geom, child.get("class", name))

    for top in root.findall("default"):
        walk_defaults(top, {}, top.get("class", "main"))
    out: set[str] = set()

    def walk_bodies(node, childclass: str) -> None:
        for g in node.findall("geom"):
            attrs = classes.get(g.get("class", childclass), {})
            if g.get("condim", attrs.get("condim", "3")).strip() == "1" and g.get("name"):
                out.add(g.get("name"))
        for body in node.findall("body"):
            walk_bodies(body, body.get("childclass", childclass))

    for world in root.findall("worldbody"):
        walk_bodies(world, "main")
    return out


def apply_mjcf_friction(builder: newton.ModelBuilder, mjcf_path: str) -> int:
    """Zero ``shape_material_mu`` of the geoms ManiSkill loads frictionless (``condim="1"``); returns their count."""
    names = mjcf_frictionless_geoms(mjcf_path)
    n = 0
    for s, label in enumerate(builder.shape_label):
        if label.rsplit("/", 1)[-1] in names:
            builder.shape_material_mu[s] = 0.0
            n += 1
    return n


def _get(mat, key):
    return mat[key] if isinstance(mat, dict) else getattr(mat, key)


def srdf_pairs(urdf_path: str) -> list[tuple[str, str]]:
    """The link pairs the SRDF beside ``urdf_path`` excludes from collision (as SAPIEN reads it), or []."""
    srdf = os.path.splitext(urdf_path)[0] + ".srdf"
    if not os.path.isfile(srdf):
        return []
    root = ET.parse(srdf).getroot()
    return [
        (e.get("link1"), e.get("link2"))
        for e in root.findall("disable_collisions")
        if (e.get("reason") or "").lower() == "default"
    ]


def filter_srdf_pairs(builder: newton.ModelBuilder, urdf_path: str) -> int:
    """Filter every shape pair of the SRDF's excluded link pairs; returns the number of shape pairs added."""
    shapes = _link_shapes(builder)
    added = 0
    for a, b in srdf_pairs(urdf_path):
        for sa in shapes.get(a, []):
            for sb in shapes.get(b, []):
                builder.add_shape_collision_filter_pair(sa, sb)
                added += 1
    return added
