"""Output sets are replaced whole or not at all: no mix of two runs, no stale files, no
temporaries left, foreign files refused and untouched, concurrent writers serialised."""

import ctypes
import errno
import os
import random
import shutil
import signal
import threading
import time
from pathlib import Path

import pytest
from helpers import solved

from cvxdual import files
from cvxdual.errors import OutputError
from cvxdual.outputs.output_set import check_output_dir
from cvxdual.outputs.output_set import write_outputs as write_set


def write_outputs(sol, out, plots=True):
    """The output set with its figures unless told otherwise: the sets replaced here include PNGs."""
    return write_set(sol, out, plots=plots)

A_ARGS, B_ARGS = ("patch", 1), ("patch", 0)


def content(d) -> dict:
    return {p.name: p.read_bytes() for p in Path(d).iterdir()}


@pytest.fixture(scope="module")
def refs(tmp_path_factory):
    """The sets of two solutions (with and without plots), written once into their own directories."""
    root = tmp_path_factory.mktemp("refs")
    out = {}
    for key, args in (("A", A_ARGS), ("B", B_ARGS)):
        for plots in (True, False):
            d = root / f"{key}{'' if plots else '-noplots'}"
            write_outputs(solved(*args), d, plots=plots)
            out[key if plots else f"{key}-noplots"] = content(d)
    assert out["A"] != out["B"] and {"stress.png", "deformed.png", "pressure.png"} <= set(out["A"])
    return out


@pytest.mark.slow
def test_replaced_whole_no_stale_plots(tmp_path, refs):
    out = tmp_path / "o"
    written = write_outputs(solved(*A_ARGS), out)
    assert content(out) == refs["A"] and sorted(p.name for p in written) == sorted(refs["A"])
    write_outputs(solved(*B_ARGS), out, plots=False)  # another scene's set, no plots: no stale PNGs
    assert content(out) == refs["B-noplots"]
    assert os.listdir(tmp_path) == ["o"]


def _half_then_fail(*args, **kwargs):
    path = next(a for a in args if isinstance(a, (str, Path)))  # a method's self comes first
    Path(path).write_bytes(b"half a file")
    raise OSError(errno.ENOSPC, "No space left on device")


@pytest.mark.slow
@pytest.mark.parametrize("target", ["pathlib.Path.write_text", "numpy.savetxt", "meshio.write",
                                    "matplotlib.figure.Figure.savefig"],
                         ids=["summary.json", "contact.csv", "solution.vtu", "plots"])
def test_failure_at_a_file_keeps_the_old_set(tmp_path, refs, monkeypatch, target):
    out = tmp_path / "o"
    write_outputs(solved(*A_ARGS), out)
    monkeypatch.setattr(target, _half_then_fail)
    with pytest.raises(OutputError, match="No space left on device.*nothing was changed in"):
        write_outputs(solved(*B_ARGS), out)
    monkeypatch.undo()
    assert content(out) == refs["A"] and os.listdir(tmp_path) == ["o"]


def test_failure_at_the_swap_keeps_the_old_set(tmp_path, refs, monkeypatch):
    out = tmp_path / "o"
    write_outputs(solved(*A_ARGS), out)

    def refuse(*a):
        raise OSError(errno.EIO, "Input/output error")

    monkeypatch.setattr(files, "exchange", refuse)
    with pytest.raises(OutputError, match="Input/output error.*nothing was changed in"):
        write_outputs(solved(*B_ARGS), out)
    assert content(out) == refs["A"] and os.listdir(tmp_path) == ["o"]


def _no_exchange(monkeypatch):
    """The filesystem refuses RENAME_EXCHANGE (EINVAL), as some do: the fallback path is taken."""
    def renameat2(*a):
        ctypes.set_errno(errno.EINVAL)
        return -1
    monkeypatch.setattr(files, "_RENAMEAT2", renameat2)


@pytest.mark.slow
def test_fallback_without_exchange(tmp_path, refs, monkeypatch):
    _no_exchange(monkeypatch)
    out = tmp_path / "o"
    write_outputs(solved(*A_ARGS), out)
    write_outputs(solved(*B_ARGS), out)
    assert content(out) == refs["B"] and os.listdir(tmp_path) == ["o"]
    # the second rename fails: the first is undone
    real_rename = os.rename

    def rename(src, dst):
        if ".stage-" in str(src):
            raise OSError(errno.EIO, "Input/output error")
        real_rename(src, dst)

    monkeypatch.setattr(os, "rename", rename)
    with pytest.raises(OutputError, match="nothing was changed in"):
        write_outputs(solved(*A_ARGS), out)
    monkeypatch.setattr(os, "rename", real_rename)
    assert content(out) == refs["B"] and os.listdir(tmp_path) == ["o"]


@pytest.mark.slow
def test_failure_after_the_swap_says_so(tmp_path, refs, monkeypatch):
    out = tmp_path / "o"
    write_outputs(solved(*A_ARGS), out)
    real_rmtree = shutil.rmtree

    def rmtree(path, ignore_errors=False, **k):
        if not ignore_errors:
            raise OSError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(shutil, "rmtree", rmtree)
    with pytest.raises(OutputError, match=r"wrote the new set to .*but then failed \(Permission denied\); "
                                          r"the previous set is left in"):
        write_outputs(solved(*B_ARGS), out)
    monkeypatch.setattr(shutil, "rmtree", real_rmtree)
    assert content(out) == refs["B"]
    (left,) = [n for n in os.listdir(tmp_path) if n != "o"]
    assert left.startswith(".o.stage-") and content(tmp_path / left) == refs["A"]
    write_outputs(solved(*A_ARGS), out)  # the next run removes it
    assert content(out) == refs["A"] and os.listdir(tmp_path) == ["o"]


@pytest.mark.slow
def test_leftovers_of_killed_runs_are_swept(tmp_path, refs):
    out = tmp_path / "o"
    write_outputs(solved(*A_ARGS), out)
    (out / ".solution.vtu.k2j4x9.tmp").write_bytes(b"x" * 1000)  # an old-style per-file temporary
    stage = tmp_path / ".o.stage-0123abcd"  # a killed run's half-written set
    stage.mkdir()
    (stage / "solution.vtu").write_bytes(b"half")
    other = tmp_path / ".p.stage-0123abcd"  # another output's: not ours to touch
    other.mkdir()
    write_outputs(solved(*B_ARGS), out)
    assert content(out) == refs["B"] and sorted(os.listdir(tmp_path)) == [".p.stage-0123abcd", "o"]
    # killed between the fallback's two renames: no `o`, the old set aside; the next run puts it back
    os.rename(out, tmp_path / ".o.old-89abcdef")
    assert files.sweep(out) == [".o.old-89abcdef"] and content(out) == refs["B"]
    os.rename(out, tmp_path / ".o.old-89abcdef")
    write_outputs(solved(*A_ARGS), out)
    assert content(out) == refs["A"] and sorted(os.listdir(tmp_path)) == [".p.stage-0123abcd", "o"]


def test_a_live_staging_directory_is_not_swept(tmp_path, refs):
    out = tmp_path / "o"
    with pytest.raises(RuntimeError), files.staged_dir(out) as live:  # a concurrent writer, still writing
        write_outputs(solved(*B_ARGS), out)
        assert live.is_dir() and content(out) == refs["B"]
        raise RuntimeError  # that writer fails: its staging directory goes
    assert os.listdir(tmp_path) == ["o"]


def test_foreign_files_refused_and_untouched(tmp_path, refs):
    out = tmp_path / "o"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    (out / "data").mkdir()
    (out / "summary.json").write_text("{}")
    for call in (check_output_dir, lambda d: write_outputs(solved(*A_ARGS), d)):
        with pytest.raises(OutputError, match=r"'data/', 'notes.txt'.*choose an empty or cvxdual-written --out"):
            call(out)
        assert sorted(os.listdir(out)) == ["data", "notes.txt", "summary.json"]
        assert (out / "notes.txt").read_text() == "mine" and os.listdir(tmp_path) == ["o"]


def test_special_directories_refused(tmp_path, monkeypatch):
    (tmp_path / "f").write_text("x")
    with pytest.raises(OutputError, match="not a directory"):
        check_output_dir(tmp_path / "f")
    with pytest.raises(OutputError, match="filesystem root"):
        check_output_dir("/")
    monkeypatch.chdir(tmp_path)
    for d in (".", tmp_path.parent):
        with pytest.raises(OutputError, match="current directory"):
            check_output_dir(d)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    (tmp_path / "home").mkdir()
    with pytest.raises(OutputError, match="home directory"):
        check_output_dir(tmp_path / "home")
    assert check_output_dir(tmp_path / "new") == tmp_path.resolve() / "new"
    assert sorted(os.listdir(tmp_path)) == ["f", "home"]


def test_a_symlinked_output_directory_is_followed(tmp_path, refs):
    (tmp_path / "real").mkdir()
    (tmp_path / "link").symlink_to("real")
    write_outputs(solved(*A_ARGS), tmp_path / "link")
    assert (tmp_path / "link").is_symlink() and content(tmp_path / "real") == refs["A"]
    assert sorted(os.listdir(tmp_path)) == ["link", "real"]


def test_concurrent_writers_end_with_one_complete_set(tmp_path, refs):
    out = tmp_path / "o"
    barrier = threading.Barrier(4)
    errors = []

    def run(args):
        try:
            barrier.wait()
            for _ in range(5):
                write_outputs(solved(*args), out, plots=False)
        except Exception as e:  # noqa: BLE001 - collected for the assert
            errors.append(e)

    threads = [threading.Thread(target=run, args=(a,)) for a in (A_ARGS, B_ARGS, A_ARGS, B_ARGS)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    assert content(out) in (refs["A-noplots"], refs["B-noplots"]) and os.listdir(tmp_path) == ["o"]


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs fork")
def test_kill_during_write_leaves_old_or_new_set(tmp_path, refs):
    """kill -9 of a writer at random moments: always set A or set B; the next run leaves nothing
    else (short writes, so the kills often fall near the swap; the experiment at level 6:
    studies/kill_write.py)."""
    out = tmp_path / "o"
    write_outputs(solved(*A_ARGS), out, plots=False)
    t = time.perf_counter()
    write_outputs(solved(*A_ARGS), out, plots=False)
    duration = time.perf_counter() - t
    rng = random.Random(13)
    for i in range(10):
        pid = os.fork()
        if pid == 0:  # the child writes set B and never returns into pytest
            try:
                write_outputs(solved(*B_ARGS), out, plots=False)
            finally:
                os._exit(0)
        time.sleep(rng.uniform(0, 1.1 * duration))
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        assert content(out) in (refs["A-noplots"], refs["B-noplots"]), f"trial {i}: a mixed set"
        write_outputs(solved(*A_ARGS), out, plots=False)  # the next run
        assert content(out) == refs["A-noplots"] and os.listdir(tmp_path) == ["o"]


def test_cli_refuses_a_foreign_directory(tmp_path, capsys):
    from cvxdual.cli import main
    out = tmp_path / "o"
    out.mkdir()
    (out / "thesis.tex").write_text("mine")
    assert main(["solve", "--scene", "patch", "--level", "0", "--out", str(out), "--no-plots"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("cvxdual: error: refusing to write outputs") and len(err.strip().splitlines()) == 1
    assert "'thesis.tex'" in err and "choose an empty or cvxdual-written --out" in err
    assert os.listdir(out) == ["thesis.tex"] and os.listdir(tmp_path) == ["o"]


def _stages(parent: Path) -> list[str]:
    return sorted(n for n in os.listdir(parent) if n.startswith(".o.stage-") or n.startswith(".o.old-"))


def test_leftovers_go_when_a_run_starts_writing(tmp_path):
    """Issue 26: killed runs' staging directories went only after a completed run; now each run
    removes them before it adds its own, and the CLI before its solve."""
    out = tmp_path / "o"
    for i in range(3):
        (tmp_path / f".o.stage-0000000{i}").mkdir()
        (tmp_path / f".o.stage-0000000{i}" / "solution.vtu").write_bytes(b"half")
    with files.staged_dir(out) as stage:
        assert _stages(tmp_path) == [stage.name]  # before anything of this run is written
    # a run that ended without its swap left its directory; the CLI's sweep before a solve takes it
    assert files.sweep_leftovers(out) == [stage.name] and _stages(tmp_path) == []
    assert files.sweep_leftovers(tmp_path / "missing" / "o") == []  # no parent: nothing to sweep


@pytest.mark.skipif(not hasattr(os, "fork") or files.fcntl is None, reason="fork and flock (POSIX)")
def test_kills_in_a_row_leave_one_staging_directory(tmp_path):
    """Writers killed (SIGKILL) while filling their staging directory, six in a row with no
    completed run between them: at most one staging directory at any time (the last one killed,
    or the live writer's own), polled while each writer runs."""
    out = tmp_path / "o"
    most = 0
    for _ in range(6):
        r, w = os.pipe()
        pid = os.fork()
        if pid == 0:  # a writer that is killed half-way through its set
            try:
                os.close(r)
                with files.staged_dir(out) as stage:
                    (stage / "solution.vtu").write_bytes(b"half a set")
                    os.write(w, b"x")
                    time.sleep(60)
            finally:
                os._exit(1)
        os.close(w)
        most = max(most, len(_stages(tmp_path)))
        assert os.read(r, 1) == b"x"  # the writer has its staging directory
        os.close(r)
        most = max(most, len(_stages(tmp_path)))
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        most = max(most, len(_stages(tmp_path)))
    assert most == 1 and len(_stages(tmp_path)) == 1
    files.sweep_leftovers(out)  # the next run (here: the CLI's sweep before its solve)
    assert _stages(tmp_path) == []
