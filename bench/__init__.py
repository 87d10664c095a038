"""Benchmarks of wpctrl against a torch baseline (see bench/README.md)."""
