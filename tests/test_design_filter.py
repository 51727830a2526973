"""The density filter on any mesh: the rod's cone filter in element sizes, area-weighted averaging and volume."""

import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax
import ffr_jax._design as fd

# Two evaluations of the same weights by different operations: centroids up to 100 element sizes
# from the origin (the 100 x 6 rod) carry eps * 100 ~ 2e-14 of an element size in each distance.
ROUNDOFF = 1e-13


@pytest.mark.parametrize("nx, ny, radius", [(12, 4, 2.7), (10, 6, 0.9), (100, 6, 1.5)])
def test_rod_filter_counts_element_sizes(nx, ny, radius):
    """On the rod's grid the default radius is in element sizes (`scale = (dx, dy)`), elements of
    aspect ratio up to 5.6 (12 x 4): `H` is the cone filter of that definition, built here by brute force."""
    domain = fd.rod_domain(nx, ny)
    mesh = domain.mesh
    filt = ffr_jax.DensityFilter(ffr_jax.cases.rod_body(nx, ny, 2), radius)
    c = domain.design_centroids() / [mesh.dx, mesh.dy]
    w = np.maximum(radius - np.linalg.norm(c[:, None] - c[None], axis=-1), 0.0)
    np.testing.assert_allclose(filt.matrix(), w / w.sum(axis=1, keepdims=True), rtol=0, atol=ROUNDOFF, err_msg="H")
    x = jnp.asarray(np.random.default_rng(0).uniform(0.01, 1.0, domain.n_design))
    np.testing.assert_allclose(filt.transpose(x), np.asarray(filt.matrix()).T @ np.asarray(x), rtol=ROUNDOFF)
    np.testing.assert_allclose(filt.volume_weights(), np.asarray(filt.matrix()).sum(axis=0), rtol=ROUNDOFF,
                               err_msg="volume weights H^T 1 on a uniform grid")


def test_filter_on_an_unstructured_mesh_with_passive_elements():
    plate = fd.plate_with_hole(1.0, 0.2, 6, grading=1.5)  # element areas vary by a factor ~10
    ring = np.arange(plate.mesh.n_elements) % 6  # radial layer of each element
    domain = fd.DesignDomain.from_masks(plate.mesh, solid=ring == 0, void=ring == 5)
    filt = fd.DensityFilter(domain, radius=0.12, scale=(1.0, 1.0))  # radius in metres
    h = np.asarray(filt.matrix())
    assert h.shape == (domain.n_design, domain.n_design), "passive elements take no part"
    np.testing.assert_allclose(h.sum(axis=1), 1.0, rtol=ROUNDOFF, err_msg="rows sum to one")
    assert np.all(h >= 0.0) and np.count_nonzero(h) > 3 * domain.n_design, "an averaging map over neighbours"
    # Area weighting: w_ei a_i / sum_i w_ei a_i, so the mean over the domain weighted by area ...
    c = domain.design_centroids()
    d = np.linalg.norm(c[:, None] - c[None], axis=-1)
    w = np.maximum(0.12 - d, 0.0) * domain.design_areas()[None]
    np.testing.assert_allclose(h, w / w.sum(axis=1, keepdims=True), rtol=0, atol=ROUNDOFF, err_msg="cone weights")
    rng = np.random.default_rng(2)
    x, g = jnp.asarray(rng.uniform(size=domain.n_design)), jnp.asarray(rng.normal(size=domain.n_design))
    np.testing.assert_allclose(g @ filt(x), filt.transpose(g) @ x, rtol=1e-13, err_msg="transpose is the adjoint")
    # Volume weights: mean(c x) is the area fraction of the physical densities, sum(a H x) / sum(a).
    a = domain.design_areas()
    np.testing.assert_allclose(jnp.mean(filt.volume_weights() * x), a @ (h @ np.asarray(x)) / a.sum(), rtol=1e-13,
                               err_msg="volume = true area fraction")
    # The same with a projection: the constraint holds the area fraction of P_beta(H x), not the elements' mean
    # (which differs by percents here: the areas vary tenfold). Both sides sum the same products: round-off.
    projection = ffr_jax.HeavisideProjection(0.5, x_min=0.01)
    volume = ffr_jax.VolumeConstraint(0.5, filter=filt, projection=projection)
    x_phys = np.asarray(projection(filt(x), 8.0))
    np.testing.assert_allclose(volume.fraction(x, 8.0), a @ x_phys / a.sum(), rtol=1e-13, err_msg="projected volume")
    assert abs(a @ x_phys / a.sum() - x_phys.mean()) > 1e-3, "the check can tell the area fraction from the mean"
    assert np.array_equal(np.asarray(fd.DensityFilter(domain, 0.0).matrix()), np.eye(domain.n_design)), "r = 0: H = I"
    # The default unit on an unstructured mesh is the element size sqrt(mean area).
    h_unit = np.sqrt(np.mean(a))
    np.testing.assert_allclose(fd.DensityFilter(domain, 0.12 / h_unit).matrix(), h, rtol=0, atol=ROUNDOFF)
    with pytest.raises(ValueError, match="non-negative"):
        fd.DensityFilter(domain, -1.0)


def test_a_design_at_its_bounds_filters_to_a_valid_design():
    """A design at x_min (or 1) everywhere filters to x_min (or 1) up to round-off (the rows of H sum
    to 1 within n eps): the design check admits that round-off (1e-12) and still refuses a density a
    hair further out (1e-9), found when the OC optimiser drove the link's elements to x_min."""
    plate = fd.plate_with_hole(1.0, 0.2, 6, grading=1.5)
    domain = fd.DesignDomain(plate.mesh)
    filt = fd.DensityFilter(domain, radius=0.12, scale=(1.0, 1.0))
    x_min = 0.01
    for bound in (x_min, 1.0):
        x_phys = filt(jnp.full(domain.n_design, bound))
        assert float(jnp.max(jnp.abs(x_phys - bound))) < 1e-13, "H x stays at the bound up to round-off"
        domain.check(x_phys - 1e-14 * (1 if bound == x_min else -1), x_min).block_until_ready()
    with pytest.raises(Exception, match=r"must lie in \[x_min, 1\]"):
        domain.check(jnp.full(domain.n_design, x_min - 1e-9), x_min).block_until_ready()
