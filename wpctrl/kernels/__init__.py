"""Private Warp kernels of wpctrl (not a public import path)."""
