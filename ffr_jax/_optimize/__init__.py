"""Topology optimisation: the design gradient as an optax-ready objective, a density filter, the
Heaviside projection, design constraints (volume, mass, first natural frequency, any function of the
design), the optimality-criteria update, the method of moving asymptotes, checkpoints and the
`optimize` driver."""
