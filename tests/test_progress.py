"""Progress lines as the work happens, the time limit, --quiet, --verbose and --version."""

import logging
import os
import subprocess
import sys
import time

import pytest
from helpers import PROGRESS, without_progress

import cvxdual as cd
from cvxdual.cli import main


class Recorder(logging.Handler):
    """Progress records with the time each was emitted."""

    def __init__(self):
        super().__init__(logging.DEBUG)
        self.records = []

    def emit(self, record):
        self.records.append((time.perf_counter(), record.getMessage()))


@pytest.fixture
def recorder():
    log = logging.getLogger("cvxdual")
    handler, saved = Recorder(), log.level
    log.addHandler(handler)
    log.setLevel(logging.INFO)
    yield handler
    log.removeHandler(handler)
    log.setLevel(saved)


def test_level5_solve_reports_each_phase_as_it_ends(tmp_path, capsys, recorder):
    """The acceptance: a level-5 solve prints a line per phase, each when that phase ends (the
    solve's line comes after its start line by the solve's own time, not at the end of the run)."""
    assert main(["solve", "--level", "5", "--solver", "fast", "--no-plots", "--out", str(tmp_path / "o")]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    phases = [line.split(":")[1].strip() for line in err]
    assert [p for p in dict.fromkeys(phases)] == ["mesh", "assemble", "solve", "recover", "write"]
    assert without_progress("\n".join(err)) == []
    assert any(line.startswith("cvxdual: solve: fast path on ") and line.endswith("...") for line in err)
    times = {msg.split(":")[0] + (" start" if msg.endswith("...") else ""): t for t, msg in recorder.records}
    # the records were emitted in phase order, as each happened: the solve took measurable time
    # between its start and end lines, after the mesh's line and before the write's
    assert times["mesh"] < times["assemble"] < times["solve start"] < times["solve"] < times["recover"] < times["write"]
    solve_seconds = float(next(m for _, m in recorder.records if m.startswith("solve: ") and " s (" in m)
                          .split()[1])
    # the end line follows the start line by the time it reports (+ the logging itself: < 50 ms)
    assert abs((times["solve"] - times["solve start"]) - solve_seconds) < 0.05


def test_cvxpy_path_reports_build_and_iterations(tmp_path, capsys):
    assert main(["solve", "--scene", "patch", "--level", "1", "--no-output"]) == 0
    err = capsys.readouterr().err
    assert "cvxdual: build: " in err and "CLARABEL: optimal in " in err and " iterations" in err


def test_quiet_prints_no_progress_and_verbose_prints_iterations(tmp_path, capsys):
    assert main(["solve", "--level", "3", "--solver", "fast", "--no-output", "--quiet"]) == 0
    assert capsys.readouterr().err == ""
    assert main(["solve", "--level", "3", "--solver", "fast", "--no-output", "--verbose"]) == 0
    err = capsys.readouterr().err
    assert "fast path: iteration 1, " in err and "warm start: the active set of level 1" in err
    with pytest.raises(SystemExit):  # argparse: the two exclude each other
        main(["solve", "--quiet", "--verbose"])


def test_verbose_solver_log_goes_to_stderr(capfd):
    """Clarabel prints its log from compiled code, past sys.stdout: --verbose sends it to stderr,
    so stdout keeps the summary only."""
    assert main(["solve", "--scene", "patch", "--level", "0", "--no-output", "--verbose"]) == 0
    out, err = capfd.readouterr()
    assert "Clarabel" in err and "Clarabel" not in out
    assert out.startswith("scene patch")


def test_version(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out.strip() == f"cvxdual {cd.__version__}"


@pytest.mark.parametrize("value", ["0", "-1", "abc", "nan", "inf"])
def test_bad_time_limit_is_one_line(tmp_path, capsys, value):
    assert main(["solve", "--time-limit", value, "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"cvxdual: error: --time-limit must be a positive number of seconds, got {value!r}"]
    assert not (tmp_path / "o").exists()


def test_python_time_limit_stops_a_long_cvxpy_solve():
    """Level 5 with Clarabel takes about 10 s here; a limit of 0.5 s stops it in its first phases
    (the bound of 5 s leaves room for a loaded machine: without the limit it would run on)."""
    t0 = time.perf_counter()
    with pytest.raises(cd.TimeLimitError, match=r"time limit of 0.5 s during \w+") as e:
        cd.solve("hertz", level=5, solver="CLARABEL", time_limit=0.5)
    assert time.perf_counter() - t0 < 5.0
    assert "time_limit" in str(e.value) and "--time-limit" in e.value.cli
    with pytest.raises(cd.CvxdualError, match="time_limit must be a positive number"):
        cd.solve("patch", level=0, time_limit=-1)


def _run_cli(args, cwd, code=None, timeout=120):
    """``cvxdual`` in a subprocess (the hard stop ends its process), with its wall time."""
    prog = code or "import sys; from cvxdual.cli import main; sys.exit(main(sys.argv[1:]))"
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", prog, *args], cwd=cwd, capture_output=True, text=True,
                       timeout=timeout, env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    return p, time.perf_counter() - t0


def test_cli_time_limit_on_level6_cvxpy_solve(tmp_path):
    """The acceptance: --time-limit 1 on a level-6 CVXPY solve stops within a few seconds (the
    run itself takes over a minute here) with one error line, writing nothing."""
    p, took = _run_cli(["solve", "--level", "6", "--time-limit", "1", "--out", "o"], tmp_path)
    assert p.returncode == 1
    lines = without_progress(p.stderr)
    assert len(lines) == 1 and lines[0].startswith("cvxdual: error: stopped at the time limit of 1 s")
    assert took < 15.0  # interpreter start and imports (2-4 s on a loaded machine) + 1 s + the grace
    assert list(tmp_path.iterdir()) == []


def test_cli_hard_stop_ends_a_solver_that_cannot_be_interrupted(tmp_path):
    """A phase that ignores the alarm (here: SIGALRM blocked, as compiled code that never returns
    to Python effectively does) is ended by the CLI's timer 1 s after the limit, with one line."""
    code = ("import signal, sys, time\n"
            "import cvxdual.pipeline\n"
            "from cvxdual.cli import main\n"
            "def stuck(*a, **k):\n"
            "    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGALRM})\n"
            "    time.sleep(60)\n"
            "cvxdual.pipeline.solve = stuck\n"
            "sys.exit(main(sys.argv[1:]))\n")
    p, took = _run_cli(["solve", "--level", "1", "--time-limit", "0.5", "--out", "o"], tmp_path, code)
    assert p.returncode == 1
    assert p.stderr.strip().splitlines() == [
        "cvxdual: error: stopped at the time limit of 0.5 s inside the solver, which cannot be interrupted there; "
        "raise --time-limit, lower --level or use --solver fast"]
    assert took < 30.0  # far below the 60 s the stuck phase would take
    assert list(tmp_path.iterdir()) == []


def test_progress_phases_are_the_ones_helpers_filter():
    """tests/helpers.without_progress knows every phase the package reports."""
    import inspect

    import cvxdual.cli
    import cvxdual.pipeline
    src = inspect.getsource(cvxdual.pipeline) + inspect.getsource(cvxdual.cli)
    import re
    used = set(re.findall(r'phase\("(\w+)"', src))
    assert used == set(PROGRESS)
