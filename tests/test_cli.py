"""The command line: `cvxdual scenes`, `cvxdual solve`, outputs and bad input."""

import json
import subprocess
import sys

import meshio
import numpy as np
import pandas as pd
import pytest
from helpers import without_progress

from cvxdual.cli import main
from cvxdual.scene.scenefile import builtin_names

SUMMARY_KEYS = {"scene", "triangulation", "level", "n_pieces", "n_stress_unknowns", "n_dofs",
                "n_contact_pairs", "solver", "status", "objective", "duality_gap", "residuals", "contact",
                "exact", "error", "timings"}


def test_scenes_lists_builtins(capsys):
    assert main(["scenes"]) == 0
    out = capsys.readouterr().out
    for name in ("patch", "hertz", "blocks"):
        assert name in out
    assert len(out.strip().splitlines()) == len(builtin_names())


def test_python_dash_m_runs_the_command_line():
    """``python -m cvxdual`` is the ``cvxdual`` script (the speed study starts runs with it)."""
    out = subprocess.run([sys.executable, "-m", "cvxdual", "scenes"], capture_output=True, text=True, check=True)
    assert set(builtin_names()) <= {line.split()[0] for line in out.stdout.splitlines() if line.strip()}


def test_solve_writes_the_output_contract(tmp_path, capsys):
    out = tmp_path / "res"
    assert main(["solve", "--scene", "hertz", "--level", "1", "--out", str(out), "--plots"]) == 0
    text = capsys.readouterr().out
    assert "optimal" in text and "Hertz" in text
    s = json.loads((out / "summary.json").read_text())
    assert SUMMARY_KEYS <= set(s)
    assert s["status"] == "optimal" and s["scene"] == "hertz" and s["level"] == 1
    assert set(s["residuals"]) >= {"equilibrium", "constitutive", "complementarity"}
    assert set(s["contact"]) == {"n_active", "x_min", "x_max", "max_pressure", "total_force"}
    assert set(s["timings"]) == {"mesh", "assemble", "build", "solve", "recover", "error", "total"}
    assert {"a", "p0"} <= set(s["exact"]) and {"l2", "l2_rel", "energy", "energy_rel"} <= set(s["error"])
    c = pd.read_csv(out / "contact.csv")
    assert list(c.columns[:5]) == ["x", "gap", "relative_displacement", "pressure", "active"]
    assert len(c) == s["n_contact_pairs"] and c["active"].sum() == s["contact"]["n_active"]
    m = meshio.read(out / "solution.vtu")
    assert m.point_data["displacement"].shape == (len(m.points), 3)
    tri = [b for b in m.cells if b.type == "triangle"]
    assert sum(len(b.data) for b in tri) == s["n_pieces"]
    bodies = [i for i, b in enumerate(m.cells) if b.type != "line"]  # the line cells are the contact face
    stress = np.concatenate([m.cell_data["stress"][i] for i in bodies])
    assert stress.shape == (s["n_pieces"], 3)
    assert np.all(np.concatenate([m.cell_data["piece_kind"][i] for i in bodies]) == 0)
    lines = [i for i, b in enumerate(m.cells) if b.type == "line"]
    assert len(lines) == 1 and len(m.cells[lines[0]].data) == s["n_contact_pairs"]
    np.testing.assert_allclose(m.cell_data["pressure"][lines[0]], c["pressure"], rtol=1e-11)  # csv: 12 digits
    for png in ("stress.png", "deformed.png", "pressure.png"):
        assert (out / png).stat().st_size > 1000
    assert not list(out.glob(".*"))  # no temporary files left behind


def test_set_overrides_a_value(tmp_path, capsys):
    assert main(["solve", "--scene", "patch", "--level", "0", "--set", "mesh.columns=3",
                 "--out", str(tmp_path), "--no-plots"]) == 0
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["n_contact_pairs"] >= 4


def test_scene_file_with_base(tmp_path, capsys):
    f = tmp_path / "soft.toml"
    f.write_text('base = "patch"\nname = "soft"\n[bodies.top.material]\nE = 1000.0\n')
    assert main(["solve", "--scene", str(f), "--level", "0", "--no-output"]) == 0
    assert "scene soft" in capsys.readouterr().out


@pytest.mark.parametrize("error", [OSError(28, "No space left on device"), ValueError("a meshio bug")])
def test_old_outputs_kept_when_writing_fails(tmp_path, monkeypatch, capsys, error):
    out = tmp_path / "o"
    assert main(["solve", "--scene", "patch", "--level", "0", "--out", str(out), "--no-plots"]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    def boom(path, *a, **k):
        with open(path, "wb") as fh:
            fh.write(b"half a file")
        raise error

    monkeypatch.setattr(meshio, "write", boom)
    assert main(["solve", "--scene", "patch", "--level", "1", "--out", str(out), "--no-plots"]) == 1
    err = without_progress(capsys.readouterr().err)
    assert len(err) == 1 and err[0].startswith("cvxdual: error: cannot write outputs")
    err = err[0]
    assert "nothing was changed in" in err
    # the whole previous set is intact (summary.json is written before the VTU): no mix of runs, no temporaries
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert [p.name for p in tmp_path.iterdir()] == ["o"]


BAD = [
    (["--set", 'bodies.cylinder.boundary.top.traction={kind="uniform", value=[0.0, -100.0]}'], "unbalanced"),
    (["--scene", "blocks", "--set", "bodies.lower.boundary.push.traction.value=[0.0, -50.0]"], "pull"),
    (["--set", "bodies.cylinder.material.nu=0.5"], "Poisson"),
    (["--set", "bodies.block.material.E=-1.0"], "positive"),
    (["--set", "bodies.block.material.E=0.0"], "positive"),
    (["--set", "bodies.block.material.E=nan"], "finite"),
    (["--set", "exact.R=inf"], "finite"),
    (["--set", "bodies.block.far=nan"], "finite"),
    (["--scene", "nosuch"], "unknown scene"),
    (["--solver", "NOSUCH"], "unknown or uninstalled solver"),
    (["--triangulation", "type3"], "triangulation"),
    (["--set", "mesh.colums=3"], "colums"),
    (["--set", "bodies.nosuch.material.E=5"], "body 'nosuch', which the scene does not have"),
]


@pytest.mark.parametrize("args,words", BAD, ids=[b[1] for b in BAD])
def test_bad_input_one_line_error_nothing_written(tmp_path, capsys, args, words):
    out = tmp_path / "out"
    rc = main(["solve", "--level", "0", *args, "--out", str(out)])
    err = without_progress(capsys.readouterr().err)
    assert rc == 1
    assert len(err) == 1 and err[0].startswith("cvxdual: error:")
    err = err[0]
    assert words.lower() in err.lower()
    assert not out.exists()


def test_unknown_key_in_scene_file(tmp_path, capsys):
    f = tmp_path / "bad.toml"
    f.write_text('base = "patch"\n[bodies.top]\nfocus_dpth = 1.0\n')
    assert main(["solve", "--scene", str(f), "--no-output"]) == 1
    err = capsys.readouterr().err
    assert "focus_dpth" in err and "bodies.top" in err


def test_unwritable_output(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["solve", "--scene", "patch", "--level", "0", "--out", str(blocker / "sub")]) == 1
    err = capsys.readouterr().err
    assert "not a directory" in err
    assert blocker.read_text() == "x" and [p.name for p in tmp_path.iterdir()] == ["file"]


GEOMETRY_BAD = [
    # the cylinder's circle (R = 50) is a graph only on [-50, 50]: a body wider than that
    (["--scene", "cylinder-on-block", "--set", "bodies.cylinder.x=[-60.0, 20.0]"], "is a graph only on"),
    # bodies side by side: no candidate contact interval
    (["--scene", "blocks", "--set", "bodies.upper.x=[20.0, 30.0]"], "do not overlap"),
    # the far side below the face of the upper body
    (["--scene", "blocks", "--set", "bodies.upper.far=-1.0"], "crosses the far side"),
    # a non-positive-definite Hooke matrix (replaces E and nu)
    (["--scene", "patch", "--set", "bodies.top.material={hooke=[[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]]}"],
     "not positive definite"),
    (["--scene", "patch", "--set", "bodies.top.body_force=[0.0, nan]"], "finite"),
    (["--scene", "patch", "--set", "exact.stress=[0.0, inf, 0.0]"], "finite"),
    # a groove too curved for type 1's first layer at level 0
    (["--scene", "cylinder-in-groove", "--set", "bodies.groove.face.R=26.0", "--set", "bodies.groove.face.yc=26.0"],
     "bulges through the first element layer"),
]


@pytest.mark.parametrize("args,words", GEOMETRY_BAD, ids=[w for _, w in GEOMETRY_BAD])
def test_bad_geometry_one_line_error_nothing_written(tmp_path, capsys, args, words):
    out = tmp_path / "out"
    assert main(["solve", "--level", "0", *args, "--out", str(out)]) == 1
    err = without_progress(capsys.readouterr().err)
    assert len(err) == 1 and err[0].startswith("cvxdual: error:")
    err = err[0]
    assert words in err
    assert not out.exists()


def test_hooke_material_from_the_command_line(tmp_path, capsys):
    from cvxdual.scene.materials import Material
    C = Material.isotropic(70000.0, 0.3).stiffness.tolist()
    assert main(["solve", "--scene", "patch", "--level", "0", "--no-output",
                 "--set", f"bodies.top.material={{hooke={C}}}"]) == 0
    assert "optimal" in capsys.readouterr().out
