"""Body-data files: the body data of one body, written once and read anywhere, versioned and validated.

A body modelled once (by the package's own FE chain, or read from another FE code's matrices) can be
reused in other mechanisms without its FE model: [`write_body_data`][] stores a [`SpatialFlexibleBodyData`][],
[`SpatialBodyData`][] or planar [`BodyData`][]; [`read_body_data`][] gives back the same object, bit for bit.

**Format (version 1).** A ZIP archive (Python's `zipfile`, entries stored uncompressed) that NumPy reads as an
`.npz` file (`numpy.load(path)`; the suffix `.npz` is recommended, not required):

- `header.json`: a UTF-8 JSON object with `format` (`"ffr_jax.body_data"`), `format_version` (an int),
  `kind` (`"SpatialFlexibleBodyData"`, `"SpatialBodyData"` or `"BodyData"`), `fields` (a list of
  `{"name", "shape", "dtype"}` in the class's field order), `sha256` (the hex SHA-256 of the concatenated
  bytes of the array entries, in that order), `units`, `description` and `writer`;
- one `<field>.npy` entry per field (NumPy's documented `.npy` format, little-endian float64 `<f8`), the
  field's meaning and shape given by the class's docstring (e.g. `second_moment_qq` `(n_q, n_q, 3, 3)`);
- optionally the design derivatives at the design the data were computed for (the "augmented standard input
  data" of Held 2021): one `d_<field>.npy` entry per field, `d field / d x` `(field shape..., n_design)`.

Why this container: `.npy`/`.npz` is NumPy's own maintained, documented format, readable without this
package (NumPy in Python, `cnpy` in C++, `NPZ.jl` in Julia) and exact for float64 (the bytes are stored as
they are, so a round trip is bit for bit); ZIP adds a CRC-32 per entry, which catches damaged bytes; the
JSON header makes the file self-describing and versioned without pickle (nothing in a file is executed:
every entry is read with `allow_pickle=False`). HDF5 would do as well but adds a dependency.

Units: the package converts nothing; the data are in the consistent units of the model they came from
(SI for the package's cases: kg, m, s, N). The writer may name them (`units=`).

Reading validates, each failure a [`BodyDataFileError`][] (a `ValueError`) naming the file, the entry and
what to do: not a body-data file; truncated (the ZIP directory at its end missing); corrupt (a CRC-32 or
SHA-256 mismatch, an unreadable entry or header); written by a newer format version than this package reads;
a missing, extra, non-float64 or wrongly shaped field or design derivative; physically impossible data (NaN or inf, mass `<= 0`,
a second moment, modal mass or modal stiffness that is not symmetric, a modal stiffness that is not
positive semi-definite, a mass matrix of the body at rest that is indefinite, or singular in the modal coordinates:
a mode that is a rigid-body motion).

References:
- A. Held, *On design sensitivities in the structural analysis and optimization of flexible multibody systems*,
  Multibody System Dynamics (2021), doi:10.1007/s11044-021-09800-1 (body input data files augmented by their
  design derivatives).
"""

import hashlib
import io
import json
import os
import tempfile
import zipfile
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from .._errors import FFRJaxError
from .._scene._body_data import BodyData
from ._body_data import SpatialBodyData
from ._flexible_body_data import SpatialFlexibleBodyData

FORMAT = "ffr_jax.body_data"
FORMAT_VERSION = 1
HEADER = "header.json"
JACOBIAN_PREFIX = "d_"
_KINDS = {"SpatialFlexibleBodyData": SpatialFlexibleBodyData, "SpatialBodyData": SpatialBodyData,
          "BodyData": BodyData}
# Each field's shape in the symbols `q` (modes, from modal_mass) and `m` (markers, from marker_positions).
_SHAPES = {
    "BodyData": {"mass": (), "first_moment": (2,), "modal_moment": (2, "q"), "inertia": (), "inertia_q": ("q",),
                 "modal_mass": ("q", "q"), "coupling_0": ("q",), "coupling": ("q", "q"),
                 "modal_stiffness": ("q", "q"), "marker_positions": ("m", 2), "marker_modes": ("m", 2, "q")},
    "SpatialBodyData": {"mass": (), "first_moment": (3,), "inertia": (3, 3), "marker_positions": ("m", 3)},
    "SpatialFlexibleBodyData": {
        "mass": (), "first_moment": (3,), "modal_moment": (3, "q"), "second_moment": (3, 3),
        "second_moment_q": ("q", 3, 3), "second_moment_qq": ("q", "q", 3, 3), "modal_mass": ("q", "q"),
        "modal_stiffness": ("q", "q"), "marker_positions": ("m", 3), "marker_modes": ("m", 3, "q"),
        "marker_rotations": ("m", 3, "q")},
}
_UNITS = "as computed (the package converts nothing; SI for its own cases: kg, m, s, N)"
# Symmetry of the FE quadratic forms (Phi^T M Phi, sum_m c c^T, ...): computed in float64 they are symmetric to
# about n_terms * eps ~ 1e-11 relative for 1e5 terms; 1e-8 (the body-data classes' own tolerance) leaves a factor
# 1000 and still catches any real asymmetry (a transposed or mistyped block).
SYMMETRY_TOL = 1e-8
# The mass matrix at rest, scaled to unit diagonal, has eigenvalues in [0, n]. Its entries are sums of N products
# (N = number of mass-matrix entries of the FE model), each rounded to ~N eps relative: for N up to 1e6 a
# perturbation of the scaled matrix below ~2e-10, so an eigenvalue within 1e-9 of zero cannot be told from zero.
# Below -1e-9 the matrix is indefinite (impossible). Zero is allowed in the rigid-body block (a point mass or a thin
# rod: the classes accept them, a joint fixes the rotation) but not for the modes: a mode whose part not explained by
# rigid motions (the Schur complement) has a scaled mass below 1e-9 is (nearly) a rigid-body motion.
DEFINITE_TOL = 1e-9


class BodyDataFileError(FFRJaxError, ValueError):
    """A body-data file cannot be read or written: not such a file, truncated, corrupt, of a newer format
    version, with missing or wrongly shaped fields, or with physically impossible data (a `ValueError`)."""


def _kind_of(data) -> str:
    for kind, cls in _KINDS.items():
        if type(data) is cls:
            return kind
    raise TypeError(f"write_body_data takes a SpatialFlexibleBodyData, SpatialBodyData or BodyData, got "
                    f"{type(data).__name__}.")


def _field_names(kind: str) -> tuple[str, ...]:
    """The fields that format version 1 stores for `kind` (the class's fields when it was written; a field added to a
    class later needs a new format version, see tests/test_body_data_file.py)."""
    return tuple(_SHAPES[kind])


def _skew(a):
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def mass_matrix_at_rest(kind: str, arrays: dict[str, np.ndarray]) -> np.ndarray:
    """The generalised mass matrix of the body at rest (`q = 0`) in its body frame, from its body data.

    Spatial, coordinates `(v_R, omega, qdot)`: a point at `u = c + Phi q` moves with `v_R - u~ omega + Phi qdot`,
    so `M = sum_m [I, -c~, Phi]^T [I, -c~, Phi]` `= [[m I, -s0~, S1], [s0~, J0, W], [S1^T, W^T, M_qq]]` with
    `J0 = tr C0 I - C0` and `W[:, k] = sum_m c x phi_k` (the vector part of `C1[k]`). Planar, coordinates
    `(v_R, theta_dot, qdot)`: `[[m I, I~ s0, S1], [(I~ s0)^T, J0, G0^T], [S1^T, G0, M_qq]]`.
    """
    a = arrays
    m = float(a["mass"])
    if kind == "BodyData":
        s0 = a["first_moment"]
        rot_s0 = np.array([-s0[1], s0[0]])
        n_q = a["modal_mass"].shape[0]
        out = np.zeros((3 + n_q, 3 + n_q))
        out[:2, :2] = m * np.eye(2)
        out[:2, 2] = out[2, :2] = rot_s0
        out[2, 2] = a["inertia"]
        out[:2, 3:] = a["modal_moment"]
        out[3:, :2] = a["modal_moment"].T
        out[2, 3:] = out[3:, 2] = a["coupling_0"]
        out[3:, 3:] = a["modal_mass"]
        return out
    s0 = a["first_moment"]
    if kind == "SpatialBodyData":
        j0, n_q = a["inertia"], 0
    else:
        c0 = a["second_moment"]
        j0, n_q = np.trace(c0) * np.eye(3) - c0, a["modal_mass"].shape[0]
    out = np.zeros((6 + n_q, 6 + n_q))
    out[:3, :3] = m * np.eye(3)
    out[:3, 3:6] = -_skew(s0)
    out[3:6, :3] = _skew(s0)
    out[3:6, 3:6] = j0
    if n_q:
        c1 = a["second_moment_q"]
        w = np.stack([c1[:, 1, 2] - c1[:, 2, 1], c1[:, 2, 0] - c1[:, 0, 2], c1[:, 0, 1] - c1[:, 1, 0]])
        out[:3, 6:], out[6:, :3] = a["modal_moment"], a["modal_moment"].T
        out[3:6, 6:], out[6:, 3:6] = w, w.T
        out[6:, 6:] = a["modal_mass"]
    return out


def _asymmetry(x: np.ndarray, xt: np.ndarray) -> float:
    return float(np.max(np.abs(x - xt), initial=0.0) / max(np.max(np.abs(x), initial=0.0), 1e-300))


def _scaled(a: np.ndarray) -> np.ndarray:
    """`D^-1/2 a D^-1/2`, `D = diag(a)` (rows with a zero diagonal unscaled)."""
    d = np.sqrt(np.abs(np.diag(a)))
    d[d == 0.0] = 1.0
    s = (a / d[:, None]) / d[None, :]
    return 0.5 * (s + s.T)


def _scaled_min_eigenvalue(a: np.ndarray) -> float:
    return float(np.linalg.eigvalsh(_scaled(a))[0])


def _modal_schur_min_eigenvalue(a: np.ndarray, n_rigid: int) -> float:
    """Smallest eigenvalue of the scaled modal block less its part explained by rigid-body motions."""
    s = _scaled(a)
    r, q = s[:n_rigid, :n_rigid], s[n_rigid:, n_rigid:]
    c = s[:n_rigid, n_rigid:]
    schur = q - c.T @ np.linalg.pinv(r, rcond=DEFINITE_TOL, hermitian=True) @ c
    return float(np.linalg.eigvalsh(0.5 * (schur + schur.T))[0])


def check_body_data_arrays(kind: str, arrays: dict[str, np.ndarray], where: str) -> None:
    """Shapes and physics of the arrays of one body's data; a [`BodyDataFileError`][] starting with `where`."""
    names, shapes = _field_names(kind), _SHAPES[kind]
    missing = [n for n in names if n not in arrays]
    extra = [n for n in arrays if n not in names]
    if missing or extra:
        raise BodyDataFileError(f"{where}: the {kind} fields {missing} are missing and {extra} are unknown; a "
                                f"{kind} has the fields {list(names)}. Write the file with ffr_jax.write_body_data.")
    for name in names:
        if arrays[name].dtype != np.float64:
            raise BodyDataFileError(f"{where}: field {name!r} has dtype {arrays[name].dtype}, expected float64 "
                                    "(<f8); the package works in float64.")
    sizes = {"q": arrays["modal_mass"].shape[0] if kind != "SpatialBodyData" and arrays["modal_mass"].ndim else None,
             "m": arrays["marker_positions"].shape[0] if arrays["marker_positions"].ndim else None}
    for name in names:
        want = tuple(sizes.get(s, s) if isinstance(s, str) else s for s in shapes[name])
        if arrays[name].shape != want:
            raise BodyDataFileError(
                f"{where}: field {name!r} has shape {arrays[name].shape}, expected {want} (n_q = {sizes['q']} modes "
                f"from modal_mass, {sizes['m']} markers from marker_positions); see the docstring of {kind}.")
    if kind == "SpatialFlexibleBodyData" and sizes["q"] == 0:
        raise BodyDataFileError(f"{where}: a SpatialFlexibleBodyData needs at least one mode (modal_mass is 0 x 0); "
                                "a rigid spatial body is a SpatialBodyData.")
    bad = [n for n in names if not np.all(np.isfinite(arrays[n]))]
    if bad:
        raise BodyDataFileError(f"{where}: fields {bad} contain NaN or inf.")
    if not float(arrays["mass"]) > 0.0:
        raise BodyDataFileError(f"{where}: field 'mass' is {float(arrays['mass'])}; the mass of a body must be "
                                "positive.")
    pairs = {"inertia": (1, 0), "second_moment": (1, 0), "modal_mass": (1, 0), "modal_stiffness": (1, 0),
             "second_moment_qq": (1, 0, 3, 2)}
    for name, axes in pairs.items():
        if name in arrays and arrays[name].ndim == len(axes):
            asym = _asymmetry(arrays[name], np.transpose(arrays[name], axes))
            if asym > SYMMETRY_TOL:
                rule = "C2[k, j] = C2[j, k]^T" if name == "second_moment_qq" else "symmetric"
                raise BodyDataFileError(
                    f"{where}: field {name!r} must be {rule} (a quadratic form of the mass or stiffness matrix), but "
                    f"differs from its transpose by {asym:.3g} of its largest entry (allowed {SYMMETRY_TOL:g}). "
                    "Check how the matrix was computed or exported (a transposed or mistyped block?).")
    if "modal_mass" in arrays and sizes["q"]:
        lam = _scaled_min_eigenvalue(arrays["modal_mass"])
        if lam <= DEFINITE_TOL:
            raise BodyDataFileError(
                f"{where}: field 'modal_mass' (Phi^T M Phi) is not positive definite (smallest eigenvalue {lam:.3g} "
                "after scaling to unit diagonal): the modes must be linearly independent and carry mass, and the "
                "FE mass matrix must be positive semi-definite.")
        k = arrays["modal_stiffness"]
        lam_k = float(np.linalg.eigvalsh(0.5 * (k + k.T))[0])
        scale = max(np.max(np.abs(k)), 1e-300)
        if lam_k < -SYMMETRY_TOL * scale:
            raise BodyDataFileError(
                f"{where}: field 'modal_stiffness' (Phi^T K Phi) has the negative eigenvalue {lam_k:.3g} (largest "
                f"entry {scale:.3g}): a body whose strain energy can be negative is unstable. Check the sign and "
                "the assembly of the stiffness matrix.")
    fields = ("mass, first_moment, inertia" if kind == "SpatialBodyData" else
              "mass, first_moment, inertia, modal_moment, coupling_0, modal_mass" if kind == "BodyData" else
              "mass, first_moment, second_moment, modal_moment, second_moment_q, modal_mass")
    at_rest = mass_matrix_at_rest(kind, arrays)
    lam = _scaled_min_eigenvalue(at_rest)
    if lam < -DEFINITE_TOL:
        raise BodyDataFileError(
            f"{where}: the mass matrix of the body at rest (from the fields {fields}) is indefinite (smallest "
            f"eigenvalue {lam:.3g} after scaling to unit diagonal): no body with a non-negative mass density has it. "
            "Check that the inertia or second moment is about the body-frame origin, of the right sign, and in the "
            "same units as the mass and first moment, and that the modal moments belong to these modes.")
    n_rigid = 3 if kind == "BodyData" else 6
    if at_rest.shape[0] > n_rigid:
        lam = _modal_schur_min_eigenvalue(at_rest, n_rigid)
        if lam <= DEFINITE_TOL:
            raise BodyDataFileError(
                f"{where}: the mass matrix of the body at rest (from the fields {fields}) is singular in the modal "
                f"coordinates (smallest eigenvalue of the modes' part not explained by rigid-body motions {lam:.3g} "
                f"after scaling, at least {DEFINITE_TOL:g} needed): a mode, or a combination of modes, is a "
                "rigid-body motion of the body, and the accelerations cannot be solved for. Remove the rigid-body "
                "motions from the modes (free-free modes, or modes of the supported body).")


def check_jacobian_arrays(kind: str, arrays: dict[str, np.ndarray], jacobian: dict[str, np.ndarray],
                          where: str) -> None:
    """The design derivatives `d field / d x` of checked body-data arrays: every field, shape `field + (n_design,)`,
    float64, finite, and symmetric where the field is (the derivative of a symmetric matrix is symmetric)."""
    if not jacobian:
        return
    names = _field_names(kind)
    missing = [n for n in names if n not in jacobian]
    extra = [n for n in jacobian if n not in names]
    if missing or extra:
        raise BodyDataFileError(f"{where}: the design derivatives of the fields {missing} are missing and those of "
                                f"{extra} are unknown; give d field / d x for every field of {kind} or for none.")
    n_design = jacobian["mass"].shape[0] if jacobian["mass"].ndim == 1 else None
    for name in names:
        d = jacobian[name]
        want = arrays[name].shape + (n_design,)
        if d.dtype != np.float64 or d.shape != want or not n_design:
            raise BodyDataFileError(
                f"{where}: the design derivative of {name!r} is {d.dtype} {d.shape}, expected float64 {want} (the "
                f"field's shape and one design axis of n_design = {n_design} from that of 'mass'). Flatten a "
                "multi-dimensional design to one axis.")
        if not np.all(np.isfinite(d)):
            raise BodyDataFileError(f"{where}: the design derivative of {name!r} contains NaN or inf.")
    pairs = {"inertia": (1, 0, 2), "second_moment": (1, 0, 2), "modal_mass": (1, 0, 2), "modal_stiffness": (1, 0, 2),
             "second_moment_qq": (1, 0, 3, 2, 4)}
    for name, axes in pairs.items():
        if name in jacobian and jacobian[name].ndim == len(axes):
            asym = _asymmetry(jacobian[name], np.transpose(jacobian[name], axes))
            if asym > SYMMETRY_TOL:
                raise BodyDataFileError(
                    f"{where}: the design derivative of {name!r} differs from its transpose by {asym:.3g} of its "
                    f"largest entry (allowed {SYMMETRY_TOL:g}): the derivative of a symmetric field is symmetric.")


def _arrays_of(data, kind: str) -> dict[str, np.ndarray]:
    arrays = {}
    for name in _field_names(kind):
        leaf = getattr(data, name)
        if isinstance(leaf, jax.core.Tracer):
            raise TypeError("write_body_data needs concrete body data: call it outside jax.jit / jax.grad.")
        arrays[name] = np.asarray(leaf)
    return arrays


def _npy_bytes(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.asarray(array, order="C"), allow_pickle=False)  # ascontiguousarray makes 0-d 1-d
    return buf.getvalue()


def write_arrays(path, kind: str, arrays: dict[str, np.ndarray], units: str = _UNITS, description: str = "",
                 version: int = FORMAT_VERSION) -> None:
    """Write a body-data file from raw arrays, unchecked (for [`write_body_data`][] and for tests of the reader).
    Atomic: a temporary file in the target's directory, renamed over the target when complete."""
    path = Path(path)
    names = [n for n in _field_names(kind) if n in arrays] + [n for n in arrays if n not in _field_names(kind)]
    # (d_<field> entries, the design derivatives, follow the fields)
    members = {n: _npy_bytes(arrays[n]) for n in names}
    header = {"format": FORMAT, "format_version": version, "kind": kind,
              "fields": [{"name": n, "shape": list(arrays[n].shape), "dtype": arrays[n].dtype.str} for n in names],
              "sha256": hashlib.sha256(b"".join(members[n] for n in names)).hexdigest(),
              "units": units, "description": description, "writer": "ffr_jax"}
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            with zipfile.ZipFile(f, "w", compression=zipfile.ZIP_STORED) as z:
                z.writestr(HEADER, json.dumps(header, indent=1))
                for n in names:
                    z.writestr(f"{n}.npy", members[n])
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def write_body_data(path, data, *, jacobian=None, units: str = _UNITS, description: str = "") -> None:
    """Write the body data of one body, and optionally their design derivatives, to a body-data file (format
    version 1; see the module docs).

    The data are checked first as [`read_body_data`][] checks them, so a file that this function writes is
    always readable. The file is written atomically (a temporary file renamed over `path`), so a reader never
    sees a half-written file, and an interrupted write leaves an older file at `path` as it was.

    **Arguments:**
    - `path`: the file to write (`.npz` recommended; overwritten if it exists).
    - `data`: a [`SpatialFlexibleBodyData`][], [`SpatialBodyData`][] or planar [`BodyData`][] with concrete
      float64 arrays (not inside `jax.jit`; one body, not a batch).
    - `jacobian`: optional design derivatives `d p / d x` of the body data at the design `x` they were computed
      for (the "augmented standard input data"): the same type as `data`, each field with one more, last axis
      of length `n_design`, as `jax.jacfwd(p)(x)` gives for a function `p` from a design vector `x` `(n_design,)`
      to body data. Stored as entries `d_<field>.npy`.
    - `units`: a note of the units the data are in (stored, never used).
    - `description`: free text stored in the header (e.g. the part's name and how it was modelled).

    **Returns:** `None`.

    **Example:**
    ```python
    fj.write_body_data("rod.npz", fj.lifted_body_data(model, k, m, modes, markers))
    rod = fj.read_body_data("rod.npz")   # the same SpatialFlexibleBodyData, bit for bit
    ```
    """
    kind = _kind_of(data)
    arrays = _arrays_of(data, kind)
    where = f"body data to write to {os.fspath(path)}"
    check_body_data_arrays(kind, arrays, where)
    if jacobian is not None:
        if type(jacobian) is not type(data):
            raise TypeError(f"jacobian must be a {kind} of design derivatives (e.g. jax.jacfwd of the function that "
                            f"gives the body data), got {type(jacobian).__name__}.")
        jac = _arrays_of(jacobian, kind)
        check_jacobian_arrays(kind, arrays, jac, where)
        arrays.update({JACOBIAN_PREFIX + name: value for name, value in jac.items()})
    write_arrays(path, kind, arrays, units=units, description=str(description))


def _fail(path, what: str) -> BodyDataFileError:
    return BodyDataFileError(f"{os.fspath(path)}: {what}")


def _open_archive(path, raw: bytes) -> zipfile.ZipFile:
    if len(raw) == 0:
        raise _fail(path, "the file is empty (truncated: an interrupted copy or download?). Copy or write it again.")
    if not raw.startswith(b"PK\x03\x04"):
        raise _fail(path, "not a body-data file (not a ZIP/.npz archive; body-data files are written by "
                          "ffr_jax.write_body_data).")
    end = raw.rfind(b"PK\x05\x06")
    if end < 0 or len(raw) < end + 22 or len(raw) < end + 22 + int.from_bytes(raw[end + 20:end + 22], "little"):
        raise _fail(path, f"truncated: the archive's directory at its end is missing ({len(raw)} bytes; an "
                          "interrupted copy, download or write?). Copy or write the file again.")
    try:
        return zipfile.ZipFile(io.BytesIO(raw))
    except (zipfile.BadZipFile, ValueError, EOFError) as err:
        raise _fail(path, f"corrupt: the archive's directory cannot be read ({err}). Copy or write the file "
                          "again.") from None


def _member(path, archive: zipfile.ZipFile, name: str) -> bytes:
    try:
        return archive.read(name)
    except KeyError:
        raise _fail(path, f"entry {name!r} is missing from the archive. Write the file again with "
                          "ffr_jax.write_body_data.") from None
    except (zipfile.BadZipFile, EOFError, ValueError, NotImplementedError, OSError) as err:
        raise _fail(path, f"corrupt: entry {name!r} cannot be read ({err}). Copy or write the file again.") from None


def _header(path, archive: zipfile.ZipFile) -> dict:
    if HEADER not in archive.namelist():
        raise _fail(path, f"not a body-data file: a ZIP/.npz archive without {HEADER!r} (entries "
                          f"{archive.namelist()[:8]}); body-data files are written by ffr_jax.write_body_data.")
    try:
        header = json.loads(_member(path, archive, HEADER).decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise _fail(path, f"corrupt: {HEADER!r} is not valid UTF-8 JSON ({err}).") from None
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        got = header.get("format") if isinstance(header, dict) else type(header).__name__
        raise _fail(path, f"not a body-data file: its header names the format {got!r}, not {FORMAT!r}.")
    version = header.get("format_version")
    if not isinstance(version, int) or isinstance(version, bool) or version < 1:
        raise _fail(path, f"corrupt: the header's format_version is {version!r}, not a positive int.")
    if version > FORMAT_VERSION:
        raise _fail(path, f"written in body-data format version {version}, newer than this ffr_jax reads (up to "
                          f"version {FORMAT_VERSION}). Upgrade ffr_jax (pip install -U ffr_jax) to read it.")
    kind = header.get("kind")
    if kind not in _KINDS:
        raise _fail(path, f"the header's kind {kind!r} is not one of {sorted(_KINDS)}.")
    fields = header.get("fields")
    if (not isinstance(fields, list) or not isinstance(header.get("sha256"), str)
            or not all(isinstance(f, dict) and isinstance(f.get("name"), str) for f in fields)):
        raise _fail(path, "corrupt: the header's field list or sha256 is malformed.")
    return header


def read_body_data(path, *, jacobian: bool = False):
    """Read the body data of one body from a body-data file written by [`write_body_data`][].

    Every check of the module docs is made before anything is built, and each failure names the file, the
    entry or field, and what to do.

    **Arguments:**
    - `path`: the file.
    - `jacobian`: also return the design derivatives stored with the data (an error if the file has none).

    **Returns:** the [`SpatialFlexibleBodyData`][], [`SpatialBodyData`][] or [`BodyData`][] that was written,
    every array bit for bit (float64 JAX arrays); with `jacobian=True` the pair `(data, d_data)`, `d_data` of
    the same type with each field's derivative `(field shape..., n_design)` (a pytree: the design gradient of an
    objective `psi(p)` is `sum` over the fields of `tensordot(dpsi_dp.field, d_data.field, field.ndim)`).

    **Raises:** [`BodyDataFileError`][] (a `ValueError`) for a file that is not a body-data file, truncated,
    corrupt, of a newer format version, with missing or wrongly shaped fields, or physically impossible;
    `FileNotFoundError` where there is no file.

    **Example:**
    ```python
    data, d_data = fj.read_body_data("rod.npz", jacobian=True)
    grad_x = sum(jnp.tensordot(g, d, g.ndim) for g, d in zip(jax.tree.leaves(grad_p), jax.tree.leaves(d_data)))
    ```
    """
    with open(path, "rb") as f:
        raw = f.read()
    archive = _open_archive(path, raw)
    header = _header(path, archive)
    names = [f["name"] for f in header["fields"]]
    members = {n: _member(path, archive, f"{n}.npy") for n in names}
    if hashlib.sha256(b"".join(members[n] for n in names)).hexdigest() != header["sha256"]:
        raise _fail(path, "corrupt: the arrays' SHA-256 checksum differs from the header's (the file was changed "
                          "after it was written). Copy or write the file again.")
    arrays = {}
    for spec in header["fields"]:
        name = spec["name"]
        try:
            arrays[name] = np.lib.format.read_array(io.BytesIO(members[name]), allow_pickle=False)
        except (ValueError, OSError, EOFError) as err:
            raise _fail(path, f"corrupt: entry '{name}.npy' is not a readable .npy array ({err}).") from None
        if list(arrays[name].shape) != list(spec.get("shape", [])) or arrays[name].dtype.str != spec.get("dtype"):
            raise _fail(path, f"corrupt: entry '{name}.npy' holds {arrays[name].dtype.str} {arrays[name].shape}, "
                              f"the header says {spec.get('dtype')} {spec.get('shape')}.")
    kind = header["kind"]
    jac = {n[len(JACOBIAN_PREFIX):]: a for n, a in arrays.items() if n.startswith(JACOBIAN_PREFIX)}
    arrays = {n: a for n, a in arrays.items() if not n.startswith(JACOBIAN_PREFIX)}
    check_body_data_arrays(kind, arrays, os.fspath(path))
    check_jacobian_arrays(kind, arrays, jac, os.fspath(path))
    try:
        data = _KINDS[kind](**{n: jnp.asarray(arrays[n]) for n in _field_names(kind)})
    except ValueError as err:
        raise _fail(path, str(err)) from None
    if not jacobian:
        return data
    if not jac:
        raise _fail(path, "the file holds no design derivatives (write them with write_body_data(..., jacobian=...)); "
                          "read it with jacobian=False.")
    # The derivatives have the data's type but not its field shapes: built as a pytree, without the class's checks.
    d_data = jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(data),
                                          [jnp.asarray(jac[n]) for n in _field_names(kind)])
    return data, d_data
