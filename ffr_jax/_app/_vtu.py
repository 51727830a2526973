"""The design of a flexible body for ParaView: a VTU file with density and mode shapes."""

from pathlib import Path

import jax
import numpy as np

from .._dynamics._case import Case


def write_vtu(path, case: Case, x_phys, *, modes: bool = True) -> Path:
    """Write the body's mesh with its physical densities and retained mode shapes as a VTU file.

    Cells are the Q4 elements (VTK `quad`), points the FE nodes in body coordinates (origin at
    joint A, `z = 0`). Cell data `density`: the physical density of every element (the solid
    interface columns at 1); `design`: 1 on design elements, 0 on the passive elements (the rod's interface columns). Point
    data `mode_1 ... mode_n`: the mass-normalised hinged–hinged mode shapes `phi_k` of the design
    (3-vectors with zero `z`, ready for ParaView's *Warp By Vector*). Field data `frequencies_Hz`:
    the retained natural frequencies. Written with `meshio` (whose VTU writer has no field data:
    that one `<FieldData>` array is added to the XML after).

    **Arguments:**
    - `path`: the `.vtu` file to write.
    - `case`: the case whose body the design shapes; `x_phys`: `(n_design,)` physical densities.
    - `modes`: also compute and write the mode shapes (one modal analysis).

    **Returns:** the path written.
    """
    import meshio

    path = Path(path)
    mesh, design = case.mesh, case.design
    x_phys = design.check(jax.numpy.asarray(x_phys))
    points = np.zeros((mesh.n_nodes, 3))
    points[:, :2] = mesh.nodes
    quads = np.asarray(mesh.elements)
    density = np.asarray(design.element_densities(x_phys))
    is_design = np.zeros(mesh.n_elements)
    is_design[np.asarray(design.domain.design_elements)] = 1.0
    point_data, frequencies = {}, None
    if modes:
        basis = case.modes(x_phys)
        shapes = np.asarray(basis.modes).reshape(mesh.n_nodes, 2, -1)
        for k in range(shapes.shape[2]):
            vectors = np.zeros((mesh.n_nodes, 3))
            vectors[:, :2] = shapes[:, :, k]
            point_data[f"mode_{k + 1}"] = vectors
        frequencies = np.asarray(basis.frequencies)
    meshio.write(path, meshio.Mesh(points, [("quad", quads)], point_data=point_data,
                                   cell_data={"density": [density], "design": [is_design]}))
    if frequencies is not None:
        values = " ".join(repr(float(f)) for f in frequencies)
        field = (f'<FieldData><DataArray type="Float64" Name="frequencies_Hz" NumberOfTuples="{frequencies.size}" '
                 f'format="ascii">{values}</DataArray></FieldData>')
        text = path.read_text()
        if text.count("<UnstructuredGrid>") != 1:
            raise RuntimeError(f"Unexpected VTU layout written by meshio in {path}.")
        path.write_text(text.replace("<UnstructuredGrid>", "<UnstructuredGrid>" + field))
    return path
