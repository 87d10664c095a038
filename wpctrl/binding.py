"""Binding: resolve controller joint names in a Newton model to per-env index tables.

Reads the model's joint tables once, on the host, at construction. A joint name matches a Newton joint label
exactly or by the label's last ``/``-separated part (``add_urdf`` labels joints ``panda/panda_joint1``).

Multi-axis joints: Newton's MJCF importer merges the hinges (or slides) that share a body into one D6 joint labelled by
their names joined with ``_`` in the file's order (``abdomen_z_abdomen_y``), one coordinate and one DOF per axis. A
controller names such an axis by its MJCF name; it binds to that axis's coordinate and DOF. Ball and free joints are
not controllable.
"""

from __future__ import annotations

import difflib
from collections.abc import Sequence
from dataclasses import dataclass

import newton
import numpy as np

from .config import ConfigError

_ONE_DOF = {int(newton.JointType.REVOLUTE): "revolute", int(newton.JointType.PRISMATIC): "prismatic"}


_D6 = int(newton.JointType.D6)


@dataclass
class JointBinding:
    """Where each controlled joint lives in every env of a Newton model.

    Row r of env e has its coordinate at ``q_base[e] + q_off[r]`` in ``joint_q``/``joint_target_q`` and its DOF at
    ``qd_base[e] + qd_off[r]`` in ``joint_qd``/``joint_target_qd``/``joint_f`` and the per-DOF model arrays.
    """

    joint_names: list[str]
    num_envs: int
    joint_index: np.ndarray  # (num_envs, rows) int32, Newton joint ids
    coord_index: np.ndarray  # (num_envs, rows) int32
    dof_index: np.ndarray  # (num_envs, rows) int32
    q_base: np.ndarray  # (num_envs,) int32
    qd_base: np.ndarray  # (num_envs,) int32
    q_off: np.ndarray  # (rows,) int32
    qd_off: np.ndarray  # (rows,) int32
    qlimits: np.ndarray  # (rows, 2) float32 [rad or m], env 0's limits (as ManiSkill's get_qlimits()[0])
    axis: np.ndarray | None = None  # (rows,) int32: the row's axis in its joint (0: 1-DOF; k: a D6 joint's k-th)


def _short(label: str) -> str:
    return label.rsplit("/", 1)[-1]


def _axis_in_label(name: str, label: str, n_axes: int) -> int | None:
    """The axis index k of ``name`` in a merged label ``a0_a1_..`` of ``n_axes`` names, or None: ``name`` must be
    one whole part, with ``k`` names before it and ``n_axes - 1 - k`` after; None also when that is ambiguous."""
    toks, want = label.split("_"), name.split("_")
    found: set[int] = set()
    for s in range(len(toks) - len(want) + 1):
        if toks[s : s + len(want)] != want:
            continue
        before, after = s, len(toks) - s - len(want)
        for k in range(n_axes):
            rest = n_axes - 1 - k
            if (k == 0) == (before == 0) and k <= before and (rest == 0) == (after == 0) and rest <= after:
                found.add(k)
    return found.pop() if len(found) == 1 else None


def _resolve(names, labels, joints, world: int, jtype, qd_start) -> tuple[np.ndarray, np.ndarray]:
    """Joint ids and axes of ``names`` among ``joints`` (those of one world), by exact label or its last ``/`` part;
    a name not found so is looked up among the merged labels of the multi-axis (D6) joints."""
    index: dict[str, list[int]] = {}
    for j in joints:
        label = labels[j]
        index.setdefault(label, []).append(j)
        short = _short(label)
        if short != label:
            index.setdefault(short, []).append(j)
    multi = [j for j in joints if int(jtype[j]) == _D6]
    out = np.zeros(len(names), np.int32)
    axes = np.zeros(len(names), np.int32)
    for r, name in enumerate(names):
        cand = sorted(set(index.get(name, [])))
        if not cand and multi:
            hits = []
            for j in multi:
                n_axes = int(qd_start[j + 1] - qd_start[j])
                k = _axis_in_label(name, _short(labels[j]), n_axes)
                if k is not None:
                    hits.append((j, k))
            if len(hits) > 1:
                raise ConfigError(
                    f"joint_names: joint {name!r} is an axis of {len(hits)} multi-axis joints in world {world}: "
                    f"{[labels[j] for j, _ in hits]}"
                )
            if hits:
                j, k = hits[0]
                out[r], axes[r] = j, k  # a D6 joint's coordinates and DOFs: one per axis, in the label's order
                continue
        if not cand:
            known = sorted({_short(lb) for lb in labels})
            close = difflib.get_close_matches(name, known, n=5, cutoff=0.5)
            hint = f"; close matches: {close}" if close else f"; the model's joints: {known[:20]}"
            raise ConfigError(f"joint_names: joint {name!r} is not in world {world} of the model{hint}")
        if len(cand) > 1:
            raise ConfigError(
                f"joint_names: joint {name!r} matches {len(cand)} joints in world {world}: "
                f"{[labels[j] for j in cand]}; use the full label"
            )
        j = cand[0]
        t = int(jtype[j])
        if t not in _ONE_DOF or int(qd_start[j + 1] - qd_start[j]) != 1:
            tname = newton.JointType(t).name if t in set(int(x) for x in newton.JointType) else str(t)
            what = (
                "name one of its axes instead (its MJCF hinge / slide name)" if t == _D6 else "it has no axis to drive"
            )
            raise ConfigError(
                f"joint_names: joint {labels[j]!r} is a {tname} joint; wpctrl controls 1-DOF revolute or "
                f"prismatic joints and single axes of multi-axis joints ({what})"
            )
        out[r] = j
    return out, axes


def _replicated_table(model, names, labels, jworld, jtype, qd_start, world_count: int):
    """Fast path for replicated worlds: resolve in world 0 and offset by each world's first joint.

    Applies when every world holds the same joints (labels and types) in the same order, contiguously; then the
    names resolve identically everywhere (checked with numpy, not a Python loop over every joint of every world).
    Returns ``(table, axes)``, or ``(None, None)`` when the worlds differ.
    """
    jws = getattr(model, "joint_world_start", None)
    if world_count < 2 or jws is None:
        return None, None
    jws = jws.numpy()[: world_count + 1].astype(np.int64)
    per = np.diff(jws)
    if per.size == 0 or (per != per[0]).any() or per[0] == 0:
        return None, None
    n = int(per[0])
    span = slice(int(jws[0]), int(jws[world_count]))
    if (jworld[span] != np.repeat(np.arange(world_count), n)).any():
        return None, None
    lab = np.array(labels[span], dtype=object).reshape(world_count, n)
    typ = jtype[span].reshape(world_count, n)
    if not (lab == lab[0]).all() or not (typ == typ[0]).all():
        return None, None
    row0, axes = _resolve(names, labels, range(int(jws[0]), int(jws[1])), 0, jtype, qd_start)
    return (row0[None, :] - jws[0] + jws[:world_count, None]).astype(np.int32), axes


def bind_joints(model: newton.Model, joint_names: Sequence[str]) -> JointBinding:
    """Resolve ``joint_names`` in every world of ``model``.

    Every world must hold each name exactly once (as a 1-DOF revolute or prismatic joint, or one axis of a
    multi-axis joint). A model with a single world whose joints are global (built without
    ``replicate``/``begin_world``) counts as one env.

    Raises:
        ConfigError: unknown or ambiguous name, a joint that is not 1-DOF, a world missing the robot, or worlds whose
            joints are laid out differently.
    """
    names = list(joint_names)
    labels = list(model.joint_label)
    jworld = model.joint_world.numpy()
    jtype = model.joint_type.numpy()
    q_start = model.joint_q_start.numpy()
    qd_start = model.joint_qd_start.numpy()
    world_count = max(int(model.world_count), 1)
    if world_count == 1 and (jworld == 0).sum() == 0:
        jworld = np.zeros_like(jworld)  # a single-world model built without worlds: its joints are global

    table, axes = _replicated_table(model, names, labels, jworld, jtype, qd_start, world_count)
    if table is None:  # worlds that differ: resolve the names world by world
        table = np.zeros((world_count, len(names)), np.int32)
        axes_w = np.zeros((world_count, len(names)), np.int32)
        members: list[list[int]] = [[] for _ in range(world_count)]
        for j in range(len(labels)):
            w = int(jworld[j])
            if 0 <= w < world_count:
                members[w].append(j)
        for w in range(world_count):
            table[w], axes_w[w] = _resolve(names, labels, members[w], w, jtype, qd_start)
        axes = axes_w[0]  # (a world binding an axis differently changes the relative offsets: refused below)

    coord = (q_start[table] + axes[None, :]).astype(np.int32)
    dof = (qd_start[table] + axes[None, :]).astype(np.int32)
    if len(names):
        q_base, qd_base = coord[:, 0].copy(), dof[:, 0].copy()
    else:
        q_base = qd_base = np.zeros(world_count, np.int32)
    q_rel = coord - q_base[:, None]
    qd_rel = dof - qd_base[:, None]
    if (q_rel != q_rel[:1]).any() or (qd_rel != qd_rel[:1]).any():
        bad = int(np.nonzero((q_rel != q_rel[:1]).any(axis=1) | (qd_rel != qd_rel[:1]).any(axis=1))[0][0])
        raise ConfigError(
            f"joint_names: the joints are laid out differently in world {bad} than in world 0 "
            f"(relative coordinate offsets {q_rel[bad].tolist()} vs {q_rel[0].tolist()}); every world must hold the "
            f"same robot"
        )
    lower = model.joint_limit_lower.numpy()
    upper = model.joint_limit_upper.numpy()
    d0 = dof[0] if len(names) else np.zeros(0, np.int32)
    qlimits = (
        np.stack([lower[d0], upper[d0]], axis=1).astype(np.float32) if len(names) else np.zeros((0, 2), np.float32)
    )
    # Newton marks unlimited joints with +-MAXVAL; report them as infinite, as ManiSkill does.
    unlimited = np.abs(qlimits) >= 0.99 * newton.MAXVAL
    qlimits[unlimited] = np.copysign(np.inf, qlimits[unlimited])
    return JointBinding(
        joint_names=names,
        num_envs=world_count,
        joint_index=table,
        axis=axes.astype(np.int32),
        coord_index=coord,
        dof_index=dof,
        q_base=q_base.astype(np.int32),
        qd_base=qd_base.astype(np.int32),
        q_off=q_rel[0].astype(np.int32) if len(names) else np.zeros(0, np.int32),
        qd_off=qd_rel[0].astype(np.int32) if len(names) else np.zeros(0, np.int32),
        qlimits=qlimits,
    )
