"""jaxtyping aliases used across the package (checked in tests through pytest `addopts`)."""

import numpy as np
from jaxtyping import Array, ArrayLike, Float

# A design may come from the user as a NumPy array; internal arrays are JAX arrays.
Design = Float[Array | np.ndarray, " n_design"]
# A design as given to the public functions: anything array-like; the design map checks it
# (complex refused, integers and float32 converted) with its own message.
DesignInput = ArrayLike
ElementField = Float[Array, " n_elements"]
Matrix = Float[Array, "n n"]
Modes = Float[Array, "n_dof n_modes"]
Vector = Float[Array, " n"]
Scalar = Float[Array, ""]
