"""Mutations: distributed."""

from .model import M

MUTATIONS = [
    M(
        "device_from_global_rank",
        "wpctrl/distributed.py",
        "dev = _resolve_device(device, local_rank, local_world)",
        "dev = _resolve_device(device, rank, local_world)",
        "a rank on a second node picks its GPU by its global rank (cuda:RANK, not cuda:LOCAL_RANK)",
        ("tests/test_distributed_ranks.py",),
    ),
    M(
        "seed_from_local_rank",
        "wpctrl/distributed.py",
        "seed=rank_seed(seed, rank),",
        "seed=rank_seed(seed, local_rank),",
        "ranks with the same local rank on different nodes draw the same seed",
        ("tests/test_distributed_ranks.py",),
    ),
    M(
        "main_process_by_local_rank",
        "wpctrl/distributed.py",
        "        return self.rank == 0\n",
        "        return self.local_rank == 0\n",
        "the first rank of every node acts as the main process (prints, writes files)",
        ("tests/test_distributed_ranks.py",),
    ),
    M(
        "rank_seed_additive",
        "wpctrl/distributed.py",
        "return int(np.random.SeedSequence([int(seed), int(rank)]).generate_state(1)[0])",
        "return int(seed) + int(rank)",
        "rank seeds are seed + rank (run 0's rank 1 repeats run 1's rank 0)",
        ("tests/test_distributed.py",),
    ),
]
