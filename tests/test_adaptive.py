"""Runs to a certified tolerance (cvxdual.adapt, docs/adaptive.md): a column body given as its
outline body is the same body; refined grids keep the paper's structure (pairs on common vertical
lines, the strip's grading, every mesh check) and the patch test; Dorfler's rule; the cycles end
with a guaranteed bound under the tolerance whose brackets meet every uniform level's; a tolerance
not met ends with one line, exit status 1 and the best result written."""

import json
from dataclasses import replace

import numpy as np
import pytest

import cvxdual
from cvxdual.adapt.marking import dorfler, mark, parse_theta, parse_tolerance
from cvxdual.adapt.outline_view import outline_body, outline_scene
from cvxdual.cli import main
from cvxdual.errors import CvxdualError, SceneError, ToleranceError
from cvxdual.geometry.grid import BALANCE, Grid, InPlace
from cvxdual.geometry.outline.cuts import find_cuts
from cvxdual.geometry.triangulation import discretize, uniform_grid
from cvxdual.kinds import Meshed
from cvxdual.pipeline import as_scene, build_system, space_of
from cvxdual.reference.exact import exact_reference
from cvxdual.scene.scene import BoundaryPart, Traction
from cvxdual.scene.scenefile import builtin_data, load_scene

# two exact computations of the same region's area (curved pieces integrated exactly): rounding only
AREA_RTOL = 1e-10


def _areas(scene, level, tri="type2"):
    return _areas_of(*discretize(scene, tri, level)[:2])


def _areas_of(mesh, pieces):
    """Each body's area: its pieces', and the pieces beyond its free arcs' polygons."""
    _, beyond, body = mesh.continuation()
    return np.array([pieces.area[pieces.body == k].sum() + beyond[body == k].sum() for k in (0, 1)])


@pytest.mark.parametrize("name", ["hertz", "cylinder-on-block", "cylinder-in-groove", "blocks", "wavy"])
def test_outline_view_is_the_same_body(name):
    scene = as_scene(name)
    view = outline_scene(scene)
    assert all(not b.is_column for b in view.bodies)
    assert (exact_reference(view)[0] is None) == (exact_reference(scene)[0] is None)  # the same problem
    np.testing.assert_allclose(_areas(view, 1), _areas(scene, 1), rtol=AREA_RTOL)
    for b, v in zip(scene.bodies, view.bodies, strict=True):
        assert [(p.name, p.kind, p.on) for p in b.boundary] == [(p.name, p.kind, p.on) for p in v.boundary]
        assert v.far == b.far


def test_outline_view_gives_a_side_interval_its_own_part():
    scene = as_scene("patch")
    lower = scene.bodies[1]
    push = BoundaryPart(name="push", on="right", kind="traction", interval=(-3.5, -2.5),
                        traction=Traction(kind="uniform", value=(-40.0, 0.0)))
    scene = replace(scene, bodies=(scene.bodies[0], replace(lower, boundary=(*lower.boundary, push))), exact=None)
    view = outline_body(scene.bodies[1])
    assert [p.name for p in view.outline.path] == ["right:0", "right:push", "right:2", "far", "left"]
    # the loads are the same functionals: the same resultant on both meshes (straight sides: exact)
    f_col = build_system(scene, "type2", 2).f.reshape(-1, 2).sum(0)  # the parts' ends clear of the strip
    f_out = build_system(outline_scene(scene), "type2", 2).f.reshape(-1, 2).sum(0)
    np.testing.assert_allclose(f_out, f_col, rtol=1e-12, atol=1e-9 * np.abs(f_col).max())
    overlap = replace(push, name="more", interval=(-3.0, -2.0))
    with pytest.raises(SceneError, match="overlap"):
        outline_body(replace(lower, boundary=(*lower.boundary, push, overlap)))


def test_uniform_grid_is_the_level():
    scene = as_scene("block-with-hole")
    m1, p1, _ = discretize(scene, "type2", 1)
    m2, p2, _ = discretize(scene, "type2", uniform_grid(scene, 1))
    assert np.array_equal(m1.points, m2.points) and np.array_equal(m1.triangles(), m2.triangles())


def _refined_grids(scene, n, seed=0, tri="type2"):
    """``n`` grids, each from the last by random column marks and spots, and every other one by
    refining the last mesh in place too (random triangles and pieces beyond free arcs halved), as a
    run alternates: a reproducible stand-in for marking."""
    rng = np.random.default_rng(seed)
    grid = uniform_grid(scene, 0)
    out = []
    for _ in range(n):
        cols = rng.random(len(grid.columns) - 1) < 0.3
        spots = []
        m, _, _ = discretize(scene, tri, grid)
        for bm in m.bodies:
            pts = bm.points()[len(bm.columns) * 2:]  # gmsh's nodes beyond the strip
            pick = pts[rng.choice(len(pts), size=min(3, len(pts)), replace=False)]
            spots.append(np.concatenate([pick, np.full((len(pick), 1), 0.3)], 1))
        again = None if grid.in_place is not None else InPlace(
            m.bodies, tuple(rng.random(len(bm.rest.triangles)) < 0.2 for bm in m.bodies),
            tuple(rng.random(len(bm.rest.virtual_weight)) < 0.5 for bm in m.bodies), grid.spots)
        grid = grid.refined(scene, cols, tuple(spots), again)
        out.append(grid)
    return out


@pytest.mark.parametrize("name, tri", [("cylinder-on-block", "type2"), ("cylinder-in-groove", "type1"),
                                       ("rounded-punch", "type2")])
def test_refined_meshes_keep_the_structure(name, tri):
    scene = outline_scene(as_scene(name))
    for i, grid in enumerate(_refined_grids(scene, 3, tri=tri)):
        w = np.diff(grid.columns)
        assert np.all(w[1:] <= BALANCE * w[:-1] * (1 + 1e-12)) and np.all(w[:-1] <= BALANCE * w[1:] * (1 + 1e-12))
        mesh, pieces, _ = discretize(scene, tri, grid)  # every check of a uniform mesh runs here
        # the first and third refined in place (a body by gmsh where its columns split twice), the second by gmsh
        assert (Meshed.IN_PLACE in [bm.meshed for bm in mesh.bodies]) == (i != 1)
        up, lo = mesh.pairs.T
        assert np.array_equal(mesh.points[up, 0], mesh.points[lo, 0])  # pairs on common vertical lines
        assert np.all(pieces.area > 0)
        if not mesh.polygonal_parts():  # loaded or held arcs are meshed as polygons: their area is the mesh's
            np.testing.assert_allclose(_areas_of(mesh, pieces), _areas(scene, 1, tri), rtol=AREA_RTOL)


@pytest.mark.slow  # two runs to 5 %, 5 s each
@pytest.mark.parametrize("tri, kind", [("type1", "concave1"), ("type2", "concave2")])
def test_the_meshes_of_a_run_keep_both_triangulations(tri, kind):
    """cylinder-in-groove's concave groove: type 1's curved triangles (and their ties) and type 2's
    tangent polygon on the final mesh of a run, pairs on common vertical lines, the bound guaranteed."""
    from cvxdual.geometry.triangulation import KIND

    sol = cvxdual.solve("cylinder-in-groove", triangulation=tri, tol=0.05)
    up, lo = sol.mesh.pairs.T
    assert np.array_equal(sol.mesh.points[up, 0], sol.mesh.points[lo, 0])
    assert np.any(sol.pieces.kind == KIND[kind]) and np.any(sol.pieces.kind == KIND["segment"])
    assert len(sol.adaptive.cycles) >= 2 and sol.bounds["guaranteed"] and sol.adaptive.met


def test_spots_refine_gmsh_locally():
    scene = as_scene("block-with-hole")
    grid = uniform_grid(scene, 0)
    spot = np.array([[5.0, -15.0, 0.1]])  # in the bottom body, far from its strip and its hole
    fine = grid.refined(scene, np.zeros(len(grid.columns) - 1, bool), (np.zeros((0, 3)), spot))

    def nearest_edge(g):
        mesh, _, _ = discretize(scene, "type2", g)
        p = mesh.points[mesh.triangles()]
        k = np.argmin(np.hypot(*(p.mean(1) - spot[0, :2]).T))
        return np.linalg.norm(p[k] - np.roll(p[k], 1, axis=0), axis=1).max(), len(p)

    (fine_edge, n_fine), (coarse_edge, n_coarse) = nearest_edge(fine), nearest_edge(grid)
    # gmsh's size is a target edge length: its triangles' longest edge is up to ~1.7 times it
    assert fine_edge <= 2 * spot[0, 2] and coarse_edge > 10 * spot[0, 2]
    assert n_coarse < n_fine < 2 * n_coarse  # local: the rest of the body keeps its triangles


def test_cuts_stay_at_the_start_levels_nodes():
    # a lower body [0, 8] x [-10, 0]: its chain at y = -1, crowded on [0, 1] as refinement leaves it
    base = np.linspace(0.0, 8.0, 9)
    x = np.unique(np.concatenate([base, np.linspace(0.0, 1.0, 33)]))
    chain = np.stack([x, np.full(len(x), -1.0)], 1)
    path = [(np.array([[8.0, -1.0], [8.0, -10.0]]), True), (np.array([[8.0, -10.0], [0.0, -10.0]]), True),
            (np.array([[0.0, -10.0], [0.0, -1.0]]), True)]  # right side, bottom, left side: the loop's path

    def cut_x(**kw):
        return [float(c.end[0]) for c in find_cuts(chain, -1, path, [], lambda p: np.full(len(p), 0.2), **kw)]

    crowded = cut_x()
    assert crowded == cut_x(cut_columns=x)  # a uniform level's own columns: the rule is unchanged there
    assert sum(v < 1.0 for v in crowded) >= 4  # by node count, most cuts land where the nodes crowd
    assert cut_x(cut_columns=base) == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]  # by the start level's nodes: spread


def test_dorfler_marks_the_fewest_largest():
    w = np.array([1.0, 5.0, 2.0, 2.0, 0.0])
    assert dorfler(w, 0.5).tolist() == [False, True, False, False, False]  # 5 of 10
    assert dorfler(w, 0.6).sum() == 2 and dorfler(w, 0.6)[1]  # 5 + 2 >= 6
    assert dorfler(w, 1.0).sum() == 4  # every non-zero one
    assert not dorfler(np.zeros(3), 0.5).any()


def test_patch_test_exact_on_refined_meshes():
    """The exact stress is constant: reproduced on locally refined meshes, and G vanishes."""
    scene = outline_scene(as_scene("patch"))
    eq = space_of("eq")
    for i, grid in enumerate(_refined_grids(scene, 2, seed=3)):
        sol = eq.run(scene, "type2", grid, "FAST")
        assert all(bm.meshed is (Meshed.GMSH if i else Meshed.IN_PLACE) for bm in sol.mesh.bodies)
        # the stresses are exact to the solver's rounding (1e-9 of the load, as on uniform meshes)
        assert sol.error["l2_rel"] < 1e-9
        assert sol.bounds["error_bound_rel"] < 1e-6  # sqrt of a rounding-level G
        marks = mark(grid, sol.space, sol.bounds["contributions"])
        assert 0.0 <= marks.share <= 1.0


def test_tolerance_met_and_brackets_meet_every_uniform_level():
    tol = 0.01
    sol = cvxdual.solve("block-with-hole", triangulation="type2", tol=tol)
    h = sol.adaptive
    assert h.met and h.stop == "tolerance" and sol.bounds["guaranteed"]
    assert h.cycles[-1].bound_rel <= tol and sol.bounds["error_bound_rel"] <= tol
    assert all(a.pieces < b.pieces for a, b in zip(h.cycles[:-1], h.cycles[1:], strict=True))
    uniform = [cvxdual.solve("block-with-hole", triangulation="type2", stress_space="eq", level=lv).bounds
               for lv in (0, 1, 2)]
    for c in h.cycles:  # every bracket holds J(u): any two share a point
        for b in uniform:
            assert max(c.energy_lower, b["energy_lower"]) <= min(c.energy_upper, b["energy_upper"])
    assert json.loads(json.dumps(sol.summary()["adaptive"]))["cycles"][-1]["bound_rel"] == h.cycles[-1].bound_rel


@pytest.mark.parametrize("space", ["eq", "p0"])
def test_error_left_out_and_added_back_is_the_runs_own(space):
    """A cycle leaves the error against the exact field out; added to the solution kept it is the
    error a whole run on that mesh gives (the same computation: equal to the last bit)."""
    scene = outline_scene(as_scene("hertz"))
    st = space_of(space)
    grid = _refined_grids(scene, 1, seed=5)[0]
    whole = st.run(scene, "type1", grid, "FAST")
    bare = st.run(scene, "type1", grid, "FAST", exact_error=False)
    assert whole.error is not None and bare.error is None
    added = st.with_exact_error(bare)
    assert added.error == whole.error
    # its time is booked where a whole run books it: error, and within recover and total
    dt = added.timings["error"] - bare.timings["error"]
    assert dt > 0
    assert all(added.timings[k] - bare.timings[k] == pytest.approx(dt, rel=1e-9) for k in ("recover", "total"))


def test_a_run_to_a_tolerance_computes_the_exact_error_once(monkeypatch):
    """The error against the exact field (3-4 s a cycle on rounded-punch-linear at 7000 pieces) is
    computed for the solution returned only, met or not."""
    import cvxdual.eq.run as eq_run
    from cvxdual.eq.bounds import exact_errors

    calls = []
    monkeypatch.setattr(eq_run, "exact_errors", lambda *a, **k: calls.append(1) or exact_errors(*a, **k))
    sol = cvxdual.solve("hertz", tol=0.03)
    assert len(sol.adaptive.cycles) >= 3 and len(calls) == 1 and sol.error is not None
    assert sol.error["combined"] <= sol.bounds["error_bound"]  # the bound dominates the true error
    with pytest.raises(ToleranceError) as e:
        cvxdual.solve("hertz", tol=0.001, max_pieces=1500)
    assert len(calls) == 2 and e.value.solution.error is not None


def test_vanishing_stresses_are_refused_not_certified(tmp_path, capsys):
    """cylinder-in-groove with the groove's push held by a support on the same side: no contact force,
    zero equilibrium stresses, yet G > 0 (the chords of the touching faces overlap, so the certificate's
    displacement must move). A relative error has nothing to be relative to: one line, no output
    (a run had reported a certified 0 % here)."""
    data = builtin_data("cylinder-in-groove")
    data["bodies"]["groove"]["boundary"]["right"]["on"] = "far"
    scene = load_scene(data)
    level0 = cvxdual.solve(scene, "type2", 0, stress_space="eq")
    assert level0.bounds["error_bound_rel"] is None and level0.bounds["gap"] > 0.1
    with pytest.raises(CvxdualError, match="stresses vanish.*nothing to be relative to"):
        cvxdual.solve(scene, "type2", tol=0.05)
    out = tmp_path / "run"
    assert main(["solve", "--scene", "cylinder-in-groove", "--set", "bodies.groove.boundary.right.on=far",
                 "--triangulation", "type2", "--tol", "5%", "--out", str(out), "--quiet"]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "use --level instead of --tol" in err[0] and not out.exists()


def test_a_zero_solution_meets_any_tolerance():
    """Nothing loads blocks: the stresses and the bound vanish (to rounding), the run stops at its first
    cycle with the tolerance met."""
    data = builtin_data("blocks")
    for body in data["bodies"].values():
        for part in body.get("boundary", {}).values():
            if part["kind"] == "traction":
                part["traction"]["value"] = [0.0, 0.0]
    sol = cvxdual.solve(load_scene(data), "type2", tol=0.01)
    assert sol.adaptive.met and len(sol.adaptive.cycles) == 1 and sol.adaptive.cycles[0].bound_rel == 0.0
    assert sol.bounds["error_bound_rel"] is None and np.abs(sol.stress).max() == 0.0


def test_the_first_cycle_is_sized_before_it_is_meshed():
    """A first cycle too large for the memory limit is refused before it is built, as a level is (a
    perturbed scene with a far side 2500 times deeper had raised MemoryError in its first cycle)."""
    with pytest.raises(cvxdual.TooLargeError, match="at level 0"):
        cvxdual.solve("cylinder-on-block", tol=0.01, max_memory="1MB")


def test_the_first_cycle_starts_where_the_scene_meshes():
    """A hole 2.5 below the face meets level 0's strip (2.5 deep): the run starts at level 1, the size
    check's probe mesh failing like the mesh itself (the check had let level 0's MeshError out)."""
    data = builtin_data("block-with-hole")
    data["bodies"]["bottom"]["holes"][0]["center"] = [0.0, -3.0]
    scene = load_scene(data)
    with pytest.raises(cvxdual.MeshError, match="strip"):
        cvxdual.solve(scene, "type2", 0, stress_space="eq")
    sol = cvxdual.solve(scene, "type2", tol=0.02)
    assert sol.adaptive.met and sol.level == 1


def test_unmet_tolerance_raises_with_the_best():
    with pytest.raises(ToleranceError, match="max_pieces") as e:
        cvxdual.solve("cylinder-on-block", tol=0.001, max_pieces=2000)
    best = e.value.solution
    assert not best.adaptive.met and best.adaptive.stop == "max_pieces"
    rels = [c.bound_rel for c in best.adaptive.cycles]
    assert best.bounds["error_bound_rel"] == min(rels) == rels[best.adaptive.chosen] > 0.001


@pytest.mark.slow  # waits for its 2 s limit
def test_time_limit_keeps_the_best_cycle():
    with pytest.raises(ToleranceError, match="time limit") as e:
        cvxdual.solve("cylinder-on-block", tol=1e-5, time_limit=2.0)  # 1e-5: beyond any mesh in 2 s
    best = e.value.solution
    assert best.adaptive.stop == "time_limit" and len(best.adaptive.cycles) >= 1 and best.bounds["guaranteed"]


def test_cli_unmet_tolerance_writes_the_best_and_exits_1(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["solve", "--scene", "cylinder-on-block", "--tol", "0.1%", "--max-pieces", "2000",
                 "--out", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--max-pieces" in err[0] and "written" in err[0]
    s = json.loads((out / "summary.json").read_text())
    assert s["adaptive"]["met"] is False and s["adaptive"]["stop"] == "max_pieces"
    assert s["stress_space"] == "eq" and s["bounds"]["error_bound_rel"] > 0.001


@pytest.mark.parametrize("bad", [0, 1.5, "150%", "0%", "abc", True, -0.01, float("nan")])
def test_bad_tolerance(bad):
    with pytest.raises(CvxdualError, match="tol must be"):
        parse_tolerance(bad)


def test_tolerance_forms():
    assert parse_tolerance("1%") == pytest.approx(0.01) and parse_tolerance(0.01) == 0.01
    assert parse_tolerance(" 0.5 % ".replace(" ", "")) == pytest.approx(0.005)


def test_max_pieces_needs_a_tolerance(capsys):
    assert main(["solve", "--scene", "patch", "--max-pieces", "10", "--no-output"]) == 1
    assert "--tol" in capsys.readouterr().err
    with pytest.raises(CvxdualError, match="max_pieces must be"):
        cvxdual.solve("patch", tol=0.01, max_pieces=0)


@pytest.mark.parametrize("bad", [0, 0.0, -0.5, 1.5, "half", True, float("nan"), None])
def test_bad_theta(bad):
    with pytest.raises(CvxdualError, match="theta must be"):
        parse_theta(bad)


def test_theta_marks_its_share(capsys):
    runs = {th: cvxdual.solve("hertz", tol=0.03, theta=th).adaptive for th in (0.3, 0.5)}
    for th, h in runs.items():
        assert h.theta == th and h.met
        # Dorfler: the fewest largest parts holding at least theta of G (every cycle but the last marks)
        assert all(c.marked_share >= th for c in h.cycles[:-1]) and h.cycles[-1].marked_share is None
    # the first cycles are the same solve: a smaller theta marks no more of it
    assert runs[0.3].cycles[0].pieces == runs[0.5].cycles[0].pieces
    assert runs[0.3].cycles[0].marked_share <= runs[0.5].cycles[0].marked_share
    assert main(["solve", "--scene", "patch", "--theta", "0.3", "--no-output"]) == 1  # theta without tol
    assert main(["solve", "--scene", "patch", "--tol", "1%", "--theta", "2", "--no-output"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "--tol" in err[0] and "--theta must be" in err[1]


def test_a_grid_meshes_outline_bodies_only():
    with pytest.raises(CvxdualError, match="outline bodies only"):
        Grid.uniform(as_scene("patch"), 0, np.array([0.0, 10.0]))
