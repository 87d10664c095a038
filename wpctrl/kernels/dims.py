"""CUDA block sizes of wpctrl's kernels (measured; ignored on the CPU)."""

PER_ENV_BLOCK_DIM = 32
"""CUDA block size of the one-thread-per-env kernels (EE solve, fused inertia, coupled drive): each thread runs a long
serial computation, so small blocks spread a few thousand envs over every SM (Warp's default of 256 threads per block
puts 4,096 envs on 16 of an H200's 132 SMs). Ignored on the CPU."""


def step_block_dim(device, num_envs: int) -> int:
    """CUDA block size of the per-step kernels (one thread per env, :mod:`wpctrl.kernels.pd_step`): 64 threads.
    Measured on an H200 (`python -m bench step-block-dim`; captured implicit step): 4k envs 3.62 / 3.36 /
    5.64 / 8.92 µs and 1M envs 190 / 188 / 187 / 235 µs for 32 / 64 / 128 / 256 threads: small blocks spread a few
    thousand envs over every SM, and 256-thread blocks of these register-heavy threads lose occupancy at 1M."""
    return 64
