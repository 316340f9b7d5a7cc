"""Certified bounds and the equilibrium stress space against the paper's P0 stresses.

Per level and Poisson ratio (plane strain, both bodies): the P0 dual on the fast path, and the
equilibrium (Johnson-Mercier, with column stresses on curved pieces) stresses with the certified
energy bracket, ``G`` and the bound ``sqrt(2G)`` on the combined error of a displacement and the
equilibrium stresses (docs/equilibrium.md), for both kinematic sides (``kinematic = ["p1", "p2"]``:
the P1 displacement of the P0 solve, and continuous P2 on the Alfeld split; the same stresses).
Flat faces: ``hertz`` (against its exact field: the effectivity ``sqrt(2G) / true``), ``blocks``
and ``patch`` at nu = 0.3, 0.49, 0.4999. Curved faces: ``cylinder-on-block``,
``cylinder-in-groove`` and ``wavy``, both triangulations, at nu = 0.3 and 0.4999, levels 0-4,
against the equilibrium stresses at level 5 (type 2) of the same scene, and at level 5 their bounds
alone (the finest energy brackets).
Run: ``python studies/bounds.py [--quick]`` (or ``cvxdual study run studies/specs/bounds.py``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cvxdual.study.spec import load_module

FLAT, CURVED = ("hertz", "blocks", "patch"), ("cylinder-on-block", "cylinder-in-groove", "wavy")
NUS = {"flat": (0.3, 0.49, 0.4999), "curved": (0.3, 0.4999)}
BODIES = {"hertz": ("cylinder", "block"), "blocks": ("upper", "lower"), "patch": ("top", "bottom"),
          "cylinder-on-block": ("cylinder", "block"), "cylinder-in-groove": ("cylinder", "groove"),
          "wavy": ("block", "waves")}
LEVELS = {"hertz": [0, 1, 2, 3, 4, 5], "blocks": [0, 1, 2, 3, 4, 5], "patch": [1, 2, 3],
          **{s: [0, 1, 2, 3, 4] for s in CURVED}}
# the curved scenes' reference (type 2, fast route). Level 5, not 6: every row's error is integrated
# over the reference's cells, about 25 s a row at level 5 and 100 s at level 6 (120 curved rows);
# the errors, rates and effectivities use the levels at least two below it (0-3), level 4 adds its
# bounds (guarantees, brackets, type 1 against type 2)
REFERENCE = {"level": 5, "stress_space": "eq"}
EQ_SOLVER = "fast"  # cvxdual.eq.active_set: the same QP as the CVXPY path, checked against it in the tests
TARGET = 0.01  # "the time each space needs for 1% stress error"
SIDES = ["p1", "p2"]  # the eq rows' kinematic sides (issue 41: P2 beside P1); a p0 row carries the default


def _finest(scene: str, nu: float) -> dict:
    """The curved scenes' eq stresses at the reference's level, bounds only (no reference to measure
    errors against there): the finest brackets of the energy."""
    return {"name": f"{scene} eq nu={nu} bounds", "scenes": [scene], "stress_spaces": ["eq"], "kinematic": SIDES,
            "solvers": [EQ_SOLVER],
            "levels": [REFERENCE["level"]], "reference": "none", "triangulations": ["type1", "type2"],
            "overrides": {"bodies": {b: {"material": {"nu": nu}} for b in BODIES[scene]}}, "tags": {"nu": nu},
            "quick": False}


def _block(scene: str, space: str, solver: str, nu: float) -> dict:
    """One scene, stress space and Poisson ratio (both bodies), every level (and on curved scenes
    both triangulations)."""
    material = {"material": {"nu": nu}}
    curved = scene in CURVED
    quick = scene not in ("blocks", "wavy") and nu in (0.3, 0.4999)
    reference = REFERENCE if curved else "exact" if scene != "blocks" else "none"
    return {"name": f"{scene} {space} nu={nu}", "scenes": [scene], "stress_spaces": [space],
            **({"kinematic": SIDES} if space == "eq" else {}), "solvers": [solver],
            "levels": LEVELS[scene], "reference": reference, "triangulations": ["type1", "type2"] if curved
            else ["type1"], "overrides": {"bodies": {b: material for b in BODIES[scene]}}, "tags": {"nu": nu},
            "quick": ({"levels": [0, 1], "reference": {**REFERENCE, "level": 3}} if curved else {"levels": [0, 1]})
            if quick else False}


SPEC = {
    "name": "bounds",
    "title": "Certified bounds: equilibrium stresses against the P0 dual",
    "description": (
        "`p0`: the paper's piecewise-constant stresses (fast path). `eq`: exactly admissible Johnson-Mercier "
        "stresses on the straight pieces and column stresses `g(x) e_y (x) e_y` on the curved ones, on the same "
        "mesh, certified against a kinematically admissible displacement `v` (`kinematic`: `p1`, the P1 "
        "displacement of the P0 solve made pointwise admissible; `p2`, continuous P2 on the Alfeld split made "
        "admissible at every x): `energy_lower <= J(u) <= energy_upper`, `G` their difference, `bound = sqrt(2G)` "
        "bounds `sqrt(||u - v||_a^2 + ||sigma - lam*||_A^2)`. `true` is that combined error against the exact field "
        "(hertz) or the reference (curved scenes), `effectivity = bound / true`. Errors are relative L2 stress "
        "errors against the same."),
    "metrics": {"edge_share": False, "check": "none"},
    "report": {"rates": False, "plots": False},
    "cases": [_block(s, sp, "fast" if sp == "p0" else EQ_SOLVER, nu) for s in FLAT + CURVED
              for sp in ("p0", "eq") for nu in NUS["curved" if s in CURVED else "flat"]]
    + [_finest(s, nu) for s in CURVED for nu in NUS["curved"]],
}


def measure(case, sol) -> dict:
    """The bound columns of an ``eq`` row (a ``p0`` row certifies the same pair: not repeated);
    the true combined error and the effectivity come with the errors (``error_combined``)."""
    if sol.bounds is None:
        return {}
    b, e = sol.bounds, sol.error or {}
    return {"energy_lower": b["energy_lower"], "energy_upper": b["energy_upper"], "G": b["gap"],
            "bound": b["error_bound"], "data_oscillation": b["data_oscillation"],
            "stress_error_A": e.get("energy", np.nan), "displacement_error_a": e.get("displacement_energy", np.nan)}


_REPORT = load_module(Path(__file__).with_name("_bounds_report.py"))


def report(df, study, out) -> str:
    """The tables, rates, findings and plots (``_bounds_report.py``: edits there keep the cache)."""
    setup = _REPORT.Setup(FLAT, CURVED, REFERENCE["level"], TARGET)
    return _REPORT.report(df, study, out, setup)
