"""The motion of a designed body for ParaView: a VTU time series (`.pvd` and one `.vtu` per time)."""

import xml.etree.ElementTree as ElementTree
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from .._dynamics._case import Case
from .._outputs._peak_stress import element_von_mises
from ._animation import body_motion, designed_body_index


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
    index, scene = designed_body_index(case), case.scene_template
    x_phys = np.asarray(case.design.check(jnp.asarray(x_phys, dtype=float)))
    ts = np.linspace(case.t0, case.t1, frames)
    rigid, elastic, y_r = body_motion(case, x_phys, ts, rtol=rtol, atol=atol)
    q = y_r[:, scene.offsets[index] + 3 : scene.offsets[index] + scene.sizes[index]]
    von_mises = np.asarray(element_von_mises(case.design, jnp.asarray(x_phys), jnp.asarray(q)))
    mesh, domain = case.mesh, case.design.domain
    quads = np.asarray(mesh.elements)
    cell_data = {"density": [np.asarray(case.design.element_densities(x_phys))],
                 "design": [np.isin(np.arange(mesh.n_elements), np.asarray(domain.design_elements)).astype(float)],
                 "peak_von_mises": [von_mises.max(axis=0)]}
    folder = path.with_name(f"{path.stem}_vtu")
    folder.mkdir(parents=True, exist_ok=True)
    collection = ElementTree.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
    datasets = ElementTree.SubElement(collection, "Collection")
    for k, t in enumerate(ts):
        points = np.zeros((mesh.n_nodes, 3))
        points[:, :2] = rigid[k]
        displacement = np.zeros((mesh.n_nodes, 3))
        displacement[:, :2] = elastic[k]
        name = folder / f"{path.stem}_{k:04d}.vtu"
        meshio.write(name, meshio.Mesh(points, [("quad", quads)], point_data={"elastic_displacement": displacement},
                                       cell_data={**cell_data, "von_mises": [von_mises[k]]}))
        ElementTree.SubElement(datasets, "DataSet", timestep=repr(float(t)), group="", part="0",
                               file=f"{folder.name}/{name.name}")
    ElementTree.indent(collection)
    path.write_text('<?xml version="1.0"?>\n' + ElementTree.tostring(collection, encoding="unicode") + "\n")
    return path
