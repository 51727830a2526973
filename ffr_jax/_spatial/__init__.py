"""Spatial bodies in the floating frame of reference: Euler parameters, rigid body data and dynamics, joints."""
