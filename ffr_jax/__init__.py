"""ffr_jax: flexible multibody dynamics (floating frame of reference) with exact design gradients."""

import jax as _jax

# float64 throughout: the one place the package sets it.
_jax.config.update("jax_enable_x64", True)
