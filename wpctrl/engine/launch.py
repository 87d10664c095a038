"""Recorded kernel launches and the small host-side records the engine keeps about them.

:class:`_Launch` records a ``wp.launch`` once and re-binds an argument only when it changed (by pointer, shape and
strides), so a step issues no Python-side launch setup and a captured graph replays the same arrays.
"""

from __future__ import annotations

import numpy as np
import warp as wp


class _Launch:
    """A recorded ``wp.launch`` whose parameters are re-bound (by name) only when they change."""

    def __init__(self, kernel, dim, params: dict, device, block_dim: int | None = None):
        names = [a.label for a in kernel.adj.args]
        assert list(params) == names, f"{kernel.key}: parameters {list(params)} != {names}"
        self._cmd = wp.launch(
            kernel, dim=dim, inputs=list(params.values()), device=device, record_cmd=True, block_dim=block_dim
        )
        self._index = {n: i for i, n in enumerate(names)}
        self._keys = [_key(v) for v in params.values()]

    def bind(self, name: str, value) -> None:
        i = self._index[name]
        k = _key(value)
        if self._keys[i] != k:
            self._cmd.set_param_at_index(i, value)
            self._keys[i] = k

    def launch(self) -> None:
        self._cmd.launch()


def _index_table(index: np.ndarray) -> tuple[np.ndarray, int]:
    """``(table, stride)`` with ``index[e, r] == table[e or 0, r] + e * stride``: a ``(1, rows)`` table and the stride
    when every env's indices are env 0's shifted by a constant (replicated worlds), else the full table and 0."""
    E = index.shape[0]
    idx = index.astype(np.int64)
    if E > 1 and index.shape[1] > 0:
        stride = int(idx[1, 0] - idx[0, 0])
        if (idx == idx[:1] + stride * np.arange(E)[:, None]).all() and abs(stride) * E < 2**31:
            return index[:1].astype(np.int32), stride
    return index.astype(np.int32), 0


class _Targets:
    """The drive-target arrays of a Control, shaped like one (``joint_target_q``, ``joint_target_qd``)."""

    def __init__(self, joint_target_q: wp.array, joint_target_qd: wp.array):
        self.joint_target_q = joint_target_q
        self.joint_target_qd = joint_target_qd


def _key(v):
    if isinstance(v, wp.array):
        return (v.ptr, v.shape, v.strides)
    return v
