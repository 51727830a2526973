"""The geometry and mesh of a small connecting rod: two bores of different size joined by a shank (issue 27).

gmsh (OpenCASCADE kernel) builds the rod's profile in the plane `z = -t/2`: a disk of radius `R_a` around the big
bore (centre at the origin, the crank pin), a disk of radius `R_b` around the small bore (centre at `(L, 0)`, the
piston pin), a shank of width `w` between them, the bores (radii `r_a > r_b`) cut out, and two rings (hubs, of
widths `hub` around each bore) fragmented from the rest, so that the profile has three named surfaces: `big_hub`,
`small_hub`, `web`; the bores' circles are the named curves `big_bore`, `small_bore`. The profile is meshed with
quadrilaterals only (Blossom recombination and gmsh's all-quad subdivision), and the quadrilaterals are extruded
into `n_layers` layers of 8-node hexahedra through the thickness `t` (`z` from `-t/2` to `t/2`): the part is
mirror-symmetric about `z = 0` and its hexahedra are straight prisms over the quads.

Extrusion turns each named surface into a physical volume and each named curve into a physical surface (the bore's
cylindrical face), written as gmsh physical groups on a `meshio.Mesh` (`field_data` names, `gmsh:physical` tags)
and read back by [`solid_groups_from_meshio`][], which checks the bore faces lie on the part's surface. (gmsh's own
extrusion with recombination leaves wedges where Blossom leaves a triangle; its hexahedral subdivision of those
makes degenerate hexahedra, so the extrusion is done here, over an all-quad profile.)
"""

import numpy as np

from .._design.solid_groups import PhysicalGroups, solid_groups_from_meshio

_SURFACES = ("big_hub", "small_hub", "web")
_CURVES = ("big_bore", "small_bore")


def _profile(length, bore_a, bore_b, radius_a, radius_b, width, hub, size):
    """gmsh: mesh the profile with quads; return nodes `(n, 2)`, quads by surface name, bore segments by name."""
    import gmsh

    gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("connecting_rod")
        occ = gmsh.model.occ
        outer, _ = occ.fuse([(2, occ.addDisk(0, 0, 0, radius_a, radius_a))],
                            [(2, occ.addDisk(length, 0, 0, radius_b, radius_b)),
                             (2, occ.addRectangle(0, -width / 2, 0, length, width))])
        plate, _ = occ.cut(outer, [(2, occ.addDisk(0, 0, 0, bore_a, bore_a)),
                                   (2, occ.addDisk(length, 0, 0, bore_b, bore_b))])
        ring_a, ring_b = bore_a + hub, bore_b + hub
        rings = [occ.cut([(2, occ.addDisk(cx, 0, 0, outer_r, outer_r))], [(2, occ.addDisk(cx, 0, 0, r, r))])[0][0]
                 for cx, r, outer_r in ((0.0, bore_a, ring_a), (length, bore_b, ring_b))]
        occ.fragment(plate, rings)
        occ.synchronize()
        eps = 0.1 * hub  # OCC pads bounding boxes (~1e-7); the next larger circle is a hub width away

        def inside(cx, r, dim):
            return [t for _, t in gmsh.model.getEntitiesInBoundingBox(cx - r - eps, -r - eps, -eps, cx + r + eps,
                                                                      r + eps, eps, dim)]

        surfaces = {"big_hub": inside(0.0, ring_a, 2), "small_hub": inside(length, ring_b, 2)}
        surfaces["web"] = [t for _, t in gmsh.model.getEntities(2)
                           if t not in surfaces["big_hub"] + surfaces["small_hub"]]
        curves = {"big_bore": inside(0.0, bore_a, 1), "small_bore": inside(length, bore_b, 1)}
        if any(not v for v in (*surfaces.values(), *curves.values())):
            raise ValueError(f"connecting rod geometry: a region came out empty ({surfaces}, {curves}); check that "
                             "bore < bore + hub < outer radius and that the hubs do not meet.")
        # All-quad subdivision halves every edge: mesh at twice the wanted size.
        for option, value in (("Mesh.MeshSizeMax", 2 * size), ("Mesh.MeshSizeMin", 2 * size),
                              ("Mesh.RecombineAll", 1), ("Mesh.Algorithm", 8), ("Mesh.RecombinationAlgorithm", 1),
                              ("Mesh.SubdivisionAlgorithm", 1)):
            gmsh.option.setNumber(option, value)
        gmsh.model.mesh.generate(2)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        index = np.full(int(tags.max()) + 1, -1, dtype=np.int64)
        index[tags.astype(np.int64)] = np.arange(tags.size)
        nodes = coords.reshape(-1, 3)[:, :2]

        def cells(dim, entities, kind, count):
            out = []
            for tag in entities:
                types, _, conn = gmsh.model.mesh.getElements(dim, tag)
                for t, c in zip(types, conn):
                    if t != kind:
                        raise ValueError(f"connecting rod mesh: gmsh left element type {t} on entity {tag}; expected "
                                         "only quadrilaterals (type 3) and line segments (type 1).")
                    out.append(index[np.asarray(c, dtype=np.int64)].reshape(-1, count))
            return np.concatenate(out)

        quads = {name: cells(2, tags_, 3, 4) for name, tags_ in surfaces.items()}
        segments = {name: cells(1, tags_, 1, 2) for name, tags_ in curves.items()}
    finally:
        gmsh.finalize()
    return nodes, quads, segments


def connecting_rod_groups(*, length: float = 0.3, bore_a: float = 0.025, bore_b: float = 0.013,
                          radius_a: float = 0.045, radius_b: float = 0.025, width: float = 0.024,
                          thickness: float = 0.016, hub: float = 0.006, size: float = 0.008,
                          n_layers: int = 2) -> PhysicalGroups:
    """The connecting rod's hexahedral mesh with its physical groups (module docstring), lengths in metres.

    **Arguments:** `length` between the bore centres; `bore_a`, `bore_b` the bore radii (big, small);
    `radius_a`, `radius_b` the outer radii of the eyes; `width` of the shank; `thickness` (`z`); `hub` the ring
    width around each bore (named `big_hub`, `small_hub`: e.g. passive solid); `size` the in-plane element size;
    `n_layers` hexahedra through the thickness.

    **Returns:** [`PhysicalGroups`][]: volumes `big_hub`, `small_hub`, `web`; surfaces `big_bore`, `small_bore`
    (the bores' faces); `.mesh` the [`SolidMesh`][] (the big bore's centre at the origin, the small bore's at
    `(length, 0, 0)`).
    """
    import meshio

    if not (0 < bore_a < bore_a + hub < radius_a and 0 < bore_b < bore_b + hub < radius_b
            and radius_a + radius_b < length and width < 2 * min(radius_a, radius_b)):
        raise ValueError("connecting_rod_groups: the geometry needs 0 < bore < bore + hub < outer radius at each eye, "
                         "eyes that do not overlap (radius_a + radius_b < length) and a shank narrower than the "
                         f"eyes; got bores {bore_a}, {bore_b}, hub {hub}, radii {radius_a}, {radius_b}, length "
                         f"{length}, width {width}.")
    if not isinstance(n_layers, int) or n_layers < 1 or not 0 < size < width:
        raise ValueError(f"n_layers must be an int >= 1 and 0 < size < width; got {n_layers}, {size}.")
    nodes2, quads, segments = _profile(length, bore_a, bore_b, radius_a, radius_b, width, hub, size)
    n2 = nodes2.shape[0]
    z = np.linspace(-thickness / 2, thickness / 2, n_layers + 1)
    points = np.concatenate([np.column_stack([nodes2, np.full(n2, zk)]) for zk in z])
    layers = np.arange(n_layers)[:, None, None] * n2
    hexes, hex_tags, faces, face_tags, field = [], [], [], [], {}
    for tag, name in enumerate(_SURFACES, start=1):
        q = quads[name]
        a, b, c = nodes2[q[:, 0]], nodes2[q[:, 1]], nodes2[q[:, 2]]
        u, v = b - a, c - b
        clockwise = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0] < 0  # clockwise from +z: inverted hexahedra
        q = np.where(clockwise[:, None], q[:, ::-1], q)
        bottom = (q[None] + layers).reshape(-1, 4)
        hexes.append(np.concatenate([bottom, bottom + n2], axis=1))
        hex_tags.append(np.full(bottom.shape[0], tag))
        field[name] = np.array([tag, 3])
    for tag, name in enumerate(_CURVES, start=len(_SURFACES) + 1):
        s = (segments[name][None] + layers).reshape(-1, 2)
        faces.append(np.column_stack([s[:, 0], s[:, 1], s[:, 1] + n2, s[:, 0] + n2]))
        face_tags.append(np.full(s.shape[0], tag))
        field[name] = np.array([tag, 2])
    mesh = meshio.Mesh(points, [("hexahedron", np.concatenate(hexes)), ("quad", np.concatenate(faces))],
                       cell_data={"gmsh:physical": [np.concatenate(hex_tags), np.concatenate(face_tags)]},
                       field_data=field)
    return solid_groups_from_meshio(mesh)
