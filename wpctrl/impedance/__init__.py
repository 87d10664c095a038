"""Operational-space control and joint impedance: the torque-level controllers, in one place.

Start from the configs (:mod:`.config`: :class:`OperationalSpaceControllerConfig`,
:class:`JointImpedanceControllerConfig`); each declares its family, which names the rest of this package, layered as
the library is (a module imports only those above it in this list):

- :mod:`.config`: the dataclasses (host only);
- :mod:`.spec`: a config validated into its joint rows and an :class:`~.spec.ImpedanceSpec`;
- :mod:`.warp_kernels`: the Warp kernels, the set-action kernel (target and variable gains from the action) and the
  torque kernel (OSC / joint impedance torques from the measured state);
- :mod:`.engine_part`: the engine part that launches them, per controller;
- :mod:`.controllers`: the controller classes (:class:`~.controllers.OperationalSpaceController`,
  :class:`~.controllers.JointImpedanceController`), loaded on first use as every controller class.

Importing this package imports the configs only (no Warp, no Newton).
"""

from .config import IMPEDANCE_CONFIGS, JointImpedanceControllerConfig, OperationalSpaceControllerConfig
from .spec import ImpedanceSpec, impedance_rows

__all__ = [
    "IMPEDANCE_CONFIGS",
    "ImpedanceSpec",
    "JointImpedanceControllerConfig",
    "OperationalSpaceControllerConfig",
    "impedance_rows",
]
