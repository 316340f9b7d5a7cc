"""The equilibrium stress space through the public pipeline: ``solve(stress_space="eq")``, the
CLI, ``summary.json`` and a ``solution.vtu`` from which admissibility can be checked alone."""

import json

import meshio
import numpy as np
import pytest

import cvxdual as cd
from cvxdual.cli import main

# 1e-9 of the stress scale: the acceptance threshold for "exact"; the post-step leaves ~1e-14,
# and reading the stresses back from the VTU file loses nothing (float64 binary)
EXACT = 1e-9


def _edges_of_cells(P, cells):
    """For every cell edge: its cell, the local vertex indices (a, b) and a key of its end points."""
    a = np.repeat(np.arange(3)[None, :], len(cells), 0)
    b = np.roll(a, -1, axis=1)
    pa, pb = P[cells[np.arange(len(cells))[:, None], a]], P[cells[np.arange(len(cells))[:, None], b]]
    lo = np.where((pa[..., 0] < pb[..., 0]) | ((pa[..., 0] == pb[..., 0]) & (pa[..., 1] < pb[..., 1])), 1, 0)
    first = np.where(lo[..., None] == 1, pa, pb)
    second = np.where(lo[..., None] == 1, pb, pa)
    key = np.round(np.concatenate([first, second], axis=-1), 9)
    cell = np.repeat(np.arange(len(cells))[:, None], 3, 1)
    return cell.ravel(), a.ravel(), b.ravel(), key.reshape(-1, 4)


def _traction(s, n):
    return np.stack([s[..., 0] * n[..., 0] + s[..., 2] * n[..., 1], s[..., 2] * n[..., 0] + s[..., 1] * n[..., 1]], -1)


def check_vtu(path, scene):
    """Admissibility of the stresses in ``path`` from the file alone; returns the worst relative
    violations by kind."""
    m = meshio.read(path)
    P = m.points[:, :2]
    cells = m.cells_dict["triangle"]
    s = m.point_data["stress"]
    body = m.cell_data["body"][0]
    scale = np.abs(s).max()
    out = {}
    # divergence: the stress is linear on each cell; div sigma + F = 0 with the body's force
    X = P[cells]
    S = s[cells]  # (n, 3, 3) vertex values
    d1, d2 = X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]
    J = np.stack([d1, d2], -1)  # columns: the two edge vectors
    dS = np.stack([S[:, 1] - S[:, 0], S[:, 2] - S[:, 0]], 1)  # (n, 2, 3) differences along the edges
    grad = np.einsum("nki,nkc->nic", np.linalg.inv(J), dS)  # d s_c / d x_i (xi = J^-1 (x - X0))
    div = np.stack([grad[:, 0, 0] + grad[:, 1, 2], grad[:, 0, 2] + grad[:, 1, 1]], 1)
    F = np.array([b.body_force for b in scene.bodies])[body]
    h = np.sqrt(np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]))
    out["divergence"] = float(np.max(np.abs(div + F) * h[:, None]) / scale)
    # traction continuity across every edge shared by two cells (sub-triangle or element edges)
    cell, a, b, key = _edges_of_cells(P, cells)
    order = np.lexsort(key.T[::-1])
    k = key[order]
    same = np.all(k[1:] == k[:-1], axis=1)
    i, j = order[:-1][same], order[1:][same]
    t = P[cells[cell[i], b[i]]] - P[cells[cell[i], a[i]]]
    n = np.stack([t[:, 1], -t[:, 0]], 1) / np.linalg.norm(t, axis=1, keepdims=True)
    jumps = []
    for end in range(2):  # match the two ends by coordinates
        pi = cells[cell[i], a[i] if end == 0 else b[i]]
        qj = np.where(np.all(np.isclose(P[cells[cell[j], a[j]]], P[pi]), axis=1), cells[cell[j], a[j]],
                      cells[cell[j], b[j]])
        jumps.append(_traction(s[pi], n) - _traction(s[qj], n))
    out["traction_jump"] = float(np.abs(np.concatenate(jumps)).max() / scale)
    return out, m


@pytest.mark.parametrize("scene", ["hertz", "blocks"])
def test_solution_vtu_alone_shows_admissibility(tmp_path, scene):
    assert main(["solve", "--scene", scene, "--level", "1", "--stress-space", "eq", "--out", str(tmp_path),
                 "--no-plots"]) == 0
    sc = cd.load_scene(scene)
    res, m = check_vtu(tmp_path / "solution.vtu", sc)
    assert res["divergence"] <= EXACT and res["traction_jump"] <= EXACT
    assert {"s11", "s22", "s12", "stress", "displacement"} <= set(m.point_data)
    assert {"body", "bound_contribution"} <= set(m.cell_data)
    assert np.all(m.cell_data["bound_contribution"][0] >= 0)  # G is a sum of non-negative terms
    # the contact face (flat): on the cell edges lying on it, compressive normal traction
    # (s22 = sigma_nn there), no shear, and action = reaction between the two bodies
    P, cells, s = m.points[:, :2], m.cells_dict["triangle"], m.point_data["stress"]
    lo_x, hi_x = sc.contact
    tol = 1e-12 * sc.length_scale  # face nodes are computed coordinates: rounding only
    on = (np.abs(P[:, 1] - sc.bodies[0].face.value(P[:, 0])) <= tol) & (P[:, 0] >= lo_x - tol) & (P[:, 0] <= hi_x + tol)
    cell, a, b, _ = _edges_of_cells(P, cells)
    ia, ib = cells[cell, a], cells[cell, b]
    face = on[ia] & on[ib]
    ends = np.concatenate([ia[face], ib[face]])
    edge_body = np.tile(m.cell_data["body"][0][cell[face]], 2)
    scale = np.abs(s).max()
    assert len(ends) > 0
    assert np.all(s[ends, 1] <= EXACT * scale)
    assert np.abs(s[ends, 2]).max() <= EXACT * scale
    # action = reaction: the face edges of the two bodies are aligned, end by end
    x = np.round(P[ends, 0], 9)
    up = np.lexsort((s[ends, 1][edge_body == 0], x[edge_body == 0]))
    lo = np.lexsort((s[ends, 1][edge_body == 1], x[edge_body == 1]))
    assert np.array_equal(x[edge_body == 0][up], x[edge_body == 1][lo])
    assert np.abs(s[ends, 1][edge_body == 0][up] - s[ends, 1][edge_body == 1][lo]).max() <= EXACT * scale
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["stress_space"] == "eq"
    bnd = summary["bounds"]
    assert set(bnd) >= {"energy_upper", "energy_lower", "gap", "error_bound", "guaranteed"}
    assert bnd["energy_lower"] <= bnd["energy_upper"] and bnd["gap"] >= 0
    # blocks: uniform tractions, a quadratic gap: guaranteed; hertz: its exact-field side tractions
    # are projected onto linear ones, so the bound is not claimed as guaranteed
    assert bnd["guaranteed"] == (scene == "blocks")


def test_vtu_check_catches_a_broken_field(tmp_path):
    """The file-only checks can fail: a perturbed stress shows a jump and a divergence."""
    assert main(["solve", "--scene", "blocks", "--level", "0", "--stress-space", "eq", "--out", str(tmp_path),
                 "--no-plots"]) == 0
    m = meshio.read(tmp_path / "solution.vtu")
    m.point_data["stress"][0, 0] += 1e-3 * np.abs(m.point_data["stress"]).max()
    meshio.write(tmp_path / "broken.vtu", m)
    res, _ = check_vtu(tmp_path / "broken.vtu", cd.load_scene("blocks"))
    assert res["traction_jump"] > 1e-6 and res["divergence"] > 1e-6


def test_patch_exact_and_bounds_through_solve():
    for level in (1, 2, 3):
        sol = cd.solve("patch", level=level, stress_space="eq")
        # the exact stress is constant: the space contains it, so it is found to solver rounding
        assert sol.error["l2_rel"] <= 1e-8
        # G <= 1e-10 of the energy: the P1 displacement is exact too (a linear field)
        assert sol.bounds["gap"] <= 1e-10 * abs(sol.bounds["energy_upper"])
        assert sol.bounds["guaranteed"]


def test_p0_bounds_and_eq_beat_p0_on_hertz():
    p0 = cd.solve("hertz", level=1, bounds=True)
    eq = cd.solve("hertz", level=1, stress_space="eq")
    # both runs certify the same P1 displacement against the same equilibrium stresses; the P0
    # displacements differ by Clarabel's tolerance (~1e-8 relative) against the exact fast path
    assert p0.bounds["error_bound"] == pytest.approx(eq.bounds["error_bound"], rel=1e-6)
    assert eq.error["l2_rel"] < p0.error["l2_rel"]
    # the bound dominates the true combined error (effectivity >= 1) and is tight (<= 1.3)
    assert 1.0 <= eq.error["effectivity"] <= 1.3


def test_eq_contact_zone_and_no_load():
    """The contact zone of equilibrium stresses ends where the pressure does: the last active
    pair carries pressure, the next one none; an unloaded scene gives zero stresses and G = 0."""
    sol = cd.solve("hertz", level=2, solver="fast", stress_space="eq")
    c = sol.contact
    k = int(np.flatnonzero(c["active"]).max())
    assert c["edge_pressure"][k - 1, 1] > 0 or c["edge_pressure"][k, 0] > 0
    assert c["edge_pressure"][k, 1] <= 1e-9 * c["edge_pressure"].max()  # the linear pressure is zero there
    spacing = np.diff(c["x"]).max()
    assert abs(c["x_max"] - sol.exact["a"]) <= spacing  # the Hertz half-width to within one spacing
    free = cd.load_scene("blocks", [{"bodies": {"lower": {"boundary": {"push": {"traction": {"value": [0.0, 0.0]}}}}}}])
    z = cd.solve(free, level=1, stress_space="eq", solver="fast")
    assert np.all(z.stress == 0) and z.contact["n_active"] == 0
    # G is not exactly 0 (v keeps a 1e-13 margin below the gap): rounding of the energy scale
    assert z.bounds["gap"] <= 1e-12 * z.space.scales.energy
