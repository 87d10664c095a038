"""The actuator models and networks: their cost on a control step, their envelope, their fidelity."""
