"""A flexible spatial body from another FE code: node coordinates, `M` and `K` in, modes and body data out.

What an FE code (Abaqus, Ansys, NETGEN/NGSolve, Code_Aster, FEniCS, ...) can export for a solid part is its node
coordinates and its global mass and stiffness matrices (Exudyn's `FEMinterface` takes the same). From them
[`body_data_from_matrices`][] computes the modes of the part and its spatial standard input data with
[`solid_body_data`][], the same function that the package's own solid FE chain uses, so a part modelled elsewhere
enters a mechanism exactly as one modelled here.

**Modes.** Free-free by default: a free part has six rigid-body motions `R` `(3 n_nodes, 6)` with `K R = 0`
(checked: it is what tells a matrix in another degree-of-freedom order, or with supports, from a free part); the
elastic modes are the lowest eigenpairs of `K phi = lam M phi` after the six zero ones (checked to be six: a
seventh is a detached piece or a mechanism), `M`-orthogonal to the rigid motions; the package's own
[`free_modes_dense`][] deflates the rigid modes instead (for a stable derivative), which gives the same modes.
With `fixed_dofs` the modes are those of the part held at those degrees of freedom (an attached frame), from the
pencil of the free degrees of freedom. Dense `eigh` up to 3000 degrees of freedom; larger ones go to shift-invert
Lanczos (ARPACK) as in [`free_modes_sparse`][].

**Gauge.** Modes are scaled to `Phi^T M Phi = I` and signed so that the first degree of freedom whose displacement
exceeds `1e-3` of the mode's largest is positive (a sign that round-off cannot flip). A repeated eigenvalue has
no preferred basis of its eigenspace: the body data then depend on the solver's choice by an orthogonal change
of the modal coordinates `q`, which changes no motion of the body.
"""

import os
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import scipy.io
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .._design.solid_modes import rigid_motions
from ._flexible_body_data import SpatialFlexibleBodyData
from ._solid_body_data import solid_body_data

# The FE matrices are symmetric up to the round-off of their assembly (~1e-16 relative per entry), and up to
# 5e-8 of the largest entry where an FE code prints them with 7 significant digits; a transposed or mistyped block,
# or a mass matrix with directions coupled, differs by O(1). 1e-6 of the largest entry tells them apart; the
# matrices are then symmetrised, 0.5 (A + A^T).
SYMMETRY_TOL = 1e-6
# K R = 0 for a free part. Measured on a 3 x 2 x 1 H8 block: 2e-16 of |K| |R| with exact coordinates, 4e-9 / 1.4e-6
# with the coordinates printed to 8 / 6 significant digits (the residual is the coordinates' relative rounding), 0.13
# with two nodes swapped, 1.7 with the nodes shuffled, 1.1 with blocked degrees of freedom read as interleaved. 1e-4
# accepts coordinates given to 6 digits and refuses any misnumbering (a swap of nodes an element apart gives about
# the element size over the part size, > 1e-3 for any mesh of fewer than 1e9 elements).
RIGID_TOL = 1e-4
# Dense eigensolution up to this many degrees of freedom (a 3000 x 3000 eigh: ~10 s); sparse Lanczos above.
DENSE_MAX = 3000


def _load(x, what: str):
    """An array or SciPy sparse matrix, or one read from a file: `.mtx`/`.mm` (Matrix Market), `.npy`, `.npz`
    (a SciPy sparse matrix from `scipy.sparse.save_npz`), `.csv` or text (`numpy.loadtxt`)."""
    if not isinstance(x, (str, os.PathLike)):
        return x
    path = Path(x)
    suffix = path.suffix.lower()
    try:
        if suffix in (".mtx", ".mm"):
            return scipy.io.mmread(path)
        if suffix == ".npy":
            return np.load(path, allow_pickle=False)
        if suffix == ".npz":
            return sp.load_npz(path)
        return np.loadtxt(path, delimiter="," if suffix == ".csv" else None, ndmin=2)
    except FileNotFoundError:
        raise
    except Exception as err:
        raise ValueError(f"{what}: cannot read {path} as a {suffix or 'text'} file ({err}). Give a Matrix Market "
                         "(.mtx), .npy, scipy.sparse .npz, .csv or whitespace-separated text file, or an array.") from None


def _as_matrix(x, n_dof: int, what: str):
    """A float64 dense array or CSR matrix of shape `(n_dof, n_dof)`, checked finite and symmetric."""
    x = _load(x, what)
    x = x.tocsr().astype(np.float64) if sp.issparse(x) else np.asarray(x, dtype=np.float64)
    if x.shape != (n_dof, n_dof):
        raise ValueError(f"{what} has shape {x.shape}, expected ({n_dof}, {n_dof}): three degrees of freedom "
                         f"(u_x, u_y, u_z) per node of the {n_dof // 3} nodes of coordinates.")
    values = x.data if sp.issparse(x) else x
    if not np.all(np.isfinite(values)):
        raise ValueError(f"{what} contains NaN or inf.")
    scale = np.max(np.abs(values), initial=0.0)
    if scale == 0.0:
        raise ValueError(f"{what} is zero.")
    asym = abs(x - x.T).max() if sp.issparse(x) else np.max(np.abs(x - x.T))
    if asym > SYMMETRY_TOL * scale:
        raise ValueError(f"{what} is not symmetric (differs from its transpose by {asym / scale:.3g} of its largest "
                         f"entry; allowed {SYMMETRY_TOL:g}). Export the full symmetric matrix.")
    return 0.5 * (x + x.T)


def _blocked_to_interleaved(x, n_nodes: int):
    perm = np.arange(3 * n_nodes).reshape(3, n_nodes).T.reshape(-1)  # new dof 3 n + a <- old dof a n_nodes + n
    return x[perm][:, perm]


def _check_mass_structure(m) -> None:
    """`M = m_s ⊗ I_3` (interleaved): equal scalar blocks for x, y and z, no coupling between directions."""
    part = lambda a, b: m[a::3][:, b::3]
    amax = lambda x: float(abs(x).max()) if sp.issparse(x) else float(np.max(np.abs(x)))
    m_s = part(0, 0)
    scale = amax(m_s)
    off = max(amax(part(a, b)) for a in range(3) for b in range(3) if a != b)
    diff = max(amax(part(a, a) - m_s) for a in (1, 2))
    if off > SYMMETRY_TOL * scale or diff > SYMMETRY_TOL * scale:
        raise ValueError(
            "mass is not m_s ⊗ I_3 in interleaved degrees of freedom (u_x, u_y, u_z of node n at 3n, 3n+1, 3n+2): "
            f"the directions differ by {diff / scale:.3g} or are coupled by {off / scale:.3g} of the largest entry. "
            "Solid elements with three translational degrees of freedom per node have it; if the matrices are "
            "ordered by direction (all u_x, then u_y, then u_z) pass dof_order='blocked'; shell or beam models with "
            "rotational degrees of freedom are not supported.")
    diag = m_s.diagonal()
    if np.any(diag <= 0.0):
        raise ValueError(f"mass has non-positive diagonal entries at nodes {np.flatnonzero(diag <= 0.0)[:8].tolist()}: "
                         "every node must carry mass (a consistent or lumped mass matrix of a solid mesh).")


def _sign_gauge(phi: np.ndarray) -> np.ndarray:
    """Each column signed so that its first entry above 1e-3 of its largest magnitude is positive."""
    big = np.abs(phi) > 1e-3 * np.max(np.abs(phi), axis=0)
    first = np.argmax(big, axis=0)
    return phi * np.sign(phi[first, np.arange(phi.shape[1])])


def _eigh_lowest(k, m, n: int, sigma_shift: float, dense: bool):
    """The `n` lowest eigenpairs of `k v = lam m v`, `v^T m v = I` (dense `eigh`, or sparse shift-invert Lanczos)."""
    if dense:
        k = k.toarray() if sp.issparse(k) else k
        m = m.toarray() if sp.issparse(m) else m
        try:
            return scipy.linalg.eigh(k, m, subset_by_index=[0, n - 1])
        except np.linalg.LinAlgError as err:
            raise ValueError(f"mass is not positive definite ({err}): a node without mass, or a wrong mass "
                             "matrix.") from None
    k, m = sp.csc_matrix(k), sp.csc_matrix(m)
    lu = spla.splu((k - sigma_shift * m).tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                   options={"SymmetricMode": True})
    op = spla.LinearOperator(k.shape, matvec=lu.solve, dtype=float)
    v0 = np.random.default_rng(0).standard_normal(k.shape[0])
    _, basis = spla.eigsh(k, n, M=m, sigma=sigma_shift, OPinv=op, which="LM", v0=v0, tol=0.0)
    k_r, m_r = basis.T @ (k @ basis), basis.T @ (m @ basis)
    lam, rot = scipy.linalg.eigh(0.5 * (k_r + k_r.T), 0.5 * (m_r + m_r.T))
    return lam, basis @ rot


def fe_modes(coordinates, stiffness, mass, n_modes: int, fixed_dofs=None, solver: str = "auto"):
    """The lowest elastic modes of a part given by its matrices (module docstring): `(lam, Phi)`, `(n_modes,)`
    `omega^2` ascending and `(3 n_nodes, n_modes)` with `Phi^T M Phi = I`, in the sign gauge of the module
    docstring. Arguments as [`body_data_from_matrices`][] (NumPy/SciPy, interleaved, already checked)."""
    n_dof = 3 * coordinates.shape[0]
    dense = solver == "dense" or (solver == "auto" and n_dof <= DENSE_MAX)
    diag_k = stiffness.diagonal() if sp.issparse(stiffness) else np.diag(stiffness)
    diag_m = mass.diagonal() if sp.issparse(mass) else np.diag(mass)
    sigma = float(np.max(diag_k / diag_m))  # a Rayleigh quotient: sigma <= lam_max
    if fixed_dofs is None:
        r = rigid_motions(coordinates)
        k_r = stiffness @ r
        residual = np.max(np.abs(k_r)) / (np.max(np.abs(diag_k)) * np.max(np.abs(r)))
        if residual > RIGID_TOL:
            raise ValueError(
                f"stiffness does not vanish on the six rigid-body motions of coordinates (|K R| / |K| |R| = "
                f"{residual:.3g}, allowed {RIGID_TOL:g}), so it is not the stiffness of this free part: check that "
                "coordinates are the nodes of the matrices in the same order, that the degrees of freedom are "
                "interleaved (else dof_order='blocked'), and that no supports are built into K (else give "
                "fixed_dofs of the supported part's free matrices).")
        if n_modes > n_dof - 6 - (0 if dense else 1):
            raise ValueError(f"n_modes={n_modes} exceeds the {n_dof - 6} elastic modes of the part.")
        lam, phi = _eigh_lowest(stiffness, mass, n_modes + 6, -1e-8 * sigma, dense)
        # The six rigid eigenvalues are round-off, ~eps lam_max (~1e-7 lam_max for matrices printed to 7 digits); the
        # first elastic one is ~(h / L)^2 lam_max (h the element size, L the part's), far above. A seventh within
        # 100 times the rigid ones' level is another zero-energy mode.
        noise = float(np.max(np.abs(lam[:6])))
        if not lam[6] > 100.0 * noise:
            raise ValueError(f"the part has more than six zero-energy modes (lowest eigenvalues {lam[:7].tolist()}): "
                             "a detached piece, a piece hinged at a node or an edge, or a mechanism. Check the mesh.")
        lam, phi = lam[6:], phi[:, 6:]
    else:
        fixed = np.unique(np.asarray(fixed_dofs, dtype=int).reshape(-1))
        if fixed.size == 0 or fixed[0] < 0 or fixed[-1] >= n_dof:
            raise ValueError(f"fixed_dofs must be degree-of-freedom indices in [0, {n_dof}) (3 node + direction), "
                             f"got {np.asarray(fixed_dofs).tolist()!r}; leave it None for free-free modes.")
        free = np.setdiff1d(np.arange(n_dof), fixed)
        if n_modes > free.size - (0 if dense else 1):
            raise ValueError(f"n_modes={n_modes} exceeds the {free.size} free degrees of freedom.")
        k_f, m_f = stiffness[free][:, free], mass[free][:, free]
        lam, phi_f = _eigh_lowest(k_f, m_f, n_modes, -1e-8 * sigma, dense)
        if lam[0] <= 1e-10 * sigma:
            raise ValueError(f"the supported part still moves rigidly (lowest eigenvalue {lam[0]:.3g}, stiffness "
                             f"scale {sigma:.3g}): fixed_dofs do not hold it; fix at least six independent "
                             "degrees of freedom (e.g. all three of three nodes not on one line).")
        phi = np.zeros((n_dof, n_modes))
        phi[free] = phi_f
    return lam, _sign_gauge(phi)


class _HostMatrix:
    """A NumPy or SciPy matrix applied to JAX arrays (for `solid_body_data`, which needs only `shape` and `@`)."""

    def __init__(self, matrix):
        self.matrix, self.shape = matrix, matrix.shape

    def __matmul__(self, v):
        return jnp.asarray(self.matrix @ np.asarray(v))


def body_data_from_matrices(coordinates, stiffness, mass, markers: tuple, n_modes: int | None = None, *,
                            modes=None, fixed_dofs=None, elements=None, dof_order: str = "interleaved",
                            solver: str = "auto") -> SpatialFlexibleBodyData:
    """Spatial body data of a solid part from its node coordinates and its FE mass and stiffness matrices.

    The modes are computed (free-free, or held at `fixed_dofs`; module docstring) unless given, and the body data
    are [`solid_body_data`][] of them: the quadratic forms of `M` with the nodal fields `1, c, phi_k`,
    `M_qq = Phi^T M Phi = I`, `K_qq = Phi^T K Phi = diag(omega^2)` (so `sqrt(diag(data.modal_stiffness))` are the
    part's angular eigenfrequencies, to compare with the FE code's own), the markers' translations and rotations.
    Computed on the host (NumPy/SciPy), not differentiable: a part read from outside has no design here.

    **Arguments:**
    - `coordinates`: `(n_nodes, 3)` node coordinates in the body frame (its origin and axes are the body frame's),
      an array or a `.npy`, `.csv` or text file.
    - `stiffness`, `mass`: `K`, `M` `(3 n_nodes, 3 n_nodes)`, symmetric; dense arrays, SciPy sparse matrices, or
      files: Matrix Market `.mtx` (`scipy.io.mmread`), `.npy`, SciPy sparse `.npz` (`scipy.sparse.save_npz`).
      Three translational degrees of freedom per node, `M = m_s ⊗ I_3` (every solid element's consistent or lumped
      mass matrix; checked).
    - `markers`: static tuple, the joint points: each a node index or a tuple of node indices (a point at their
      centroid; its rotation is that of their rigid fit, so give nodes that span a plane, e.g. a bore's surface,
      or pass `elements`).
    - `n_modes`: how many modes to compute (a positive int), or `None` with `modes` given.
    - `modes`: `(3 n_nodes, n_q)` shape vectors to use instead of computing them (e.g. the FE code's own modes, or
      Craig–Bampton modes).
    - `fixed_dofs`: degree-of-freedom indices (`3 node + direction`, after reordering) held for the modes (an
      attached frame); `None` (default): free-free modes, the six rigid-body motions removed.
    - `elements`: optional `(n_elements, nodes per element)` connectivity (0-based), for markers of one node or of
      nodes on one line (their rotation comes from the patch of elements around them).
    - `dof_order`: `"interleaved"` (`u_x, u_y, u_z` of node `n` at `3n, 3n+1, 3n+2`, the default) or `"blocked"`
      (all `u_x`, then all `u_y`, then all `u_z`).
    - `solver`: `"auto"` (dense up to 3000 degrees of freedom, else sparse), `"dense"` or `"sparse"`.

    **Returns:** a [`SpatialFlexibleBodyData`][]; write it with [`write_body_data`][] to reuse the part without its
    matrices.

    **Raises:** `ValueError` for unreadable files, wrong shapes, non-symmetric matrices, a mass matrix that is not
    `m_s ⊗ I_3` or not positive definite, a stiffness that does not vanish on rigid motions of a free part (wrong
    order of nodes or degrees of freedom), and too many modes.

    **Example:**
    ```python
    data = fj.body_data_from_matrices("nodes.csv", "K.mtx", "M.mtx", markers=(bore_a, bore_b), n_modes=6)
    fj.write_body_data("link.npz", data)
    ```
    """
    coords = _load(coordinates, "coordinates")
    coords = np.asarray(coords.toarray() if sp.issparse(coords) else coords, dtype=np.float64)
    if coords.ndim != 2 or coords.shape[1] != 3 or coords.shape[0] < 3 or not np.all(np.isfinite(coords)):
        raise ValueError(f"coordinates must be a finite (n_nodes, 3) array with n_nodes >= 3, got shape "
                         f"{coords.shape}.")
    if dof_order not in ("interleaved", "blocked"):
        raise ValueError(f"dof_order must be 'interleaved' or 'blocked', got {dof_order!r}.")
    if solver not in ("auto", "dense", "sparse"):
        raise ValueError(f"solver must be 'auto', 'dense' or 'sparse', got {solver!r}.")
    n_nodes = coords.shape[0]
    k = _as_matrix(stiffness, 3 * n_nodes, "stiffness")
    m = _as_matrix(mass, 3 * n_nodes, "mass")
    if dof_order == "blocked":
        k, m = _blocked_to_interleaved(k, n_nodes), _blocked_to_interleaved(m, n_nodes)
    _check_mass_structure(m)
    if (modes is None) == (n_modes is None):
        raise ValueError("give either n_modes (the modes are computed) or modes (used as given), not both or "
                         "neither.")
    if modes is not None and fixed_dofs is not None:
        raise ValueError("fixed_dofs choose the supports of computed modes; with modes given they would be ignored: "
                         "give one of them.")
    if modes is None:
        if not isinstance(n_modes, (int, np.integer)) or isinstance(n_modes, bool) or n_modes < 1:
            raise ValueError(f"n_modes must be a positive int, got {n_modes!r}.")
        _, phi = fe_modes(coords, k, m, int(n_modes), fixed_dofs, solver)
    else:
        phi = np.asarray(_load(modes, "modes"), dtype=np.float64)
        if phi.ndim != 2 or phi.shape[0] != 3 * n_nodes or phi.shape[1] < 1 or not np.all(np.isfinite(phi)):
            raise ValueError(f"modes must be a finite (3 n_nodes, n_q) = ({3 * n_nodes}, n_q >= 1) array, got "
                             f"{phi.shape}.")
        if dof_order == "blocked":
            phi = phi.reshape(3, n_nodes, -1).transpose(1, 0, 2).reshape(3 * n_nodes, -1)
    return solid_body_data(coords, _HostMatrix(k), _HostMatrix(m), jnp.asarray(phi), markers, elements=elements)
