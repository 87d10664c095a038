"""Host-side checks of what a user hands the tasks' envs (actions, env selections, seeds), before any launch."""

from __future__ import annotations

import numpy as np
import warp as wp

from ..config import ConfigError

__all__ = ["action_tensor", "env_mask", "reset_options", "seed_value"]


def action_tensor(action, num_envs: int, action_dim: int, device):
    """``action`` as a float32 torch tensor of shape (num_envs, action_dim) on ``device`` (a single env's
    (action_dim,) action is accepted when num_envs is 1). NaN / Inf values pass: the controller holds the previous
    targets of such an env (its NaN policy)."""
    import torch

    if isinstance(action, dict):
        raise ConfigError("step: expected an action array, got a dict (the tasks have one agent)")
    t = action if isinstance(action, torch.Tensor) else torch.as_tensor(np.asarray(action, dtype=np.float32))
    if t.ndim == 1 and num_envs == 1:
        t = t[None]
    if tuple(t.shape) != (num_envs, action_dim):
        raise ConfigError(f"step: action expected shape ({num_envs}, {action_dim}), got {tuple(t.shape)}")
    if t.dtype.is_complex or t.dtype == torch.bool:
        raise ConfigError(f"step: action expected real numbers, got dtype {t.dtype}")
    return t.to(device=device, dtype=torch.float32)


def env_mask(env_idx, num_envs: int, device) -> wp.array:
    """A device bool mask of ``env_idx``: env indices (int, sequence, numpy or torch) or a bool mask of num_envs."""
    a = env_idx.detach().cpu().numpy() if hasattr(env_idx, "detach") else np.asarray(env_idx)
    if a.dtype == np.bool_:
        if a.shape != (num_envs,):
            raise ConfigError(f"env_idx: a bool mask must have shape ({num_envs},), got {a.shape}")
        mask = a
    else:
        if a.size and not np.issubdtype(a.dtype, np.integer):
            raise ConfigError(f"env_idx: expected env indices (integers) or a bool mask, got dtype {a.dtype}")
        ids = a.reshape(-1).astype(np.int64)
        if ids.size and (ids.min() < 0 or ids.max() >= num_envs):
            raise ConfigError(f"env_idx: indices must be in [0, {num_envs}), got {sorted(set(ids.tolist()))}")
        mask = np.zeros(num_envs, np.bool_)
        mask[ids] = True
    return wp.array(mask, dtype=wp.bool, device=device)


def seed_value(seed) -> int:
    """A reset seed as a non-negative int32 (ManiSkill takes any int; Warp's RNG a 32-bit one)."""
    if isinstance(seed, (list, tuple, np.ndarray)):
        raise ConfigError("reset: seed expected one int for all envs (per-env seed lists are not supported), got a "
                          f"sequence of {len(seed)}")  # fmt: skip
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise ConfigError(f"reset: seed expected an int, got {seed!r}")
    return int(seed) % (2**31)


def reset_options(options, known: tuple[str, ...]) -> dict:
    """``reset``'s ``options`` as a dict (None: empty); a key outside ``known`` is refused (it would be ignored)."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise ConfigError(f"reset: options expected a dict with keys from {list(known)} or None, got "
                          f"{type(options).__name__}")  # fmt: skip
    unknown = sorted((k for k in options if k not in known), key=str)
    if unknown:
        raise ConfigError(f"reset: unknown options key(s) {unknown}; expected keys from {list(known)}")
    return options
