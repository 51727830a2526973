"""`fj.link_profile`: the all-quad gmsh recipe on the usual link shapes (pin holes of different radii with and
without rims, slots with rounded ends or corners, filleted outlines), swept over shapes and sizes.

Every mesh of the sweep: only quadrilaterals (the reader refuses anything else), every element's corner-Jacobian
ratio above `RATIO_BOUND`, and groups that describe the part: the rims' elements inside the rings and the design
elements outside, each bore's nodes on its circle, and the mesh's boundary exactly the curves "outline", "slots"
and "bore_*". The default run meshes each shape at one coarse size (well under a second each); the finer sizes are
marked slow (and the bell crank, the largest part)."""

import dataclasses
import inspect
import re

import numpy as np
import pytest

import ffr_jax as fj
from ffr_jax._design.quad_relocation import jacobian_ratios, relocate_nodes

pytest.importorskip("gmsh")
meshio = pytest.importorskip("meshio")

# The recipe's promise: corner Jacobians within 4:1 in every element. A triangle split into three quadrilaterals
# (gmsh's subdivision) has the ratio 1/3 when equilateral; the relocation only takes moves that raise the worst
# element around a node, and the refusal bound of QuadMeshing (0.2) lies below.
RATIO_BOUND = 0.25

L, W = 0.3, 0.04
_ROD = [(-W / 2, -W / 2), (L + W / 2, -W / 2), (L + W / 2, W / 2), (-W / 2, W / 2)]
SHAPES = {
    # The issue's rod: two pin holes and a lightening slot with rounded corners (gmsh 4.15's full-quad Blossom
    # recombination fails on it: "1D mesh cannot be divided by 2").
    "rod_slot": dict(outline=_ROD, holes=[fj.Hole((0, 0), 0.006, 0.004), fj.Hole((L, 0), 0.006, 0.004)],
                     slots=[fj.Slot((L / 2, 0), 0.12, 0.014, corner_radius=0.004)]),
    # Rounded ends (fillet = half the width uses the end edges up) and a slot with semicircular ends.
    "stadium": dict(outline=_ROD, holes=[fj.Hole((0, 0), 0.006, 0.004), fj.Hole((L, 0), 0.006, 0.004)],
                    slots=[fj.Slot((L / 2, 0), 0.12, 0.014)], fillet=W / 2),
    # Pin holes of different radii and rims, two slots with different corners, filleted corners.
    "two_slots": dict(outline=_ROD, holes=[fj.Hole((0, 0), 0.005, 0.004, "small"), fj.Hole((L, 0), 0.008, 0.005)],
                      slots=[fj.Slot((0.1, 0), 0.07, 0.012, 0.003), fj.Slot((0.2, 0), 0.07, 0.012, 0.006)],
                      fillet=0.008),
    # A triangular bell crank: three holes (one without a rim), an inclined slot, a reflex-free filleted outline.
    "bell_crank": dict(outline=[(-0.04, -0.03), (0.24, -0.03), (0.1, 0.2)],
                       holes=[fj.Hole((0, 0), 0.008, 0.005), fj.Hole((0.2, 0), 0.006, 0.004),
                              fj.Hole((0.1, 0.13), 0.005, 0.0)],
                       slots=[fj.Slot((0.1, 0.03), 0.06, 0.02, angle=0.3)], fillet=0.015),
    # A dog-bone crank: a big and a small end joined by a narrow web, reflex (inward) corners with fillets of
    # 5 to 20 mm, a narrow slot in the web.
    "dog_bone": dict(outline=[(-0.03, -0.03), (0.03, -0.03), (0.05, -0.012), (0.16, -0.012), (0.175, -0.02),
                              (0.22, -0.02), (0.22, 0.02), (0.175, 0.02), (0.16, 0.012), (0.05, 0.012), (0.03, 0.03),
                              (-0.03, 0.03)],
                     holes=[fj.Hole((0, 0), 0.012, 0.006), fj.Hole((0.2, 0), 0.006, 0.004)],
                     slots=[fj.Slot((0.105, 0), 0.07, 0.008)],
                     fillet=[0.02, 0.02, 0.01, 0.01, 0.005, 0.012, 0.012, 0.005, 0.01, 0.01, 0.02, 0.02]),
}
COARSE = 0.004


def _check_part(groups, shape):
    mesh = groups.mesh
    ratios = mesh.jacobian_ratios()
    assert ratios.min() >= RATIO_BOUND, f"worst corner-Jacobian ratio {ratios.min():.3f} (element {ratios.argmin()})"
    holes = {f"bore_{h.name or chr(ord('A') + k)}": h for k, h in enumerate(shape["holes"])}
    assert set(groups.names(1)) == {"outline", "slots", *holes}
    # Geometry nodes lie on the geometry: gmsh places curve nodes on the arcs, the relocation moves only inner
    # nodes; 1e-9 of the radius is far above the rounding of coordinates ~0.3 m (1e-16 relative) and far below
    # the distance of any inner node (at least an element's size, ~mesh_size).
    for name, hole in holes.items():
        distance = np.linalg.norm(mesh.nodes[list(groups.nodes(name))] - hole.centre, axis=1)
        np.testing.assert_allclose(distance, hole.radius, rtol=1e-9, err_msg=f"{name} on its circle")
        assert len(distance) >= 2 * fj.QuadMeshing().circle_points, f"{name}: a bore is resolved"
    # The boundary is exactly the named curves: none missing, none inside.
    boundary = {tuple(e) for e in np.sort(_boundary_edges(mesh), axis=1)}
    named = {tuple(e) for name in groups.names(1) for e in np.sort(groups.edges(name), axis=1)}
    assert named == boundary, f"{len(boundary - named)} boundary edges unnamed, {len(named - boundary)} named inside"
    # Rims and design: a partition; rim elements inside a ring, design elements outside every ring (centroids).
    rims, design = groups.mask("rims"), groups.mask("design")
    assert np.all(rims ^ design), "every element in exactly one of 'rims' and 'design'"
    centroids = mesh.element_centroids()
    in_ring = np.zeros(mesh.n_elements, dtype=bool)
    for hole in holes.values():
        d = np.linalg.norm(centroids - hole.centre, axis=1)
        in_ring |= (d > hole.radius) & (d < hole.radius + hole.rim)
    np.testing.assert_array_equal(rims, in_ring, err_msg="rim elements are those in the rings")
    # The rims' area is that of the rings up to the chords of the circles: with at least n = 32 segments on a
    # circle of radius R the inscribed polygon misses at most pi R^2 (2 pi / n)^2 / 6 < 0.7 % of its area (on
    # the outer circle; the bore's deficit adds area to the ring), so 2 % of the rings' area bounds it.
    rings = sum(np.pi * ((h.radius + h.rim) ** 2 - h.radius ** 2) for h in holes.values())
    np.testing.assert_allclose(mesh.element_areas()[rims].sum(), rings, rtol=2e-2, err_msg="rims' area")


def _boundary_edges(mesh):
    from ffr_jax._design.planar_groups import boundary_edges

    return boundary_edges(mesh)


@pytest.fixture(scope="module")
def rod(tmp_path_factory):
    """The issue's rod at the coarse size, also written to a file: `(groups, path)`."""
    path = tmp_path_factory.mktemp("rod") / "rod.msh"
    return fj.link_profile(**SHAPES["rod_slot"], mesh_size=COARSE, path=path), path


@pytest.mark.parametrize("name", [name for name in SHAPES if name != "bell_crank"])  # the largest: slow only
def test_every_shape_meshes_in_good_quadrilaterals(name, request):
    shape = SHAPES[name]
    groups = request.getfixturevalue("rod")[0] if name == "rod_slot" else fj.link_profile(**shape, mesh_size=COARSE)
    _check_part(groups, shape)


@pytest.mark.slow
@pytest.mark.parametrize("name, size", [("bell_crank", COARSE)] + [(name, size) for name in SHAPES
                                                                    for size in (0.003, 0.002, 0.0015)])
def test_every_shape_and_size(name, size):
    shape = SHAPES[name]
    _check_part(fj.link_profile(**shape, mesh_size=size), shape)


def test_the_file_holds_the_same_mesh_and_groups(rod, tmp_path):
    groups, path = rod
    assert {block.type for block in meshio.read(path).cells} == {"quad", "line"}, "no triangles in the file"
    read = fj.read_planar_groups(path)
    assert read.mesh == groups.mesh and read.dimensions == groups.dimensions
    for name in groups.names():
        assert read.nodes(name) == groups.nodes(name), name
    domain = fj.DesignDomain.from_groups(read, solid="rims")
    np.testing.assert_array_equal(domain.role_array() == 0, groups.mask("design"))
    with pytest.raises(ValueError, match=r"\.msh"):
        fj.link_profile(**SHAPES["rod_slot"], mesh_size=COARSE, path=tmp_path / "rod.vtu")


@pytest.mark.parametrize("change, match", [
    ({"outline": [(0, 0), (0.3, 0.04), (0.3, 0), (0, 0.04)]}, "crosses itself"),
    ({"outline": [(0, 0), (0.3, 0)]}, "n >= 3"),
    ({"fillet": 0.03}, "fillets at corners"),
    ({"holes": [fj.Hole((0, 0), 0.006, 0.004), fj.Hole((L + 0.015, 0), 0.006, 0.004)]}, "'B'.*outline"),
    ({"holes": [fj.Hole((0, 0), 0.006, 0.004), fj.Hole((0.012, 0), 0.003, 0.004)]}, "'B'.*'A'.*overlap"),
    ({"slots": [fj.Slot((0.03, 0), 0.06, 0.014)]}, "slot 0.*hole 'A'"),
    ({"holes": [fj.Hole((0, 0), 0.006, 0.002)]}, "rim .* narrower than mesh_size"),
    ({"holes": [fj.Hole((0, 0), 0.006, 0.004, "A"), fj.Hole((L, 0), 0.006, 0.004, "A")]}, "distinct"),
    ({"holes": []}, "at least one Hole"),
    ({"slots": [fj.Slot((L / 2, 0), 0.12, 0.014, corner_radius=0.01)]}, r"corner_radius must lie in \[0, width / 2\]"),
    ({"mesh_size": 0.0}, "mesh_size must be a positive"),
    ({"fillet": [0.01, 0.01]}, "one per corner"),
    ({"meshing": fj.QuadMeshing}, "QuadMeshing"),
])
def test_bad_shapes_are_refused_before_meshing(change, match, monkeypatch):
    import ffr_jax._design.link_profile as recipe

    def no_gmsh(*args, **kwargs):
        raise AssertionError("gmsh ran before the shape was checked")

    monkeypatch.setattr(recipe, "_mesh", no_gmsh)
    arguments = {**SHAPES["rod_slot"], "mesh_size": COARSE, **change}
    with pytest.raises((ValueError, TypeError), match=match):
        fj.link_profile(**arguments)


@pytest.mark.parametrize("bad, match", [({"algorithm": 3}, "algorithm"), ({"circle_points": 2}, "circle_points"),
                                        ({"target_ratio": 0.0}, "target_ratio"), ({"passes": -1}, "passes")])
def test_meshing_options_are_checked(bad, match):
    with pytest.raises(ValueError, match=match):
        fj.QuadMeshing(**bad)


def test_relocation_raises_the_worst_element_and_keeps_fixed_nodes():
    # A 2 x 2 grid of unit squares with its centre node pushed to (1.7, 1.6): the relocation, free to move only
    # that node, finds the centre again (ratio 1 there). Its compass search stops within its last step,
    # 1/4 * (mean distance to the element corners, < 1.4) / 2^8 < 2e-3, of a point no step improves, and the
    # ratios change by O(that step) there; 0.95 leaves a wide margin.
    nodes = np.array([(i, j) for i in range(3) for j in range(3)], dtype=float)
    elements = np.array([[3 * i + j, 3 * (i + 1) + j, 3 * (i + 1) + j + 1, 3 * i + j + 1]
                         for i in range(2) for j in range(2)])
    nodes[4] = (1.7, 1.6)
    movable = np.zeros(9, dtype=bool)
    movable[4] = True
    before = jacobian_ratios(nodes[elements]).min()
    moved = relocate_nodes(nodes, elements, movable, target=1.0, passes=4)
    np.testing.assert_array_equal(moved[~movable], nodes[~movable], err_msg="fixed nodes stay")
    assert before < 0.5 and jacobian_ratios(moved[elements]).min() >= 0.95


@pytest.mark.slow
def test_the_part_goes_into_a_slider_crank_by_names(rod):
    # The docs' recipe: design domain, clamped set, interface and markers from the group names, no node search.
    # Each bore's nodes sit at equal angle steps on four quarter arcs (gmsh's uniform parametrisation, halved by
    # the subdivision), a set symmetric under quarter turns about the centre: their centroid, the marker, is the
    # pin centre up to rounding (sums of ~30 coordinates below 0.3 m: ~1e-15 m; 1e-9 m bounds it).
    groups, _ = rod
    a, b = groups.nodes("bore_A"), groups.nodes("bore_B")
    body = fj.DesignedBody(fj.FEModel(groups.mesh, fj.QM6(), thickness=0.005, poisson=0.3),
                           fj.DesignDomain.from_groups(groups, solid="rims"), fj.SIMP(),
                           fj.ModalReduction(2, fj.Clamped(a), interfaces=(fj.Interface(b, rigid=True),)),
                           markers=(a, b))
    case = fj.cases.slider_crank(rod=body, t1=0.02)
    assert case.n_design == groups.mask("design").sum()
    data = case.scene_template.bodies[-1].data
    np.testing.assert_allclose(data.marker_positions, [(0.0, 0.0), (L, 0.0)], rtol=0, atol=1e-9,
                               err_msg="markers at the pin centres")


def test_a_clockwise_outline_is_the_same_part(monkeypatch):
    # Corners given clockwise with their fillets in the same order describe the same part: the recipe meshes the
    # same pieces (lines and arcs, as sets of end points and centres) as for the counter-clockwise order.
    import ffr_jax._design.link_profile as recipe

    class Captured(Exception):
        pass

    seen = []

    def capture(outline, *args):
        seen.append(outline)
        raise Captured

    monkeypatch.setattr(recipe, "_mesh", capture)
    shape = {**SHAPES["dog_bone"], "fillet": [0.02, 0.015, 0.01, 0.008, 0.005, 0.012, 0.01, 0.004, 0.01, 0.006,
                                              0.02, 0.018]}  # a different radius at each corner
    for order in (slice(None), slice(None, None, -1)):
        with pytest.raises(Captured):
            fj.link_profile(**{**shape, "outline": shape["outline"][order], "fillet": shape["fillet"][order]},
                            mesh_size=COARSE)

    def pieces(outline):
        return {(p[0], *(tuple(np.round(q, 12)) for q in p[1:])) for p in outline}

    assert len(seen) == 2 and pieces(seen[0]) == pieces(seen[1])


def test_a_mesh_below_the_quality_bound_is_refused_with_knobs_that_exist():
    # Without relocation and with a bound of 0.9 (near-parallelograms only) the recipe's mesh is refused; the
    # message names QuadMeshing fields and link_profile's mesh_size, each of which exists.
    with pytest.raises(ValueError, match="below 0.9") as refused:
        fj.link_profile(**SHAPES["stadium"], mesh_size=COARSE, meshing=fj.QuadMeshing(passes=0, min_jacobian_ratio=0.9))
    message = str(refused.value)
    fields = set(re.findall(r"QuadMeshing\((\w+)=", message))
    assert fields and fields <= {f.name for f in dataclasses.fields(fj.QuadMeshing)}, message
    assert "mesh_size" in message and "mesh_size" in inspect.signature(fj.link_profile).parameters
