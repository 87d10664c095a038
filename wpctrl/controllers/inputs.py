"""Input conversion on the host: actions, env selections and per-row values as device arrays.

Only metadata (shapes, dtypes, devices) is checked here; nothing is read back from a device, so every conversion of
a device input is graph-capturable.
"""

from __future__ import annotations

import weakref

import numpy as np
import warp as wp

from ..kernels.pd import _cast_f64_kernel


def _torch():
    try:
        import torch
    except ImportError:  # torch is optional
        return None
    return torch


def _is_torch(x) -> bool:
    torch = _torch()
    return torch is not None and isinstance(x, torch.Tensor)


def _type_name(x) -> str:
    return type(x).__name__


# Which model a State / Control belongs to. Newton's State and Control hold no reference to their model, and two
# models with the same joint counts give States of identical shapes. So a State (or Control) is bound to the model of
# the first wpctrl controller that uses it (a weak reference, dropped with the State); a controller of any other
# model then rejects it. Limit: a State that no controller of its own model has used yet is accepted by a controller
# of another model of the same sizes (and bound to that model from then on). Cost: one dict lookup per call.
_OWNER: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _claim(obj, model, what: str, kind: str) -> None:
    ref = _OWNER.get(obj)
    owner = None if ref is None else ref()
    if owner is model:
        return
    if owner is not None:
        raise ValueError(
            f"{what}: this {kind} belongs to another newton.Model (a controller of that model used it first), not to "
            f"this controller's model, although the sizes match; create it with this model's model.{kind}()"
        )
    _OWNER[obj] = weakref.ref(model)


def _check_shape(name: str, shape: tuple, num_envs: int, dim: int) -> None:
    if tuple(shape) != (num_envs, dim):
        raise ValueError(f"{name}: expected shape ({num_envs}, {dim}) (num_envs, action_dim), got {tuple(shape)}")


def _action_array(action, num_envs: int, dim: int, device, buffer: wp.array, cache: dict | None = None) -> wp.array:
    """Return ``action`` as a float32 (num_envs, dim) wp.array on ``device``, zero-copy where possible.

    A float32 torch tensor is wrapped in place (wrappers are cached by address, shape and strides: torch's caching
    allocator hands the same memory back step after step). Anything that needs a conversion (float64, a layout
    Warp cannot index) is copied into the controller's own ``buffer``, never into a temporary that could be freed
    before the kernel runs.
    """
    if _is_torch(action):
        torch = _torch()
        t = action.detach()
        if t.dim() == 1 and num_envs == 1:
            t = t.unsqueeze(0)
        _check_shape("action", tuple(t.shape), num_envs, dim)
        if t.dtype not in (torch.float32, torch.float64):
            raise TypeError(f"action: expected a float32 (or float64) tensor, got dtype {t.dtype}")
        if wp.device_from_torch(t.device) != device:
            raise ValueError(f"action: expected a tensor on {device}, got one on {t.device}")
        if dim == 0:
            return buffer
        if t.dtype != torch.float32:
            wp.to_torch(buffer).copy_(t)
            return buffer
        key = (t.data_ptr(), t.stride(0), t.stride(1))
        if cache is not None and key in cache:
            return cache[key]
        a = wp.array(
            ptr=t.data_ptr(),
            dtype=wp.float32,
            shape=tuple(t.shape),
            strides=(t.stride(0) * 4, t.stride(1) * 4),
            device=device,
        )
        if cache is not None:
            if len(cache) >= 16:
                cache.clear()
            cache[key] = a
        return a
    if isinstance(action, wp.array):
        a = action
        if a.ndim == 1 and num_envs == 1:
            a = a.reshape((1, a.shape[0]))
        _check_shape("action", a.shape, num_envs, dim)
        if a.device != device:
            raise ValueError(f"action: expected a wp.array on {device}, got one on {a.device}")
        if a.dtype == wp.float32:
            return a
        if a.dtype == wp.float64:
            if dim:
                wp.launch(_cast_f64_kernel, dim=a.shape, inputs=[a, buffer], device=device)
            return buffer
        raise TypeError(f"action: expected a float32 (or float64) wp.array, got dtype {wp.types.type_repr(a.dtype)}")
    if action is None or isinstance(action, (str, bytes, dict)):
        raise TypeError(
            f"action: expected an array of shape ({num_envs}, {dim}) (torch tensor, numpy array, wp.array or nested "
            f"sequence of floats), got {_type_name(action)}"
        )
    a = np.asarray(action)
    if a.dtype.kind not in "biuf":
        raise TypeError(
            f"action: expected an array of shape ({num_envs}, {dim}) of floats (torch tensor, numpy array, wp.array "
            f"or nested sequence of floats), got {_type_name(action)} holding dtype {a.dtype}"
        )
    if a.ndim == 1 and num_envs == 1:
        a = a[None, :]
    _check_shape("action", a.shape, num_envs, dim)
    if a.dtype.kind != "f":
        raise TypeError(
            f"action: expected a float32 (or float64) array, got dtype {a.dtype} (integer actions are not truncated "
            f"silently: convert them explicitly)"
        )
    if a.dtype == np.float32 and device.is_cpu and a.flags.c_contiguous:
        return wp.array(a, dtype=wp.float32, device=device, copy=False)
    buffer.assign(np.ascontiguousarray(a, dtype=np.float32))
    return buffer


def _raise_on_nonfinite(a: wp.array) -> None:
    """nan_policy="raise": a host check (a device-to-host copy and a sync; not graph-capturable)."""
    host = a.numpy()
    bad = ~np.isfinite(host)
    if bad.any():
        envs = np.nonzero(bad.any(axis=1))[0]
        e = int(envs[0])
        raise ValueError(
            f"action: non-finite values in {envs.size} env(s), e.g. env {e}: {host[e].tolist()} "
            f"(nan_policy='raise'; the default 'hold' keeps those envs' targets and counts them)"
        )


def _env_selection(env_ids, num_envs: int, device):
    """Return (ids, mask) device arrays for ``reset``; exactly one may be non-None, both None means all envs."""
    if env_ids is None:
        return None, None
    if isinstance(env_ids, (int, np.integer)) and not isinstance(env_ids, bool):
        env_ids = [int(env_ids)]
    if _is_torch(env_ids):
        torch = _torch()
        t = env_ids.detach()
        if wp.device_from_torch(t.device) != device:
            raise ValueError(f"env_ids: expected a tensor on {device}, got one on {t.device}")
        if t.dtype == torch.bool:
            if tuple(t.shape) != (num_envs,):
                raise ValueError(f"env_ids: a bool mask must have shape ({num_envs},), got {tuple(t.shape)}")
            return None, wp.from_torch(t.contiguous(), dtype=wp.bool)
        if t.dtype in (torch.int32, torch.int64, torch.int16, torch.uint8, torch.int8):
            t = t.reshape(-1)
            if t.device.type == "cpu" and t.numel() and (int(t.min()) < 0 or int(t.max()) >= num_envs):
                raise ValueError(f"env_ids: expected indices in [0, {num_envs}), got {t.tolist()}")
            return wp.from_torch(t.to(torch.int32).contiguous(), dtype=wp.int32), None
        raise TypeError(f"env_ids: expected an int or bool tensor, got dtype {t.dtype}")
    if isinstance(env_ids, wp.array):
        if env_ids.device != device:
            raise ValueError(f"env_ids: expected a wp.array on {device}, got one on {env_ids.device}")
        if env_ids.dtype == wp.bool:
            if env_ids.shape != (num_envs,):
                raise ValueError(f"env_ids: a bool mask must have shape ({num_envs},), got {env_ids.shape}")
            return None, env_ids
        if env_ids.dtype == wp.int32:
            return env_ids.flatten(), None
        raise TypeError(f"env_ids: expected an int32 or bool wp.array, got {wp.types.type_repr(env_ids.dtype)}")
    a = np.asarray(env_ids)
    if a.dtype == np.bool_:
        if a.shape != (num_envs,):
            raise ValueError(f"env_ids: a bool mask must have shape ({num_envs},), got {a.shape}")
        return None, wp.array(a, dtype=wp.bool, device=device)
    if a.size == 0:
        a = a.astype(np.int32)
    if a.dtype.kind not in "iu":
        raise TypeError(f"env_ids: expected env indices (ints) or a bool mask, got dtype {a.dtype}")
    a = a.reshape(-1)
    if a.size and (a.min() < 0 or a.max() >= num_envs):
        raise ValueError(f"env_ids: expected indices in [0, {num_envs}), got {a.tolist()}")
    return wp.array(a.astype(np.int32), dtype=wp.int32, device=device), None


def _as_rows_array(name: str, value, shape: tuple) -> np.ndarray:
    if _is_torch(value):
        value = value.detach().cpu().numpy()
    elif isinstance(value, wp.array):
        value = value.numpy()
    a = np.asarray(value, dtype=np.float32)
    if a.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {a.shape}")
    return a
