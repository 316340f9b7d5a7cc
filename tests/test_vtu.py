"""``solution.vtu``: named stress arrays, von Mises and principal stresses, the body, and the
contact face as line cells carrying the rows of ``contact.csv``."""

import functools

import meshio
import numpy as np
import pandas as pd
import pytest

import cvxdual as cd
from cvxdual.cli import main
from cvxdual.geometry.pieces import piece_outlines
from cvxdual.outputs.output_set import write_contact_csv
from cvxdual.outputs.vtu import stress_measures, write_vtu
from cvxdual.scene.materials import Material
from cvxdual.solution import TOLERANCES

EPS = np.finfo(float).eps
STRESS = ("s11", "s22", "s12", "von_mises", "principal_1", "principal_2")
CONTACT = ("pressure", "gap", "relative_normal")
# every cell array of a p0 file (frictionless); with friction also tangential_force and slip
P0_CELL = (*STRESS, "stress", "body", "piece_kind", *CONTACT, "active")
# contact.csv writes %.12g: 12 significant digits, a relative error of at most 5e-13 of each
# value (not of the column's scale), so a relative tolerance of 1e-11 and no absolute one
CSV_RTOL = 1e-11


@functools.lru_cache(maxsize=None)
def solved(scene: str, level: int, **kw):
    return cd.solve(scene, level=level, solver="fast", **kw)


def write_read(sol, tmp_path, name="s.vtu"):
    write_vtu(sol, tmp_path / name)
    return meshio.read(tmp_path / name)


def cell_order(sol):
    """Piece index of every area cell: the straight pieces, then the curved ones as
    :func:`~cvxdual.geometry.pieces.piece_outlines` lists them (the order of the module docstring)."""
    p = sol.pieces
    return np.concatenate([np.flatnonzero(p.kind == 0), *(ids for ids, _ in piece_outlines(p))])


def area_and_lines(m, name):
    """An array's values on the area cells (all blocks but the last) and on the line cells."""
    assert m.cells[-1].type == "line"
    return np.concatenate(m.cell_data[name][:-1]), m.cell_data[name][-1]


def read_csv(sol, tmp_path):
    write_contact_csv(sol, tmp_path / "contact.csv")
    return pd.read_csv(tmp_path / "contact.csv")


def check_invariants(s11, s22, s12, p1, p2):
    """Principal stresses against the invariants of the Voigt stress. Tolerances: a few ulps of
    the cell's stress scale ``S`` (``p1, p2 = c +- r`` each carry a rounding of ``eps (|c| + r)``
    with ``|c| + r <= S``; the product of two such values ``eps S^2``)."""
    S = np.abs(s11) + np.abs(s22) + 2 * np.abs(s12)
    assert np.all(p1 >= p2)
    assert np.all(np.abs((p1 + p2) - (s11 + s22)) <= 8 * EPS * S)
    assert np.all(np.abs(p1 * p2 - (s11 * s22 - s12**2)) <= 16 * EPS * S**2)


def check_von_mises(p1, p2, nu, vm):
    """Von Mises against its principal-frame form (``s33 = nu (p1 + p2)`` is principal too), an
    independent formula; compared as squares, whose rounding is a few ulps of ``S^2`` (the
    values themselves lose digits near vm = 0)."""
    s33 = nu * (p1 + p2)
    ref2 = 0.5 * ((p1 - p2) ** 2 + (p2 - s33) ** 2 + (s33 - p1) ** 2)
    S = np.abs(p1) + np.abs(p2)
    assert np.all(np.abs(vm**2 - ref2) <= 64 * EPS * S**2)


# --- the stress measures, closed forms ---------------------------------------------------------

def test_stress_measures_closed_forms():
    s = np.array([[50.0, 0.0, 0.0],  # uniaxial, plane stress: vm = |s|, principal (s, 0)
                  [0.0, 0.0, 30.0],  # pure shear, plane stress: vm = sqrt(3) tau, principal +-tau
                  [-80.0, -80.0, 0.0],  # hydrostatic in-plane, plane strain nu = 0.3: s33 = 2 nu p
                  [0.0, -100.0, 0.0]])  # the patch test's stress, plane strain nu = 0.3
    nu = np.array([0.0, 0.0, 0.3, 0.3])
    out = stress_measures(s, nu)
    vm = [50.0, np.sqrt(3) * 30.0, abs(1 - 2 * 0.3) * 80.0, np.sqrt(0.5 * (100**2 + 70**2 + 30**2))]
    # a handful of operations on values of order 100: a few ulps of 100
    tol = 1e-13 * 100
    assert np.allclose(out["von_mises"], vm, rtol=0, atol=tol)
    assert np.allclose(out["principal_1"], [50.0, 30.0, -80.0, 0.0], rtol=0, atol=tol)
    assert np.allclose(out["principal_2"], [0.0, -30.0, -80.0, -100.0], rtol=0, atol=tol)
    assert np.array_equal(np.c_[out["s11"], out["s22"], out["s12"]], s)
    # a body without s33 (factor NaN): von Mises NaN, the principal stresses still defined
    out = stress_measures(s[:1], np.array([np.nan]))
    assert np.isnan(out["von_mises"][0]) and out["principal_1"][0] == 50.0


# --- p0 ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("scene", ["hertz", "cylinder-in-groove"])
def test_p0_named_arrays(tmp_path, scene):
    """hertz: flat faces; cylinder-in-groove: curved pieces (polygon cells) on both bodies and a
    curved lower face for the line cells."""
    sol = solved(scene, 1)
    m = write_read(sol, tmp_path)
    n_blocks = len(m.cells)
    assert [b.type for b in m.cells][-1] == "line"
    assert "polygon" in [b.type for b in m.cells] or scene == "hertz"
    for name in P0_CELL:  # on every block, one value per cell
        assert len(m.cell_data[name]) == n_blocks
        assert all(len(d) == len(b.data) for d, b in zip(m.cell_data[name], m.cells, strict=True))
    assert not {"tangential_force", "slip"} & set(m.cell_data)  # frictionless
    order = cell_order(sol)
    assert sorted(order) == list(range(len(sol.pieces)))  # every piece exactly once
    s = {k: area_and_lines(m, k)[0] for k in STRESS}
    # float64 binary: the file holds the solution's values exactly
    assert np.array_equal(np.c_[s["s11"], s["s22"], s["s12"]], sol.stress[order])
    assert np.array_equal(area_and_lines(m, "stress")[0], sol.stress[order])
    check_invariants(s["s11"], s["s22"], s["s12"], s["principal_1"], s["principal_2"])
    body, body_line = area_and_lines(m, "body")
    assert np.array_equal(body, sol.pieces.body[order])
    assert np.all(body_line == 1)  # the lower body
    nu = np.array([b.material.nu for b in sol.scene.bodies])[body]
    check_von_mises(s["principal_1"], s["principal_2"], nu, s["von_mises"])
    kind, kind_line = area_and_lines(m, "piece_kind")
    assert np.array_equal(kind, sol.pieces.kind[order]) and np.all(kind_line == -1)
    # fills: stresses NaN on the line cells, contact data NaN (active -1) on the area cells
    for k in (*STRESS, "stress"):
        assert np.all(np.isnan(area_and_lines(m, k)[1]))
    for k in CONTACT:
        assert np.all(np.isnan(area_and_lines(m, k)[0]))
    assert np.all(area_and_lines(m, "active")[0] == -1)


def test_p0_bound_contribution_filled_on_the_line_cells(tmp_path):
    sol = solved("hertz", 1, bounds=True)
    m = write_read(sol, tmp_path)
    area, line = area_and_lines(m, "bound_contribution")
    assert np.array_equal(area, sol.bounds["contributions"]["element"])  # flat faces: pieces = triangles
    assert np.all(np.isnan(line))


def test_patch_von_mises_closed_form(tmp_path):
    """Uniform uniaxial stress (0, -100, 0), plane strain: vm^2 = 0.5 (100^2 + (100 - 100 nu)^2
    + (100 nu)^2) with the body's nu (0.3 upper, 0.2 lower)."""
    sol = solved("patch", 1)
    m = write_read(sol, tmp_path)
    vm, body = area_and_lines(m, "von_mises")[0], area_and_lines(m, "body")[0]
    nu = np.array([0.3, 0.2])[body]
    exact = np.sqrt(0.5 * (100**2 + (100 - 100 * nu) ** 2 + (100 * nu) ** 2))
    # vm is a seminorm of the stress: |vm(s) - vm(exact)| <= vm(s - exact) <= 3 max|s - exact|
    # (|ds33| <= 2 nu max|ds| <= max|ds|); plus rounding of the stress scale 100
    dev = float(np.abs(sol.stress - [0.0, -100.0, 0.0]).max())
    assert dev <= 1e-9 * 100  # the patch test: the constant stress to solver rounding
    assert np.abs(vm - exact).max() <= 3 * dev + 1e-12 * 100


@pytest.mark.parametrize("scene", ["hertz", "cylinder-in-groove", "blocks"])
def test_line_cells_are_the_contact_csv_rows(tmp_path, scene):
    sol = solved(scene, 1)
    m = write_read(sol, tmp_path)
    csv = read_csv(sol, tmp_path)
    line = m.cells[-1].data
    assert len(line) == len(csv) == len(sol.mesh.pair_x)
    for vtu_name, col in (("pressure", "pressure"), ("gap", "gap"), ("relative_normal", "relative_displacement")):
        assert np.allclose(area_and_lines(m, vtu_name)[1], csv[col], rtol=CSV_RTOL, atol=0), vtu_name
    assert np.array_equal(area_and_lines(m, "active")[1], csv["active"])
    # gap - relative_normal >= 0 (no penetration), to the promise every solution keeps: the
    # penetration tolerance relative to the displacement scale delta (cvxdual.p0.checks.penetration)
    rel = area_and_lines(m, "relative_normal")[1]
    g = area_and_lines(m, "gap")[1]
    delta = max(np.abs(sol.displacement).max(), np.abs(g).max(), sol.system.scales.displacement)
    assert np.all(g - rel >= -TOLERANCES["penetration"] * delta)


@pytest.mark.parametrize("scene", ["hertz", "cylinder-in-groove"])
def test_line_cells_cover_the_contact_interval_once(tmp_path, scene):
    sol = solved(scene, 1)
    m = write_read(sol, tmp_path)
    line = m.cells[-1].data
    P = m.points
    xa, xb = P[line[:, 0], 0], P[line[:, 1], 0]
    L = sol.scene.length_scale
    a, b = sol.scene.contact
    # computed coordinates (midpoints, break points of the column mesh): rounding only
    tol = 1e-12 * L
    # on the lower face (y = f''(x), z = 0)
    lower = sol.scene.lower.face
    assert np.all(np.abs(P[line.ravel(), 1] - lower.value(P[line.ravel(), 0])) <= tol)
    assert np.all(P[line.ravel(), 2] == 0)
    # consecutive, each starting where the previous ends: no gap and no overlap
    assert np.all(xb > xa)
    assert np.array_equal(line[1:, 0], line[:-1, 1])
    assert abs(xa[0] - a) <= tol and abs(xb[-1] - b) <= tol
    assert abs(np.sum(xb - xa) - (b - a)) <= tol
    # each the tributary interval of its pair: holds the pair, x length the width w_k
    x = sol.mesh.pair_x
    assert np.all((xa <= x) & (x <= xb))
    assert np.allclose(xb - xa, sol.system.width, rtol=0, atol=tol)
    # the displacement there: the lower face nodes' one, linear along the face
    u = sol.displacement[sol.mesh.pairs[:, 1]]
    ends = np.r_[line[:, 0], line[-1, 1]]
    d = m.point_data["displacement"][ends]
    scale = np.abs(u).max()
    for c in range(2):
        assert np.allclose(d[:, c], np.interp(P[ends, 0], x, u[:, c]), rtol=0, atol=1e-13 * scale)
    assert np.all(d[:, 2] == 0)


def test_friction_columns_on_the_line_cells(tmp_path):
    sc = cd.load_scene("patch", [{"contact": {"friction": {"g": 20.0}}}])
    sol = cd.solve(sc, level=1)  # the fast path refuses friction: Clarabel, a small mesh
    m = write_read(sol, tmp_path)
    csv = read_csv(sol, tmp_path)
    assert np.abs(csv["tangential_force"]).max() > 0  # the patch's bodies do push sideways
    for k in ("tangential_force", "slip", *CONTACT):
        assert len(m.cell_data[k]) == len(m.cells)
        area, line = area_and_lines(m, k)
        assert np.all(np.isnan(area))
    for k in ("tangential_force", "slip"):
        assert np.allclose(area_and_lines(m, k)[1], csv[k], rtol=CSV_RTOL, atol=0), k


@pytest.mark.parametrize("plane", ["strain", "stress"])
def test_hooke_body_von_mises(tmp_path, plane):
    """A body given by its Hooke matrix has no nu: in plane strain no s33, so its von Mises is
    NaN (and the write does not fail); in plane stress s33 = 0 and von Mises is defined."""
    C = Material.isotropic(210000.0, 0.2, plane=plane).stiffness.tolist()  # the patch's lower body
    sc = cd.load_scene("patch", [{"plane": plane, "bodies": {"bottom": {"material": {"hooke": C}}}}])
    assert sc.lower.material.nu is None
    sol = cd.solve(sc, level=1, solver="fast")
    m = write_read(sol, tmp_path)
    vm, body = area_and_lines(m, "von_mises")[0], area_and_lines(m, "body")[0]
    p1, p2 = area_and_lines(m, "principal_1")[0], area_and_lines(m, "principal_2")[0]
    assert np.all(np.isfinite(p1)) and np.all(np.isfinite(p2))
    assert np.all(np.isfinite(vm[body == 0]))
    if plane == "strain":
        assert np.all(np.isnan(vm[body == 1]))
    else:
        check_von_mises(p1, p2, 0.0, vm)
        # uniaxial -100 with s33 = 0: vm = 100 to the patch's accuracy (as above, 3 max|ds|)
        dev = float(np.abs(sol.stress - [0.0, -100.0, 0.0]).max())
        assert np.abs(vm - 100.0).max() <= 3 * dev + 1e-12 * 100


# --- eq ----------------------------------------------------------------------------------------

def test_eq_arrays(tmp_path):
    sol = solved("hertz", 1, stress_space="eq")
    m = write_read(sol, tmp_path)
    assert [b.type for b in m.cells] == ["triangle", "line"]
    for k in ("piece_kind", "body", *CONTACT, "active"):
        assert len(m.cell_data[k]) == 2
    kind, kind_line = area_and_lines(m, "piece_kind")
    assert np.all(kind == 0) and np.all(kind_line == -1)
    body, body_line = area_and_lines(m, "body")
    assert np.array_equal(body, np.repeat(sol.space.body, 3)) and np.all(body_line == 1)
    pd_ = m.point_data
    assert {"s11", "s22", "s12", "stress", "von_mises", "principal_1", "principal_2"} <= set(pd_)
    tri = m.cells[0].data
    n = tri.size  # the sub-triangles' own points come first, in cell order
    assert np.array_equal(tri.ravel(), np.arange(n))
    # float64 binary: the solution's vertex stresses exactly
    assert np.array_equal(np.c_[pd_["s11"], pd_["s22"], pd_["s12"]][:n], sol.stress.reshape(-1, 3))
    check_invariants(pd_["s11"], pd_["s22"], pd_["s12"], pd_["principal_1"], pd_["principal_2"])
    check_von_mises(pd_["principal_1"], pd_["principal_2"], 0.3, pd_["von_mises"])  # nu = 0.3 in both
    # every point value finite: the line points carry the lower face's trace
    assert all(np.all(np.isfinite(v)) for v in pd_.values())
    # the first line point is a lower face vertex: its stress is one of that vertex's values
    line = m.cells[-1].data
    p0 = m.points[line[0, 0]]
    same = np.flatnonzero(np.all(m.points[:n] == p0, axis=1) & (np.repeat(body, 3) == 1))
    assert len(same) and np.any(np.all(pd_["stress"][same] == pd_["stress"][line[0, 0]], axis=1))
    csv = read_csv(sol, tmp_path)
    assert np.allclose(area_and_lines(m, "pressure")[1], csv["pressure"], rtol=CSV_RTOL, atol=0)
    assert np.array_equal(area_and_lines(m, "active")[1], csv["active"])


# --- the command line --------------------------------------------------------------------------

def test_cli_solution_vtu_matches_contact_csv(tmp_path):
    out = tmp_path / "o"
    assert main(["solve", "--scene", "hertz", "--level", "1", "--solver", "fast", "--no-plots", "--out",
                 str(out)]) == 0
    m = meshio.read(out / "solution.vtu")
    csv = pd.read_csv(out / "contact.csv")
    assert m.cells[-1].type == "line" and len(m.cells[-1].data) == len(csv)
    for name in P0_CELL:
        assert len(m.cell_data[name]) == len(m.cells)
    # the acceptance: the contact line cells' pressures match contact.csv (12 digits there)
    assert np.allclose(area_and_lines(m, "pressure")[1], csv["pressure"], rtol=CSV_RTOL, atol=0)
    assert np.array_equal(area_and_lines(m, "active")[1], csv["active"])
    # the line cells sit at the pairs' x: each pair inside its own tributary interval
    line = m.cells[-1].data
    assert np.all((m.points[line[:, 0], 0] <= csv["x"]) & (csv["x"] <= m.points[line[:, 1], 0]))
