"""Sliding supports on slanted straight parts of an outline: the displacement normal to the line
is zero and the tangential traction too. P0 holds the normal component through node frames (the
nodes' ``r`` components are the line's tangent), the equilibrium space frees the edges' normal
traction and fixes the tangential one; these are checked against a uniform stress that satisfies
them exactly, against a KKT solve in plain ``(u_x, u_y)`` with the support rows written out, and
by the certified energy bracket, which needs both spaces right."""

import re
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import cvxdual as cd
from cvxdual.geometry.mesh import build_mesh
from cvxdual.geometry.triangulation import discretize
from cvxdual.scene import load_scene
from cvxdual.system.assembly import assemble
from cvxdual.system.boundary import supports

ROOT = Path(__file__).resolve().parents[1]

# Hydrostatic stress -100 I in two blocks: its traction -100 n has no tangential part on any line,
# and the isotropic strain's displacement, a dilation about the corner (11, -4) where the slope
# meets the bottom, is normal-free on both sliding lines of the lower block (the upper block
# dilates about a point of its sliding left side).
SLANTED_PATCH = """name = "slanted-patch"
units = ["mm", "MPa"]
plane = "strain"
[exact]
kind = "uniform"
stress = [-100.0, -100.0, 0.0]
any_material = true
[mesh]
columns = 4
default_level = 2
[bodies.top]
position = "upper"
x = [0.0, 10.0]
far = 6.0
face = { kind = "flat", y0 = 0.0 }
material = { E = 70000.0, nu = 0.3 }
[bodies.top.boundary.symmetry]
on = "left"
kind = "sliding"
[bodies.top.boundary.pressure]
on = "far"
kind = "traction"
traction = { value = [0.0, -100.0] }
[bodies.top.boundary.side]
on = "right"
kind = "traction"
traction = { value = [-100.0, 0.0] }
[bodies.bottom]
position = "lower"
x = [0.0, 10.0]
face = { kind = "flat", y0 = 0.0 }
material = { E = 210000.0, nu = 0.2 }
outline = [{ name = "step", to = [10.0, -1.0] }, { name = "slope", to = [11.0, -4.0] },
           { name = "bottom", to = [0.0, -4.0] }, { name = "left", to = [0.0, 0.0] }]
[bodies.bottom.boundary.slope]
on = "slope"
kind = "sliding"
[bodies.bottom.boundary.support]
on = "bottom"
kind = "sliding"
[bodies.bottom.boundary.left]
on = "left"
kind = "traction"
traction = { value = [100.0, 0.0] }
[bodies.bottom.boundary.step]
on = "step"
kind = "traction"
traction = { value = [-100.0, 0.0] }
"""

# examples/wedge-on-rollers.toml: a cylinder (clamped on top) pressed by a block pushed up from
# below and held only by rollers along its two slanted sides, guided at 45 degrees (GUIDED); without
# the guides' directions the sides slide along their own slopes (WEDGE); with the slopes' own
# directions named, the same problem (ALONG). No rigid motion is left in any of them.
GUIDED = (ROOT / "examples" / "wedge-on-rollers.toml").read_text()
WEDGE = re.sub(r"\ndirection = \[[^]]*\]", "", GUIDED)


def _directed(right, left):
    """WEDGE with ``direction``s on its two slopes."""
    text = WEDGE
    for part, d in (("right", right), ("left", left)):
        text = text.replace(f'on = "{part}"\nkind = "sliding"', f'on = "{part}"\nkind = "sliding"\ndirection = {d}')
    return text


ALONG = _directed("[-3.0, 12.0]", "[3.0, 12.0]")  # the slopes' own directions: the same problem as WEDGE
SLOPES = {"right": ((10.0, 0.0), (13.0, -12.0)), "left": ((-13.0, -12.0), (-10.0, 0.0))}
GUIDES = {"right": (1.0, 1.0), "left": (1.0, -1.0)}


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    assert [t.count("\ndirection") for t in (GUIDED, WEDGE, ALONG)] == [2, 0, 2]
    assert _directed("[1.0, 1.0]", "[1.0, -1.0]") == GUIDED
    d = tmp_path_factory.mktemp("slanted")
    out = {}
    for name, text in (("patch", SLANTED_PATCH), ("wedge", WEDGE), ("guided", GUIDED), ("along", ALONG)):
        (d / f"{name}.toml").write_text(text)
        out[name] = load_scene(str(d / f"{name}.toml"))
    return out


def _across(d):
    """The unit normal of the direction ``d`` (``d`` turned by +90 degrees)."""
    d = np.asarray(d, float)
    return np.array([-d[1], d[0]]) / np.hypot(*d)


def _unit_normal(p, q):
    """The unit normal of the line from ``p`` to ``q``."""
    return _across(np.subtract(q, p, dtype=float))


@pytest.mark.parametrize("space", ["p0", "eq"])
@pytest.mark.parametrize("level", [2, 3])
def test_uniform_stress_is_exact_with_a_slanted_support(scenes, space, level):
    """Both spaces hold the uniform stress; the fast routes solve directly: 1e-8 relative leaves
    1e3 times their rounding (1e-14 to 3e-12 seen). Levels 0-1 are refused: their strip is deeper
    than the short part ``step``."""
    sol = cd.solve(scenes["patch"], level=level, stress_space=space, solver="fast")  # coarse warm starts skipped
    assert sol.error["l2_rel"] <= 1e-8
    if space == "eq":
        assert sol.bounds["guaranteed"], sol.bounds["reasons"]


@pytest.mark.parametrize("space", ["p0", "eq"])
def test_uniform_stress_through_cvxpy(scenes, space):
    """The CVXPY models: CLARABEL stops at a relative gap of 1e-8, an energy-norm stress error of
    up to sqrt(1e-8) = 1e-4 relative (3e-9 to 7e-8 seen)."""
    sol = cd.solve(scenes["patch"], level=2, stress_space=space, solver="CLARABEL")
    assert sol.error["l2_rel"] <= 1e-4


def test_slanted_nodes_slide_along_their_line(scenes):
    """On the slope the displacement is tangential: its normal part is rounding (the node frame's
    tangent times one unknown), its tangential part the dilation's, which grows with the distance
    from the corner (11, -4) about which the block dilates."""
    sol = cd.solve(scenes["patch"], level=2, solver="fast")
    bm = sol.mesh.bodies[1]
    nodes = bm.side_nodes("slope")
    n = _unit_normal((10.0, -1.0), (11.0, -4.0))
    u = sol.displacement[nodes]
    scale = np.abs(sol.displacement).max()
    assert np.abs(u @ n).max() <= 1e-13 * scale  # rounding of t s: a few ulps of the largest value
    dist = np.linalg.norm(sol.mesh.points[nodes] - [11.0, -4.0], axis=1)
    slide = u @ np.array([n[1], -n[0]])
    far = dist > 0.5
    # uniform dilation: the slide is proportional to the distance (a straight line through 0)
    ratio = slide[far] / dist[far]
    assert np.ptp(ratio) <= 1e-8 * np.abs(ratio).max() and np.abs(ratio).min() > 0


def test_supports_take_frames_and_corners(tmp_path):
    """The frame of a slanted sliding node is (tangent, normal) with the normal fixed; where it meets
    another non-parallel support the node is held both ways; elsewhere frames are the identity."""
    text = WEDGE.replace('kind = "traction"\ntraction = { value = [0.0, 200.0] }',
                         'kind = "sliding"')  # the bottom slides too: its corners are held
    assert text != WEDGE
    (tmp_path / "w.toml").write_text(text)
    mesh = build_mesh(load_scene(str(tmp_path / "w.toml")), 1)
    sup = supports(mesh)
    bm = mesh.bodies[1]
    right, bottom = bm.side_nodes("right"), bm.side_nodes("bottom")
    n = _unit_normal((10.0, 0.0), (13.0, -12.0))
    inner = right[1:-1]
    assert np.allclose(np.abs(sup.frame[inner, 1] @ n), 1.0, rtol=0, atol=1e-15)
    assert np.allclose(sup.frame[inner, 0] @ n, 0.0, rtol=0, atol=1e-15)
    assert np.all(sup.fixed[inner] == [False, True])
    corner = np.intersect1d(right, bottom)
    assert len(corner) == 1 and np.all(sup.fixed[corner])  # slope meets the sliding bottom
    assert np.all(sup.fixed[bottom[1:-1]] == [False, True])  # u_y on the horizontal line
    others = np.setdiff1d(np.arange(mesh.n_nodes), np.concatenate([right, bm.side_nodes("left")]))
    assert np.array_equal(sup.frame[others], np.broadcast_to(np.eye(2), (len(others), 2, 2)))


@pytest.mark.parametrize("name", ["wedge", "guided"])
def test_p0_matches_a_kkt_solve_with_the_support_rows(scenes, name):
    """The fast path's displacement (unknowns in node frames) against the minimum of the energy
    in plain ``(u_x, u_y)`` with the constraints as rows: clamped dofs, ``m . u = 0`` on the two
    slopes (``m`` their normals from the outline's corners, or across the named directions), the
    ties, ``[u] = eps`` on the active pairs. The multipliers of the active pairs are pressures
    (>= 0) and no inactive pair penetrates."""
    sol = cd.solve(scenes[name], level=2, triangulation="type1", solver="fast")
    mesh, pieces, ties = discretize(scenes[name], "type1", 2)
    s = assemble(mesh, pieces, ties)
    n_dofs = s.n_dofs
    rows, rhs = [], []

    def row(cols, vals, value=0.0):
        rows.append(sp.csr_matrix((vals, (np.zeros(len(cols), int), cols)), shape=(1, n_dofs)))
        rhs.append(value)

    for k in mesh.bodies[0].side_nodes("far"):
        row([2 * k], [1.0])
        row([2 * k + 1], [1.0])
    block = mesh.bodies[1]
    for part in ("right", "left"):
        m = _unit_normal(*SLOPES[part]) if name == "wedge" else _across(GUIDES[part])
        for k in block.side_nodes(part):
            row([2 * k, 2 * k + 1], m)
    for a, b in ([] if ties is None else ties):
        for c in (0, 1):
            row([2 * a + c, 2 * b + c], [1.0, -1.0])
    active = np.asarray(sol.contact["active"], bool)
    up, lo = mesh.pairs[active].T
    for u_, l_, e in zip(up, lo, s.eps[active], strict=True):
        row([2 * l_ + 1, 2 * u_ + 1], [1.0, -1.0], e)
    C = sp.vstack(rows).tocsr()
    # corner nodes sit on both slopes' lists only once each; duplicate rows would make C singular
    assert np.linalg.matrix_rank(C.toarray()) == C.shape[0]
    K = s.stiffness()
    kkt = sp.bmat([[K, C.T], [C, None]], format="csc")
    x = spla.spsolve(kkt, np.concatenate([s.f, rhs]))
    q, mu = x[:n_dofs].reshape(-1, 2), x[n_dofs:]
    # two direct solves of one system: 3.7e-10 relative seen, 5.9e-10 on the same wedge with vertical
    # sides (the fast path's own accuracy, not the frames'); a wrong frame is an O(1) difference
    assert np.abs(q - sol.displacement).max() <= 1e-8 * np.abs(q).max()
    pressure = mu[-len(up):]
    assert pressure.min() >= -1e-8 * np.abs(pressure).max()  # compressive: a sign, up to rounding
    jump = q[mesh.pairs[:, 1], 1] - q[mesh.pairs[:, 0], 1]
    assert np.all(jump[~active] <= s.eps[~active] + 1e-9 * np.abs(s.eps).max())


@pytest.mark.slow
@pytest.mark.parametrize(("name", "rate_min"), [("wedge", 0.8), ("guided", 0.45)])
def test_wedge_bracket_is_certified_and_closes(scenes, name, rate_min):
    """The equilibrium stress (traction 0 along the slopes or the guides, free across) against
    the P0 displacement (its component across them 0): two spaces built independently must
    bracket one energy. The bounds are guaranteed (the support violation is rounding) and the
    error bound sqrt(2 G) falls with h: at about h^1 on the wedge (fitted 0.94 on levels 1-3; 0.8
    allows for the contact zone's jump at level 3). The guided block is singular where a guide
    meets the loaded bottom: its P0 stress in the corner triangle grows as r^-0.46 (levels 4-6),
    so the energy error falls no faster than h^0.54; 0.56 fitted on levels 1-3, 0.45 asked."""
    h, err = [], []
    for level in (1, 2, 3):
        sol = cd.solve(scenes[name], level=level, stress_space="eq", solver="fast")
        b = sol.bounds
        assert b["guaranteed"], b["reasons"]
        assert b["energy_lower"] <= b["energy_upper"]
        h.append(2.0**-level)
        err.append(b["error_bound"])
    rate = np.polyfit(np.log(h), np.log(err), 1)[0]
    assert rate >= rate_min


def test_cvxpy_and_fast_agree_on_the_wedge(scenes):
    """The dual QP in CVXPY and the active-set path on the frames' unknowns: the same contact set
    and pressures within CLARABEL's tolerance (1e-8 relative gap: 1e-4 on the stress; 5e-10 seen)."""
    a = cd.solve(scenes["wedge"], level=1, solver="fast")
    b = cd.solve(scenes["wedge"], level=1, solver="CLARABEL")
    assert np.array_equal(np.asarray(a.contact["active"]), np.asarray(b.contact["active"]))
    pa, pb = np.asarray(a.contact["pressure"]), np.asarray(b.contact["pressure"])
    assert np.abs(pa - pb).max() <= 1e-4 * np.abs(pa).max()


def test_a_support_on_a_contact_node_is_refused(scenes, tmp_path):
    """A slope starting at the face's end, with the contact interval reaching it: the face-end pair
    would slide along the slope, so the assembly refuses it in one line."""
    text = WEDGE.replace("interval = [-6.0, 6.0]", "interval = [-10.0, 10.0]").replace(
        "x = [-12.0, 12.0]", "x = [-10.0, 10.0]")
    (tmp_path / "w.toml").write_text(text)
    with pytest.raises(cd.SceneError, match=r"set a \[contact\] interval that stops short"):
        cd.solve(load_scene(str(tmp_path / "w.toml")), level=1, solver="fast")


@pytest.mark.parametrize("space", ["p0", "eq"])
def test_naming_the_slopes_own_direction_changes_nothing(scenes, space):
    """``direction`` along the line is the default: the same stresses to rounding (the normal is
    computed from the direction instead of the corners: a few ulps)."""
    a = cd.solve(scenes["wedge"], level=2, stress_space=space, solver="fast")
    b = cd.solve(scenes["along"], level=2, stress_space=space, solver="fast")
    sa, sb = np.asarray(a.stress), np.asarray(b.stress)
    assert np.abs(sa - sb).max() <= 1e-10 * np.abs(sa).max()  # rounding through two direct solves


def test_guides_change_the_solution(scenes):
    """The guided rollers are a different support: the block's slopes now move across their lines
    (a guide at 45 degrees lets them), which the plain sliding support forbids."""
    g = cd.solve(scenes["guided"], level=2, solver="fast")
    nodes = g.mesh.bodies[1].side_nodes("right")
    n = _unit_normal(*SLOPES["right"])
    across = np.abs(g.displacement[nodes] @ n).max()
    assert across > 1e-3 * np.abs(g.displacement).max()
    assert np.abs(g.displacement[nodes] @ _across(GUIDES["right"])).max() <= 1e-13 * np.abs(g.displacement).max()


@pytest.mark.parametrize(("part", "words"), [
    ({"kind": "traction", "traction": {"value": [0.0, 1.0]}, "direction": [1.0, 0.0]}, "only a sliding support"),
    ({"kind": "sliding", "direction": [0.0, 0.0]}, "must not be zero"),
    ({"kind": "sliding", "direction": [1.0]}, "pair of numbers"),
    ({"kind": "sliding", "direction": "up"}, "pair of numbers"),
])
def test_bad_directions_are_refused_in_one_line(part, words):
    with pytest.raises(cd.SceneError, match=words):
        load_scene("block-with-hole", [{"bodies": {"bottom": {"boundary": {"support": part}}}}])


def test_a_direction_on_the_face_is_refused():
    extra = {"bodies": {"lower": {"boundary": {"f": {"on": "face", "kind": "sliding", "direction": [1.0, 1.0]}}}}}
    with pytest.raises(cd.SceneError, match="on the face has a direction"):
        load_scene("blocks", [extra])


def test_eq_traction_along_the_guides_is_zero(scenes):
    """Read back from the equilibrium stress field itself, just inside the right slope: the traction
    ``sigma n`` has no component along the guide; the plain sliding support's field has one there
    (so the check bites), and none along its own line. Points 1e-7 inside the edge: the stress
    changes by about 1e-7 of its size over h there (h >= 0.1), hence 1e-5 of the largest value
    (4e-8 and 1e-8 seen; the controls 0.37 and 0.90)."""
    p, q = map(np.asarray, SLOPES["right"])
    n_out = _unit_normal(p, q)  # (12, 3) / |.|: right of the slope, away from the block
    s_ = np.linspace(0.1, 0.9, 17)[:, None]
    pts = p + s_ * (q - p) - 1e-7 * n_out
    along_guide = np.asarray(GUIDES["right"]) / np.hypot(*GUIDES["right"])
    along_line = (q - p) / np.linalg.norm(q - p)

    def traction(name):
        sol = cd.solve(scenes[name], level=2, stress_space="eq", solver="fast")
        sig, _ = sol.field.at(pts, np.ones(len(pts), int))
        t = np.stack([sig[:, 0] * n_out[0] + sig[:, 2] * n_out[1], sig[:, 2] * n_out[0] + sig[:, 1] * n_out[1]], 1)
        return t, np.abs(sig).max()

    t, scale = traction("guided")
    assert np.abs(t @ along_guide).max() <= 1e-5 * scale
    assert np.abs(t @ along_line).max() > 1e-2 * scale  # the guide's reaction is not normal to the slope
    t, scale = traction("wedge")
    assert np.abs(t @ along_line).max() <= 1e-5 * scale
    assert np.abs(t @ along_guide).max() > 1e-2 * scale


def test_a_side_shorter_than_the_strip_is_refused_until_the_strip_thins(scenes):
    """The slanted patch's 1 mm ``step`` runs down the strip's side: at level 1 the strip is 1.25
    deep and would cover the void beyond the step's end, so the mesh is refused in one line."""
    with pytest.raises(cd.MeshError, match="meets the outline part 'step'; raise the level"):
        build_mesh(scenes["patch"], 1)
    assert len(build_mesh(scenes["patch"], 2).bodies[1].side_nodes("step")) >= 2


def test_a_traction_across_the_guide_changes_nothing(scenes):
    """A load on the guided slope straight across the guide goes into the rollers: P0's displacement
    and the eq bracket stay as they were (the load's values are written in the edges' guided frame;
    in the edges' own normal frame they moved the bracket to lower > upper)."""
    m = _across(GUIDES["right"])
    loaded = load_scene(str(ROOT / "examples" / "wedge-on-rollers.toml"), [{"bodies": {"block": {"boundary": {
        "across": {"on": "right", "kind": "traction", "traction": {"value": (100.0 * m).tolist()}}}}}}])
    for space in ("p0", "eq"):
        a = cd.solve(scenes["guided"], level=2, stress_space=space, solver="fast")
        b = cd.solve(loaded, level=2, stress_space=space, solver="fast")
        # the rollers' reaction changes by the load, nothing else: rounding through direct solves
        assert np.abs(b.displacement - a.displacement).max() <= 1e-10 * np.abs(a.displacement).max()
    assert b.bounds["guaranteed"]
    assert b.bounds["energy_lower"] == pytest.approx(a.bounds["energy_lower"], rel=1e-10)
    assert b.bounds["energy_upper"] == pytest.approx(a.bounds["energy_upper"], rel=1e-10)


def test_a_guide_reaching_a_tied_node_holds_both_nodes():
    """Type 1 ties a node one layer below a concave face's end to the face node above it (one
    displacement for both). A guide on the side up to between them holds the lower node: the tie
    makes both take it, and both move along the guide."""
    d = {"contact": {"interval": [-16.0, 16.0]},
         "bodies": {"groove": {"boundary": {"right": {"interval": [-20.0, 6.0], "direction": [1.0, -2.0]}}}}}
    scene = load_scene("cylinder-in-groove", [d])
    mesh, pieces, ties = discretize(scene, "type1", 2)
    sup = supports(mesh)
    rotated = np.isin(ties, sup.rotated)
    split = ties[rotated[:, 0] != rotated[:, 1]]
    assert len(split)  # the case: one node of a tie on the guide, the other not
    sol = cd.solve(scene, level=2, triangulation="type1", solver="fast")
    m = _across([1.0, -2.0])
    u = sol.displacement[split]  # (k, 2 nodes, 2)
    scale = np.abs(sol.displacement).max()
    assert np.abs(u[:, 0] - u[:, 1]).max() <= 1e-14 * scale  # tied: equal up to rounding
    assert np.abs(u @ m).max() <= 1e-13 * scale  # both on the guide
    assert cd.solve(scene, level=2, triangulation="type1", stress_space="eq", solver="fast").bounds["guaranteed"]


def test_sliding_on_an_outline_bodys_face():
    """A flat face outside the contact interval may slide (``u_y = 0``) on an outline body too."""
    over = {"contact": {"interval": [-6.0, 6.0]},
            "bodies": {"top": {"boundary": {"f": {"on": "face", "kind": "sliding", "interval": [-10.0, -8.0]}}}}}
    sol = cd.solve(load_scene("block-with-hole", [over]), level=1, solver="fast")
    top = sol.mesh.bodies[0]
    face = top.side_nodes("face")
    x = sol.mesh.points[face, 0]
    held = face[(x >= -10.0) & (x <= -8.0)]
    assert len(held) >= 2 and np.all(sol.displacement[held, 1] == 0.0)  # held exactly: not an unknown
    assert np.abs(sol.displacement[face[x > -7.0], 1]).max() > 0
