"""``wpctrl.distributed.init`` for ranks on more than one node: ``RANK`` (global) differs from ``LOCAL_RANK`` (on
this node). The device comes from the local rank, the seed and the main-process role from the global one. A single
process stands in for one rank of the run: a process group (gloo, world size 1) already exists, which ``init`` reuses
as it does under torchrun; the CUDA device count is set to what the node would have."""

from __future__ import annotations

import pytest

from wpctrl import distributed

dist = pytest.importorskip("torch.distributed", reason="torch is a dev dependency")
if not dist.is_available():  # pragma: no cover - torch builds without torch.distributed
    pytest.skip("this torch build has no torch.distributed", allow_module_level=True)


@pytest.fixture
def group():
    """A one-process gloo group, destroyed afterwards (``init`` reuses it and must not destroy it)."""
    if dist.is_initialized():  # pragma: no cover - another test left one
        dist.destroy_process_group()
    dist.init_process_group("gloo", store=dist.HashStore(), rank=0, world_size=1)
    yield
    assert dist.is_initialized()
    dist.destroy_process_group()


def _node(monkeypatch, rank, local_rank, world, local_world, gpus):
    import warp as wp

    for k, v in (("RANK", rank), ("LOCAL_RANK", local_rank), ("WORLD_SIZE", world), ("LOCAL_WORLD_SIZE", local_world)):
        monkeypatch.setenv(k, str(v))
    monkeypatch.setattr(wp, "get_cuda_device_count", lambda: gpus)
    monkeypatch.setattr(wp, "is_cuda_available", lambda: gpus > 0)


@pytest.mark.parametrize(
    "rank, local_rank, device",
    [(3, 1, "cuda:1"), (2, 0, "cuda:0"), (5, 1, "cuda:1")],
)
def test_second_node_ranks_take_their_local_gpu_and_their_global_seed(monkeypatch, group, rank, local_rank, device):
    """Two nodes with 2 GPUs each plus a third node: global rank 3 is local rank 1 of its node and takes cuda:1 (not
    cuda:3, which the node does not have); its seed is the one of rank 3; it is not the main process."""
    _node(monkeypatch, rank, local_rank, world=6, local_world=2, gpus=2)
    for dev in ("cuda", None):
        ctx = distributed.init(device=dev, seed=11)
        assert (ctx.rank, ctx.local_rank, ctx.world_size, ctx.local_world_size) == (rank, local_rank, 6, 2)
        assert ctx.device == device
        assert ctx.seed == distributed.rank_seed(11, rank) != distributed.rank_seed(11, local_rank)
        assert not ctx.is_main and ctx.distributed and ctx.backend == "gloo"
        ctx.shutdown()  # a group it did not create: left alone (the fixture checks)
    cpu = distributed.init(device="cpu", seed=11)
    assert cpu.device == "cpu" and cpu.seed == distributed.rank_seed(11, rank)


def test_main_process_is_global_rank_zero_only(monkeypatch, group):
    _node(monkeypatch, 0, 0, world=4, local_world=2, gpus=2)
    assert distributed.init(device="cuda").is_main
    _node(monkeypatch, 2, 0, world=4, local_world=2, gpus=2)  # local rank 0 of the second node
    assert not distributed.init(device="cuda").is_main


def test_a_local_rank_past_the_nodes_gpus_is_refused_with_the_numbers(monkeypatch, group):
    _node(monkeypatch, 1, 2, world=4, local_world=3, gpus=2)
    with pytest.raises(ValueError, match=r"local rank 2 needs cuda:2, but this node has 2 CUDA device\(s\)"):
        distributed.init(device="cuda")
    _node(monkeypatch, 7, 1, world=8, local_world=2, gpus=2)  # a high global rank is fine
    assert distributed.init(device="cuda").device == "cuda:1"
    _node(monkeypatch, 4, 0, world=4, local_world=1, gpus=1)
    with pytest.raises(ValueError, match=r"RANK=4 is not in \[0, WORLD_SIZE=4\)"):
        distributed.init(device="cpu")
