"""Geometric stiffening of a planar design lifted into space (issue 26): the design map computes the six unit-case
matrices of a lifted body's [`SpatialGeometricStiffening`][], and the planar spinning beam embedded in space with it
gives the planar case's objective.

The six matrices of a lifted body satisfy exact identities: `K_3` (a spin about `z`) is the planar `K_geo` of the
same design, `K_1 + K_2 = K_3` (the load fields add up: `(0, c_y) + (c_x, 0) = (c_x, c_y)`), and the out-of-plane
cases vanish. Marked slow: the modes of a designed body compile (~5 s), the two simulations ~10-25 s each.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax as fj
from ffr_jax._dynamics._case import Case
from ffr_jax._design.design_map import DesignMap
from ffr_jax._dynamics._model import Partition
from ffr_jax._spatial._lift import uniform_lifted_body_data

NX, NY, N_MODES, T1, SPEED = 8, 2, 3, 0.05, 100.0
_Z = (0.0, 0.0, 1.0)


def _spatial_spinning_beam(rod):
    """`fj.cases.spinning_beam` with the rod lifted into space: hinge about `z` at A, the frame angle
    `speed * t` about `z`, the Euler normalisation, and the spatial stiffening; same initial state."""
    n_q = N_MODES
    scene = fj.Scene(
        bodies=(fj.Body("rod", uniform_lifted_body_data(rod)),),
        constraints=(fj.SpatialRevolute(0, 0, _Z), fj.SpatialAngleDriver(0, _Z, fj.ConstantSpeedLaw(SPEED)),
                     fj.EulerNormalisation(0)),
        forces=(fj.SpatialGeometricStiffening(body=0, modal_geometric_stiffness=jnp.zeros((6, n_q, n_q))),),
    )
    positions = np.concatenate([np.zeros(3), [1.0, 0.0, 0.0, 0.0], np.zeros(n_q)])
    positions[7] = 1e-3  # the planar case's perturbation of mode 1
    velocities = np.zeros(7 + n_q)
    velocities[3:7] = np.asarray(fj.euler_parameter_rates(positions[3:7], (0.0, 0.0, SPEED)))
    partition = Partition(independent=tuple(range(7, 7 + n_q)), dependent=tuple(range(7)))
    problem = fj.Problem(scene, T1, positions=positions, velocities=velocities, objective=fj.Compliance(body=0),
                         partition=partition)
    return Case(problem=problem, design_map=DesignMap({"rod": rod}))


@pytest.fixture(scope="module")
def cases():
    planar = fj.cases.spinning_beam(NX, NY, N_MODES, T1, speed=SPEED)
    rod = planar.design_map.only
    x = planar.initial_design(0.5) + 0.3 * jnp.asarray(np.random.default_rng(0).uniform(-1.0, 1.0, rod.n_design))
    return planar, _spatial_spinning_beam(rod), x


@pytest.mark.slow
def test_lifted_unit_cases_are_the_planar_geometric_stiffness(cases):
    planar, spatial, x = cases
    k_six = np.asarray(spatial.scene(x).forces[0].modal_geometric_stiffness)
    k_planar = np.asarray(planar.scene(x).forces[0].modal_geometric_stiffness)
    scale = np.max(np.abs(k_planar))
    # The same solves and sums (K_3) or one linear combination of them (K_1 + K_2): round-off, ~1e-13 of K.
    assert np.max(np.abs(k_six[2] - k_planar)) <= 1e-10 * scale, "K_3 (spin about z) is the planar K_geo"
    assert np.max(np.abs(k_six[0] + k_six[1] - k_six[2])) <= 1e-10 * scale, "K_1 + K_2 = K_3"
    assert np.all(k_six[3:5] == 0.0), "out-of-plane load cases do not stiffen in-plane modes"
    assert np.max(np.abs(k_six[5])) > 1e-3 * scale, "the in-plane shear case omega_x omega_y is not empty"


@pytest.mark.slow
def test_lifted_spinning_beam_equals_the_planar_one(cases):
    planar, spatial, x = cases
    psi_planar = fj.objective(planar, x)
    psi_spatial = fj.objective(spatial, x)
    # Both integrate the same equations at rtol 1e-10 (the lift is exact, the stiffening of a spin about z is
    # theta'^2 K_3 = theta'^2 K_geo): they agree to the solvers' accuracy, ~1e-9 of psi or better (measured 1e-15:
    # the same step sequence). Without the stiffening (or with K_3 not written by the design map) psi is 8.9 %
    # higher at this speed (fj.cases.spinning_beam(..., stiffening=False) at the same design).
    assert abs(float(psi_spatial) - float(psi_planar)) <= 1e-8 * abs(float(psi_planar))


@pytest.mark.slow
def test_lifted_unit_cases_carry_design_gradients(cases):
    _, spatial, x = cases
    direction = jnp.asarray(np.random.default_rng(1).normal(size=x.shape))
    # tr K_k is invariant under sign flips and rotations of the M-orthonormal modes, so central differences see a
    # smooth function of the design.
    traces = lambda x: jnp.trace(spatial.scene(x).forces[0].modal_geometric_stiffness, axis1=1, axis2=2)
    _, jvp = jax.jvp(traces, (x,), (direction,))
    h = 1e-5
    fd = (traces(x + h * direction) - traces(x - h * direction)) / (2 * h)
    # Central differences: truncation ~h^2 |f'''| ~ 1e-10 relative, round-off ~eps |f| / h ~ 1e-11 relative.
    scale = float(jnp.max(jnp.abs(traces(x))))
    assert float(jnp.max(jnp.abs(jvp - fd))) <= 1e-7 * scale, f"JVP {jvp} vs central differences {fd}"
    assert float(jnp.max(jnp.abs(jvp))) > 1e-3 * scale, "the design moves the stiffening"
