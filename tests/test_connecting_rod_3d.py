"""The worked 3-D example (issue 27): the connecting rod on an offset crank pin, the time-averaged objective, the
pictures of a solid design and its VTU series, and the `connecting-rod` CLI scene.

Default tests need no simulation (the objective term, the surface of a set of hexahedra, input checks, the CLI
scene's settings); the slow ones mesh the coarsest rod (`size=0.02`, one layer) and simulate it (one compiled motion
program for both pin offsets and the VTU series).
"""

import jax.numpy as jnp
import meshio
import numpy as np
import pytest

import ffr_jax as fj
from ffr_jax._app._cli_scenes import SCENE_DEFAULTS, case_name, scene_settings
from ffr_jax._app._solid_render import solid_surface


def test_time_window_is_the_time_average_over_the_window():
    term = fj.FunctionIntegrand(lambda t, y_r, scene: 3.0 + t)
    window = fj.TimeWindow(term, 0.5, 2.5)
    assert window.breakpoints == (0.5, 2.5)
    # Outside the window nothing, inside the term over the window's length (exact arithmetic on these numbers).
    for t, expected in ((0.0, 0.0), (0.4999, 0.0), (0.5, 3.5 / 2.0), (2.0, 5.0 / 2.0), (2.5, 5.5 / 2.0), (3.0, 0.0)):
        assert float(window(jnp.asarray(t), jnp.zeros(1), jnp.zeros(1), None)) == pytest.approx(expected, abs=1e-15)
    # Its integral is the mean of the term: trapezoidal rule, exact for the linear term.
    ts = np.linspace(0.5, 2.5, 11)
    values = [float(window(jnp.asarray(t), jnp.zeros(1), jnp.zeros(1), None)) for t in ts]
    assert np.trapezoid(values, ts) == pytest.approx(3.0 + 1.5, rel=1e-14)


def test_time_window_refuses_an_empty_window_and_a_non_term():
    with pytest.raises(ValueError, match="t_end > t_start"):
        fj.TimeWindow(fj.Compliance(body=0), 1.0, 1.0)
    with pytest.raises(ValueError, match="objective term"):
        fj.TimeWindow(lambda t: t, 0.0, 1.0)


def test_surface_of_a_set_of_hexahedra_is_its_boundary_outward():
    mesh = fj.box_grid(2, 2, 2, 2.0, 2.0, 2.0)  # 8 unit cubes
    elements = np.asarray(mesh.elements)
    # All cubes: 6 sides of 4 unit squares; one cube: its 6 faces; two cubes side by side: 10 faces.
    assert solid_surface(elements, "hexahedron", np.ones(8, bool)).shape == (24, 4)
    one = np.zeros(8, bool)
    one[0] = True
    faces = solid_surface(elements, "hexahedron", one)
    assert faces.shape == (6, 4)
    centroids = mesh.nodes[elements].mean(axis=1)
    neighbour = int(np.argmin(np.where(one, np.inf, np.linalg.norm(centroids - centroids[0], axis=1))))
    two = one.copy()
    two[neighbour] = True
    assert solid_surface(elements, "hexahedron", two).shape == (10, 4)
    assert solid_surface(elements, "hexahedron", np.zeros(8, bool)).shape == (0, 4)
    # Outward: each face's normal (its numbering's right-hand rule) points away from the cube's centre.
    points = np.asarray(mesh.nodes)[faces]
    normals = np.cross(points[:, 1] - points[:, 0], points[:, 2] - points[:, 0])
    assert np.all(np.einsum("ij,ij->i", normals, points.mean(axis=1) - centroids[0]) > 0.0)


def test_plot_solid_design_and_the_rod_options_refuse_bad_input():
    with pytest.raises(ValueError, match="solid body"):
        fj.plot_solid_design(object(), np.zeros(3))
    with pytest.raises(ValueError, match="pin_offset"):
        fj.cases.connecting_rod_slider_crank(0.02, 1, 2, 0.01, damping_ratio=0.05)
    with pytest.raises(ValueError, match="e\\^2 \\+ r\\^2 < length\\^2"):
        fj.cases.connecting_rod_slider_crank(0.02, 1, 2, 0.01, pin_offset=0.299)


def test_connecting_rod_cli_scene_settings():
    assert case_name()("connecting-rod") == "connecting-rod"
    settings = scene_settings("connecting-rod", {"modes": 3, "mesh_size": None})
    assert settings == {**SCENE_DEFAULTS["connecting-rod"], "modes": 3}
    with pytest.raises(ValueError, match="--nx"):
        scene_settings("connecting-rod", {"nx": 4})


T1, FRAMES = 0.01, 5


@pytest.fixture(scope="module")
def rods():
    """The coarsest rod at 3000 rpm with the crank pin offset 30 mm and in the crank's plane (the same compiled
    programs: the offset is data)."""
    def case(offset):
        return fj.cases.connecting_rod_slider_crank(0.02, 1, 2, T1, t_ramp=T1 / 2, speed=100 * np.pi,
                                                    pin_offset=offset, damping_ratio=0.05, average_from=T1 / 2)

    return case(0.03), case(0.0)


@pytest.mark.slow  # gmsh, the uniform body data and one compiled motion (336 s at load 11-13; ~1 min quiet)
def test_offset_crank_pin_excites_the_out_of_plane_modes(rods):
    from ffr_jax._app._solid_motion import solid_body_motion
    from ffr_jax._spatial._euler_parameters import rotation_matrix

    offset, in_plane = rods
    x = offset.initial_design(0.5)
    phi = np.asarray(offset.design.eigenpairs(x)[1]).reshape(offset.mesh.n_nodes, 3, -1)
    # Out-of-plane modes move the part along z (u_z symmetric through the thickness), in-plane ones in x, y.
    out = np.sqrt((phi[:, 2] ** 2).mean(axis=0)) > np.sqrt((phi[:, :2] ** 2).mean(axis=(0, 1)))
    assert out.any() and (~out).any(), "the two retained modes should be one out-of-plane and one in-plane"
    ts = np.linspace(0.0, T1, FRAMES)
    ratios, tilts = [], []
    for case in rods:
        y_r = solid_body_motion(case, x, ts)[2]
        q = y_r[:, 7:9]
        ratios.append(np.abs(q[:, out]).max() / np.abs(q[:, ~out]).max())
        tilts.append([float(rotation_matrix(jnp.asarray(p))[2, 0]) for p in y_r[:, 3:7]])
    # In the crank's plane the mirror-symmetric part is loaded symmetrically: the out-of-plane coordinate is zero up
    # to the solver's absolute tolerance (1e-12 against in-plane q ~ 1e-6: 1e-6 bounds it with margin). Tilted by
    # asin(e / l) = 0.1 rad the rod takes about a tenth of the in-plane inertia loads across its plane, on a softer
    # mode: at least a hundredth of the in-plane response (measured about 0.5 at t1 = 0.04 s, RESULTS).
    assert ratios[1] < 1e-6, f"out-of-plane / in-plane modal coordinate with the pin in plane: {ratios[1]:.2e}"
    assert ratios[0] > 1e-2, f"out-of-plane / in-plane modal coordinate with the pin offset: {ratios[0]:.2e}"
    # The modes hold the big bore in x, y, z and the small one in y, z, so the chord A -> B is the rod frame's x-axis:
    # its z-component is -e / |AB| = -e / l up to the elastic stretch of the chord (displacements of a few um on
    # l = 0.3 m, ~1e-5 relative; 1e-3 bounds it with margin and still fails for a wrong tilt).
    np.testing.assert_allclose(tilts[0], -0.03 / 0.3, rtol=1e-3)
    np.testing.assert_allclose(tilts[1], 0.0, atol=1e-12)


@pytest.mark.slow  # reuses the motion program compiled above
def test_vtu_series_of_the_solid_rod(rods, tmp_path):
    case = rods[0]
    x = case.initial_design(0.5)
    pvd = fj.write_vtu_series(tmp_path / "rod.pvd", case, x, frames=FRAMES)
    first = meshio.read(tmp_path / "rod_vtu" / "rod_0000.vtu")
    last = meshio.read(tmp_path / "rod_vtu" / f"rod_{FRAMES - 1:04d}.vtu")
    assert pvd.read_text().count("<DataSet") == FRAMES
    assert first.cells[0].type == "hexahedron" and len(first.cells[0].data) == case.mesh.n_elements
    density = np.asarray(case.design.domain.element_densities(x, case.material.x_min))
    np.testing.assert_array_equal(first.cell_data["density"][0], density)
    assert last.point_data["elastic_displacement"].shape == (case.mesh.n_nodes, 3)
    # At t = 0 the rod is undeformed and the centroid of its big bore's nodes (marker A) sits on the crank pin
    # (r, 0, e) = (0.06, 0, 0.03): Newton's tolerance on the constraints, 1e-10 with margin.
    bore = np.unique(np.concatenate([np.ravel(m) for m in case.marker_nodes[:1]]))
    np.testing.assert_allclose(first.points[bore].mean(axis=0), [0.06, 0.0, 0.03], atol=1e-10)
    assert np.abs(first.point_data["elastic_displacement"]).max() == 0.0
    assert np.abs(last.point_data["elastic_displacement"]).max() > 0.0


@pytest.mark.slow  # gmsh and the body data of the two-layer rod (about 20 s of one quiet core)
def test_cli_info_connecting_rod(capsys):
    from ffr_jax._app._cli import main

    assert main(["info", "connecting-rod", "--mesh-size", "0.02", "--modes", "2"]) == 0
    out = capsys.readouterr().out
    assert "connecting rod:" in out and "crank pin offset 0.03 m" in out
    frequencies = [float(f) for f in out.split("natural frequencies [Hz]: ")[1].splitlines()[0].split(", ")]
    # Two retained modes, ascending and positive (the supports remove the rigid motions).
    assert len(frequencies) == 2 and 0.0 < frequencies[0] <= frequencies[1]
