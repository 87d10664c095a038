"""One process per GPU (or per CPU worker) under ``torchrun``: device, process group, seed and small reductions.

RL codes that outgrow one GPU run one process per GPU, started by ``torchrun``, with NCCL for the gradients.
wpctrl itself needs nothing for that: a controller lives on the device of its Newton model. This module does the
per-process plumbing around it::

    ctx = wpctrl.distributed.init(device="cuda")     # cuda:{LOCAL_RANK} (or "cpu"); NCCL (CUDA) or gloo (CPU)
    model = build_my_model(device=ctx.device)          # each rank its own Newton model, controller and envs
    rng = np.random.default_rng(ctx.seed)              # a different seed on every rank
    total = ctx.all_reduce_sum([steps, errors])        # torch.distributed collectives
    per_rank = ctx.all_gather([fps, err])              # [[fps0, err0], [fps1, err1], ...] on every rank
    if ctx.is_main: print(...)
    ctx.shutdown()

Without torchrun's variables (``RANK``, ``WORLD_SIZE``) :func:`init` returns a single-process context and imports
nothing: torch stays optional. Under torchrun, torch is required (it provides the process group).

NCCL options come from the environment and are left as they are: a machine whose NVLink multicast does not work
(the 2xH200 machine this was measured on) needs ``NCCL_NVLS_ENABLE=0`` exported before ``torchrun``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

__all__ = ["DistContext", "init", "launched", "rank_seed"]


def launched() -> bool:
    """True inside a process started by ``torchrun`` (``RANK`` and ``WORLD_SIZE`` are set)."""
    return "RANK" in os.environ and "WORLD_SIZE" in os.environ


def rank_seed(seed: int, rank: int) -> int:
    """A 32-bit seed for ``rank`` derived from the run's ``seed`` (independent streams, not ``seed + rank``)."""
    return int(np.random.SeedSequence([int(seed), int(rank)]).generate_state(1)[0])


def _env_int(name: str, default: int) -> int:
    value = os.environ.get(name)
    if value is None or value == "":
        return default
    try:
        return int(value)
    except ValueError:
        raise ValueError(f"{name}: expected an integer (set by torchrun), got {value!r}") from None


def _require_torch():
    try:
        import torch
        import torch.distributed as dist
    except ImportError as e:
        from .extras import TORCH_BUILDS

        raise ImportError(
            f"wpctrl.distributed: running under torchrun needs torch ({TORCH_BUILDS}); a single process does not"
        ) from e
    if not dist.is_available():
        raise RuntimeError("wpctrl.distributed: this torch build has no torch.distributed")
    return torch, dist


def _resolve_device(device: str | None, local_rank: int, local_world_size: int) -> str:
    """ "cuda" (or None with a GPU) -> cuda:{local_rank}; "cpu" -> cpu; an explicit "cuda:k" is kept, but only one
    rank per node may use it."""
    import warp as wp

    if device is None:
        device = "cuda" if wp.is_cuda_available() else "cpu"
    device = str(device)
    if device == "cpu":
        return device
    if device == "cuda":
        n = wp.get_cuda_device_count()
        if local_rank >= n:
            raise ValueError(
                f"device 'cuda': local rank {local_rank} needs cuda:{local_rank}, but this node has {n} CUDA "
                f"device(s): start at most {n} processes per node (torchrun --nproc-per-node={n})"
            )
        return f"cuda:{local_rank}"
    if device.startswith("cuda:"):
        if local_world_size > 1:
            raise ValueError(
                f"device {device!r}: {local_world_size} processes on this node would share one GPU; pass 'cuda' and "
                f"each rank takes cuda:LOCAL_RANK"
            )
        return device
    raise ValueError(f"device: expected 'cpu', 'cuda' or 'cuda:N', got {device!r}")


@dataclass
class DistContext:
    """Where this process stands in the run. ``world_size == 1`` and ``backend is None`` without torchrun."""

    rank: int = 0
    local_rank: int = 0
    world_size: int = 1
    local_world_size: int = 1
    device: str = "cpu"
    seed: int = 0
    backend: str | None = None
    _owns_group: bool = field(default=False, repr=False)

    @property
    def is_main(self) -> bool:
        """Rank 0: the process that prints and writes files."""
        return self.rank == 0

    @property
    def distributed(self) -> bool:
        """True when a torch.distributed process group is in use."""
        return self.backend is not None

    # -- collectives -------------------------------------------------------------------------------------------------

    def _tensor(self, values):
        torch, _ = _require_torch()
        dev = torch.device("cuda", int(self.device.split(":")[1])) if self.backend == "nccl" else torch.device("cpu")
        return torch.as_tensor(np.asarray(values, dtype=np.float64).reshape(-1), device=dev)

    def _all_reduce(self, values, op: str) -> np.ndarray:
        a = np.asarray(values, dtype=np.float64).reshape(-1)
        if not self.distributed:
            return a.copy()
        _, dist = _require_torch()
        t = self._tensor(a)
        dist.all_reduce(t, op=getattr(dist.ReduceOp, op))
        return t.cpu().numpy()

    def all_reduce_sum(self, values) -> np.ndarray:
        """Element-wise sum over ranks of a flat float64 vector (NaN propagates: a diverged rank shows)."""
        return self._all_reduce(values, "SUM")

    def all_reduce_max(self, values) -> np.ndarray:
        """Element-wise max over ranks of a flat float64 vector."""
        return self._all_reduce(values, "MAX")

    def all_gather(self, values) -> np.ndarray:
        """(world_size, n) float64: every rank's flat vector of n values (same n on every rank), on every rank."""
        a = np.asarray(values, dtype=np.float64).reshape(-1)
        if not self.distributed:
            return a[None, :].copy()
        _, dist = _require_torch()
        t = self._tensor(a)
        out = [t.clone() for _ in range(self.world_size)]
        dist.all_gather(out, t)
        return np.stack([o.cpu().numpy() for o in out])

    def barrier(self) -> None:
        if not self.distributed:
            return
        _, dist = _require_torch()
        if self.backend == "nccl":
            dist.barrier(device_ids=[int(self.device.split(":")[1])])
        else:
            dist.barrier()

    def shutdown(self) -> None:
        """Destroy the process group if :func:`init` created it (idempotent)."""
        if self._owns_group:
            _, dist = _require_torch()
            if dist.is_initialized():
                dist.destroy_process_group()
            self._owns_group = False


def init(device: str | None = None, seed: int = 0, backend: str | None = None) -> DistContext:
    """Read torchrun's ``RANK`` / ``LOCAL_RANK`` / ``WORLD_SIZE`` / ``LOCAL_WORLD_SIZE``, pick the device and
    initialise the default process group.

    ``device``: ``"cuda"`` (each rank takes ``cuda:{LOCAL_RANK}``), ``"cpu"``, an explicit ``"cuda:k"`` (one rank
    per node only), or None (``"cuda"`` when Warp sees a GPU, else ``"cpu"``). ``backend``: default NCCL for CUDA,
    gloo for CPU. ``seed``: the run's seed; :attr:`DistContext.seed` is this rank's own (:func:`rank_seed`; without
    torchrun it is ``seed`` itself, so a single process behaves as before). A process group that already exists is
    reused (and not destroyed by :meth:`DistContext.shutdown`).
    """
    if not launched():
        dev = _resolve_device(device, 0, 1)
        return DistContext(device=dev, seed=int(seed))
    rank = _env_int("RANK", 0)
    world = _env_int("WORLD_SIZE", 1)
    local_rank = _env_int("LOCAL_RANK", 0)
    local_world = _env_int("LOCAL_WORLD_SIZE", 1)
    if not (0 <= rank < world):
        raise ValueError(f"RANK={rank} is not in [0, WORLD_SIZE={world})")
    dev = _resolve_device(device, local_rank, local_world)
    torch, dist = _require_torch()
    if backend is None:
        backend = "nccl" if dev.startswith("cuda") else "gloo"
    owns = False
    if not dist.is_initialized():
        kwargs = {}
        if backend == "nccl":
            index = int(dev.split(":")[1])
            torch.cuda.set_device(index)
            kwargs["device_id"] = torch.device("cuda", index)
        dist.init_process_group(backend=backend, **kwargs)
        owns = True
    else:
        backend = dist.get_backend()
    return DistContext(
        rank=rank,
        local_rank=local_rank,
        world_size=world,
        local_world_size=local_world,
        device=dev,
        seed=rank_seed(seed, rank),
        backend=backend,
        _owns_group=owns,
    )
