"""A control mode validated for its engine: its configs, each through its family, become rows over one binding.

Every config class declares its family (:class:`wpctrl.config.family.Family`): how it becomes rows (and, for a
family with launches of its own, a spec) and which module holds its engine part. Nothing here knows a family by
name: a new family needs no change in this module.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import newton
import numpy as np

from ..binding import JointBinding, bind_joints
from ..config.errors import ConfigError
from ..config.family import ControllerConfig
from ..config.options import Actuation, Delay, Diagnostics
from ..config.rows import Rows, check_mode_dict, controller_rows
from ..config.validate import _joint_names
from ..engine.plan import Options


@dataclass
class Child:
    """One config of a mode: its uid (``""`` for a single config), its rows and where they start."""

    uid: str
    config: Any
    rows: Rows
    row0: int
    col0: int

    @property
    def row_slice(self) -> slice:
        return slice(self.row0, self.row0 + self.rows.count)

    @property
    def col_slice(self) -> slice:
        return slice(self.col0, self.col0 + self.rows.action_dim)


@dataclass
class Mode:
    """A validated control mode, ready to plan: its configs in order, all their rows, where the joints are, the
    options, and the specs of the families with a part (first row -> (first action column, rows, spec))."""

    children: list[Child]
    rows: Rows
    binding: JointBinding
    options: Options
    specs: dict[int, tuple]


def make_mode(
    config,
    model: newton.Model,
    control_freq: int,
    sim_freq: int,
    *,
    actuation: Actuation | None,
    delay: Delay | None,
    diagnostics: Diagnostics | None,
    balance_passive_force: bool | None,
) -> Mode:
    """Validate a config or a mode dict with the option groups: its rows through each config's family, bound to
    ``model``. The part module of every family with a spec is imported (so the engine knows the part)."""
    num_substeps = _num_substeps(control_freq, sim_freq)
    actuation = Actuation() if actuation is None else actuation
    diagnostics = Diagnostics() if diagnostics is None else diagnostics
    for name, value, kind in (("actuation", actuation, Actuation), ("diagnostics", diagnostics, Diagnostics)):
        if not isinstance(value, kind):
            raise ConfigError(f"{name}: expected a wpctrl.{kind.__name__}, got {value!r}")
    if delay is not None and not isinstance(delay, Delay):
        raise ConfigError(f"delay: expected a wpctrl.Delay or None, got {delay!r}")
    if isinstance(config, Mapping):
        configs = dict(config)
        balance = configs.pop("balance_passive_force", None)  # an agent-level option, not a controller
        check_mode_dict(configs)
    else:
        configs, balance = {"": config}, None
    options = Options(
        num_substeps=num_substeps,
        sim_dt=1.0 / sim_freq,
        actuation=actuation,
        delay=delay,
        diagnostics=diagnostics,
        balance_passive_force=_balance_passive_force(balance, balance_passive_force),
    )
    names: list[str] = []
    for c in configs.values():
        if not isinstance(c, ControllerConfig):
            raise ConfigError(f"config: expected a controller config, got {type(c).__name__}")
        names += _joint_names(c)
    binding = bind_joints(model, names)  # once for the whole mode
    children: list[Child] = []
    specs: dict[int, tuple] = {}
    r0 = c0 = 0
    for uid, c in configs.items():
        rows, spec = controller_rows(c, binding.qlimits[r0 : r0 + len(c.joint_names)])
        if spec is not None:
            type(c).family.load_part()  # its module registers the part that runs this spec
            specs[r0] = (c0, rows.count, spec)
        children.append(Child(uid, c, rows, r0, c0))
        r0 += rows.count
        c0 += rows.action_dim
    return Mode(children, Rows.concat([ch.rows for ch in children]), binding, options, specs)


def _balance_passive_force(in_mode_dict, keyword) -> bool:
    """The one value of ``balance_passive_force``: the keyword or the mode dict's entry (given both ways they must
    agree), else True (ManiSkill's default)."""
    for v in (keyword, in_mode_dict):
        if v is not None and not isinstance(v, (bool, np.bool_)):
            raise ConfigError(f"balance_passive_force: expected True or False, got {v!r}")
    if keyword is not None and in_mode_dict is not None and bool(keyword) != bool(in_mode_dict):
        raise ConfigError(
            f"balance_passive_force: expected None or the mode dict's 'balance_passive_force' entry "
            f"({bool(in_mode_dict)}), got {keyword!r}"
        )
    return bool(True if keyword is None and in_mode_dict is None else (in_mode_dict if keyword is None else keyword))


def _num_substeps(control_freq, sim_freq) -> int:
    for name, v in (("control_freq", control_freq), ("sim_freq", sim_freq)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v <= 0:
            raise ConfigError(f"{name}: expected a positive int [Hz], got {v!r}")
    if sim_freq % control_freq != 0:
        raise ConfigError(
            f"sim_freq: expected a multiple of control_freq={control_freq} so that each control step spans whole "
            f"substeps, got sim_freq={sim_freq} (ManiSkill's env asserts this too)"
        )
    return int(sim_freq // control_freq)
