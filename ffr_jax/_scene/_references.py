"""Body and marker indices of scene elements and objective terms, checked against the scene's bodies.

A body or marker index reaches the dynamics as a static index into a tuple of bodies or into a
body's `(n_markers, 2)` marker array. Python refuses a body index past the end, but a negative one
counts from the end, and JAX's gather clamps a marker index past the end to the last marker: the
motion of a wrong point, without a word. So every index is checked once, where the element meets
the scene ([`Scene`][] for joints, drivers and forces, [`Problem`][] for the objective's terms).
"""

import dataclasses
import numbers

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

# (body field, marker field or None) pairs that scene elements and objective terms use.
_PAIRS = (("body", "marker"), ("body_i", "marker_i"), ("body_j", "marker_j"))


def _ground_end(names: set, body_field: str, body) -> bool:
    """`body_j = -1` of an element with a ground point (`SpringDamper(ground_point=...)`, a spatial
    revolute's `point`): that end is the inertial point, not a body. An element without a ground point
    (a planar `Revolute`) has no such meaning for `-1`, and it is refused like any other index."""
    return body_field == "body_j" and body == -1 and bool(names & {"ground_point", "point"})


def _children(element):
    """The modules held by `element`'s fields (terms of sums, laws, paths), for the recursive check."""
    for f in dataclasses.fields(element):
        value = element.__dict__.get(f.name)
        items = value if isinstance(value, (tuple, list)) else (value,)
        for item in items:
            if isinstance(item, eqx.Module):
                yield item


def check_references(element, scene, where: str) -> None:
    """Raise a `ValueError` naming `where`, the field, the index and the valid range when a body or
    marker index of `element` (or of a module inside it) does not exist in `scene`.

    **Arguments:**
    - `element`: a joint, driver, force element or objective term (any equinox Module).
    - `scene`: the [`Scene`][] it acts on (only its bodies are read).
    - `where`: how the message names the element, e.g. `"constraints[1] (Revolute)"`.
    """
    names = {f.name for f in dataclasses.fields(element)}
    n_bodies = len(scene.bodies)
    label = f"{where} ({type(element).__name__})" if type(element).__name__ not in where else where
    for body_field, marker_field in _PAIRS:
        if body_field not in names:
            continue
        body = element.__dict__.get(body_field)
        if _ground_end(names, body_field, body):
            continue
        _check_body(body, f"{label}.{body_field}", n_bodies, scene)
        if marker_field in names:
            marker = element.__dict__.get(marker_field)
            n_markers = scene.bodies[body].data.marker_positions.shape[0]
            if isinstance(marker, bool) or not isinstance(marker, numbers.Integral) or not 0 <= marker < n_markers:
                raise ValueError(
                    f"{label}.{marker_field} = {marker!r} is not a marker of body {body} "
                    f"({scene.bodies[body].name!r}), which has {n_markers} marker{'s' if n_markers != 1 else ''}: "
                    f"valid indices are 0 to {n_markers - 1}." if n_markers else
                    f"{label}.{marker_field} = {marker!r}: body {body} ({scene.bodies[body].name!r}) has no markers; "
                    "give its body data marker_positions."
                )
    if "bodies" in names and element.__dict__.get("bodies") is not None:
        for k, body in enumerate(element.__dict__["bodies"]):
            _check_body(body, f"{label}.bodies[{k}]", n_bodies, scene)
    for child in _children(element):
        check_references(child, scene, f"{label} > {type(child).__name__}")


def _check_body(body, what: str, n_bodies: int, scene) -> None:
    if isinstance(body, bool) or not isinstance(body, numbers.Integral) or not 0 <= body < n_bodies:
        raise ValueError(
            f"{what} = {body!r} is not a body of the scene: valid indices are 0 to {n_bodies - 1} "
            f"(bodies {[b.name for b in scene.bodies]}; scene.body_index(name) gives the index of a name)."
            + (" A negative index does not count from the end here." if isinstance(body, numbers.Integral)
               and not isinstance(body, bool) and body < 0 else "")
        )


def finite_vector(value, name: str, size: int | tuple[int, ...]):
    """`value` as a finite float64 vector of one of the lengths `size`, or a `ValueError` naming `name`
    (a NaN in a point, a direction or gravity otherwise surfaced as Newton's "cannot assemble")."""
    sizes = (size,) if isinstance(size, int) else tuple(size)
    if any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(value)):
        return jnp.asarray(value, dtype=float)  # built inside a traced function: its values are not known yet
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a vector of {' or '.join(map(str, sizes))} numbers, got {value!r}.") from None
    if array.shape not in {(n,) for n in sizes}:
        raise ValueError(f"{name} must have shape {' or '.join(f'({n},)' for n in sizes)}, got {array.shape}.")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite, got {array.tolist()}.")
    return jnp.asarray(array)
