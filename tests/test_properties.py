"""Property-based tests: random valid scenes solve with small residuals and the right total
contact force; random invalid ones are rejected with a cvxdual error, never anything else."""

import copy
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import cvxdual as cd
from cvxdual.scene.scenefile import scene_from_dict
from cvxdual.solution import TOLERANCES
from cvxdual.validate import TINY

pos = st.floats(min_value=1.0, max_value=100.0)
# Poisson ratios of valid scenes: 0, or at least validate.TINY (smaller magnitudes are refused by
# design: products of such numbers underflow)
nus = st.floats(0.0, 0.45).filter(lambda v: v == 0.0 or v >= TINY)


@st.composite
def block_scenes(draw):
    """Two blocks: the upper clamped on top, the lower sliding on its sides and pushed up."""
    w = draw(st.floats(5.0, 50.0))
    h1, h2 = draw(st.floats(2.0, 30.0)), draw(st.floats(2.0, 30.0))
    p = draw(st.floats(1.0, 100.0))
    gap = draw(st.one_of(st.none(), st.floats(10.0, 1e4)))
    d = {
        "name": "random", "plane": draw(st.sampled_from(["strain", "stress"])),
        "mesh": {"columns": draw(st.integers(3, 8)), "grading": draw(st.floats(1.0, 4.0)),
                 "focus": [-0.25 * w, 0.25 * w]},
        "bodies": {
            "a": {"position": "upper", "x": [-w / 2, w / 2], "far": h1, "face": {"kind": "flat", "y0": 0.0},
                  "material": {"E": draw(st.floats(1e3, 1e6)), "nu": draw(nus)},
                  "layers": draw(st.integers(1, 4)),
                  "boundary": {"top": {"on": "far", "kind": "clamped"}}},
            "b": {"position": "lower", "x": [-w / 2, w / 2], "far": -h2, "face": {"kind": "flat", "y0": 0.0},
                  "material": {"E": draw(st.floats(1e3, 1e6)), "nu": draw(nus)},
                  "layers": draw(st.integers(1, 4)),
                  "boundary": {"l": {"on": "left", "kind": "sliding"}, "r": {"on": "right", "kind": "sliding"},
                               "push": {"on": "far", "kind": "traction",
                                        "traction": {"kind": "uniform", "value": [0.0, p]}}}},
        },
    }
    if gap is not None:
        d["contact"] = {"gap": {"kind": "parabola", "R": gap}}
    return d, p * w


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(block_scenes(), st.sampled_from(["fast", "CLARABEL"]))
def test_valid_scenes_solve(case, solver):
    data, total = case
    sol = cd.solve(scene_from_dict(data), "type1", 1, solver)
    for k, tol in TOLERANCES.items():
        assert sol.residuals[k] <= tol
    assert sol.duality_gap <= 1e-6
    # the lower body is held only by contact: all of the push goes through it
    assert sol.contact["total_force"] == pytest.approx(total, rel=1e-6)
    assert sol.contact["force"].min() >= -1e-7 * total


NUMERIC_PATHS = [
    ("bodies", "a", "material", "E"), ("bodies", "b", "material", "nu"), ("bodies", "a", "far"),
    ("bodies", "b", "far"), ("mesh", "grading"), ("bodies", "b", "face", "y0"),
]


def _set(d, path, value):
    for k in path[:-1]:
        d = d[k]
    d[path[-1]] = value


@st.composite
def corrupted(draw):
    data, _ = draw(block_scenes())
    d = copy.deepcopy(data)
    kind = draw(st.sampled_from(["nan", "inf", "E", "nu", "key", "far", "layers", "grading", "range", "pull",
                                 "string", "scalar-table"]))
    if kind in ("nan", "inf"):
        _set(d, draw(st.sampled_from(NUMERIC_PATHS)), math.nan if kind == "nan" else -math.inf)
    elif kind == "E":
        d["bodies"]["b"]["material"]["E"] = draw(st.floats(-1e6, 0.0))
    elif kind == "nu":
        d["bodies"]["a"]["material"]["nu"] = draw(st.one_of(st.floats(0.5, 10.0), st.floats(-10.0, -1.0)))
    elif kind == "key":
        d["bodies"]["a"][draw(st.sampled_from(["thickness", "colour", "Far"]))] = 1.0
    elif kind == "far":
        d["bodies"]["a"]["far"] = -draw(st.floats(0.0, 10.0))  # below its own face
    elif kind == "layers":
        d["bodies"]["b"]["layers"] = draw(st.integers(-3, 0))
    elif kind == "grading":
        d["mesh"]["grading"] = draw(st.floats(-5.0, 0.99))
    elif kind == "range":
        x = d["bodies"]["a"]["x"]
        d["bodies"]["a"]["x"] = [x[1], x[0]]
    elif kind == "string":  # a word where a number belongs
        _set(d, draw(st.sampled_from(NUMERIC_PATHS)), draw(st.sampled_from(["abc", "1e3x", ""])))
    elif kind == "scalar-table":  # a number or a list where a table belongs
        path = draw(st.sampled_from([("bodies",), ("bodies", "a", "material"), ("bodies", "b", "boundary"),
                                     ("bodies", "a", "face"), ("mesh",)]))
        _set(d, path, draw(st.sampled_from([5, "x", [1.0, 2.0]])))
    else:
        d["bodies"]["b"]["boundary"]["push"]["traction"]["value"][1] *= -1
    return d, kind


@settings(max_examples=40, deadline=None)
@given(corrupted())
def test_invalid_scenes_rejected_cleanly(case):
    d, kind = case
    with pytest.raises(cd.CvxdualError) as info:
        cd.solve(scene_from_dict(d), "type1", 0, "fast")
    msg = str(info.value)
    assert 10 < len(msg) < 500  # a sentence that names the problem, not a dump
    if kind == "pull":
        assert isinstance(info.value, cd.NoAdmissibleStressError)
    if kind == "key":
        assert "unknown key" in msg


def test_inverted_and_misaligned_meshes_are_rejected():
    from cvxdual.geometry.mesh import _pairs, build_mesh, check_triangles
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [2.0, 0.0]])
    with pytest.raises(cd.MeshError, match="inverted or zero-area"):
        check_triangles(pts, np.array([[0, 2, 1]]))  # clockwise: inverted
    with pytest.raises(cd.MeshError, match="inverted or zero-area"):
        check_triangles(pts, np.array([[0, 1, 3]]))  # collinear: zero area
    scene = cd.load_scene("patch")
    mesh = build_mesh(scene, 0)
    bad = mesh.points.copy()
    bad[mesh.pairs[1, 1], 0] += 1e-3  # move one lower contact node off its vertical line
    with pytest.raises(cd.MeshError, match="not aligned"):
        _pairs(scene, mesh.bodies, bad)
