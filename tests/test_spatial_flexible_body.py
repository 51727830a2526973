"""Flexible spatial body (issue 26): the invariants' mass matrix and forces against node-by-node mechanics.

A small point-mass body (lumped `M = diag(m_n) ⊗ I_3`, random positions and modes, 3D and out of plane) is the
oracle: its kinetic energy `T = 1/2 sum_n m_n |rdot_n|^2` with `r_n = R + A(p) (c_n + Phi_n q)` is written node by
node, and Lagrange's equations of `T + 1/2 k rho^2 - 1/2 q^T K q` (automatic derivatives) give the mass matrix and
the quadratic-velocity and elastic forces that the invariants of `SpatialFlexibleBodyData` must reproduce.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ffr_jax._spatial import _flexible_body as flex
from ffr_jax._spatial._euler_parameters import rotation_matrix, unit
from ffr_jax._spatial._flexible_body_data import spatial_flexible_body_data

# Both sides are the same sums in a different order (invariants first, then products, or node by node): they agree
# to round-off, ~1e-15 relative per operation, times the few hundred operations of a 7 + 3 coordinate body.
ROUNDOFF = 1e-12
GRAVITY = jnp.array([0.3, -1.2, -9.81])


def _body(seed=0, n_nodes=7, n_q=3):
    rng = np.random.default_rng(seed)
    masses = rng.uniform(0.5, 2.0, n_nodes)
    positions = rng.normal(size=(n_nodes, 3))
    modes = 0.3 * rng.normal(size=(n_nodes, 3, n_q))
    k = rng.normal(size=(n_q, n_q))
    return masses, positions, modes, k @ k.T + n_q * np.eye(n_q)


def _state(seed=1, n_q=3):
    rng = np.random.default_rng(seed)
    p = rng.normal(size=4)
    p = 1.3 * p / np.linalg.norm(p)  # not of unit length: the equations hold for any |p|
    y = np.concatenate([rng.normal(size=3), p, 0.2 * rng.normal(size=n_q)])
    z = rng.normal(size=7 + n_q)
    return jnp.asarray(y), jnp.asarray(z)


def _lagrangian(masses, positions, modes, k_qq, reg):
    def nodes(y):
        return y[:3] + (positions + modes @ y[7:]) @ rotation_matrix(y[3:7]).T

    def lag(y, z):
        rdot = jax.jvp(nodes, (y,), (z,))[1]
        rho = unit(y[3:7])[0] @ z[3:7]
        return 0.5 * jnp.sum(masses * jnp.sum(rdot * rdot, axis=1)) + 0.5 * reg * rho**2 - 0.5 * y[7:] @ k_qq @ y[7:]
    return lag


@pytest.fixture(scope="module")
def computed():
    """Both sides at one random state, in one compiled program (eager JAX would cost seconds)."""
    masses, positions, modes, k = _body()
    data = spatial_flexible_body_data(masses, positions, modes, k, markers=(0, 3))
    reg = float(flex._regularisation(data))
    lag = _lagrangian(masses, positions, modes, k, reg)
    y, z = _state()

    def potential(y):  # -g . sum_n m_n r_n, node by node
        return -GRAVITY @ jnp.sum(masses[:, None] * (y[:3] + (positions + modes @ y[7:]) @ rotation_matrix(y[3:7]).T),
                                  axis=0)

    @jax.jit
    def run(data, y, z):
        m_ref = jax.hessian(lag, argnums=1)(y, z)
        f_ref = jax.grad(lag, argnums=0)(y, z) - jax.jacfwd(jax.grad(lag, argnums=1), argnums=0)(y, z) @ z
        t_ref = 0.5 * z @ m_ref @ z - 0.5 * reg * (unit(y[3:7])[0] @ z[3:7]) ** 2
        r_ref = y[:3] + rotation_matrix(y[3:7]) @ (positions[3] + modes[3] @ y[7:])
        return {"mass matrix": (flex.mass_matrix(data, y), m_ref),
                "forces": (flex.inertia_and_elastic_forces(data, y, z), f_ref),
                "kinetic energy": (flex.kinetic_energy(data, y, z), t_ref),
                "marker position": (flex.marker_position(data, 1, y), r_ref),
                "gravity force": (flex.gravity_force(data, GRAVITY, y), -jax.grad(potential)(y)),
                "gravity potential": (flex.gravity_potential(data, GRAVITY, y), potential(y))}

    return {name: (np.asarray(a), np.asarray(b)) for name, (a, b) in run(data, y, z).items()}


@pytest.mark.slow  # ~3 s on the shared machine (compiling the oracle's second derivatives)
@pytest.mark.parametrize("name", ["mass matrix", "forces", "kinetic energy", "marker position", "gravity force",
                                  "gravity potential"])
def test_invariants_equal_node_by_node(computed, name):
    """Mass matrix, forces (`M zdot = f`, `f = dL/dy - (d^2 L / dz dy) z`, Lagrange's equations), kinetic
    energy, marker position and gravity (`Q = -dV/dy` of `V = -g . sum_n m_n r_n`) from the invariants equal the
    node-by-node oracle."""
    got, want = computed[name]
    assert np.max(np.abs(got - want)) <= ROUNDOFF * np.max(np.abs(want)), name
    if name == "mass matrix":
        assert np.min(np.linalg.eigvalsh(got)) > 0.0, "mass matrix positive definite"


def test_bad_data_is_refused():
    masses, positions, modes, k = _body()
    with pytest.raises(ValueError, match="at least one mode"):
        spatial_flexible_body_data(masses, positions, modes[:, :, :0], k[:0, :0], markers=(0,))
    with pytest.raises(ValueError, match="modal_stiffness"):
        spatial_flexible_body_data(masses, positions, modes, -k, markers=(0,))
    with pytest.raises(ValueError, match="mass must be positive"):
        spatial_flexible_body_data(-masses, positions, modes, k, markers=(0,))
