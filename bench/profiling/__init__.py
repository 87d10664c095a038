"""Where the time goes: host overhead, launch cost, Nsight Compute workloads."""
