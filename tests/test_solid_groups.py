"""Named regions of solid meshes (issue 27): physical groups by name, and the bad input of the issue's list — a
group name that does not exist, an interface face that is not on the mesh's surface — as clear errors.

A two-hexahedron bar `[0, 2] x [0, 1] x [0, 1]` with gmsh-style physical groups: the end face `x = 0` ("left"), the
face `x = 1` between the two elements ("middle", inside the part), a quad on a point no element uses ("stray"), and
the two elements as volumes "hub" and "shank".
"""

import meshio
import numpy as np
import pytest

import ffr_jax as fj

LEFT, MIDDLE, STRAY, HUB, SHANK = 1, 2, 3, 4, 5


def _bar():
    mesh = fj.box_grid(2, 1, 1, 2.0, 1.0, 1.0)
    points = np.concatenate([mesh.nodes, [[5.0, 5.0, 5.0]]])  # one stray point, used by no element
    x = points[:, 0]
    on = lambda value: [int(i) for i in np.flatnonzero(np.isclose(x[:-1], value))]
    left, middle = on(0.0), on(1.0)
    left_face = [left[0], left[1], left[3], left[2]]  # any cyclic order of the four corners
    middle_face = [middle[0], middle[1], middle[3], middle[2]]
    stray_face = [left[0], left[1], left[3], points.shape[0] - 1]
    field_data = {"left": np.array([LEFT, 2]), "middle": np.array([MIDDLE, 2]), "stray": np.array([STRAY, 2]),
                  "hub": np.array([HUB, 3]), "shank": np.array([SHANK, 3])}
    cells = [("hexahedron", mesh.elements), ("quad", np.array([left_face, middle_face, stray_face]))]
    physical = [np.array([HUB, SHANK]), np.array([LEFT, MIDDLE, STRAY])]
    return meshio.Mesh(points, cells, cell_data={"gmsh:physical": physical, "gmsh:geometrical": physical},
                       field_data=field_data), mesh


@pytest.fixture(scope="module")
def groups():
    meshio_mesh, mesh = _bar()
    return fj.solid_groups_from_meshio(meshio_mesh), mesh


def test_groups_by_name(groups):
    g, mesh = groups
    assert g.mesh == mesh
    assert g.dimensions == {"left": 2, "middle": 2, "stray": 2, "hub": 3, "shank": 3}
    np.testing.assert_array_equal(g.elements("hub"), [0])
    np.testing.assert_array_equal(g.elements("shank"), [1])
    assert g.nodes("left") == tuple(int(i) for i in np.flatnonzero(mesh.nodes[:, 0] == 0.0))
    assert g.faces("left").shape == (1, 4)
    assert g.nodes("hub") == tuple(sorted(int(n) for n in mesh.elements[0]))


def test_unknown_group_name_is_an_error_listing_the_groups(groups):
    g, _ = groups
    with pytest.raises(ValueError, match=r"no physical group named 'bore'.*'hub' \(volume\).*'left' \(surface\)"):
        g.nodes("bore")
    with pytest.raises(ValueError, match="no physical group named 'Left'"):
        g.faces("Left")


def test_group_of_the_wrong_dimension_is_an_error(groups):
    g, _ = groups
    with pytest.raises(ValueError, match="'left' has dimension 2, but this needs a physical volume"):
        g.elements("left")
    with pytest.raises(ValueError, match="'hub' has dimension 3, but this needs a physical surface"):
        g.faces("hub")


def test_interface_face_off_the_surface_is_an_error(groups):
    """A face between two elements, and a face on a point no element uses, are not on the part's surface."""
    g, _ = groups
    with pytest.raises(ValueError, match="1 of the 1 faces of the physical surface 'middle' are not on the surface"):
        g.faces("middle")
    with pytest.raises(ValueError, match="'middle' are not on the surface"):
        g.nodes("middle")
    with pytest.raises(ValueError, match="'stray' are not on the surface"):
        g.faces("stray")


def test_mesh_without_groups_is_an_error():
    _, mesh = _bar()
    with pytest.raises(ValueError, match="no named physical groups"):
        fj.solid_groups_from_meshio(meshio.Mesh(mesh.nodes, [("hexahedron", mesh.elements)]))


def test_gmsh_file_round_trip(tmp_path):
    """Written as a gmsh 2.2 file (which keeps the names and tags) and read back by name."""
    meshio_mesh, mesh = _bar()
    path = tmp_path / "bar.msh"
    meshio.write(path, meshio_mesh, file_format="gmsh22", binary=False)
    g = fj.read_solid_groups(path)
    assert g.mesh == mesh
    assert g.nodes("left") == tuple(int(i) for i in np.flatnonzero(mesh.nodes[:, 0] == 0.0))
    with pytest.raises(ValueError, match="no physical group named 'bore'"):
        g.elements("bore")
    with pytest.raises(FileNotFoundError, match="no mesh file"):
        fj.read_solid_groups(tmp_path / "missing.msh")


def test_a_named_group_without_cells_is_an_error():
    """A name in the file whose cells meshio did not keep (gmsh 4.1 keeps one physical tag per element, so a group
    sharing its entities with another reads empty) is refused with that reason, not used as an empty set."""
    meshio_mesh, _ = _bar()
    meshio_mesh.field_data.update({"bore": np.array([9, 2]), "web": np.array([10, 3])})  # names without cells
    g = fj.solid_groups_from_meshio(meshio_mesh)
    for call in (lambda: g.faces("bore"), lambda: g.nodes("bore"), lambda: g.elements("web"), lambda: g.nodes("web")):
        with pytest.raises(ValueError, match="has no cells in this mesh.*one physical group"):
            call()
