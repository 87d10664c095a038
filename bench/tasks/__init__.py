"""Whole environments: task env steps, rollouts with a solver, robot loading, multi-GPU scaling."""
