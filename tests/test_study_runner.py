"""The study runner on Dask: the acceptance scenario (a user's scene, 2 triangulations x 4 levels
x 2 nu) on a local cluster, on a separately started scheduler with two workers, and resumed
after the CLI is killed halfway; failed and killed cases become rows. One local cluster is
shared by the tests of this module."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from cvxdual.cli import main
from cvxdual.study import run
from cvxdual.study.cases import REQUIRED

SCENE = """\
name = "my_hertz"
description = "a small Hertz contact of my own"
base = "hertz"
[mesh]
columns = 4
[bodies.cylinder]
layers = 2
[bodies.block]
layers = 2
"""
SPEC = """\
name = "acceptance"
title = "My scene under refinement"
scenes = ["my_scene.toml"]
triangulations = ["type1", "type2"]
levels = [0, 1, 2, 3]
reference = "exact"
[set]
"bodies.cylinder.material.nu" = [0.3, 0.4]
"""
FIGURES = ["error_l2_rel", "error_energy_rel", "n_pieces", "h"]
ORDER = ["overrides", "triangulation", "level"]


CLUSTER_MEMORY = "1.5GB"  # per worker (conftest.client); small enough for the out-of-memory case


def _write_spec(d: Path, extra: str = "", name: str = "acceptance") -> Path:
    (d / "my_scene.toml").write_text(SCENE)
    p = d / f"{name}.toml"
    p.write_text(extra + SPEC.replace('name = "acceptance"', f'name = "{name}"'))
    return p


@pytest.fixture(scope="module")
def clean_run(client, tmp_path_factory):
    d = tmp_path_factory.mktemp("acceptance")
    spec = _write_spec(d)
    df = run(spec, d / "out", client=client, cache=d / "cache", quiet=True)
    return d, spec, df


def _figures(df: pd.DataFrame) -> pd.DataFrame:
    return df.sort_values(ORDER)[ORDER + FIGURES].reset_index(drop=True)


@pytest.mark.slow
def test_local_cluster(clean_run, client):
    d, spec, df = clean_run
    assert len(df) == 2 * 4 * 2 and set(REQUIRED) <= set(df.columns)
    assert (df.status == "optimal").all() and not df.cached.any()
    assert set(df.overrides) == {"bodies.cylinder.material.nu=0.3", "bodies.cylinder.material.nu=0.4"}
    assert set(df.worker) <= set(client.scheduler_info()["workers"])
    for _, g in df.groupby(["overrides", "triangulation"]):
        e = g.sort_values("level").error_l2_rel.to_numpy()
        assert (e[1:] < e[:-1]).all()
    written = pd.read_csv(d / "out" / "acceptance.csv")
    # the CSV keeps 6 significant digits
    pd.testing.assert_frame_equal(_figures(written), _figures(df), check_dtype=False, rtol=1e-5)
    text = (d / "out" / "acceptance.md").read_text()
    assert "## Fitted rates" in text and "bodies.cylinder.material.nu=0.4" in text
    for f in ("acceptance_h.png", "acceptance_time.png"):
        assert (d / "out" / f).stat().st_size > 1000
    # a rerun takes every row from the cache, with the same figures
    again = run(spec, None, client=client, cache=d / "cache", quiet=True)
    assert again.cached.all()
    pd.testing.assert_frame_equal(_figures(again), _figures(df), check_dtype=False)


def _dask(*args) -> list[str]:
    exe = Path(sys.executable).with_name("dask")
    return [str(exe), *args] if exe.exists() else [sys.executable, "-m", "dask", *args]


@pytest.fixture
def scheduler(tmp_path):
    """A separately started `dask scheduler` and two `dask worker` processes (loopback only)."""
    f = tmp_path / "scheduler.json"
    procs = []
    kw = dict(stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp_path, start_new_session=True)
    try:
        procs.append(subprocess.Popen(_dask("scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                            "--scheduler-file", str(f)), **kw))
        for _ in range(2):
            procs.append(subprocess.Popen(_dask("worker", "--scheduler-file", str(f), "--nthreads", "1",
                                                "--nworkers", "1", "--host", "127.0.0.1", "--no-dashboard",
                                                "--memory-limit", "1.5GB"), **kw))
        from distributed import Client
        t0 = time.monotonic()
        while not f.exists():
            assert time.monotonic() - t0 < 30, "the dask scheduler did not start"
            time.sleep(0.05)
        with Client(scheduler_file=str(f), timeout="20s") as c:
            c.wait_for_workers(2, timeout=40)
            address = c.scheduler.address
        assert address.startswith("tcp://127.0.0.1:")
        yield address
    finally:
        for p in reversed(procs):
            try:
                os.killpg(p.pid, signal.SIGKILL)  # each process group: a dask process and its children
            except ProcessLookupError:
                pass
            p.wait()


@pytest.mark.slow
def test_separate_scheduler_two_workers(scheduler, clean_run, tmp_path, capsys):
    spec = _write_spec(tmp_path)
    out = tmp_path / "out"
    assert main(["study", "run", str(spec), "--scheduler", scheduler, "--out", str(out), "--cache",
                 str(tmp_path / "cache"), "--quiet"]) == 0
    assert "16 cases, 16 solved" in capsys.readouterr().out
    df = pd.read_csv(out / "acceptance.csv")
    assert df.worker.nunique() == 2 and (df.status == "optimal").all()
    pd.testing.assert_frame_equal(_figures(df), _figures(clean_run[2]), check_dtype=False, rtol=1e-5)  # 6 digits


SLOW = """\
import time


def measure(case, solution):
    time.sleep(0.25)
    return {"slept": 0.25}
"""


@pytest.mark.slow
def test_resume_after_kill(client, clean_run, tmp_path):
    (tmp_path / "slow.py").write_text(SLOW)
    spec = _write_spec(tmp_path, 'hooks = "slow.py"\n')
    cache = tmp_path / "cache"
    rows = cache / "rows"
    cmd = [sys.executable, "-m", "cvxdual.cli", "study", "run", str(spec), "--workers", "1", "--out",
           str(tmp_path / "out"), "--cache", str(cache), "--quiet", "--memory-limit", "1GB"]
    p = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                         start_new_session=True)
    try:
        t0 = time.monotonic()
        while len(list(rows.glob("*.json"))) < 4:
            assert p.poll() is None, "the study ended before it could be killed"
            assert time.monotonic() - t0 < 60
            time.sleep(0.02)
    finally:
        os.killpg(p.pid, signal.SIGKILL)  # the CLI and its local cluster's processes
        p.wait()
    done = len(list(rows.glob("*.json")))
    assert 4 <= done < 16 and not (tmp_path / "out" / "acceptance.csv").exists()
    df = run(spec, tmp_path / "out", client=client, cache=cache, quiet=True)
    assert int(df.cached.sum()) == done and int((~df.cached).sum()) == 16 - done
    assert (df.slept == 0.25).all()
    pd.testing.assert_frame_equal(_figures(df), _figures(clean_run[2]), check_dtype=False, rtol=1e-5)  # 6 digits


HOOKS = """\
import os
import numpy as np


def measure(case, solution):
    if case.name == "oom":
        a = np.ones(int(3e9) // 8)  # beyond the worker's memory limit
        return {"never": float(a.sum())}
    return {}
"""


@pytest.mark.slow
def test_finer_reference_compare_and_failures(client, tmp_path):
    """A finer-level reference, two paths compared, a solver failure and an out-of-memory case:
    every case is a row, failures say why."""
    (tmp_path / "hooks.py").write_text(HOOKS)
    (tmp_path / "groove.toml").write_text('name = "groove"\nbase = "cylinder-in-groove"\n[mesh]\ncolumns = 3\n')
    spec = {
        "name": "mixed", "hooks": "hooks.py", "scenes": ["groove.toml"], "levels": [0, 1],
        "triangulations": ["type2"], "reference": {"level": 3}, "compare": ["CLARABEL", "fast"],
        "cases": [
            {"name": "paths", "solvers": ["CLARABEL", "fast"]},
            {"name": "too few iterations", "solvers": ["OSQP"], "levels": [1],
             "solver_options": {"OSQP": {"max_iter": 2}}},
            {"name": "oom", "solvers": ["fast"], "levels": [0]},
        ],
    }
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        df = run(spec, None, client=client, cache=None, quiet=True)
    finally:
        os.chdir(cwd)
    paths = df[df.case == "paths"]
    # Clarabel (gaps ~1e-8) against the exact active set: ~1e-7 measured, 6e-6 at worst in reports/stability.md
    assert (paths.status == "optimal").all() and paths.paths_agree_l2_rel.max() < 1e-5
    assert paths.reference.unique().tolist() == ["type2 level 3"]
    assert (paths.reference_error_est > 0).all() and (paths.error_l2_rel > paths.reference_error_est).all()
    osqp = df[df.case == "too few iterations"].iloc[0]
    assert osqp.status.startswith("failed: SolverError") and "OSQP" in osqp.status
    oom = df[df.case == "oom"].iloc[0]
    assert oom.status.startswith("killed:") and "memory" in oom.status


def test_workers_drop_the_heartbeat_race_and_nothing_else():
    """The local cluster's workers drop dask's shutdown-race line (a heartbeat meeting the stream the
    retiring scheduler closed; its traceback broke the docs test) and log every other error."""
    import logging

    from cvxdual.study.runner import HEARTBEAT_RACE, heartbeat_race_plugin

    log = logging.getLogger("distributed.worker")
    before = list(log.filters)
    seen = []

    class Keep(logging.Handler):
        def emit(self, record):
            seen.append(record.getMessage())

    handler = Keep()
    log.addHandler(handler)
    try:
        heartbeat_race_plugin().setup(worker=None)
        log.error(HEARTBEAT_RACE)
        log.error("Unexpected exception during heartbeat. Closing worker.")
    finally:
        log.removeHandler(handler)
        log.filters[:] = before
    assert seen == ["Unexpected exception during heartbeat. Closing worker."]
