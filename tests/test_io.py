"""Results to look at, from an optimised design: an MMA run with volume and first-frequency constraints
through `ffr-jax optimize`, then `ffr-jax export` (VTU read back with meshio, SVG, DXF) and
`ffr-jax animate` (GIF frames), and the kinematics the animation draws checked against the joints."""

import contextlib
import io
import json
import xml.etree.ElementTree as ElementTree

import jax
import jax.numpy as jnp
import numpy as np
import scipy.linalg
import pytest

import ffr_jax as fj
from ffr_jax._app._animation import body_motion
from ffr_jax._app._cli import main

# The case and solver settings of test_optimize.py's tiny CLI run: the compiled objective (the
# expensive program) is the same, so one of the two finds it in the persistent compilation cache.
TINY = ["slider-crank", "--nx", "8", "--ny", "2", "--modes", "2", "--t1", "0.2", "--rtol", "1e-6", "--atol", "1e-12",
        "--method", "adjoint", "--no-progress"]
# f_1 of the uniform x = 0.5 start is 53.8 Hz; a 12-density rod of two element rows at V <= 0.5
# reaches about 54.7 Hz (MMA, 12 steps), so 54.5 Hz is an active but reachable bound.
F_MIN = 54.5


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    directory = tmp_path_factory.mktemp("mma_frequency")
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        # --projection-beta 0: the frequency bound above was measured without the projection MMA takes by default.
        code = main(["optimize", *TINY, "--optimizer", "mma", "--projection-beta", "0", "--frequency-min", str(F_MIN),
                     "--iters", "6",
                     "--checkpoint-every", "3", "--out", str(directory)])
    assert code == 0
    (directory / "stdout.txt").write_text(out.getvalue())
    return directory


@pytest.fixture(scope="module")
def case():
    # The commands' own case object, so that the programs they compiled (modes, motion) are reused.
    from ffr_jax._app._cli_io import slider_crank_case

    return slider_crank_case(8, 2, 2, 0.2)


def test_mma_run_with_volume_and_frequency_constraints(run_dir, case):
    log = (run_dir / "log.csv").read_text().splitlines()
    assert log[0] == "iteration,psi,volume,max_change,g_volume,g_frequency" and len(log) == 7
    saved = np.load(run_dir / "design.npz")
    assert json.loads(str(saved["constraint_names"])) == ["volume", "frequency"]
    assert saved["constraint_history"].shape == (6, 2)
    assert saved["constraint_history"][0, 1] > 0.0, "the start design violates the frequency bound"
    # MMA moves the design into the feasible set; the final values are those of the design it wrote.
    x_phys = jnp.asarray(saved["x_phys"])
    f1 = float(jax.jit(lambda x: case.frequencies(x)[0])(x_phys))
    np.testing.assert_allclose(saved["constraints"], [x_phys.mean() / 0.5 - 1, 1 - f1 / F_MIN], atol=1e-9,
                               err_msg="constraints reported at the final design")
    assert np.all(saved["constraints"] <= 1e-3), f"both constraints hold at the end: {saved['constraints']}"
    stdout = (run_dir / "stdout.txt").read_text()
    assert f"f_1 {f1:.6g} Hz (bound >= {F_MIN:g} Hz): holds" in stdout and "volume fraction" in stdout


def test_export_writes_vtu_svg_and_dxf(run_dir, case, tmp_path):
    meshio = pytest.importorskip("meshio")
    files = {suffix: tmp_path / f"design.{suffix}" for suffix in ("vtu", "svg", "dxf")}
    assert main(["export", "slider-crank", "--design", str(run_dir / "design.npz"),
                 *[arg for suffix, path in files.items() for arg in (f"--{suffix}", str(path))]]) == 0
    x_phys = np.load(run_dir / "design.npz")["x_phys"]
    mesh = meshio.read(files["vtu"])
    assert mesh.points.shape == (case.mesh.n_nodes, 3) and mesh.cells[0].type == "quad"
    np.testing.assert_array_equal(mesh.cell_data["density"][0], case.design.element_densities(x_phys),
                                  err_msg="density cell field")
    assert mesh.cell_data["design"][0].sum() == case.n_design
    basis = jax.jit(lambda x: case.modes(x))(jnp.asarray(x_phys))
    # The command computed the modes in its own program; the test computes them again. Each is a
    # backward-stable symmetric-definite eigen-solution (tests/TOLERANCES.md, "eigen-solutions"):
    # eigenvalues within n eps lambda_max, each mode's direction within n eps lambda_max / gap_k
    # (Davis-Kahan), M-norm to max-norm by sqrt(cond M_II); two such solutions differ by twice that
    # (a fixed 1e-12 failed by 2e-12 on mode 2 when the two programs were compiled differently).
    body = next(iter(case.design_map.bodies.values()))
    k_full, m_full = (np.asarray(a.todense()) for a in body.matrices(jnp.asarray(x_phys)))
    interior = np.asarray(body.reduction.layout(body.model.mesh).interior)
    k_ii, m_ii = k_full[np.ix_(interior, interior)], m_full[np.ix_(interior, interior)]
    lam = scipy.linalg.eigh(k_ii, m_ii, eigvals_only=True)
    n_eps_lam_max = interior.size * np.finfo(float).eps * lam[-1]
    for k in range(case.n_modes):
        gap = min(lam[k + 1] - lam[k], lam[k] - lam[k - 1] if k > 0 else np.inf)
        phi = np.asarray(basis.modes[:, k])
        bound = 2 * n_eps_lam_max / gap * np.sqrt(np.linalg.cond(m_ii)) * np.max(np.abs(phi))
        np.testing.assert_allclose(mesh.point_data[f"mode_{k + 1}"][:, :2].ravel(), phi, rtol=0.0, atol=bound,
                                   err_msg=f"mode {k + 1} as a point field")
    # f = sqrt(lambda) / (2 pi): relative error n eps lambda_max / (2 lambda_k) per solution, twice that between two.
    np.testing.assert_allclose(mesh.field_data["frequencies_Hz"], basis.frequencies, rtol=n_eps_lam_max / lam[0])

    svg = ElementTree.parse(files["svg"]).getroot()
    paths = svg.findall("{http://www.w3.org/2000/svg}path")
    assert len(paths) == 1 and paths[0].get("d").startswith("M ") and paths[0].get("d").endswith("Z")
    loops = fj.density_outline(case, x_phys)
    assert paths[0].get("d").count("M ") == len(loops) >= 1

    pairs = files["dxf"].read_text().splitlines()
    codes = list(zip(pairs[0::2], pairs[1::2], strict=True))
    assert codes[:2] == [("0", "SECTION"), ("2", "ENTITIES")] and codes[-1] == ("0", "EOF")
    assert codes.count(("0", "POLYLINE")) == len(loops)
    assert codes.count(("0", "VERTEX")) == sum(len(loop) - 1 for loop in loops)


def test_outline_of_simple_designs():
    case = fj.cases.slider_crank(12, 4, 2, 0.2)
    mesh = case.mesh

    def area(loop):  # shoelace
        return 0.5 * abs(np.sum(loop[:-1, 0] * loop[1:, 1] - loop[1:, 0] * loop[:-1, 1]))

    solid = fj.density_outline(case, np.ones(case.n_design))
    assert len(solid) == 1
    np.testing.assert_allclose(area(solid[0]), mesh.length * mesh.height, rtol=1e-14, err_msg="the solid rectangle")
    grid = np.ones((mesh.ny, mesh.nx - 2))
    grid[1:3, 3:6] = 0.0  # (at x_min the 0.5 crossing sits 0.5 / 0.99 of the way from solid to void)
    holed = fj.density_outline(case, grid.ravel())
    assert len(holed) == 2, "outer boundary and one hole"
    # The hole of 3 x 2 elements along element edges, its four corners cut by half an element each way.
    np.testing.assert_allclose(area(holed[1]), (6 - 4 * 0.125) * mesh.dx * mesh.dy, rtol=1e-12, err_msg="hole")


def test_animate_writes_the_frames(run_dir, tmp_path, capsys):
    image = pytest.importorskip("PIL.Image")
    path = tmp_path / "anim.gif"
    assert main(["animate", "slider-crank", "--design", str(run_dir / "design.npz"), "--out", str(path),
                 "--frames", "4", "--fps", "10"]) == 0
    assert "4 frames" in capsys.readouterr().out
    with image.open(path) as gif:
        assert gif.n_frames == 4 and gif.size[0] > 200
    assert main(["animate", "slider-crank", "--design", str(run_dir / "design.npz"), "--out",
                 str(tmp_path / "anim.avi")]) == 2
    assert ".gif" in capsys.readouterr().err


def test_the_drawn_motion_keeps_the_joints(run_dir, case):
    # What the animation draws is the simulated motion: joint A of the rod on the crank pin, joint B
    # on the slider's line, at every frame (to the Newton tolerance of the dependent coordinates).
    x_phys = np.load(run_dir / "design.npz")["x_phys"]
    ts = np.linspace(case.t0, case.t1, 4)
    rigid, elastic, _ = body_motion(case, x_phys, ts)
    nodes = rigid + elastic
    crank = case.scene_template.constraints[0]
    a, b = case.marker_nodes
    pins = np.stack([np.asarray(crank.pin(t)) for t in ts])
    np.testing.assert_allclose(nodes[:, a], pins, atol=1e-10, err_msg="joint A on the crank pin")
    np.testing.assert_allclose(nodes[:, b, 1], 0.0, atol=1e-10, err_msg="joint B on the slider line y = 0")
    assert np.abs(elastic).max() > 0.0, "the rod deforms"


def test_export_and_animate_refuse_bad_input(run_dir, tmp_path, capsys):
    assert main(["export", "slider-crank", "--design", str(run_dir / "design.npz")]) == 2
    assert "Nothing to export" in capsys.readouterr().err
    assert main(["export", "slider-crank", "--design", str(tmp_path / "missing.npz"), "--svg", "x.svg"]) == 2
    assert "No design file" in capsys.readouterr().err
    assert main(["export", "slider-crank", "--design", str(run_dir / "design.npz"), "--nx", "10",
                 "--svg", str(tmp_path / "x.svg")]) == 2
    assert "densities" in capsys.readouterr().err
