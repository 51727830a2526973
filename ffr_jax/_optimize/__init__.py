"""Topology optimisation: the design gradient as an optax-ready objective, a density filter, the
volume constraint, the optimality-criteria update, checkpoints and the `optimize` driver."""
