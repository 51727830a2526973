"""A scene: bodies, constraints and force elements, and its redundant-coordinate functions."""

import equinox as eqx
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import jax.tree_util as jtu

from .._dynamics._body_dynamics import body_coordinate_names, body_inertia_and_elastic_forces, body_kinetic_energy, body_mass_matrix, body_strain_energy, marker_position
from ._base import AbstractConstraint, AbstractForce
from ._body import Body
from ._laws import AbstractLaw
from ._references import check_references


class Scene(eqx.Module):
    """A planar multibody system in redundant coordinates `y_r = (y_1, ..., y_p)`, `y_b = (R, theta, q)`.

    The scene is the parameter pytree `p` of the dynamics: every array in it (body data, spring
    constants, crank radius, law coefficients, gravity) can be differentiated. Which elements
    exist is static structure: an effect that is not in `forces` is not traced at all.
    """

    bodies: tuple[Body, ...]
    constraints: tuple[AbstractConstraint, ...]
    forces: tuple[AbstractForce, ...] = ()

    def __check_init__(self):
        names = [b.name for b in self.bodies]
        if len(set(names)) != len(names):
            raise ValueError(f"Body names must be unique, got {names}.")
        for group in ("constraints", "forces"):
            for k, element in enumerate(getattr(self, group)):
                check_references(element, self, f"Scene {group}[{k}]")

    @property
    def sizes(self) -> tuple[int, ...]:
        return tuple(b.n_coordinates for b in self.bodies)

    @property
    def offsets(self) -> tuple[int, ...]:
        out, acc = [], 0
        for s in self.sizes:
            out.append(acc)
            acc += s
        return tuple(out)

    @property
    def n_coordinates(self) -> int:
        return sum(self.sizes)

    @property
    def n_constraints(self) -> int:
        return sum(c.n_equations for c in self.constraints)

    @property
    def breakpoints(self) -> tuple[float, ...]:
        """Times where a law of the scene (a driver, a force magnitude) switches pieces, sorted.

        The step-size controller lands on them (`jump_ts`), so that no step straddles a kink.
        """
        laws = jtu.tree_leaves(self, is_leaf=lambda node: isinstance(node, AbstractLaw))
        return tuple(sorted({float(b) for law in laws if isinstance(law, AbstractLaw) for b in law.breakpoints}))

    def body_index(self, name: str) -> int:
        for i, b in enumerate(self.bodies):
            if b.name == name:
                return i
        raise ValueError(f"No body named {name!r}; bodies are {[b.name for b in self.bodies]}.")

    def coordinate_names(self) -> tuple[str, ...]:
        names = []
        for b in self.bodies:
            names += [f"{b.name}.{n}" for n in body_coordinate_names(b.data)]
        return tuple(names)

    def body_coordinates(self, b: int, v):
        """The slice of a redundant vector (positions or velocities) that belongs to body `b`."""
        o = self.offsets[b]
        return v[o : o + self.sizes[b]]

    def scatter(self, b: int, v_b):
        """Embed body `b`'s vector into a zero redundant vector."""
        o = self.offsets[b]
        return jnp.zeros(self.n_coordinates, v_b.dtype).at[o : o + self.sizes[b]].set(v_b)

    def marker_position(self, b: int, marker: int, y_r):
        return marker_position(self.bodies[b].data, marker, self.body_coordinates(b, y_r))

    def mass_matrix(self, y_r):
        """Block-diagonal redundant mass matrix `M(y_r)` (paper eq. 8 per body)."""
        return jsl.block_diag(*[body_mass_matrix(b.data, self.body_coordinates(i, y_r)) for i, b in enumerate(self.bodies)])

    def applied_forces(self, t, y_r, z_r):
        """`h_a = h_p + h_b - h_omega - h_e` over all bodies (paper eq. 8), plus force elements."""
        h = jnp.concatenate(
            [
                body_inertia_and_elastic_forces(b.data, self.body_coordinates(i, y_r), self.body_coordinates(i, z_r))
                for i, b in enumerate(self.bodies)
            ]
        )
        for f in self.forces:
            h = h + f.generalized_force(t, y_r, z_r, self)
        return h

    def constraint_residual(self, t, y_r):
        """`c(y_r, t, p)`, shape `(n_c,)` (paper eq. 9)."""
        if not self.constraints:
            return jnp.zeros((0,), y_r.dtype)
        return jnp.concatenate([c.residual(t, y_r, self) for c in self.constraints])

    def kinetic_energy(self, y_r, z_r):
        return sum(body_kinetic_energy(b.data, self.body_coordinates(i, y_r), self.body_coordinates(i, z_r))
                   for i, b in enumerate(self.bodies))

    def potential_energy(self, t, y_r):
        """Strain energy of all flexible bodies plus the potentials of conservative force elements."""
        total = jnp.zeros(())
        for i, b in enumerate(self.bodies):
            total = total + body_strain_energy(b.data, self.body_coordinates(i, y_r))
        for f in self.forces:
            total = total + f.potential_energy(t, y_r, self)
        return total
