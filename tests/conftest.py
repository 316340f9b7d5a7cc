"""Shared fixtures: a local Dask cluster configured as the study runner configures its own.

The tests leave no files in the repository's working tree: outputs go to ``tmp_path``,
Hypothesis keeps its files in a temporary directory, pytest no cache (``-p no:cacheprovider`` in
pyproject.toml), and the session fails if anything else appeared (``git status``).
"""

import contextlib
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
from hypothesis.configuration import set_hypothesis_home_dir

ROOT = Path(__file__).resolve().parents[1]
# the project's study code (fuzzing, peers, specs) lives beside the tests, outside the package
sys.path.insert(0, str(ROOT / "studies"))
# Hypothesis keeps its example database and constants under .hypothesis/ of the working directory
HYPOTHESIS_HOME = tempfile.mkdtemp(prefix="cvxdual-tests-hypothesis-")
set_hypothesis_home_dir(HYPOTHESIS_HOME)
LEFT_ALONE = ("__pycache__", ".venv", ".ruff_cache")  # bytecode and lint caches; the environment the tests run in
_BEFORE = pytest.StashKey[set | None]()


def _tree_entries() -> set[str] | None:
    """Changed, untracked and ignored entries of the working tree, with their status (``None``
    outside a git checkout)."""
    try:
        p = subprocess.run(["git", "status", "--porcelain", "--ignored", "--untracked-files=all"], cwd=ROOT,
                           capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.SubprocessError):
        return None
    if p.returncode:
        return None
    return {line for line in p.stdout.splitlines() if not any(part in LEFT_ALONE for part in Path(line[3:]).parts)}


def pytest_sessionstart(session):
    session.config.stash[_BEFORE] = _tree_entries()


def pytest_sessionfinish(session, exitstatus):
    shutil.rmtree(HYPOTHESIS_HOME, ignore_errors=True)
    before = session.config.stash.get(_BEFORE, None)
    after = _tree_entries() if before is not None else None
    if after is not None and after - before:
        new = sorted(after - before)
        session.config.get_terminal_writer().line(
            f"the tests changed the working tree (git status): {', '.join(new[:10])}", red=True)
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


@contextlib.contextmanager
def local_client(memory_limit: str):
    import dask
    from distributed import Client, LocalCluster

    from cvxdual.study.runner import local_config
    with dask.config.set(local_config()):
        cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, memory_limit=memory_limit,
                               dashboard_address=":0", silence_logs=50)
    cl = Client(cluster)
    try:
        yield cl
    finally:
        cl.close()
        cluster.close()


@pytest.fixture(scope="module")
def client(request):
    """A two-worker local cluster; a module sets ``CLUSTER_MEMORY`` to change the per-worker limit."""
    with local_client(getattr(request.module, "CLUSTER_MEMORY", "2GB")) as cl:
        yield cl
