"""The dynamics, in the order the data flows: the problem (scene, time span, initial state, objective), the
body kinematics and mass matrices, the minimal model (coordinate partition, Newton's method for the dependent
coordinates), the simulation, and a case (a design map in front of a problem)."""
