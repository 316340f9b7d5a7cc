"""Progress lines as the work happens, the time limit, --quiet, --verbose and --version."""

import logging
import os
import signal
import subprocess
import sys
import threading
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


@pytest.mark.slow
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
    assert "cvxdual: build: " in err and "CLARABEL: optimal, iterations " in err
    assert "which the summary counts as build" in err  # the progress and the summary split the time alike


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


@pytest.mark.parametrize("value", ["0", "-1", "abc", "nan", "inf", "1e12"])
def test_bad_time_limit_is_one_line(tmp_path, capsys, value):
    assert main(["solve", "--time-limit", value, "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"cvxdual: error: --time-limit must be a positive number of seconds up to 1e+06, got {value!r}"]
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
    with pytest.raises(cd.TimeLimitError, match="lower the level;|lower the level$"):  # no "use the fast path"
        cd.solve("hertz", level=5, solver="fast", time_limit=1e-3)


def _alarm_state():
    return signal.getsignal(signal.SIGALRM), signal.getitimer(signal.ITIMER_REAL)


def test_alarm_is_disarmed_after_every_run():
    """solve() leaves no alarm handler or timer behind, whether it finished or timed out."""
    clean = (signal.SIG_DFL, (0.0, 0.0))
    cd.solve("patch", level=1, solver="fast", time_limit=60)
    assert _alarm_state() == clean
    with pytest.raises(cd.TimeLimitError):
        cd.solve("hertz", level=5, solver="CLARABEL", time_limit=0.2)
    assert _alarm_state() == clean


@pytest.mark.slow
def test_time_limit_in_another_thread_is_a_time_limit_error():
    """No alarm outside the main thread: the deadline is checked as phases end and Clarabel gets
    what is left (after CVXPY's compile), and its time-out is reported as the run's time limit,
    not as a solver failure (the run takes about 10 s without the limit)."""
    out = {}

    def work():
        try:
            cd.solve("hertz", level=5, solver="CLARABEL", time_limit=1.0)
        except Exception as e:  # noqa: BLE001 - the test looks at what came out
            out["error"] = e

    t = threading.Thread(target=work)
    t.start()
    t.join(120)
    assert isinstance(out.get("error"), cd.TimeLimitError), out
    assert "time limit of 1 s during" in str(out["error"])


def test_failing_import_check_under_the_alarm_is_not_cached(monkeypatch):
    """The alarm is a BaseException past `except Exception` sinks: a cached backend check that it
    interrupts is not cached as 'not available' (that would slow every later solve)."""
    from cvxdual.linalg import factor
    from cvxdual.progress import Deadline

    factor._has_cholmod.cache_clear()  # noqa: SLF001 - the cache under test
    real_import = __import__

    def slow_import(name, *args, **kwargs):
        if name == "cvxopt.cholmod":
            time.sleep(1.0)  # the alarm goes off here
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr("builtins.__import__", slow_import)
    with pytest.raises(cd.TimeLimitError), Deadline(0.1).enforced():
        factor._has_cholmod()  # noqa: SLF001
    monkeypatch.undo()
    assert factor._has_cholmod.cache_info().currsize == 0  # noqa: SLF001 - nothing was cached
    factor._has_cholmod.cache_clear()  # noqa: SLF001


def test_cli_logging_is_restored_and_not_duplicated(capsys):
    """main() prints its progress once, even under a caller's root handler, and leaves the
    logger as it found it."""
    log = logging.getLogger("cvxdual")
    before = (log.level, log.propagate, list(log.handlers))
    root = Recorder()
    logging.getLogger().addHandler(root)
    try:
        for _ in range(2):
            assert main(["solve", "--scene", "patch", "--level", "0", "--no-output"]) == 0
    finally:
        logging.getLogger().removeHandler(root)
    assert root.records == []
    assert capsys.readouterr().err.count("cvxdual: mesh: ") == 2
    assert (log.level, log.propagate, list(log.handlers)) == before


def _run_cli(args, cwd, code=None, timeout=120):
    """``cvxdual`` in a subprocess (the hard stop ends its process), with its wall time."""
    prog = code or "import sys; from cvxdual.cli import main; sys.exit(main())"  # the console script's call
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", prog, *args], cwd=cwd, capture_output=True, text=True,
                       timeout=timeout, env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    return p, time.perf_counter() - t0


@pytest.mark.slow
def test_cli_time_limit_on_level6_cvxpy_solve(tmp_path):
    """The acceptance: --time-limit 1 on a level-6 CVXPY solve stops within a few seconds (the
    run itself takes over a minute here) with one error line, writing nothing."""
    p, took = _run_cli(["solve", "--level", "6", "--time-limit", "1", "--max-memory", "none", "--out", "o"], tmp_path)
    assert p.returncode == 1
    lines = without_progress(p.stderr)
    assert len(lines) == 1 and lines[0].startswith("cvxdual: error: stopped at the time limit of 1 s")
    assert took < 15.0  # interpreter start and imports (2-4 s on a loaded machine) + 1 s + the grace
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
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
            "sys.exit(main())\n")
    p, took = _run_cli(["solve", "--level", "1", "--time-limit", "0.5", "--out", "o"], tmp_path, code)
    assert p.returncode == 1
    assert p.stderr.strip().splitlines() == [
        "cvxdual: error: stopped at the time limit of 0.5 s inside compiled code (a solver or a factorisation), "
        "which cannot be interrupted; raise --time-limit, lower --level or use --solver fast"]
    assert took < 30.0  # far below the 60 s the stuck phase would take
    assert list(tmp_path.iterdir()) == []


def test_progress_phases_are_the_ones_helpers_filter():
    """tests/helpers.without_progress knows every phase the package reports."""
    import re
    from pathlib import Path

    import cvxdual
    src = "".join(p.read_text() for p in Path(cvxdual.__file__).parent.rglob("*.py"))
    used = set(re.findall(r'phase\("(\w+)"', src))
    assert used == set(PROGRESS)
