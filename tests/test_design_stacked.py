"""Stacked designs of several bodies (issue 14): the flat layout and the per-body density filter."""

import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax as fj
import ffr_jax._design as fd


@pytest.fixture(scope="module")
def two_rods():
    """Two rods of different grids (different element areas: 8 x 2 over 1 m, 6 x 4 over 0.8 m)."""
    coupler = fj.cases.rod_body(8, 2, 1, modal_solver=fd.DenseModes())
    rocker = fj.cases.rod_body(6, 4, 1, length=0.8, modal_solver=fd.DenseModes())
    return fj.DesignMap({"coupler": coupler, "rocker": rocker})


def test_layout_ravels_and_unravels_in_sorted_order(two_rods):
    layout = fj.StackedDesigns(two_rods)
    assert layout.names == ("coupler", "rocker") and layout.sizes == (12, 16) and layout.n_design == 28
    x = {"rocker": jnp.arange(16.0), "coupler": -jnp.arange(12.0)}
    flat = layout.ravel(x)
    np.testing.assert_array_equal(flat[:12], x["coupler"])
    np.testing.assert_array_equal(flat[12:], x["rocker"])
    back = layout.unravel(flat)
    assert set(back) == {"coupler", "rocker"}
    np.testing.assert_array_equal(back["rocker"], x["rocker"])


def test_layout_errors_name_the_body(two_rods):
    layout = fj.StackedDesigns(two_rods)
    with pytest.raises(ValueError, match=r"missing: \['rocker'\]"):
        layout.ravel({"coupler": jnp.zeros(12)})
    with pytest.raises(ValueError, match=r"extra: \['crank'\]"):
        layout.ravel({"coupler": jnp.zeros(12), "rocker": jnp.zeros(16), "crank": jnp.zeros(1)})
    with pytest.raises(ValueError, match=r"body 'rocker' has shape \(15,\), expected \(16,\)"):
        layout.ravel({"coupler": jnp.zeros(12), "rocker": jnp.zeros(15)})
    with pytest.raises(ValueError, match=r"expected \(28,\)"):
        layout.unravel(jnp.zeros(27))


def test_stacked_filter_is_each_bodys_filter_on_its_block(two_rods):
    """`H = diag(H_c, H_r)`: blocks equal the bodies' own filters exactly (the same arithmetic), `H^T` is
    its transpose (<H x, g> = <x, H^T g> to round-off, 1e-14 relative), and `mean(c x)` is the area
    fraction of both rods' physical densities together (element areas differ between the rods)."""
    filt = fj.StackedFilter.of(two_rods, {"coupler": 1.5, "rocker": 2.0})
    rng = np.random.default_rng(0)
    x = jnp.asarray(rng.uniform(0.1, 1.0, 28))
    g = jnp.asarray(rng.normal(size=28))
    own = {name: fj.DensityFilter(two_rods.bodies[name], r) for name, r in (("coupler", 1.5), ("rocker", 2.0))}
    hx = filt(x)
    np.testing.assert_array_equal(hx[:12], own["coupler"](x[:12]))
    np.testing.assert_array_equal(hx[12:], own["rocker"](x[12:]))
    np.testing.assert_allclose(float(hx @ g), float(x @ filt.transpose(g)), rtol=1e-14)
    areas = jnp.concatenate([own["coupler"].areas, own["rocker"].areas])
    assert not np.allclose(own["coupler"].areas[0], own["rocker"].areas[0]), "the test needs different element areas"
    np.testing.assert_allclose(float(jnp.mean(filt.volume_weights() * x)), float(areas @ hx / jnp.sum(areas)),
                               rtol=1e-14)
    with pytest.raises(ValueError, match=r"No filter radius for the designed bodies \['rocker'\]"):
        fj.StackedFilter.of(two_rods, {"coupler": 1.5})


def test_shared_volume_constraint_on_the_stacked_design(two_rods):
    """The loop's `VolumeConstraint` with a stacked filter holds the area fraction of both rods together."""
    filt = fj.StackedFilter.of(two_rods, 1.5)
    constraint = fj.VolumeConstraint(0.4, x_min=0.01, filter=filt)
    y = jnp.asarray(np.random.default_rng(1).uniform(-0.5, 1.5, 28))
    x = constraint.project(y)
    hx = filt(x)
    areas = jnp.concatenate([filt.filters["coupler"].areas, filt.filters["rocker"].areas])
    np.testing.assert_allclose(float(areas @ hx / jnp.sum(areas)), 0.4, rtol=1e-12)
    assert float(jnp.min(x)) >= 0.01 and float(jnp.max(x)) <= 1.0
