"""The errors of bad configuration: every option, config field or binding that wpctrl refuses raises one of these.

Kept in a module of their own (imported by every other config module, importing none) so that the config package
imports one way. Both are ``ValueError`` subclasses: ``except ValueError`` catches them.
"""

from __future__ import annotations


class ConfigError(ValueError):
    """A controller config, a ``build_controller`` option (or its binding to a model) is invalid. The message names
    the field, the expected and the received value."""


class MimicJointError(ConfigError, TypeError):
    """A mimic entry names a joint outside ``joint_names`` (ManiSkill raises ``TypeError`` here)."""
