"""Errors against a finer reference on outline bodies with arcs (issue 39, item 2): integrated
over the common part of both meshes, what that leaves out reported and bounded, different
bodies still refused; the failed-cases table names every key of a case; ``--quiet`` writes
nothing to stderr when a case fails; ``C e(v)`` of a P2 displacement as the field the combined error
against a finer reference integrates."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from cvxdual import load_scene, solve
from cvxdual.errors import CvxdualError
from cvxdual.system.field import field_distance
from cvxdual.system.field import piece_distance as stress_distance

REF = 3  # the reference level of (a): 5103 pieces of rounded-punch, solved in about a second


@pytest.fixture(scope="module")
def punch():
    scene = load_scene("rounded-punch")
    return scene, {L: solve(scene, "type2", L, "fast") for L in (0, 1, 2, REF)}


def corner_segments(level: int) -> float:
    """The area between rounded-punch's free corner arc (r = 20, a 30 degree sweep: the face's
    arc is the strip's, exact) and the chords standing for it at ``level``: 2 chords at level 0
    (4 a quarter turn), doubled a level, each cutting off ``r^2 / 2 (t - sin t)``."""
    r, n = 20.0, 2 * 2**level
    t = math.radians(30.0) / n
    return n * 0.5 * r * r * (t - math.sin(t))


def test_common_part_on_an_outline_body_with_an_arc(punch):
    scene, sol = punch
    ref = sol[REF]
    total = float(ref.pieces.area.sum())
    dropped = []
    for L in (0, 1, 2):
        p0 = stress_distance(ref, sol[L], 2, 6)
        for d in (p0, field_distance(ref.field, sol[L].field, 2, 6)):
            assert all(np.isfinite(d[k]) and d[k] > 0 for k in ("l2", "l2_rel", "energy", "energy_rel"))
            # each level's chords lie inside the last's (every edge halved), so the reference's mesh
            # holds the studied one and the two differ by the chords' segments of the coarse level
            # less the reference's: exact from the pieces' areas, up to their sums' rounding (1e-9)
            assert d["dropped_area"] == pytest.approx(corner_segments(L) - corner_segments(REF), rel=1e-9)
            # a sliver: under 0.05 % of the bodies' 2434 mm^2 (1.19 mm^2 at level 0), and within the
            # bound that refuses different bodies (twice the polygons' bands of both meshes)
            assert 0 < d["dropped_share"] < 5e-4 and d["dropped_area"] <= d["dropped_bound"]
            assert d["dropped_share"] == pytest.approx(d["dropped_area"] / total, rel=1e-12)  # of the finer mesh
        dropped.append(d["dropped_area"])
    # a level halves the chords: their segments (sagitta times length) quarter, less the reference's
    assert dropped[0] > 3 * dropped[1] > 9 * dropped[2]


def _old_stress_distance(a, b, n, n_fine):
    """:func:`stress_distance` before the common part, with its helpers (verbatim but for the
    refusal of points outside ``b``, which a column scene never has): the value it must keep there."""
    from cvxdual.geometry.locate import locate
    from cvxdual.voigt import VOIGT_WEIGHT

    def _accumulate(d, r, w, A, acc):
        acc[0] += w @ np.einsum("mi,mi,i->m", d, d, VOIGT_WEIGHT)
        acc[1] += w @ np.einsum("mi,mi,i->m", r, r, VOIGT_WEIGHT)
        acc[2] += w @ np.einsum("mi,ij,mj->m", d, A, d)
        acc[3] += w @ np.einsum("mi,ij,mj->m", r, A, r)

    def _result(acc, n):
        l2, ref_l2, en, ref_en = np.sqrt(acc)
        return {"l2": float(l2), "l2_rel": float(l2 / ref_l2), "energy": float(en), "energy_rel": float(en / ref_en),
                "rule": int(n)}

    def locate_in(pts, idx):
        loc = locate(b.mesh, b.pieces, pts, a.pieces.body[idx], 1e-10 * a.scene.length_scale)
        assert np.all(loc >= 0)
        return loc

    pa = a.pieces
    pts, w, idx = pa.quadrature(n)
    loc = locate_in(pts, idx)
    some = np.empty(len(pa), dtype=loc.dtype)
    some[idx] = loc
    straddle = np.zeros(len(pa), bool)
    straddle[idx[loc != some[idx]]] = True
    keep = ~straddle[idx]
    fp, fw, fi = pa.quadrature(n_fine, only=straddle)
    pts, w, idx = np.concatenate([pts[keep], fp]), np.concatenate([w[keep], fw]), np.concatenate([idx[keep], fi])
    loc = np.concatenate([loc[keep], locate_in(fp, fi)])
    body = pa.body[idx]
    acc = np.zeros(4)
    for k, bd in enumerate(a.scene.bodies):
        m = np.flatnonzero(body == k)
        if len(m):
            ta = a.stress[idx[m]]
            _accumulate(ta - b.stress[loc[m]], ta, w[m], bd.material.compliance, acc)
    return _result(acc, n)


def test_a_column_scene_drops_nothing_and_keeps_its_errors():
    scene = load_scene("cylinder-on-block")  # column bodies, a curved face: exact pieces, no polygons
    ref, coarse = solve(scene, "type2", 3, "fast"), solve(scene, "type1", 1, "fast")
    new, old = stress_distance(ref, coarse, 2, 6), _old_stress_distance(ref, coarse, 2, 6)
    assert new["dropped_area"] == 0.0 and new["dropped_share"] == 0.0
    # no point is dropped: the same points, weights and sums in the same order, bit for bit
    assert {k: new[k] for k in old} == old
    eq = field_distance(ref.field, solve(scene, "type1", 1, "fast", stress_space="eq").field, 2, 6)
    assert eq["dropped_area"] == 0.0 and np.isfinite(eq["l2_rel"])


@pytest.mark.parametrize("name, override, level", [
    # Kirsch's hole moved by 4 radii: 2 pi r^2 = 1.57 mm^2 differ, the hole's polygons 0.016 at most
    ("block-with-hole", {"bodies": {"bottom": {"holes": [{"name": "hole", "center": [2.0, -10.0], "radius": 0.5}]}}},
     1),
    # the block 5 mm shallower: 300 mm^2 of column body that no polygon explains (the bound is rounding)
    ("cylinder-on-block", {"bodies": {"block": {"far": -25.0}}}, 1),
])
def test_different_bodies_are_refused(name, override, level):
    a = solve(load_scene(name), "type2", level + 1, "fast")
    b = solve(load_scene(name, [override]), "type2", level, "fast")
    for dist in (lambda: stress_distance(a, b, 2, 6),
                 lambda: field_distance(a.field, b.field, 2, 6)):
        with pytest.raises(CvxdualError, match="not meshes of one scene; compare solutions of the same scene") as e:
            dist()
        assert "\n" not in str(e.value)


def test_the_failed_cases_table_names_every_key_of_a_case():
    from cvxdual.study.cases import base_row
    from cvxdual.study.report import markdown
    from cvxdual.study.spec import load_spec
    study = load_spec({"name": "keys", "scenes": ["hertz"], "levels": [0], "stress_spaces": ["p0", "eq"],
                       "solvers": ["fast"], "tags": {"variant": "soft"}})
    # the runner names the scene of a row (its label, else the scene's name)
    rows = [{**base_row(c), "scene": "hertz", "status": "failed: CvxdualError: no" if c.stress_space == "eq"
             else "optimal", "worker": "", "n_pieces": 144, "h": 1.0, "error_l2_rel": 0.1, "error_energy_rel": 0.1}
            for c in study.cases]
    text = markdown(pd.DataFrame(rows), study, "keys")
    table = text[text.index("## Failed cases"):].splitlines()
    head, row = table[2], table[4]
    for key in ("scene", "triangulation", "stress_space", "level", "solver", "reference", "variant"):
        assert f" {key} |" in head
    assert "| hertz |" in row and "| eq |" in row and "| soft |" in row


SPEC = """\
name = "noisy"
triangulations = ["type1"]
solvers = ["fast"]
levels = [0]
[[cases]]
scenes = [{ source = "hertz", reference = "exact" }]
[[cases]]
name = "too_fine"
# past any machine's memory: every reference level task raises TooLargeError on its worker,
# which Dask logs with its traceback on stderr unless --quiet silences it
scenes = [{ source = "hertz", reference = { level = 13 } }]
"""


def test_quiet_study_writes_nothing_to_stderr(tmp_path, capfd):
    from cvxdual.cli import main
    spec = tmp_path / "noisy.toml"
    spec.write_text(SPEC)
    out = tmp_path / "out"
    assert main(["study", "run", str(spec), "--quiet", "--workers", "1", "--out", str(out), "--cache", ""]) == 0
    captured = capfd.readouterr()
    assert captured.err == ""  # worker and scheduler processes included (capfd reads the descriptor)
    assert "1 solved, 1 failed" in captured.out
    df = pd.read_csv(out / "noisy.csv")
    assert df.loc[df["case"] == "too_fine", "status"].str.contains("TooLargeError").all()  # the reason is kept
    report = (out / "noisy.md").read_text()
    failed = report[report.index("## Failed cases"):]
    assert "stress_space" in failed and "TooLargeError" in failed


@pytest.mark.parametrize("name, tri", [("cylinder-on-block", "type2"), ("hertz", "type1")])
def test_p2_kinematic_field_is_the_p2_strain(name, tri):
    """The field ``C e(v)`` of a P2 displacement (:func:`cvxdual.eq.fields.kinematic_field`), which
    the combined error against a finer reference integrates, is the strain the certificate's own
    exact-field error evaluates (``exact_errors``: the sub-triangles' vertex values, the slabs'
    traces at each abscissa): with the field itself as the "exact" stress, ``||lam* - C e(v)||_A``
    vanishes to rounding, on the curved pieces' slabs too; and its quadrature's values are its
    values at the same points."""
    from cvxdual.eq.bounds import exact_errors
    from cvxdual.eq.fields import P2KinematicField, kinematic_field
    sol = solve(load_scene(name), tri, 1, "fast", stress_space="eq", kinematic="p2")
    f = kinematic_field(sol.space, sol.bounds["displacement"])
    assert isinstance(f, P2KinematicField)
    tol = 1e-10 * sol.scene.length_scale  # locate() absorbs rounding only

    class Itself:
        def stress(self, k, pts):
            return f.at(pts, np.full(len(pts), k), tol)[0]

    e = exact_errors(sol.space, sol.stress, sol.bounds["displacement"], Itself(), n=3, g=sol.column_stress)
    # a difference of two evaluations of one linear function: rounding (1.6e-16 measured) below 1e-12
    assert e["displacement_a"] <= 1e-12 * e["reference_A"]
    pts, w, body, vals, cell = f.rule(3)
    at, where = f.at(pts, body, tol)
    assert np.array_equal(where, cell)  # every point in the cell the rule put it in
    assert np.abs(vals - at).max() <= 1e-12 * np.abs(vals).max()  # the same values, to rounding (4e-16 measured)
    assert (cell < 0).any() == (name == "cylinder-on-block")  # the slabs are covered where there are any
