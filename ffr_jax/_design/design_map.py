"""The design map: designs of the designed bodies -> their body data -> the scene `p(x)`.

`designs {name: x_b} -> (for each designed body b) body data p_b(x_b) -> scene with those data`

The map is the design stage of the data flow; a [`Case`][] puts it in front of a [`Problem`][]
(`psi(x) = psi(problem with scene p(x))`), and the gradient of `psi` with respect to every design
is one VJP of this map after any sensitivity method — its cost grows with the number of retained
modes, not with the number of densities or of bodies.
"""

import abc

import equinox as eqx

from .._errors import clean_errors
from .._scene._body_data import BodyData
from .._scene._scene import Scene
from .._scene._stiffening import GeometricStiffening
from .designed_body import DesignedBody
from .._spatial._flexible_body_data import SpatialFlexibleBodyData
from .._spatial._lifted_stiffening import lifted_body_data_and_geometric_stiffness
from .._spatial._stiffening import SpatialGeometricStiffening
from .modal.basis import ModalBasis


class AbstractDesignMap(eqx.Module):
    """A design → parameters map: writes the data of the designed bodies for given designs into a scene."""

    @property
    @abc.abstractmethod
    def n_design(self) -> int:
        """Number of design variables (over all designed bodies)."""

    @abc.abstractmethod
    def initial_design(self, value=0.5):
        """A uniform design."""

    @abc.abstractmethod
    def check(self, designs):
        """Validate designs (structure and shapes at trace time, values at run time); return them as float."""

    @abc.abstractmethod
    def check_scene(self, scene: Scene) -> None:
        """Raise a `ValueError` if `scene` cannot take this map's data (called once, by the case)."""

    @abc.abstractmethod
    def __call__(self, designs, scene: Scene) -> Scene:
        """The scene `p(x)`: `scene` with the designed bodies' data for `designs`."""


def _is_mapping(designs) -> bool:
    return isinstance(designs, dict)


class DesignMap(AbstractDesignMap):
    """Designed bodies of a scene, keyed by the scene's body names: `DesignMap({"rod": DesignedBody(...)})`.

    **Designs** are a dict `{name: x_b}` with one `(n_design_b,)` density vector per designed body
    (missing or extra bodies, and wrong shapes, are `ValueError`s naming the body). With exactly
    one designed body a flat array is accepted as well. Results per body (`frequencies`, `modes`,
    `body_data`) come in the form of the design: a dict for a dict, one body's result for an
    array. Gradients with respect to the designs (`ffr_jax.value_and_grad(case, designs)`) have
    the structure of the designs.

    A scene body with [`SpatialFlexibleBodyData`][] gets the designed (planar) body lifted into space
    (`ffr_jax._spatial._lift`: nodes at `z = 0`, in-plane modes).

    The map recomputes, besides the body data, the design-dependent data of each designed body's
    [`GeometricStiffening`][] in the scene (`K_geo(x_b)`), or for a lifted body the six matrices of its
    [`SpatialGeometricStiffening`][]; a scene without such an effect computes nothing more.

    **Arguments:**
    - `bodies`: `{scene body name: DesignedBody}` (at least one).
    """

    bodies: dict[str, DesignedBody]

    def __init__(self, bodies):  # checked below (a clear message rather than an annotation's)
        if isinstance(bodies, DesignedBody):
            raise TypeError("DesignMap takes a dict {scene body name: DesignedBody}, e.g. DesignMap({'rod': body}).")
        if not isinstance(bodies, dict) or not bodies:
            raise TypeError(f"DesignMap takes a non-empty dict {{scene body name: DesignedBody}}, got {bodies!r}.")
        for name, body in bodies.items():
            if not isinstance(name, str):
                raise TypeError(f"Designed bodies are keyed by the scene's body names (str), got {name!r}.")
            if not isinstance(body, DesignedBody):
                raise TypeError(f"DesignMap: body {name!r} must be a DesignedBody, got {type(body).__name__}.")
        self.bodies = dict(bodies)

    # --- layout ---------------------------------------------------------------------------------
    @property
    def names(self) -> tuple[str, ...]:
        """The designed bodies' names, sorted (the order of the dict's pytree leaves)."""
        return tuple(sorted(self.bodies))

    @property
    def only(self) -> DesignedBody:
        """The designed body of a map with exactly one (a `ValueError` otherwise)."""
        if len(self.bodies) != 1:
            raise ValueError(f"This design map has {len(self.bodies)} designed bodies {list(self.names)}; pick one, "
                             "e.g. design_map.bodies['name'].")
        return next(iter(self.bodies.values()))

    @property
    def n_design(self) -> int:
        """Number of design variables over all designed bodies."""
        return sum(body.n_design for body in self.bodies.values())

    @property
    def design_sizes(self) -> dict[str, int]:
        """Number of design variables of each designed body."""
        return {name: body.n_design for name, body in self.bodies.items()}

    def initial_design(self, value=0.5):
        """A uniform design: `x_b = value` for every body (`value` a float, or a dict of floats by body).

        **Returns:** a flat `(n_design,)` array when the map has one designed body and `value` is a
        float, else a dict `{name: (n_design_b,)}`.
        """
        if _is_mapping(value):
            self._check_names(value, "value")
            return {name: body.initial_design(value[name]) for name, body in self.bodies.items()}
        if len(self.bodies) == 1:
            return self.only.initial_design(value)
        return {name: body.initial_design(value) for name, body in self.bodies.items()}

    def _check_names(self, designs: dict, what: str = "design") -> None:
        missing = [n for n in self.names if n not in designs]
        extra = [n for n in designs if n not in self.bodies]
        if missing:
            raise ValueError(f"The {what} has no entry for the designed bod{'y' if len(missing) == 1 else 'ies'} "
                             f"{', '.join(map(repr, missing))} (designed bodies: {list(self.names)}); give one "
                             "density vector per body, e.g. case.initial_design(0.5).")
        if extra:
            raise ValueError(f"The {what} has entries for {', '.join(map(repr, extra))}, which "
                             f"{'is not a designed body' if len(extra) == 1 else 'are not designed bodies'} "
                             f"(designed bodies: {list(self.names)}).")

    def as_dict(self, designs) -> dict:
        """The designs as a dict `{name: x_b}` (a flat array is the one body's design); no value checks."""
        if _is_mapping(designs):
            self._check_names(designs)
            return dict(designs)
        if len(self.bodies) != 1:
            raise ValueError(f"This case has {len(self.bodies)} designed bodies {list(self.names)}: pass the design "
                             "as a dict {name: density vector}, e.g. case.initial_design(0.5).")
        return {self.names[0]: designs}

    def _like(self, designs, results: dict):
        """`results` (a dict by body) in the form of `designs`."""
        return results if _is_mapping(designs) else results[self.names[0]]

    def _checked(self, designs) -> dict:
        by_body = self.as_dict(designs)
        return {name: body.domain.check(by_body[name], body.material.x_min, body=name)
                for name, body in self.bodies.items()}

    def check(self, designs):
        """Validate designs: bodies and shapes at trace time, NaN and bounds at run time (messages name the body).

        **Returns:** the designs as float arrays, in their form (dict or flat array).
        """
        return self._like(designs, self._checked(designs))

    def check_scene(self, scene: Scene) -> None:
        """Every designed body is a body of `scene` whose data have this body's numbers of shape vectors and markers."""
        for name, body in self.bodies.items():
            data = scene.bodies[scene.body_index(name)].data
            n_q = body.reduction.n_q(body.mesh)
            if data.n_modes != n_q or data.marker_positions.shape[0] != len(body.markers):
                raise ValueError(
                    f"The scene's body {name!r} has {data.n_modes} shape vectors and {data.marker_positions.shape[0]} "
                    f"markers, but its DesignedBody gives {n_q} and {len(body.markers)}: build the scene's body from "
                    "the designed body, Body(name, designed_body.uniform_body_data())."
                )

    # --- the map ----------------------------------------------------------------------------------
    def __call__(self, designs, scene: Scene) -> Scene:
        """The parameter pytree `p(x)`: `scene` with every designed body's data (and `K_geo`) for `designs`."""
        by_body = self._checked(designs)
        for name, body in self.bodies.items():
            index = scene.body_index(name)
            stiffening = [k for k, force in enumerate(scene.forces)
                          if isinstance(force, GeometricStiffening) and force.body == index]
            if isinstance(scene.bodies[index].data, SpatialFlexibleBodyData):  # a planar design lifted into space
                if stiffening:
                    raise ValueError(f"The spatial body {name!r} has a (planar) GeometricStiffening; a spatial body "
                                     f"takes SpatialGeometricStiffening(body={index}, modal_geometric_stiffness="
                                     "jnp.zeros((6, n_q, n_q))), whose six matrices the design map computes.")
                spatial = [k for k, force in enumerate(scene.forces)
                           if isinstance(force, SpatialGeometricStiffening) and force.body == index]
                data, k_six = lifted_body_data_and_geometric_stiffness(body, by_body[name], stiffening=bool(spatial))
                scene = eqx.tree_at(lambda s: s.bodies[index].data, scene, data)
                for k in spatial:
                    scene = eqx.tree_at(lambda s: s.forces[k].modal_geometric_stiffness, scene, k_six)
                continue
            data, k_geo = body.body_data_and_geometric_stiffness(by_body[name], stiffening=bool(stiffening))
            scene = eqx.tree_at(lambda s: s.bodies[index].data, scene, data)
            for k in stiffening:
                scene = eqx.tree_at(lambda s: s.forces[k].modal_geometric_stiffness, scene, k_geo)
        return scene

    # --- per body ---------------------------------------------------------------------------------
    @clean_errors  # a body refused by the modal check: a DesignError, not equinox's runtime error
    def modes(self, designs) -> ModalBasis | dict[str, ModalBasis]:
        """The modal basis of each designed body (in the form of `designs`)."""
        by_body = self._checked(designs)
        return self._like(designs, {n: b.modes(by_body[n]) for n, b in self.bodies.items()})

    @clean_errors
    def frequencies(self, designs):
        """Retained natural frequencies in Hz of each designed body, `(n_modes,)` each (in the form of `designs`)."""
        by_body = self._checked(designs)
        return self._like(designs, {n: b.frequencies(by_body[n]) for n, b in self.bodies.items()})

    @clean_errors
    def body_data(self, designs) -> BodyData | dict[str, BodyData]:
        """The body data of each designed body (in the form of `designs`)."""
        by_body = self._checked(designs)
        return self._like(designs, {n: b.body_data(by_body[n]) for n, b in self.bodies.items()})
