"""Test configuration: float64 and strict dtype promotion for every test.

`ffr_jax` is deliberately not imported here: the jaxtyping import hook from `addopts`
(`--jaxtyping-packages=ffr_jax,...`) must be installed before the package is first imported,
and root conftest files load before that hook.
"""

import jax


jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")
