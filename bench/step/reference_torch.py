"""A torch baseline of ManiSkill 3's PD joint controllers, over Newton's flat arrays. Benchmarks only.

This is how ManiSkill writes its controllers (``mani_skill/agents/controllers/pd_joint_pos.py``), one torch op per
ManiSkill expression and one child controller object per ``{uid: config}`` entry, re-targeted at Newton's flat
``State``/``Control`` arrays through precomputed index tensors (ManiSkill gathers ``qpos[..., active_joint_indices]``;
here ``joint_q.index_select(0, coord_index)``; writing drive targets is ``joint_target_q.index_copy_``).

Stages per control step (``K = sim_freq // control_freq``):

* ``set_action``: clip + scale (``clip_and_scale_action``), ``_start_qpos = qpos``, absolute / delta from q / delta on
  the virtual target, mimic rows ``target[:, M] = target[:, Mc] * m + o``, then either the interpolation step size or
  one drive-target write;
* ``before_simulation_step`` (K times): ``_step += 1``, the interpolated target ``start + step_size * _step`` and its
  drive-target write; with explicit actuation also the PD torque
  ``clamp(Kp (q* - q) + Kd (qd* - qd), -force_limit, force_limit)`` scattered into ``joint_f`` (what PhysX's drive, or
  Isaac Lab's explicit ``IdealPDActuator``, computes; ManiSkill itself leaves that to PhysX).

Deliberate differences from ManiSkill's source, none of which change a value or the number of torch ops:

* Buffers that live across calls (``_start_qpos``, ``_target_qpos``, ``_step_size``) are preallocated (as ManiSkill's
  main branch does) and written in place (``out=``/``copy_``/``add_``) instead of being rebound to new tensors, so that
  the same code can be captured in a CUDA graph and replayed (a rebound virtual target would be read from a stale
  address on replay).
* The substep counter ``_step`` stays a host int, as in ManiSkill: a captured control step bakes k = 1..K.

The index tables come from the Newton model (:func:`layout_from_model`) or are tiled from a small model for a
synthetic large-N layout (:func:`tile_layout`), exactly as ``ModelBuilder.replicate`` lays worlds out.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import torch

__all__ = [
    "JointLayout",
    "NewtonArrays",
    "TorchCombinedController",
    "TorchPDJointPosController",
    "TorchPDJointPosMimicController",
    "clip_and_scale_action",
    "layout_from_model",
    "tile_layout",
]

_MAXVAL = 1.0e10  # newton.MAXVAL: Newton's "unlimited" joint limit


# ----------------------------------------------------------------------------------------------------------------------
# Index tables


@dataclass
class JointLayout:
    """Where each named joint lives in every env of a Newton-like flat layout.

    ``coord_index[e, j]`` indexes ``joint_q``/``joint_target_q`` and ``dof_index[e, j]`` indexes
    ``joint_qd``/``joint_target_qd``/``joint_f`` for joint ``joint_names[j]`` of env ``e``.
    """

    joint_names: list[str]
    coord_index: np.ndarray  # (num_envs, n) int64
    dof_index: np.ndarray  # (num_envs, n) int64
    qlimits: np.ndarray  # (n, 2) float32: env 0's [lower, upper] (+-inf if unlimited), as ManiSkill's get_qlimits()[0]
    coord_count: int  # length of joint_q
    dof_count: int  # length of joint_qd

    @property
    def num_envs(self) -> int:
        return self.coord_index.shape[0]

    def select(self, names: list[str]) -> JointLayout:
        cols = [self.joint_names.index(n) for n in names]
        return JointLayout(
            list(names),
            self.coord_index[:, cols],
            self.dof_index[:, cols],
            self.qlimits[cols],
            self.coord_count,
            self.dof_count,
        )


def layout_from_model(model, joint_names: list[str]) -> JointLayout:
    """Resolve ``joint_names`` (matched to the last ``/`` part of Newton's joint labels) in every world of ``model``."""
    labels = list(model.joint_label)
    short = np.array([lb.rsplit("/", 1)[-1] for lb in labels])
    world = model.joint_world.numpy()
    q_start = model.joint_q_start.numpy()
    qd_start = model.joint_qd_start.numpy()
    num_worlds = max(int(model.world_count), 1)
    coord = np.zeros((num_worlds, len(joint_names)), np.int64)
    dof = np.zeros((num_worlds, len(joint_names)), np.int64)
    for j, name in enumerate(joint_names):
        ids = np.nonzero(short == name)[0]
        w = world[ids]
        if len(ids) != num_worlds or not np.array_equal(np.sort(w), np.arange(num_worlds)):
            raise ValueError(f"joint {name!r}: expected exactly one per world, found worlds {w.tolist()}")
        ids = ids[np.argsort(w)]
        coord[:, j] = q_start[ids]
        dof[:, j] = qd_start[ids]
    lo = model.joint_limit_lower.numpy()[dof[0]]
    hi = model.joint_limit_upper.numpy()[dof[0]]
    qlimits = np.stack([lo, hi], axis=1).astype(np.float32)
    unlimited = np.abs(qlimits) >= 0.99 * _MAXVAL
    qlimits[unlimited] = np.copysign(np.inf, qlimits[unlimited])
    return JointLayout(list(joint_names), coord, dof, qlimits, int(model.joint_coord_count), int(model.joint_dof_count))


def tile_layout(layout: JointLayout, num_envs: int) -> JointLayout:
    """A synthetic ``num_envs`` layout: the worlds of ``layout`` repeated with ``replicate``'s per-world stride.

    ``layout`` must come from a homogeneous model without global joints (every world the same size).
    """
    w = layout.num_envs
    if layout.coord_count % w or layout.dof_count % w:
        raise ValueError("tile_layout: the model's worlds are not all the same size (global joints?)")
    cs, ds = layout.coord_count // w, layout.dof_count // w
    if not np.all(layout.coord_index - layout.coord_index[:1] == np.arange(w)[:, None] * cs):
        raise ValueError("tile_layout: the model's worlds are not laid out with a constant stride")
    e = np.arange(num_envs, dtype=np.int64)[:, None]
    return JointLayout(
        list(layout.joint_names),
        layout.coord_index[:1] + e * cs,
        layout.dof_index[:1] + e * ds,
        layout.qlimits.copy(),
        num_envs * cs,
        num_envs * ds,
    )


class NewtonArrays:
    """Torch views (zero-copy) of the flat Newton arrays a controller reads and writes."""

    def __init__(self, state, control):
        self.bind(state, control)

    def bind(self, state, control) -> None:
        self.joint_q = _as_torch(state.joint_q)
        self.joint_qd = _as_torch(state.joint_qd)
        self.joint_target_q = _as_torch(control.joint_target_q)
        self.joint_target_qd = _as_torch(control.joint_target_qd)
        self.joint_f = _as_torch(control.joint_f)


def _as_torch(a):
    if isinstance(a, torch.Tensor):
        return a
    import warp as wp

    return wp.to_torch(a)


# ----------------------------------------------------------------------------------------------------------------------
# ManiSkill's controllers


def clip_and_scale_action(action: torch.Tensor, low: torch.Tensor, high: torch.Tensor) -> torch.Tensor:
    """``mani_skill.utils.gym_utils.clip_and_scale_action``: clip to [-1, 1], then map onto [low, high]."""
    action = torch.clip(action, -1, 1)
    return 0.5 * (high + low) + 0.5 * (high - low) * action


def _broadcast(value, n: int) -> np.ndarray:
    return np.broadcast_to(np.asarray(value, dtype=np.float64), (n,)).astype(np.float32)


class TorchPDJointPosController:
    """ManiSkill's ``PDJointPosController`` on Newton arrays (+ an explicit PD torque stage)."""

    def __init__(self, config, layout: JointLayout, arrays: NewtonArrays, sim_steps: int, explicit: bool, device):
        self.config = config
        self.arrays = arrays
        self.device = torch.device(device)
        self.num_envs = layout.num_envs
        self.n = len(layout.joint_names)
        self._sim_steps = sim_steps
        self.explicit = explicit
        dev = self.device
        self.coord_flat = torch.as_tensor(layout.coord_index.reshape(-1), device=dev)
        self.dof_flat = torch.as_tensor(layout.dof_index.reshape(-1), device=dev)
        self._init_action_space(layout)
        n = self.n
        self.kp = torch.as_tensor(_broadcast(config.stiffness, n), device=dev)
        self.kd = torch.as_tensor(_broadcast(config.damping, n), device=dev)
        self.force_limit = torch.as_tensor(_broadcast(config.force_limit, n), device=dev)
        shape = (self.num_envs, n)
        self._start_qpos = torch.zeros(shape, device=dev)
        self._target_qpos = torch.zeros(shape, device=dev)
        self._step_size = torch.zeros(shape, device=dev)
        self._drive_target = self._target_qpos  # the last drive target written (the PD torque tracks it)
        self._drive_velocity_target = torch.zeros(shape, device=dev)  # never written: PhysX's default 0
        self._interp = torch.zeros(shape, device=dev)
        self._step = 0

    # -- ManiSkill: _initialize_action_space / _preprocess_action ------------------------------------------------------

    def _init_action_space(self, layout: JointLayout) -> None:
        low, high = layout.qlimits[:, 0].copy(), layout.qlimits[:, 1].copy()
        if self.config.lower is not None:
            low[:] = self.config.lower
        if self.config.upper is not None:
            high[:] = self.config.upper
        self.action_low = torch.as_tensor(low, device=self.device)
        self.action_high = torch.as_tensor(high, device=self.device)
        self.action_dim = self.n

    def _preprocess_action(self, action: torch.Tensor) -> torch.Tensor:
        if self.config.normalize_action:
            action = clip_and_scale_action(action, self.action_low, self.action_high)
        return action

    # -- Newton I/O ------------------------------------------------------------------------------------------------

    @property
    def qpos(self) -> torch.Tensor:
        """The measured positions, a fresh (N, n) tensor (ManiSkill: ``get_qpos()[..., active_joint_indices]``)."""
        return self.arrays.joint_q.index_select(0, self.coord_flat).view(self.num_envs, self.n)

    def _snapshot_qpos(self) -> None:
        """``_start_qpos = self.qpos``: the same single gather, written into the persistent buffer."""
        torch.index_select(self.arrays.joint_q, 0, self.coord_flat, out=self._start_qpos.view(-1))

    def set_drive_targets(self, targets: torch.Tensor) -> None:
        self.arrays.joint_target_q.index_copy_(0, self.coord_flat, targets.reshape(-1))
        self._drive_target = targets

    def _apply_pd(self) -> None:
        """Explicit actuation: the PD torque of the current drive target, clamped, into ``joint_f``."""
        a = self.arrays
        q = a.joint_q.index_select(0, self.coord_flat).view(self.num_envs, self.n)
        qd = a.joint_qd.index_select(0, self.dof_flat).view(self.num_envs, self.n)
        tau = self.kp * (self._drive_target - q) + self.kd * (self._drive_velocity_target - qd)
        tau = torch.clamp(tau, -self.force_limit, self.force_limit)
        a.joint_f.index_copy_(0, self.dof_flat, tau.view(-1))

    # -- ManiSkill's API -------------------------------------------------------------------------------------------

    def reset(self) -> None:
        self._step = 0
        self._snapshot_qpos()
        self._target_qpos.copy_(self._start_qpos)
        self._drive_target = self._target_qpos

    def _update_target(self, action: torch.Tensor) -> None:
        c = self.config
        if c.use_delta:
            if c.use_target:
                self._target_qpos.add_(action)  # ManiSkill: _target_qpos = _target_qpos + action
            else:
                torch.add(self._start_qpos, action, out=self._target_qpos)  # _target_qpos = _start_qpos + action
        else:
            self._target_qpos.copy_(action)  # _target_qpos = broadcast_to(action, _start_qpos.shape)

    def set_action(self, action: torch.Tensor) -> None:
        action = self._preprocess_action(action)
        self._step = 0
        self._snapshot_qpos()
        self._update_target(action)
        if self.config.interpolate:
            torch.div(self._target_qpos - self._start_qpos, self._sim_steps, out=self._step_size)
        else:
            self.set_drive_targets(self._target_qpos)

    def before_simulation_step(self) -> None:
        self._step += 1
        if self.config.interpolate:
            torch.add(self._start_qpos, self._step_size * self._step, out=self._interp)
            self.set_drive_targets(self._interp)
        if self.explicit:
            self._apply_pd()


class TorchPDJointPosMimicController(TorchPDJointPosController):
    """ManiSkill's ``PDJointPosMimicController``: control columns from the action, then the mimic rows."""

    def _init_action_space(self, layout: JointLayout) -> None:
        super()._init_action_space(layout)
        names = layout.joint_names
        mimic = dict(self.config.mimic or {})
        if not mimic:
            mimic = {names[0]: {"joint": names[1]}}
        dev = self.device
        self.mimic_joint_indices = torch.tensor([names.index(k) for k in mimic], device=dev)
        self.mimic_control_joint_indices = torch.tensor([names.index(v["joint"]) for v in mimic.values()], device=dev)
        self.mimic_multiplier = torch.tensor([v.get("multiplier", 1.0) for v in mimic.values()], device=dev)
        self.mimic_offset = torch.tensor([v.get("offset", 0.0) for v in mimic.values()], device=dev)
        self.control_joint_indices = torch.unique(self.mimic_control_joint_indices)
        ci = self.control_joint_indices.cpu().numpy()
        self.action_low = self.action_low[ci]
        self.action_high = self.action_high[ci]
        self.action_dim = len(ci)

    def _update_target(self, action: torch.Tensor) -> None:
        c = self.config
        C = self.control_joint_indices
        if c.use_delta:
            if c.use_target:
                self._target_qpos[:, C] += action
            else:
                self._target_qpos[:, C] = self._start_qpos[:, C] + action
        else:
            self._target_qpos[:, C] = action
        self._target_qpos[:, self.mimic_joint_indices] = (
            self._target_qpos[:, self.mimic_control_joint_indices] * self.mimic_multiplier + self.mimic_offset
        )


class TorchCombinedController:
    """ManiSkill's ``CombinedController``: one child per ``{uid: config}`` entry, a flat action split by columns.

    Args:
        mode: ``{uid: PDJointPosControllerConfig | PDJointPosMimicControllerConfig}`` (wpctrl's or ManiSkill's).
        layout: Index tables of every joint of the mode (:func:`layout_from_model` or :func:`tile_layout`).
        state, control: Objects with Newton's flat ``joint_q``, ``joint_qd`` / ``joint_target_q``, ``joint_target_qd``,
            ``joint_f`` arrays (wp.array or torch).
        actuation: ``"implicit"`` (write drive targets only) or ``"explicit"`` (also the PD torque into ``joint_f``).
    """

    def __init__(
        self,
        mode: Mapping,
        layout: JointLayout,
        state,
        control,
        control_freq: int = 20,
        sim_freq: int = 100,
        actuation: str = "explicit",
        device="cpu",
    ):
        self.arrays = NewtonArrays(state, control)
        self._sim_steps = sim_freq // control_freq
        self.num_envs = layout.num_envs
        self.controllers = {}
        self.action_mapping = {}
        col = 0
        for uid, cfg in mode.items():
            if uid == "balance_passive_force":
                continue
            cls = TorchPDJointPosMimicController if hasattr(cfg, "mimic") else TorchPDJointPosController
            if not hasattr(cfg, "use_delta"):
                raise NotImplementedError(f"{type(cfg).__name__}: the torch baseline covers position controllers only")
            child = cls(
                cfg, layout.select(list(cfg.joint_names)), self.arrays, self._sim_steps, actuation == "explicit", device
            )
            self.controllers[uid] = child
            self.action_mapping[uid] = (col, col + child.action_dim)
            col += child.action_dim
        self.action_dim = col

    def bind(self, state, control) -> None:
        """Re-point the torch views at other State/Control objects (after a state swap)."""
        self.arrays.bind(state, control)

    def reset(self) -> None:
        for c in self.controllers.values():
            c.reset()

    def set_action(self, action: torch.Tensor) -> None:
        for uid, c in self.controllers.items():
            start, end = self.action_mapping[uid]
            c.set_action(action[:, start:end])

    def before_simulation_step(self) -> None:
        for c in self.controllers.values():
            c.before_simulation_step()

    @property
    def target_qpos(self) -> torch.Tensor:
        return torch.cat([c._target_qpos for c in self.controllers.values()], dim=1)

    @property
    def start_qpos(self) -> torch.Tensor:
        return torch.cat([c._start_qpos for c in self.controllers.values()], dim=1)
