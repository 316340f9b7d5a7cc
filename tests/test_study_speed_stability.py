"""The speed and stability studies in --quick mode (the full runs write reports/)."""

import pandas as pd

from cvxdual.cli import main


def test_speed_quick(tmp_path):
    assert main(["study", "speed", "--quick", "--out", str(tmp_path), "--cache", "", "--quiet"]) == 0
    df = pd.read_csv(tmp_path / "speed.csv")
    scan = df[df.part == "scan"]
    assert set(scan.path) == {"limit", "fast", "cvxpy"}
    ok = scan[scan.path != "limit"]
    assert (ok.status == "optimal").all()
    # both paths solve the same discrete problem: the same error against the exact field
    p = df[(df.part == "pareto") & (df.scene == "hertz") & (df.mesh == "graded")]
    for (tri, level), g in p.groupby(["triangulation", "level"]):
        if len(g) == 2:
            e = g.error_l2_rel.to_numpy()
            assert abs(e[0] - e[1]) <= 1e-6 * e[0]  # Clarabel's tolerance against the exact path
    solv = df[df.part == "solvers"]
    assert set(solv.solver) == {"CLARABEL", "OSQP", "SCS"}
    assert solv[solv.solver == "CLARABEL"].diff_to_fast.max() < 1e-6
    text = (tmp_path / "speed.md").read_text()
    assert "## Targets" in text and "limit" in text
    for f in ("speed_scaling.png", "speed_pareto.png"):
        assert (tmp_path / f).stat().st_size > 1000


def test_stability_quick(tmp_path):
    assert main(["study", "stability", "--quick", "--out", str(tmp_path), "--cache", "", "--quiet"]) == 0
    df = pd.read_csv(tmp_path / "stability.csv")
    # every quick case runs on both paths and both triangulations, and the paths agree where both solve
    assert set(df.path) == {"cvxpy", "fast"} and set(df.triangulation) == {"type1", "type2"}
    solved = df[df.status == "optimal"]
    assert solved.paths_agree_l2_rel.max() < 1e-5  # Clarabel's tolerance at the hardest quick case
    # nothing degrades silently: either within the package's tolerances or flagged
    assert solved.within_tolerances.all()
    # locking near incompressibility is shown, not hidden: the error grows as nu -> 1/2
    nu = solved[solved.case.str.startswith("nu") & (solved.path == "fast") & (solved.triangulation == "type1")]
    err = dict(zip(nu.case, nu.error_l2_rel))
    assert err["nu = 0.4999"] > 10 * err["nu = 0.3"]
    assert "## What the table says" in (tmp_path / "stability.md").read_text()
