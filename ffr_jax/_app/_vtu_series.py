"""The motion of a designed body for ParaView: a VTU time series (`.pvd` and one `.vtu` per time)."""

import xml.etree.ElementTree as ElementTree
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from .._dynamics._case import Case
from .._outputs._peak_stress import element_von_mises
from .._design.solid_mesh import SolidMesh
from ._animation import body_motion, designed_body_index
from ._solid_motion import solid_body_motion


def write_vtu_series(path, case: Case, x_phys, *, frames: int = 60, rtol: float = 1e-8,
                     atol: float = 1e-12) -> Path:
    """Write the designed body over the motion as a ParaView time series: a `.pvd` collection and
    one `.vtu` file per output time (in a folder beside it named after it, `<stem>_vtu/`).

    Each `.vtu` holds the body's elements (VTK `quad`) at the rigid placement `R + A(theta) c_n`
    of time `t_k` (inertial frame, `z = 0`), with point data `elastic_displacement`, the elastic
    displacement `A(theta) Phi q` in the inertial frame (3-vectors, `z = 0`: ParaView's *Warp By
    Vector* with scale factor 1 draws the true deformed body, a larger factor amplifies it), and
    cell data `density` (physical density of every element, passive ones included) and `design`
    (1 on design elements, 0 on passive ones), `von_mises` (the element's von Mises stress at time
    `t_k`, the largest of its 2x2 Gauss points, from the stress modes) and
    `peak_von_mises` (its peak over all frames, [`peak_von_mises`][]; both in Pa, the macroscopic
    SIMP stress). The `.pvd` lists the files with their times, so
    ParaView plays the motion. The motion is `body_motion`'s: one simulation with output at
    `linspace(t0, t1, frames)`. Works on any quadrilateral mesh.

    A solid body ([`SolidMesh`][]: hexahedra or 10-node tetrahedra in a spatial scene) is written as its
    VTK cells (`hexahedron`, `tetra10`) at the placement `R + A(p) c_n` with the 3-D elastic
    displacement `A(p) Phi q`, and cell data `density` and `design` (no stresses).

    **Arguments:**
    - `path`: the `.pvd` file to write.
    - `case`: a case with one designed body; `x_phys`: `(n_design,)` physical densities.
    - `frames`: number of output times (at least 2); `rtol`, `atol`: tolerances of the simulation.

    **Returns:** the path of the `.pvd` written.
    """
    import meshio

    path = Path(path)
    # Every input is checked before the simulation runs.
    if path.suffix.lower() != ".pvd":
        raise ValueError(f"Write the VTU series as a .pvd collection (one .vtu per time beside it), got {path.name}.")
    if not (isinstance(frames, (int, np.integer)) and frames >= 2):
        raise ValueError(f"A time series needs a whole number of frames, at least 2, got frames={frames!r}.")
    solid = isinstance(case.mesh, SolidMesh)
    index = None if solid else designed_body_index(case)
    x_phys = np.asarray(case.design.check(jnp.asarray(x_phys, dtype=float)))
    ts = np.linspace(case.t0, case.t1, frames)
    mesh, domain = case.mesh, case.design.domain
    design = np.isin(np.arange(mesh.n_elements), np.asarray(domain.design_elements)).astype(float)
    if solid:
        points, displacement = solid_body_motion(case, x_phys, ts, rtol=rtol, atol=atol)[:2]
        cells = [(mesh.cell_type, np.asarray(mesh.elements))]
        density = case.design.domain.element_densities(jnp.asarray(x_phys), case.design.material.x_min)
        cell_data = {"density": [np.asarray(density)], "design": [design]}
        frame_data = [{} for _ in ts]
    else:
        scene = case.scene_template
        rigid, elastic, y_r = body_motion(case, x_phys, ts, rtol=rtol, atol=atol)
        q = y_r[:, scene.offsets[index] + 3 : scene.offsets[index] + scene.sizes[index]]
        von_mises = np.asarray(element_von_mises(case.design, jnp.asarray(x_phys), jnp.asarray(q)))
        cells = [("quad", np.asarray(mesh.elements))]
        cell_data = {"density": [np.asarray(case.design.element_densities(x_phys))], "design": [design],
                     "peak_von_mises": [von_mises.max(axis=0)]}
        frame_data = [{"von_mises": [von_mises[k]]} for k in range(len(ts))]
        points = np.zeros((len(ts), mesh.n_nodes, 3))
        points[:, :, :2] = rigid
        displacement = np.zeros((len(ts), mesh.n_nodes, 3))
        displacement[:, :, :2] = elastic
    folder = path.with_name(f"{path.stem}_vtu")
    folder.mkdir(parents=True, exist_ok=True)
    collection = ElementTree.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
    datasets = ElementTree.SubElement(collection, "Collection")
    for k, t in enumerate(ts):
        name = folder / f"{path.stem}_{k:04d}.vtu"
        meshio.write(name, meshio.Mesh(points[k], cells, point_data={"elastic_displacement": displacement[k]},
                                       cell_data={**cell_data, **frame_data[k]}))
        ElementTree.SubElement(datasets, "DataSet", timestep=repr(float(t)), group="", part="0",
                               file=f"{folder.name}/{name.name}")
    ElementTree.indent(collection)
    path.write_text('<?xml version="1.0"?>\n' + ElementTree.tostring(collection, encoding="unicode") + "\n")
    return path
