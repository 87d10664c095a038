"""The end-effector part of a control mode: chain binding in the Newton model, device arrays, recorded launches.

An EE controller's joints are ordinary position rows of the mode's :class:`wpctrl.engine._Engine` (drive targets,
interpolation, actuation, NaN hold, resets and graph capture work as for joint controllers); :class:`EEPart` adds
one kernel launch before the joint launch of ``set_action`` (it writes those rows' ``target_qpos``) and one after
the joint reset (measured EE pose, and the target pose with ``use_target``).

Frames come from the Newton model: the chain is its joints (``joint_parent``, ``joint_X_p``, ``joint_X_c``,
``joint_axis``), read on the host once; ``ee_link`` is a body or a site on a body. A link the importer merged away
(``collapse_fixed_joints``) is found in the robot descriptions the config layer read for the controller
(:mod:`wpctrl.config.robot_description`: ``urdf_path``'s joints, else the descriptions robot modules registered); this
module reads no file.

Root frame: the body ``root_link_name`` when given; otherwise the articulation root: the child of the chain's top
joint when that joint is free or fixed, or, for a fixed base merged into the world, the root link's frame as the
robot's description places the top joint in it, moved with each env's own base placement (so every env reports poses
relative to its base, wherever ``replicate`` put it); without a description, env 0's world frame.
"""

from __future__ import annotations

import difflib
import logging

import newton
import numpy as np
import warp as wp

from ...config import ConfigError
from ...config.ee import MAX_EE_DOF, EESpec
from ...kernels import ee as ee_kernels
from ...kernels.dims import PER_ENV_BLOCK_DIM
from ...kernels.ee_math import EEChain
from ..hostmath import LinkFrames, tmul
from ..launch import _Launch
from .part import Part

logger = logging.getLogger("wpctrl")

_MOVING = (int(newton.JointType.REVOLUTE), int(newton.JointType.PRISMATIC))
_FIXED = int(newton.JointType.FIXED)


def ee_chain(model, chain_joint=None, chain_col=None, env_root=None, ee_offset=None) -> EEChain:
    """The EE kernels' chain argument (:class:`wpctrl.kernels.ee_math.EEChain`): the chain's tables, the model's joint
    arrays (alone, without a chain: a placeholder for kernels compiled without one)."""
    chain = EEChain()
    chain.chain_joint, chain.chain_col, chain.env_root = chain_joint, chain_col, env_root
    chain.ee_offset = wp.transform_identity() if ee_offset is None else ee_offset
    chain.joint_type, chain.joint_axis = model.joint_type, model.joint_axis
    chain.joint_X_p, chain.joint_X_c = model.joint_X_p, model.joint_X_c
    chain.joint_q_start, chain.joint_qd_start = model.joint_q_start, model.joint_qd_start
    return chain


def _short(label: str) -> str:
    return label.rsplit("/", 1)[-1]


def _find(labels, ids, name: str) -> list[int]:
    return [i for i in ids if labels[i] == name or _short(labels[i]) == name]


def _up_fixed(frames: LinkFrames, link: str, x, until):
    """Carry ``x`` (a frame in ``link``'s) up the fixed joints above ``link`` until ``until(link)``: ``(the link
    reached, x in its frame)``; a missing or moving joint on the way stops it: ``(None, that joint's row or None)``."""
    while not until(link):
        row = frames.joint_of(link)
        if row is None or not row[1]:
            return None, row
        x = tmul((row[4], row[5]), x)
        link = row[2]
    return link, x


def _wp(x) -> wp.transform:
    return wp.transform(wp.vec3(*(float(v) for v in x[0])), wp.quat(*(float(v) for v in x[1])))


def _merged_offset(frames: LinkFrames, ee_link: str, kept: set[str]) -> tuple[str, wp.transform]:
    """The link of ``kept`` that ``ee_link`` is merged into (through fixed joints) and ``ee_link``'s frame in it."""
    if ee_link not in frames.links:
        raise ConfigError(f"ee_link: link {ee_link!r} is neither in the model nor in urdf_path {frames.source}")
    link, x = _up_fixed(frames, ee_link, (np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0])), kept.__contains__)
    if link is None and x is None:
        raise ConfigError(f"ee_link: {ee_link!r} has no ancestor body in the model (searched {frames.source})")
    if link is None:
        raise ConfigError(
            f"ee_link: {ee_link!r} hangs off the moving joint {x[0]!r}, which the model lacks; "
            f"the model and urdf_path {frames.source} describe different robots"
        )
    return link, _wp(x)


def _urdf_frames(spec) -> LinkFrames:
    """``urdf_path``'s description (the file exists): raises when it could not be read."""
    found = spec.descriptions.found
    if not found:
        raise ConfigError(
            f"urdf_path: cannot read {spec.urdf_path!r} to locate ee_link {spec.ee_link!r}: {spec.descriptions.error}"
        )
    return LinkFrames.from_description(found[0])


def _descriptions(spec) -> list[LinkFrames]:
    """Where links and base frames missing from the model are looked up: the descriptions the config layer found
    for the controller (``urdf_path``'s when the file exists and parses, else the registered ones)."""
    return [LinkFrames.from_description(d) for d in spec.descriptions.found]


def _known_offset(spec, labels, bodies0, kept: set[str]):
    """``([body], offset)`` of a link merged away, from a registered description, or None."""
    for frames in _descriptions(spec):
        try:
            link, offset = _merged_offset(frames, spec.ee_link, kept)
        except ConfigError:
            continue
        cand = _find(labels, bodies0, link)
        if len(cand) == 1:
            logger.info("ee_link %r: located through %s (not in the model)", spec.ee_link, frames.source)
            return cand, offset
    return None


def _design_frame(spec, joint: str):
    """Where ``joint`` (the top of a chain whose root link is merged into the world) sits in the root link's frame
    as the robot's description places it: its origin carried up the fixed joints to the root link. None when no
    description holds ``joint``."""
    for frames in _descriptions(spec):
        row = frames.joint(joint)
        if row is None:
            continue
        link, x = _up_fixed(frames, row[2], (row[4], row[5]), lambda lk, f=frames: f.joint_of(lk) is None)
        return None if link is None else _wp(x)
    return None


def _is_merged_root(spec) -> bool:
    """Whether ``root_link_name`` is the robot's root link (absent from the model: merged into the world)."""
    return any(f.root == spec.root_link_name for f in _descriptions(spec))


class EEPart:
    """The device side of one EE controller inside a control mode's engine."""

    def __init__(self, spec: EESpec, engine, row0: int, col0: int, num_dof: int):
        self.spec = spec
        self.engine = engine
        self.row0 = row0
        self.col0 = col0
        self.num_dof = num_dof
        model = engine.model
        dev = engine.device
        E = engine.num_envs
        self._bind_chain(model, engine.binding, spec)

        self.row_q_off = wp.array(engine.binding.q_off[row0 : row0 + num_dof], dtype=wp.int32, device=dev)
        self.target_pose = wp.zeros((E, 7), dtype=wp.float32, device=dev)
        self.ee_pose = wp.zeros((E, 7), dtype=wp.float32, device=dev)
        self.ik_success = wp.ones(E, dtype=wp.int32, device=dev)
        self.initialized = False
        self._launch = None
        self._chain_params = {"chain": ee_chain(model, self.chain_joint, self.chain_col, self.env_root, self.ee_offset)}

    # -- binding ----------------------------------------------------------------------------------------------------

    def _bind_chain(self, model, binding, spec: EESpec) -> None:
        labels = list(model.body_label)
        jlabels = list(model.joint_label)
        world_count = binding.num_envs
        bworld = model.body_world.numpy()
        if world_count == 1 and (bworld == 0).sum() == 0:
            bworld = np.zeros_like(bworld)
        bodies0 = [b for b in range(len(labels)) if bworld[b] == 0]
        jparent = model.joint_parent.numpy()
        jchild = model.joint_child.numpy()
        jtype = model.joint_type.numpy()
        jxp = model.joint_X_p.numpy()

        # The EE body and its offset: a body, a site/shape on a body, or a URDF link merged into a kept body.
        offset = wp.transform_identity()
        cand = _find(labels, bodies0, spec.ee_link)
        if not cand:
            slabels = list(getattr(model, "shape_label", []) or [])
            sbody = model.shape_body.numpy() if len(slabels) else np.zeros(0, np.int32)
            scand = [s for s in _find(slabels, range(len(slabels)), spec.ee_link) if sbody[s] in set(bodies0)]
            if scand:
                s = scand[0]
                cand = [int(sbody[s])]
                st = model.shape_transform.numpy()[s]
                offset = wp.transform(wp.vec3(*st[:3]), wp.quat(*st[3:]))
            elif spec.descriptions.from_file:
                kept = {_short(labels[b]) for b in bodies0}
                link, offset = _merged_offset(_urdf_frames(spec), spec.ee_link, kept)
                cand = _find(labels, bodies0, link)
            elif (known := _known_offset(spec, labels, bodies0, {_short(labels[b]) for b in bodies0})) is not None:
                cand, offset = known
            elif spec.urdf_path is not None:
                raise ConfigError(
                    f"urdf_path: cannot read {spec.urdf_path!r} to locate ee_link {spec.ee_link!r}: "
                    f"{spec.descriptions.error}"
                )
            else:
                known = sorted({_short(labels[b]) for b in bodies0})
                close = difflib.get_close_matches(spec.ee_link, known, n=5, cutoff=0.5)
                raise ConfigError(
                    f"ee_link: {spec.ee_link!r} is not a body or site of world 0 of the model"
                    f"{'; close matches: ' + str(close) if close else '; the bodies: ' + str(known[:20])}"
                    f" (give urdf_path to locate a link merged away by collapse_fixed_joints)"
                )
        if len(cand) > 1:
            raise ConfigError(f"ee_link: {spec.ee_link!r} matches {len(cand)} bodies: {[labels[b] for b in cand]}")
        ee_body = cand[0]

        root_body = -1
        root_name = spec.root_link_name
        if root_name is not None and not _find(labels, bodies0, root_name) and _is_merged_root(spec):
            root_name = None  # the URDF's root link, merged into the world (a fixed base): the default root
        if root_name is not None:
            rc = _find(labels, bodies0, spec.root_link_name)
            if len(rc) != 1:
                raise ConfigError(
                    f"root_link_name: expected one body named {spec.root_link_name!r} in world 0, got {len(rc)}"
                )
            root_body = rc[0]

        joint_of_child = np.full(len(labels), -1, np.int64)
        joint_of_child[jchild] = np.arange(len(jchild))
        chain = []
        b = ee_body
        while b != root_body and b >= 0:
            j = int(joint_of_child[b])
            if j < 0:
                break
            chain.append(j)
            b = int(jparent[j])
        if root_name is not None and b != root_body:
            raise ConfigError(f"root_link_name: {spec.root_link_name!r} is not an ancestor of ee_link {spec.ee_link!r}")
        chain.reverse()
        world_top = False
        if root_name is None and chain:
            top = chain[0]
            if int(jtype[top]) not in _MOVING:
                chain = chain[1:]  # a free or fixed base: its child is the root link
            else:
                world_top = True
        for j in chain:
            if int(jtype[j]) not in _MOVING and int(jtype[j]) != _FIXED:
                raise ConfigError(
                    f"ee_link: the chain to {spec.ee_link!r} passes through joint {jlabels[j]!r} of type "
                    f"{newton.JointType(int(jtype[j])).name}; EE control supports revolute, prismatic and fixed joints"
                )
        # Jacobian columns: the controlled rows, in row order.
        ctrl0 = binding.joint_index[0, self.row0 : self.row0 + self.num_dof]
        col = np.full(len(chain), -1, np.int32)
        for c, j in enumerate(ctrl0):
            if int(j) not in chain:
                raise ConfigError(
                    f"joint_names: {jlabels[int(j)]!r} is not on the kinematic chain from the root to ee_link "
                    f"{spec.ee_link!r}"
                )
            col[chain.index(int(j))] = c
        # Other envs: the same chain shifted by each world's first joint (checked against the row binding).
        chain0 = np.asarray(chain, np.int64)
        if world_count > 1:
            jws = model.joint_world_start.numpy()[:world_count].astype(np.int64)
            table = chain0[None, :] - jws[0] + jws[:, None]
            ok = (jtype[table] == jtype[chain0][None, :]).all()
            ctrl = binding.joint_index[:, self.row0 : self.row0 + self.num_dof]
            ok = ok and (table[:, col >= 0][:, np.argsort(col[col >= 0])] == ctrl).all()
            if not ok:
                raise ConfigError(
                    "ee_link: the EE chain is laid out differently across worlds; every world must hold the same robot"
                )
        else:
            table = chain0[None, :]
        root = np.tile(np.array([0, 0, 0, 0, 0, 0, 1], np.float32), (world_count, 1))
        if world_top:
            # The root link is merged into the world: the root frame is where the robot's description puts the top
            # joint (its URDF origin), so env e's frame is X_design X_p(e)^-1 of its own placement (replicate's
            # spacing centres the envs: env 0 need not sit at the origin); without a description, env 0's world.
            t0 = jxp[table[0, 0]]
            x0 = _design_frame(spec, _short(jlabels[table[0, 0]]))
            if x0 is None:
                x0 = wp.transform(wp.vec3(*t0[:3]), wp.quat(*t0[3:]))
            for e in range(world_count):
                te = jxp[table[e, 0]]
                xe = wp.transform(wp.vec3(*te[:3]), wp.quat(*te[3:]))
                r = x0 * wp.transform_inverse(xe)
                if np.allclose(np.array([*r.p, *r.q]), root[e], rtol=0.0, atol=1e-7):
                    continue  # the placement the description gives: the world frame is the root frame
                root[e] = np.array([*r.p, *r.q], np.float32)
        dev = model.device
        self.chain_joint = wp.array(table.astype(np.int32).reshape(world_count, len(chain)), dtype=wp.int32, device=dev)
        self.chain_col = wp.array(col, dtype=wp.int32, device=dev)
        self.env_root = wp.array(root, dtype=wp.transform, device=dev)
        self.ee_offset = offset
        self.ee_body = ee_body

    # -- stages -----------------------------------------------------------------------------------------------------

    def set_action(self, action: wp.array, state) -> None:
        eng = self.engine
        s = self.spec
        if self._launch is None:
            lo = eng.rows.action_low[self.col0 : self.col0 + 3]
            hi = eng.rows.action_high[self.col0 : self.col0 + 3]
            params = dict(self._chain_params)
            params.update(
                {
                    "row_q_off": self.row_q_off,
                    "env_q_base": eng.core.env_q_base,
                    "row_qlo": eng.core.row_qlo,
                    "row_qhi": eng.core.row_qhi,
                    "clip_targets": int(eng.plan.clip_targets),
                    "row0": self.row0,
                    "num_dof": self.num_dof,
                    "col0": self.col0,
                    "pose": int(s.pose),
                    "use_delta": int(s.use_delta),
                    "use_target": int(s.use_target),
                    "normalize": int(s.normalize),
                    "frame_bits": s.frame_bits,
                    "solver": s.solver,
                    "alpha": s.alpha,
                    "lm_lambda": s.lm_lambda,
                    "iterations": s.iterations,
                    "tolerance": s.tolerance,
                    "clik_dt": s.clik_dt,
                    "clik_damping": s.clik_damping,
                    "act_lo": wp.vec3(*(float(v) for v in np.nan_to_num(lo))),
                    "act_hi": wp.vec3(*(float(v) for v in np.nan_to_num(hi))),
                    "rot_scale": wp.vec3(*(float(v) for v in s.rot_scale)),
                    "action_in": action,
                    "joint_q_in": state.joint_q,
                    "processed_action_out": eng.core.processed_action,
                    "target_qpos_out": eng.core.target_qpos,
                    "target_pose_out": self.target_pose,
                    "ee_pose_out": self.ee_pose,
                    "ik_success_out": self.ik_success,
                }
            )
            kernel = ee_kernels._ee_clik_kernel if s.iterations > 1 else ee_kernels._ee_set_action_kernel
            self._launch = _Launch(kernel, eng.num_envs, params, eng.device, block_dim=PER_ENV_BLOCK_DIM)
        self._launch.bind("action_in", action)
        self._launch.bind("joint_q_in", state.joint_q)
        self._launch.launch()

    def reset(self, state, env_ids, env_mask, use_target: bool | None = None) -> None:
        """The measured EE pose of the reset envs; with ``use_target`` (default: the spec's) also their target."""
        eng = self.engine
        use_target = self.spec.use_target if use_target is None else use_target
        dim = eng.num_envs if env_ids is None else env_ids.shape[0]
        if dim == 0:
            return
        p = self._chain_params
        wp.launch(
            ee_kernels._ee_reset_kernel,
            dim=dim,
            inputs=[
                *p.values(),
                self.row_q_off,
                eng.core.env_q_base,
                self.num_dof,
                int(use_target),
                env_ids,
                env_mask,
                state.joint_q,
                self.target_pose,
                self.ee_pose,
            ],
            device=eng.device,
            block_dim=PER_ENV_BLOCK_DIM,
        )

    def fk_jacobian(self, joint_q: wp.array) -> tuple[wp.array, wp.array]:
        """(num_envs, 7) EE poses and (num_envs, 6, num_dof) Jacobians at ``joint_q`` (allocates; not per step)."""
        eng = self.engine
        pose = wp.zeros((eng.num_envs, 7), dtype=wp.float32, device=eng.device)
        jac = wp.zeros((eng.num_envs, 6, self.num_dof), dtype=wp.float32, device=eng.device)
        wp.launch(
            ee_kernels._ee_fk_jacobian_kernel,
            dim=eng.num_envs,
            inputs=[
                *self._chain_params.values(),
                self.row_q_off,
                eng.core.env_q_base,
                self.num_dof,
                joint_q,
                pose,
                jac,
            ],
            device=eng.device,
        )
        return pose, jac


class EndEffectors(Part):
    """The mode's end-effector controllers: each an :class:`EEPart` (its launch before the joint set_action launch,
    which leaves its rows' targets alone, and after the joint reset)."""

    name = "ee"

    @staticmethod
    def wanted(plan) -> bool:
        return any(isinstance(v[2], EESpec) for v in plan.ee_specs.values())

    def __init__(self, plan, alloc):
        # {first row: (first action column, rows, spec)} (the impedance controllers' specs are another part's)
        self.specs = {r0: v for r0, v in plan.ee_specs.items() if isinstance(v[2], EESpec)}
        self.parts: dict[int, EEPart] = {}

    def build(self, engine, model, solver) -> None:
        for row0, (col0, n, spec) in self.specs.items():
            self.parts[row0] = EEPart(spec, engine, row0, col0, n)

    def before_set_action(self, engine, action, state) -> None:
        for part in self.parts.values():
            part.set_action(action, state)

    def after_reset(self, engine, state, env_ids, env_mask) -> None:
        for part in self.parts.values():
            part.reset(state, env_ids, env_mask)
            if not part.initialized:  # the build's reset: a defined target pose before any step
                wp.copy(part.target_pose, part.ee_pose)
                part.initialized = True


__all__ = ["EEPart", "EndEffectors", "MAX_EE_DOF"]
