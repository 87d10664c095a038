"""``check_device``: refuse a Warp device this machine does not have, naming it and the devices it has, before anything
is built (:func:`wpctrl.tasks.make` and the command lines' ``--device`` use it)."""

from __future__ import annotations

from .config.errors import ConfigError

__all__ = ["available_devices", "check_device", "not_a_device"]


def not_a_device(what: str, device: str, cuda_missing: bool, available: list[str]) -> str:
    """The refusal of ``device``: ``what`` (the argument), the name asked for, that the machine has no CUDA device
    where that is why, and the devices it has."""
    why = " (it has no CUDA device)" if cuda_missing and device.startswith("cuda") else ""
    return f"{what}: {device!r} is not a device of this machine{why}; available devices: {available}"


def available_devices() -> list[str]:
    """The Warp devices of this machine by name (``"cpu"``, then ``"cuda:0"``, ...)."""
    import warp as wp

    return [str(d.alias) for d in wp.get_devices()]


def check_device(device, what: str = "device"):
    """The Warp device ``device`` names (a name such as ``"cpu"``, ``"cuda"``, ``"cuda:1"``, a ``warp.Device``
    or a ``torch.device``); a :class:`~wpctrl.config.ConfigError` naming ``what``, the device asked for and the
    devices available when this machine has no such device."""
    import warp as wp

    if not isinstance(device, (str, wp.Device)) and type(device).__name__ == "device":  # a torch.device
        device = str(device)
    if isinstance(device, wp.Device):
        return device
    if not isinstance(device, str):
        raise ConfigError(f"{what}: expected a device name such as 'cpu' or 'cuda:0', got {device!r}")
    try:
        return wp.get_device(device)
    except (ValueError, RuntimeError) as e:  # Warp's "Invalid device identifier" and the like
        raise ConfigError(not_a_device(what, device, not wp.is_cuda_available(), available_devices())) from e
