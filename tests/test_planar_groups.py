"""Planar meshes with their physical groups: names -> element masks (passive regions, design region) and
boundary node sets (interfaces, clamped sets), the errors for unknown names, wrong dimensions and curves off the
boundary, the design domain by names, the file round trip, and reading messages whose advice the API can follow.

The meshes are built by hand as `meshio.Mesh` objects (no gmsh needed): a 3 x 2 grid of unit squares, so every
expected element and node follows from the numbering below."""

import inspect
import re

import numpy as np
import pytest

import ffr_jax as fj

meshio = pytest.importorskip("meshio")

# Points: index 0 is a geometry point no element uses (gmsh files hold such points), so the reader must renumber:
# grid point (i, j), i = 0..3 along x, j = 0..2 along y, is point 1 + 3 i + j and, after the unused point is
# dropped, node 3 i + j. Element (i, j) (column i, row j) has the counter-clockwise corners (i, j), (i+1, j),
# (i+1, j+1), (i, j+1) and index 2 i + j.
_GRID = [(i, j) for i in range(4) for j in range(3)]


def _point(i, j):
    return 1 + 3 * i + j


def _node(i, j):
    return 3 * i + j


def _grid(groups=True, extra_cells=(), extra_fields=None, points=None):
    """The 3 x 2 grid: surfaces "left" (column 0) and "rest" (columns 1, 2); curves "clamp" (the edge x = 0),
    "tip" (the edge x = 3), "inner" (the line x = 1 between two elements); point "corner" (3, 0)."""
    points = np.array([(9.0, 9.0, 0.0)] + [(i, j, 0.0) for i, j in _GRID]) if points is None else points
    quads = np.array([[_point(i, j), _point(i + 1, j), _point(i + 1, j + 1), _point(i, j + 1)]
                      for i in range(3) for j in range(2)])
    column = np.repeat(np.arange(3), 2)
    cells = [("quad", quads), ("line", np.array([[_point(0, 0), _point(0, 1)], [_point(0, 1), _point(0, 2)]])),
             ("line", np.array([[_point(3, 0), _point(3, 1)], [_point(3, 1), _point(3, 2)]])),
             ("line", np.array([[_point(1, 0), _point(1, 1)]])), ("vertex", np.array([[_point(3, 0)]]))]
    tags = [np.where(column == 0, 1, 2), np.full(2, 3), np.full(2, 4), np.full(1, 5), np.full(1, 6)]
    fields = {"left": np.array([1, 2]), "rest": np.array([2, 2]), "clamp": np.array([3, 1]), "tip": np.array([4, 1]),
              "inner": np.array([5, 1]), "corner": np.array([6, 0])}
    for cell, tag in extra_cells:
        cells.append(cell)
        tags.append(tag)
    fields.update(extra_fields or {})
    if not groups:
        return meshio.Mesh(points, cells)
    return meshio.Mesh(points, cells, cell_data={"gmsh:physical": tags}, field_data=fields)


@pytest.fixture(scope="module")
def groups():
    return fj.planar_groups_from_meshio(_grid())


def test_groups_by_name(groups):
    mesh = groups.mesh
    assert mesh == fj.from_meshio(_grid()), "the groups' mesh is the reader's mesh"
    np.testing.assert_array_equal(mesh.nodes[_node(2, 1)], (2.0, 1.0), err_msg="the unused point is dropped")
    np.testing.assert_array_equal(groups.elements("left"), [0, 1])
    np.testing.assert_array_equal(groups.elements("rest"), [2, 3, 4, 5])
    assert groups.mask("left").tolist() == [True, True, False, False, False, False]
    assert groups.nodes("clamp") == (_node(0, 0), _node(0, 1), _node(0, 2))
    assert groups.nodes("tip") == (_node(3, 0), _node(3, 1), _node(3, 2))
    assert groups.nodes("corner") == (_node(3, 0),)
    assert groups.nodes("left") == tuple(sorted(_node(i, j) for i in (0, 1) for j in range(3)))
    np.testing.assert_array_equal(np.sort(groups.edges("clamp"), axis=1), [[_node(0, 0), _node(0, 1)],
                                                                            [_node(0, 1), _node(0, 2)]])
    assert groups.names(1) == ("clamp", "inner", "tip") and groups.names() == tuple(sorted(groups.dimensions))
    assert "'inner' (curve)" in repr(groups) and "'corner' (point)" in repr(groups)


def test_unknown_names_and_wrong_dimensions(groups):
    with pytest.raises(ValueError, match=r"no physical group named 'bore'.*'clamp' \(curve\).*'left' \(surface\)"):
        groups.nodes("bore")
    with pytest.raises(ValueError, match=r"Physical Surface\(\"Left\"\)"):
        groups.elements("Left")
    with pytest.raises(ValueError, match="'clamp' has dimension 1, but this needs a physical surface"):
        groups.elements("clamp")
    with pytest.raises(ValueError, match="'left' has dimension 2, but this needs a physical curve"):
        groups.edges("left")
    with pytest.raises(TypeError):  # in the tests jaxtyping's check of the annotation comes first
        groups.nodes(3)


def test_a_curve_inside_the_part_is_refused(groups):
    # The line x = 1, y in [0, 1] lies between elements 0 and 2: an interface must be on the boundary.
    with pytest.raises(ValueError, match="1 of the 1 edges of the physical curve 'inner' are not on the boundary"):
        groups.nodes("inner")


def test_files_without_groups_or_with_volumes_or_stray_curves_are_refused():
    with pytest.raises(ValueError, match="no named physical groups"):
        fj.planar_groups_from_meshio(_grid(groups=False))
    with pytest.raises(ValueError, match=r"\['hub'\] are volumes.*read_solid_groups"):
        fj.planar_groups_from_meshio(_grid(extra_fields={"hub": np.array([7, 3])}))
    stray = (("line", np.array([[0, _point(0, 0)]])), np.full(1, 8))  # from the unused point 0
    with pytest.raises(ValueError, match="'stray' holds nodes that no quadrilateral uses"):
        fj.planar_groups_from_meshio(_grid(extra_cells=[stray], extra_fields={"stray": np.array([8, 1])}))


def test_design_domain_by_names(groups):
    domain = fj.DesignDomain.from_groups(groups, solid="left")
    assert domain.n_design == 4 and np.asarray(domain.design_elements).tolist() == [2, 3, 4, 5]
    voids = fj.DesignDomain.from_groups(groups, void=("left",))
    assert voids.role_array().tolist() == [2, 2, 0, 0, 0, 0]
    with pytest.raises(ValueError, match="no design element"):
        fj.DesignDomain.from_groups(groups, solid=("left", "rest"))
    with pytest.raises(ValueError, match="'clamp' has dimension 1"):
        fj.DesignDomain.from_groups(groups, solid="clamp")
    with pytest.raises(TypeError, match="PlanarGroups"):
        fj.DesignDomain.from_groups(groups.mesh, solid="left")


def test_file_round_trip(tmp_path, groups):
    path = tmp_path / "grid.msh"
    meshio.write(path, _grid(), file_format="gmsh22", binary=False)
    read = fj.read_planar_groups(path)
    assert read.mesh == groups.mesh and read.dimensions == groups.dimensions
    for name in groups.dimensions:
        if name != "inner":
            assert read.nodes(name) == groups.nodes(name), name
    with pytest.raises(FileNotFoundError, match="no mesh file"):
        fj.read_planar_groups(tmp_path / "missing.msh")
    (tmp_path / "bad.msh").write_text("not a mesh")
    with pytest.raises(ValueError, match="read_planar_groups: meshio could not read"):
        fj.read_planar_groups(tmp_path / "bad.msh")


def test_distortion_advice_names_an_argument_that_exists(tmp_path):
    # Move grid point (1, 1) to (0.52, 0.52), near the diagonal of element 0: its corner Jacobians there and at
    # (0, 0) are 0.04 / 4 and 1 / 4 (a quarter of the cross products of the edges), a ratio 0.04 < 0.05.
    points = np.array([(9.0, 9.0, 0.0)] + [(i, j, 0.0) for i, j in _GRID])
    points[_point(1, 1), :2] = (0.52, 0.52)
    path = tmp_path / "distorted.msh"
    meshio.write(path, _grid(points=points), file_format="gmsh22", binary=False)
    with pytest.raises(ValueError, match="badly distorted") as refused:
        fj.read_mesh(path)
    name, owners = _named_knob(str(refused.value))
    for owner in owners:
        assert name in inspect.signature(getattr(fj, owner)).parameters, f"{owner} takes {name}"
    ratio = fj.QuadMesh(points[1:, :2], fj.from_meshio(_grid()).elements, min_jacobian_ratio=1e-3).jacobian_ratios()
    lower = 0.5 * ratio.min()
    assert fj.read_mesh(path, min_jacobian_ratio=lower).n_elements == 6
    assert fj.read_planar_groups(path, min_jacobian_ratio=lower).nodes("clamp") == (0, 1, 2)
    assert fj.from_meshio(meshio.read(path), min_jacobian_ratio=lower).n_elements == 6


def _named_knob(message: str):
    knob = re.search(r"pass a lower (\w+) \(an argument of ([^)]*)\)", message)
    assert knob, message
    return knob.group(1), re.split(r", | and ", knob.group(2))


def test_solid_distortion_advice_names_an_argument_that_exists(tmp_path):
    # A unit cube with one corner pulled 40 % towards the opposite one: valid, but refused at a ratio of 0.99.
    cube = fj.box_grid(1, 1, 1, 1.0, 1.0, 1.0)
    nodes = np.array(cube.nodes)
    far, near = np.argmax(nodes.sum(axis=1)), np.argmin(nodes.sum(axis=1))
    nodes[far] = 0.6 * nodes[far] + 0.4 * nodes[near]
    with pytest.raises(ValueError, match="badly shaped") as refused:
        fj.SolidMesh(nodes, cube.elements, min_jacobian_ratio=0.99)
    name, owners = _named_knob(str(refused.value))
    for owner in owners:
        assert name in inspect.signature(getattr(fj, owner)).parameters, f"{owner} takes {name}"
    path = tmp_path / "cube.vtu"
    meshio.write(path, meshio.Mesh(nodes, [("hexahedron", np.asarray(cube.elements))]))
    with pytest.raises(ValueError, match="badly shaped"):
        fj.read_solid_mesh(path, min_jacobian_ratio=0.99)
    assert fj.read_solid_mesh(path).n_elements == 1


def test_groups_sharing_entities_are_errors_not_silent_gaps():
    # gmsh 4.1 files carry one physical tag per element (meshio keeps the first): a second group of the same
    # surface reads empty. gmsh 2.2 files repeat the element once per group: the mesh repeats quadrilaterals.
    shadowed = fj.planar_groups_from_meshio(_grid(extra_fields={"again": np.array([9, 2]), "edge": np.array([10, 1])}))
    for method in ("elements", "nodes"):
        with pytest.raises(ValueError, match="'again' has no cells in this mesh.*one physical group"):
            getattr(shadowed, method)("again")
    with pytest.raises(ValueError, match="'edge' has no cells"):
        shadowed.nodes("edge")
    mesh = _grid()
    copy = (("quad", mesh.cells[0].data[:2]), np.full(2, 9))
    with pytest.raises(ValueError, match="repeats 2 quadrilaterals.*one physical group"):
        fj.planar_groups_from_meshio(_grid(extra_cells=[copy], extra_fields={"again": np.array([9, 2])}))
