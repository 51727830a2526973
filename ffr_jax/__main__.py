"""`python -m ffr_jax ...`: the `ffr-jax` command."""

import sys

from ._app._cli import main

sys.exit(main())
