"""jaxtyping aliases used across the package (checked in tests through pytest `addopts`)."""

import numpy as np
from jaxtyping import Array, Float

# A design may come from the user as a NumPy array; internal arrays are JAX arrays.
Design = Float[Array | np.ndarray, " n_design"]
# Designs of a case: one body's flat vector, or a dict {body name: vector} (sizes differ by body).
Designs = Design | dict[str, Float[Array | np.ndarray, " _n_body_design"]]
ElementField = Float[Array, " n_elements"]
Matrix = Float[Array, "n n"]
Modes = Float[Array, "n_dof n_modes"]
Vector = Float[Array, " n"]
Scalar = Float[Array, ""]
