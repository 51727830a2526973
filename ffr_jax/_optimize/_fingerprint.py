"""Fingerprints of what defines an optimisation run: the case, its objective, constraints and optimizer.

A checkpoint stores them; a resume compares them with the run that resumes it, so that a checkpoint
of another mesh with the same number of densities, of another volume bound or of other optimizer
settings is refused instead of being continued (issue 32).
"""

import hashlib
import re

import jax
import numpy as np

# Object reprs carry memory addresses (`<function f at 0x7f...>`), which differ between processes.
_ADDRESS = re.compile(r" at 0x[0-9a-fA-F]+")


def tree_fingerprint(tree) -> str:
    """A short hex digest of a pytree: its structure (static fields included) and every leaf's value.

    Arrays count by dtype, shape and bytes; other leaves (numbers, strings) by their `repr`;
    functions by their qualified name (their code is not compared). Equal trees built in different
    processes give equal digests.

    **Arguments:** `tree`: any pytree (equinox Modules, arrays, tuples, dicts, numbers, `None`).

    **Returns:** a 16-character hex string.
    """
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    digest = hashlib.sha256(_ADDRESS.sub("", str(treedef)).encode())
    for leaf in leaves:
        if isinstance(leaf, (jax.Array, np.ndarray, np.generic)):
            array = np.asarray(leaf)
            digest.update(f"{array.dtype}{array.shape}".encode())
            digest.update(np.ascontiguousarray(array).tobytes())
        elif callable(leaf):
            digest.update(getattr(leaf, "__qualname__", type(leaf).__qualname__).encode())
        else:
            digest.update(_ADDRESS.sub("", repr(leaf)).encode())
    return digest.hexdigest()[:16]
