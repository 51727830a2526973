"""Body-data files (`fj.write_body_data` / `fj.read_body_data`) and a body read from another FE code's matrices
(`fj.body_data_from_matrices`), issue 26.

- A round trip is bit for bit: every field's bytes and dtype, for the three kinds of body data (no tolerance).
- Every kind of bad file is refused with a `fj.BodyDataFileError` (a `ValueError`) that names the file and what is
  wrong: not a body-data file, truncated, corrupt (CRC-32 and SHA-256), a newer format version, a missing or
  wrongly shaped field, and physically impossible data (mass <= 0, a non-symmetric or indefinite mass).
- A box modelled by the package's own H8 chain, exported as Matrix Market matrices and a CSV of node coordinates,
  read back by `fj.body_data_from_matrices`, gives the package's body data to 1e-12 (tolerance argued at
  `test_body_from_matrices_equals_the_package_chain`).

Cheap: point-mass body data (no compiled program) and one 72-dof box (dense 72 x 72 eigensolutions).
"""

import io
import json
import zipfile

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.io

import ffr_jax as fj
from ffr_jax._design.solid_assembly import solid_dense_matrix
from ffr_jax._spatial import _body_data_file as files

EPS = np.finfo(np.float64).eps


def _planar_point_masses(masses, c2, phi2, modal_k):
    """Planar body data of point masses in the plane, every field by its definition (module docstring of BodyData)."""
    rot = np.stack([-c2[:, 1], c2[:, 0]], axis=1)  # I~ c
    rot_phi = np.stack([-phi2[:, 1], phi2[:, 0]], axis=1)
    return fj.BodyData(
        mass=jnp.asarray(masses.sum()), first_moment=jnp.asarray(masses @ c2),
        modal_moment=jnp.asarray(np.einsum("n,nak->ak", masses, phi2)),
        inertia=jnp.asarray(np.einsum("n,na,na->", masses, c2, c2)),
        inertia_q=jnp.asarray(np.einsum("n,nak,na->k", masses, phi2, c2)),
        modal_mass=jnp.asarray(np.einsum("n,naj,nak->jk", masses, phi2, phi2)),
        coupling_0=jnp.asarray(np.einsum("n,nak,na->k", masses, phi2, rot)),
        coupling=jnp.asarray(np.einsum("n,naj,nak->jk", masses, phi2, rot_phi)),
        modal_stiffness=jnp.asarray(modal_k), marker_positions=jnp.asarray(c2[:2]),
        marker_modes=jnp.asarray(phi2[:2]))


def _point_mass_bodies():
    """One body of each kind from a point-mass model (every field exact for it, no FE model needed)."""
    rng = np.random.default_rng(7)
    n, n_q = 12, 3
    masses = rng.uniform(0.5, 1.5, n)
    positions = rng.normal(size=(n, 3)) * [0.5, 0.2, 0.1]
    modes = rng.normal(size=(n, 3, n_q))
    modal_k = np.diag([3.0, 5.0, 11.0])
    rotations = rng.normal(size=(2, 3, n_q))
    flexible = fj.spatial_flexible_body_data(masses, positions, modes, modal_k, (0, 5), rotations)
    s = masses @ positions
    c0 = np.einsum("n,na,nb->ab", masses, positions, positions)
    rigid = fj.spatial_rigid_body_data(masses.sum(), s, np.trace(c0) * np.eye(3) - c0, positions[:3])
    planar = _planar_point_masses(masses, positions[:, :2], modes[:, :2, :], modal_k)
    return {"SpatialFlexibleBodyData": flexible, "SpatialBodyData": rigid, "BodyData": planar}


BODIES = _point_mass_bodies()


def test_the_format_names_every_field_of_the_classes():
    for kind, cls in files._KINDS.items():
        assert tuple(cls.__dataclass_fields__) == files._field_names(kind), (
            f"{kind} changed its fields: give the new ones a shape in _body_data_file._SHAPES, raise FORMAT_VERSION, "
            "and read the older version's files too.")


def _fields(data):
    return tuple(data.__dataclass_fields__)


def _assert_bit_for_bit(got, want):
    assert type(got) is type(want)
    for name in _fields(want):
        a, b = np.asarray(getattr(got, name)), np.asarray(getattr(want, name))
        assert a.dtype == b.dtype == np.float64 and a.shape == b.shape, name
        assert a.tobytes() == b.tobytes(), f"{name} differs after the round trip"


@pytest.mark.parametrize("kind", sorted(BODIES))
def test_round_trip_is_bit_for_bit(tmp_path, kind):
    data = BODIES[kind]
    path = tmp_path / "body.npz"
    fj.write_body_data(path, data, description="point masses")
    got = fj.read_body_data(path)
    _assert_bit_for_bit(got, data)
    assert isinstance(getattr(got, "mass"), jnp.ndarray)
    # Overwriting is atomic: the new content replaces the old, no temporary file is left.
    fj.write_body_data(path, data)
    _assert_bit_for_bit(fj.read_body_data(path), data)
    assert [p.name for p in tmp_path.iterdir()] == ["body.npz"]
    # The container is NumPy's own: np.load reads the fields, and the header documents the format.
    with np.load(path) as npz:
        np.testing.assert_array_equal(npz["mass"], np.asarray(data.mass))
    with zipfile.ZipFile(path) as z:
        header = json.loads(z.read("header.json"))
    assert (header["format"], header["format_version"], header["kind"]) == ("ffr_jax.body_data", 1, kind)
    assert [f["name"] for f in header["fields"]] == list(_fields(data))


def _arrays(data):
    return {name: np.asarray(getattr(data, name)) for name in _fields(data)}


def _expect(path, *words):
    with pytest.raises(fj.BodyDataFileError) as info:
        fj.read_body_data(path)
    msg = str(info.value)
    assert str(path) in msg, msg
    for word in words:
        assert word in msg, f"{word!r} not in: {msg}"
    assert isinstance(info.value, ValueError)
    return msg


@pytest.fixture
def good(tmp_path):
    path = tmp_path / "good.npz"
    fj.write_body_data(path, BODIES["SpatialFlexibleBodyData"])
    return path


def test_not_a_body_data_file(tmp_path):
    text = tmp_path / "notes.npz"
    text.write_text("mass = 1 kg\n")
    _expect(text, "not a body-data file", "not a ZIP")
    plain = tmp_path / "plain.npz"
    np.savez(plain, mass=np.array(1.0))
    _expect(plain, "not a body-data file", "header.json")


def test_truncated_file(good, tmp_path):
    raw = good.read_bytes()
    for cut in (len(raw) // 2, len(raw) - 5):
        path = tmp_path / f"cut{cut}.npz"
        path.write_bytes(raw[:cut])
        _expect(path, "truncated")
    empty = tmp_path / "empty.npz"
    empty.write_bytes(b"")
    _expect(empty, "truncated")


def test_corrupt_file(good, tmp_path):
    raw = bytearray(good.read_bytes())
    # A damaged byte in the middle of the second moments' data: the entry's CRC-32 fails.
    with zipfile.ZipFile(good) as z:
        info = z.getinfo("second_moment_qq.npy")
    at = info.header_offset + 30 + len(info.filename) + info.file_size - 20
    raw[at] ^= 0x10
    damaged = tmp_path / "damaged.npz"
    damaged.write_bytes(bytes(raw))
    _expect(damaged, "corrupt", "second_moment_qq.npy")
    # An entry replaced after writing (a valid archive whose arrays no longer match the header's SHA-256).
    edited = tmp_path / "edited.npz"
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(edited, "w") as dst:
        for name in src.namelist():
            data = src.read(name)
            if name == "mass.npy":
                buf = io.BytesIO()
                np.save(buf, np.array(2.0))
                data = buf.getvalue()
            dst.writestr(name, data)
    _expect(edited, "corrupt", "SHA-256")


def test_newer_format_version(tmp_path):
    path = tmp_path / "future.npz"
    files.write_arrays(path, "SpatialFlexibleBodyData", _arrays(BODIES["SpatialFlexibleBodyData"]), version=2)
    _expect(path, "format version 2", "up to version 1", "Upgrade ffr_jax")


def test_missing_and_wrongly_shaped_fields(tmp_path):
    arrays = _arrays(BODIES["SpatialFlexibleBodyData"])
    missing = tmp_path / "missing.npz"
    files.write_arrays(missing, "SpatialFlexibleBodyData", {k: v for k, v in arrays.items() if k != "marker_rotations"})
    _expect(missing, "marker_rotations", "missing")
    shaped = tmp_path / "shaped.npz"
    files.write_arrays(shaped, "SpatialFlexibleBodyData", {**arrays, "marker_modes": arrays["marker_modes"][..., :2]})
    _expect(shaped, "'marker_modes'", "shape (2, 3, 2)", "expected (2, 3, 3)")
    typed = tmp_path / "typed.npz"
    files.write_arrays(typed, "SpatialFlexibleBodyData", {**arrays, "mass": arrays["mass"].astype(np.float32)})
    _expect(typed, "'mass'", "float64")


def _impossible():
    """(name, kind, arrays, words): body data that no body with a non-negative mass density has."""
    flex = _arrays(BODIES["SpatialFlexibleBodyData"])
    rigid = _arrays(BODIES["SpatialBodyData"])
    planar = _arrays(BODIES["BodyData"])
    skewed = flex["modal_mass"].copy()
    skewed[0, 1] *= 1.01  # a 1 % asymmetry, far above the round-off allowance 1e-8
    # |S1_k|^2 <= m M_qq[k, k] (Cauchy–Schwarz in the M inner product): breaking it makes the mass matrix indefinite.
    big_s1 = flex["modal_moment"].copy()
    big_s1[:, 0] = 2.0 * np.sqrt(flex["mass"] * flex["modal_mass"][0, 0]) * np.array([1.0, 0.0, 0.0])
    negative_j = rigid["inertia"] - 2.0 * np.eye(3) * np.max(np.linalg.eigvalsh(rigid["inertia"]))
    # A mode that is a rigid translation (every point moves by e_x): the planar mass matrix at rest is singular.
    rng = np.random.default_rng(7)
    masses, positions, modes = rng.uniform(0.5, 1.5, 12), rng.normal(size=(12, 3)), rng.normal(size=(12, 2, 3))
    modes[:, :, 0] = [1.0, 0.0]
    rigid_mode = _arrays(_planar_point_masses(masses, positions[:, :2], modes, np.diag([3.0, 5.0, 11.0])))
    return [
        ("zero mass", "SpatialFlexibleBodyData", {**flex, "mass": np.array(0.0)}, ("'mass'", "positive")),
        ("asymmetric modal mass", "SpatialFlexibleBodyData", {**flex, "modal_mass": skewed},
         ("'modal_mass'", "symmetric")),
        ("asymmetric second moment", "SpatialFlexibleBodyData",
         {**flex, "second_moment": flex["second_moment"] + np.triu(np.ones((3, 3)), 1) * 0.1},
         ("'second_moment'", "symmetric")),
        ("indefinite body mass", "SpatialFlexibleBodyData", {**flex, "modal_moment": big_s1},
         ("mass matrix of the body at rest", "indefinite")),
        ("indefinite inertia", "SpatialBodyData", {**rigid, "inertia": negative_j},
         ("mass matrix of the body at rest", "indefinite")),
        ("indefinite modal mass", "BodyData", {**planar, "modal_mass": -planar["modal_mass"]},
         ("'modal_mass'", "not positive definite")),
        ("rigid mode", "BodyData", rigid_mode, ("mass matrix of the body at rest", "singular", "rigid-body motion")),
        ("NaN", "SpatialBodyData", {**rigid, "first_moment": np.array([0.0, np.nan, 0.0])}, ("first_moment", "NaN")),
    ]


@pytest.mark.parametrize("case", _impossible(), ids=lambda c: c[0])
def test_physically_impossible_data(tmp_path, case):
    name, kind, arrays, words = case
    path = tmp_path / "impossible.npz"
    files.write_arrays(path, kind, arrays)
    _expect(path, *words)
    # The writer refuses the same data (a file it writes is always readable), and writes nothing.
    with pytest.raises(fj.BodyDataFileError, match="body data to write"):
        files.check_body_data_arrays(kind, arrays, "body data to write")


def test_write_refuses_what_is_not_body_data(tmp_path):
    with pytest.raises(TypeError, match="SpatialFlexibleBodyData"):
        fj.write_body_data(tmp_path / "x.npz", {"mass": 1.0})
    assert not list(tmp_path.iterdir())


# ---------------------------------------------------------------------------------------------------------------
# A body from another FE code's matrices.

@pytest.fixture(scope="module")
def box():
    """A compact 3 x 2 x 1 H8 steel block `1.0 x 0.6 x 0.35`: the package's own chain (dense free-free modes,
    `fj.solid_body_data`) and its exported M, K (Matrix Market) and node coordinates (CSV)."""
    mesh = fj.box_grid(3, 2, 1, 1.0, 0.6, 0.35)
    model = fj.SolidFEModel(mesh, fj.H8(), poisson=0.3)
    youngs, densities = jnp.full(mesh.n_elements, 2.1e11), jnp.full(mesh.n_elements, 7800.0)
    lam, modes = fj.free_modes_dense(model, youngs, densities, 4)
    k = np.asarray(solid_dense_matrix(model, youngs, "stiffness"))
    m = np.asarray(solid_dense_matrix(model, densities, "mass"))
    x = mesh.nodes[:, 0]
    markers = (tuple(int(i) for i in np.flatnonzero(x < 1e-9)), tuple(int(i) for i in np.flatnonzero(x > 1.0 - 1e-9)))
    return dict(coords=np.asarray(mesh.nodes), k=k, m=m, lam=np.asarray(lam), modes=np.asarray(modes),
                markers=markers)


@pytest.fixture(scope="module")
def exported(box, tmp_path_factory):
    d = tmp_path_factory.mktemp("fe_export")
    scipy.io.mmwrite(d / "K.mtx", box["k"], symmetry="symmetric")
    scipy.io.mmwrite(d / "M.mtx", box["m"], symmetry="symmetric")
    np.savetxt(d / "nodes.csv", box["coords"], delimiter=",", fmt="%.17g")
    return d


def _scales(data):
    """A natural size of each field, by Cauchy–Schwarz in the M inner product with `Phi^T M Phi = I`: `|S1| <= sqrt(m)`,
    `|C1| <= sqrt(tr C0)`, `|C2|, |M_qq| <= 1`, `|K_qq| <= omega_max^2`; the rest their largest entry (their
    entries are not near-cancelling sums)."""
    m, c0 = float(data.mass), np.asarray(data.second_moment)
    out = {name: max(float(np.max(np.abs(np.asarray(getattr(data, name))))), 1e-300) for name in _fields(data)}
    out.update(modal_moment=np.sqrt(m), second_moment_q=np.sqrt(np.trace(c0)), second_moment_qq=1.0, modal_mass=1.0)
    return out


def test_body_from_matrices_equals_the_package_chain(box, exported):
    """`fj.body_data_from_matrices(nodes.csv, K.mtx, M.mtx)` = `fj.solid_body_data` of `fj.free_modes_dense`, 1e-12.

    Both are exact for the FE model; Matrix Market and CSV round-trip float64 exactly (shortest repr). They differ
    by the two eigensolutions (SciPy's of the pencil, JAX's of the deflated pencil) and the modes' sign, the gauge
    aligned here by `sign(phi_pkg^T M phi)`. A backward-stable symmetric eigensolver perturbs the pencil by
    ~eps lam_max, which turns mode k by at most eps lam_max / gap_k (Davis–Kahan), gap_k its eigenvalue's distance
    to every other (the six zero ones included); this block is compact so that the bound is below 1e-13 (asserted), leaving 10x for the
    solvers' constants within 1e-12 of each field's natural size (`_scales`): the body data are linear or
    quadratic in the modes with coefficients bounded by those sizes."""
    chol = np.linalg.cholesky(box["m"])
    lam_all = np.linalg.eigvalsh(np.linalg.solve(chol, np.linalg.solve(chol, box["k"]).T))  # the six rigid ones too
    gaps = [np.min(np.abs(np.delete(lam_all, k) - lam_all[k])) for k in range(6, 10)]
    assert EPS * lam_all[-1] / min(gaps) < 1e-13, "the tolerance argument needs well-separated eigenvalues"

    got = fj.body_data_from_matrices(exported / "nodes.csv", exported / "K.mtx", exported / "M.mtx", box["markers"],
                                     n_modes=4)
    freq = np.sqrt(np.diag(np.asarray(got.modal_stiffness)))
    np.testing.assert_allclose(freq**2, box["lam"], rtol=1e-12, err_msg="omega^2 of the two eigensolutions")
    # The gauge: the package's modes signed as the computed ones.
    m_phi = box["m"] @ box["modes"]
    from ffr_jax._spatial._body_from_matrices import fe_modes
    _, phi = fe_modes(box["coords"], box["k"], box["m"], 4)
    signs = np.sign(np.sum(m_phi * phi, axis=0))
    want = fj.solid_body_data(box["coords"], jnp.asarray(box["k"]), jnp.asarray(box["m"]),
                              jnp.asarray(box["modes"] * signs), box["markers"])
    scales = _scales(want)
    for name in _fields(want):
        err = float(np.max(np.abs(np.asarray(getattr(got, name)) - np.asarray(getattr(want, name)))))
        assert err <= 1e-12 * scales[name], f"{name}: {err:.3g} vs 1e-12 x {scales[name]:.3g}"

    # Given modes (e.g. the FE code's own) take the same path: the same data to round-off of the products.
    given = fj.body_data_from_matrices(box["coords"], box["k"], box["m"], box["markers"],
                                       modes=box["modes"] * signs)
    for name in _fields(want):
        err = float(np.max(np.abs(np.asarray(getattr(given, name)) - np.asarray(getattr(want, name)))))
        assert err <= 1e-13 * scales[name], name


def test_body_from_matrices_variants(box):
    """The sparse solver, blocked degree-of-freedom order and supports give consistent modes."""
    import scipy.sparse as sp
    from ffr_jax._spatial._body_from_matrices import fe_modes
    lam, phi = fe_modes(box["coords"], box["k"], box["m"], 4)
    # Sparse shift-invert Lanczos: the same eigenvalues; its Ritz vectors are accurate to ~1e-10 (ARPACK's
    # convergence on a 72-dof pencil), so compare the projectors.
    lam_s, phi_s = fe_modes(box["coords"], sp.csr_matrix(box["k"]), sp.csr_matrix(box["m"]), 4, solver="sparse")
    np.testing.assert_allclose(lam_s, lam, rtol=1e-10)
    np.testing.assert_allclose(phi_s @ phi_s.T @ box["m"], phi @ phi.T @ box["m"], atol=1e-8)
    # Blocked order (all u_x, then u_y, then u_z): the same body data.
    n = box["coords"].shape[0]
    perm = np.arange(3 * n).reshape(n, 3).T.reshape(-1)
    blocked = fj.body_data_from_matrices(box["coords"], box["k"][perm][:, perm], box["m"][perm][:, perm],
                                         box["markers"], n_modes=2, dof_order="blocked")
    inter = fj.body_data_from_matrices(box["coords"], box["k"], box["m"], box["markers"], n_modes=2)
    for name in _fields(inter):
        np.testing.assert_allclose(np.asarray(getattr(blocked, name)), np.asarray(getattr(inter, name)),
                                   rtol=1e-12, atol=1e-12 * _scales(inter)[name], err_msg=name)
    # Coordinates printed to 8 significant digits, as FE codes often write them, pass the K R = 0 check (their
    # residual is their rounding, ~5e-9); the modes do not depend on them, the moments change by the rounding.
    rounded = np.array([[float(f"{v:.7e}") for v in row] for row in box["coords"]])
    coarse = fj.body_data_from_matrices(rounded, box["k"], box["m"], box["markers"], n_modes=2)
    np.testing.assert_array_equal(np.asarray(coarse.modal_stiffness), np.asarray(inter.modal_stiffness))
    for name in _fields(inter):
        np.testing.assert_allclose(np.asarray(getattr(coarse, name)), np.asarray(getattr(inter, name)), rtol=0,
                                   atol=1e-6 * _scales(inter)[name], err_msg=name)
    # Clamped at the x = 0 face: an attached frame; the modes vanish there and are stiffer than free-free ones.
    fixed = [3 * i + a for i in box["markers"][0] for a in range(3)]
    clamped = fj.body_data_from_matrices(box["coords"], box["k"], box["m"], box["markers"], n_modes=2,
                                         fixed_dofs=fixed)
    assert np.all(np.asarray(clamped.marker_modes)[0] == 0.0)
    assert np.asarray(clamped.modal_stiffness)[0, 0] < lam[0]  # a cantilever is softer than the free block


def test_body_from_matrices_bad_input(box, tmp_path):
    c, k, m, mk = box["coords"], box["k"], box["m"], box["markers"]
    n = c.shape[0]
    perm = np.arange(3 * n).reshape(n, 3).T.reshape(-1)
    shuffled = c[np.random.default_rng(0).permutation(n)]  # nodes in another order than the matrices
    with pytest.raises(ValueError, match="rigid-body motions"):
        fj.body_data_from_matrices(shuffled, k, m, mk, n_modes=2)
    with pytest.raises(ValueError, match="m_s ⊗ I_3.*dof_order='blocked'"):
        fj.body_data_from_matrices(c, k[perm][:, perm], m[perm][:, perm], mk, n_modes=2)
    asym = k.copy()
    asym[0, 1] += 1e-3 * np.max(np.abs(k))
    with pytest.raises(ValueError, match="stiffness is not symmetric"):
        fj.body_data_from_matrices(c, asym, m, mk, n_modes=2)
    with pytest.raises(ValueError, match=r"expected \(72, 72\)"):
        fj.body_data_from_matrices(c, k[:-3, :-3], m, mk, n_modes=2)
    with pytest.raises(ValueError, match="either n_modes"):
        fj.body_data_from_matrices(c, k, m, mk)
    bad = tmp_path / "K.mtx"
    bad.write_text("not a matrix\n")
    with pytest.raises(ValueError, match="cannot read"):
        fj.body_data_from_matrices(c, bad, m, mk, n_modes=2)


def test_design_derivatives_round_trip(tmp_path):
    """The augmented data (Held 2021): `d p / d x` from `jax.jacfwd` written with the data and read back bit for bit
    as a pytree of the data's type; a file without them, or derivatives of the wrong shape, are refused."""
    rng = np.random.default_rng(3)
    masses, positions = rng.uniform(0.5, 1.5, 6), rng.normal(size=(6, 3))
    modes = rng.normal(size=(6, 3, 2))

    def body(x):  # node masses and modal stiffness scaled by a 3-entry design
        return fj.spatial_flexible_body_data(masses * (1.0 + x[0] * np.arange(6.0) + x[1]), positions, modes,
                                             jnp.diag(jnp.array([3.0, 5.0]) * (1.0 + x[2])), (0, 4))

    x = jnp.array([0.1, 0.2, 0.3])
    data, d_data = body(x), jax.jacfwd(body)(x)
    path = tmp_path / "augmented.npz"
    fj.write_body_data(path, data, jacobian=d_data)
    got, d_got = fj.read_body_data(path, jacobian=True)
    _assert_bit_for_bit(got, data)
    for name in _fields(data):
        a, b = np.asarray(getattr(d_got, name)), np.asarray(getattr(d_data, name))
        assert a.shape == np.shape(getattr(data, name)) + (3,) and a.tobytes() == b.tobytes(), name
    _assert_bit_for_bit(fj.read_body_data(path), data)  # a reader that wants only the data

    plain = tmp_path / "plain.npz"
    fj.write_body_data(plain, data)
    _expect_jacobian = pytest.raises(fj.BodyDataFileError, match="no design derivatives")
    with _expect_jacobian:
        fj.read_body_data(plain, jacobian=True)
    arrays = {**_arrays(data), **{"d_" + k: v for k, v in _arrays(d_data).items()}}
    arrays["d_modal_mass"] = arrays["d_modal_mass"][..., :2]
    bad = tmp_path / "bad.npz"
    files.write_arrays(bad, "SpatialFlexibleBodyData", arrays)
    _expect(bad, "design derivative of 'modal_mass'", "(2, 2, 3)")
