"""Spatial bodies in the floating frame of reference: Euler parameters, rigid and flexible body data and dynamics
(a planar FE body lifted into space among them), joints."""
