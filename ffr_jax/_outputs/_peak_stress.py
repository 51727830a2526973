"""The peak von Mises stress of each element of a designed body over the motion."""

import equinox as eqx
import jax.numpy as jnp

from .._design.design_map import DesignMap
from .._dynamics._case import Case
from .._dynamics._simulate import Trajectory
from ._relaxed_stresses import relaxed_stress_modes
from ._stresses import stress_modes, von_mises


def designed_body_index(case, where: str) -> int:
    """The scene index of the case's one designed body, or a `ValueError` saying how many it has."""
    if not isinstance(case, Case):
        raise ValueError(f"{where} takes a case (e.g. ffr_jax.cases.slider_crank(...)), got {type(case).__name__}.")
    names = case.design_map.names if isinstance(case.design_map, DesignMap) else ()
    if len(names) != 1:
        raise ValueError(f"{where} measures the stress of one designed body; this case designs {list(names)}.")
    return case.problem.scene.body_index(names[0])


@eqx.filter_jit
def element_von_mises(body, x, q, relaxation=None):
    """`max_g sigma_vm(t)_eg`: the von Mises stress of every element (the largest of its 2x2 Gauss points) at
    each row of modal coordinates `q` `(n_t, n_q)` of the body `body` at design `x`, `(n_t, n_elements)`.

    Macroscopic stresses ([`stress_modes`][]) with `relaxation=None`, else the relaxed stresses of
    [`relaxed_stress_modes`][] with exponent `relaxation` (a static float).
    """
    modes = stress_modes(body, x) if relaxation is None else relaxed_stress_modes(body, x, relaxation)
    sigma = jnp.einsum("egck,tk->tegc", modes, q)
    return jnp.max(von_mises(sigma), axis=2)


def peak_von_mises(case, trajectory, x, *, relaxation=None):
    """`max_{t, g} sigma_vm(t)_eg`: the peak von Mises stress of every element of the case's designed body
    over the output times of `trajectory` and the element's 2x2 Gauss points, `(n_elements,)`.

    The stresses are `sum_k sigma_k q_k(t)` with the stress modes of design `x` ([`stress_modes`][]: the
    macroscopic SIMP stress `E_e D B Phi q`), or, with `relaxation=s`, the relaxed stresses
    `x_e^s E0 D B Phi q` of [`relaxed_stress_modes`][] that [`aggregated_stress`][] constrains. The peak is
    taken over the output times only: give `ts` fine enough to resolve the motion.

    **Arguments:**
    - `case`: a case with one designed body; `trajectory`: [`simulate`][]`(case, x, ts=...)`; `x`: its design.
    - `relaxation`: `None` (macroscopic stress) or the exponent `s >= 0`.

    **Returns:** `(n_elements,)` in Pa, in the mesh's element order (`case.mesh`).
    """
    index = designed_body_index(case, "ffr_jax.peak_von_mises")
    if not isinstance(trajectory, Trajectory):
        raise ValueError(f"ffr_jax.peak_von_mises takes the ffr_jax.Trajectory of ffr_jax.simulate(case, x, ts=...), "
                         f"got {type(trajectory).__name__}.")
    scene = case.problem.scene
    if trajectory.positions.shape[-1] != scene.n_coordinates:
        raise ValueError(f"The trajectory has {trajectory.positions.shape[-1]} redundant coordinates, the case's scene "
                         f"{scene.n_coordinates}: simulate this case first.")
    if relaxation is not None and (isinstance(relaxation, bool) or not isinstance(relaxation, (int, float))
                                   or not relaxation >= 0):
        raise ValueError(f"ffr_jax.peak_von_mises: relaxation is None or an exponent s >= 0, got {relaxation!r}.")
    o = scene.offsets[index]
    q = trajectory.positions[:, o + 3 : o + scene.sizes[index]]
    return jnp.max(element_von_mises(case.design, case.check(x), q, None if relaxation is None else float(relaxation)),
                   axis=0)
