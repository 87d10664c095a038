"""The device engine of one control mode: its arrays, its recorded kernel launches, the model's drive properties.

:mod:`.core` (the engine of one control mode), :mod:`.launch` (recorded launches), :mod:`.drive_props` (per-env drive
properties and their mirror in the model), :mod:`.ee` (the end-effector part: chain binding, EE launches).
"""

from .core import _Engine

__all__ = ["_Engine"]
