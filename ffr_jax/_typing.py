"""jaxtyping aliases used across the package (checked in tests through pytest `addopts`)."""

from jaxtyping import Array, Float

Design = Float[Array, " n_design"]
ElementField = Float[Array, " n_elements"]
Matrix = Float[Array, "n n"]
Modes = Float[Array, "n_dof n_modes"]
Vector = Float[Array, " n"]
Scalar = Float[Array, ""]
