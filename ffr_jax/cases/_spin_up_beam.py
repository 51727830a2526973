"""The spin-up beam of Kane, Ryan and Banerjee (1987) as a solid H11 body in space, with or without stiffening."""

import jax.numpy as jnp
import numpy as np
import scipy.linalg

from .._design.element.h11 import H11
from .._design.solid_assembly import SolidFEModel, solid_dense_matrix
from .._design.solid_geometric_stiffness import solid_centrifugal_geometric_stiffness
from .._design.solid_mesh import box_grid
from .._dynamics._model import Partition
from .._dynamics._problem import Problem
from .._objective._kinetic_energy import KineticEnergy
from .._scene._body import Body
from .._scene._gravity import Gravity
from .._scene._scene import Scene
from .._scene._spin_up_law import SpinUpLaw
from .._spatial._angle_driver import EulerNormalisation, SpatialAngleDriver
from .._spatial._revolute import SpatialRevolute
from .._spatial._solid_body_data import solid_body_data
from .._spatial._stiffening import SpatialGeometricStiffening

_Z = (0.0, 0.0, 1.0)


def _turn_about_z(angle):
    half = 0.5 * angle
    zero = jnp.zeros_like(half)
    return jnp.stack([jnp.cos(half), zero, zero, jnp.sin(half)])


def _prescribed_frame(t, y, scene):
    """The dependent coordinates `(R, p)`: the frame origin on the axis, turned by the driver's angle about `z`."""
    del y
    return jnp.concatenate([jnp.zeros(3), _turn_about_z(scene.constraints[1].angle(t))])


def spin_up_beam(nx: int = 40, n_modes: int = 6, t1: float = 20.0, *, stiffening: bool = True, gravity: float = 9.81,
                 speed: float = 6.0, t_spin: float = 15.0, length: float = 10.0, area: float = 4e-4,
                 inertia: float = 2e-7, youngs: float = 7e10, density: float = 3000.0) -> Problem:
    """Kane, Ryan and Banerjee's cantilever, clamped on the `z` axis and spun up about it, as a solid H11 body.

    **The beam** (defaults: Kane et al.'s `L = 10 m`, `A = 4e-4 m^2`, `I = 2e-7 m^4`, `E = 7e10 Pa`,
    `rho = 3000 kg/m^3`): a straight bar along the body `x` axis of `nx` x 1 x 1 [`H11`][] elements (pure bending is
    exact in H11 on boxes) with the square section `a x a`, `a = (12 I)^(1/4)`, so that the bending stiffness is
    `E I` both in the plane of rotation (chordwise, body `y`) and across it (flapwise, body `z`), and the density
    `rho A / a^2`, so that the mass per length is `rho A` (a solid rectangle cannot have both Kane's `A` and `I`;
    bending, the centrifugal axial force and hence the stiffening depend on `E I` and `rho A` only). Poisson ratio 0
    (Euler–Bernoulli bending). The frame origin is the centre of the clamped root face at the axis; the modes are
    the `n_modes` lowest clamped modes (in pairs: chordwise and flapwise bending have the same frequencies; the
    torsion and axial modes are far above the first pairs). Markers: 0 the root face (on the axis), 1 the tip face.

    **The motion**: a [`SpatialRevolute`][] about `z` at the root, a [`SpatialAngleDriver`][] with the
    [`SpinUpLaw`][] `(speed, t_spin)` (Kane et al.'s `Omega_s = 6 rad/s`, `T = 15 s`) and the Euler normalisation;
    [`Gravity`][] `gravity` along `-z` (along the spin axis: flapwise bending, stiffened by the rotation; 0 to leave
    it out). With `stiffening` the scene holds a [`SpatialGeometricStiffening`][] of the beam from the six unit
    centrifugal load cases with the root clamped. The beam starts undeformed and at rest. Independent coordinates:
    the modal ones; dependent: the frame `(R, p)`, prescribed. Objective: the kinetic energy (a placeholder: the
    benchmark reads the tip deflection `marker_modes[1] @ q`).

    **Returns:** a [`Problem`][] (the beam is not designed: no design map).
    """
    if not (isinstance(nx, int) and nx >= 2 and isinstance(n_modes, int) and n_modes >= 1):
        raise ValueError(f"spin_up_beam needs nx >= 2 elements and n_modes >= 1 (ints), got nx={nx!r}, "
                         f"n_modes={n_modes!r}.")
    if t1 <= 0:
        raise ValueError(f"t1 must be positive, got {t1}.")
    side = (12.0 * inertia) ** 0.25
    mesh = box_grid(nx, 1, 1, length, side, side)
    model = SolidFEModel(mesh, H11(), poisson=0.0)
    youngs_e = jnp.full(model.n_elements, float(youngs))
    density_e = jnp.full(model.n_elements, density * area / side**2)
    k = solid_dense_matrix(model, youngs_e, "stiffness")
    m = solid_dense_matrix(model, density_e, "mass")
    nodes = np.asarray(mesh.nodes)
    root = np.flatnonzero(np.isclose(nodes[:, 0], 0.0))
    tip = np.flatnonzero(np.isclose(nodes[:, 0], length))
    fixed = np.sort(np.concatenate([3 * root, 3 * root + 1, 3 * root + 2]))
    free = np.setdiff1d(np.arange(model.n_dof), fixed)
    k_np, m_np = np.asarray(k), np.asarray(m)
    _, vectors = scipy.linalg.eigh(k_np[np.ix_(free, free)], m_np[np.ix_(free, free)], subset_by_index=[0, n_modes - 1])
    modes = np.zeros((model.n_dof, n_modes))
    modes[free] = vectors
    modes = jnp.asarray(modes)
    data = solid_body_data(nodes, k, m, modes, (tuple(int(n) for n in root), tuple(int(n) for n in tip)))

    forces = []
    if gravity:
        forces.append(Gravity((0.0, 0.0, -float(gravity))))
    if stiffening:
        forces.append(SpatialGeometricStiffening(
            body=0, modal_geometric_stiffness=solid_centrifugal_geometric_stiffness(
                model, youngs_e, density_e, modes, tuple(int(d) for d in fixed))))
    scene = Scene(
        bodies=(Body("beam", data),),
        constraints=(SpatialRevolute(0, 0, _Z), SpatialAngleDriver(0, _Z, SpinUpLaw(speed, t_spin)),
                     EulerNormalisation(0)),
        forces=tuple(forces),
    )
    positions = np.concatenate([np.zeros(3), [1.0, 0.0, 0.0, 0.0], np.zeros(n_modes)])
    independent = tuple(range(7, 7 + n_modes))
    partition = Partition(independent=independent, dependent=tuple(range(7)))
    return Problem(scene, t1, positions=positions, objective=KineticEnergy(), partition=partition,
                   dependent_guess=_prescribed_frame)
