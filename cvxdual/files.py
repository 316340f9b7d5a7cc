"""Files and directories written whole or not at all, and the one conversion of results to JSON.

Every file cvxdual writes goes through :func:`atomic_path`: it is written to a temporary
file in the same directory and renamed into place, so a crash leaves the old file or none,
never half a file.

A set of files that belong together (a directory) is written with :func:`staged_dir` and
:func:`replace_dir`: the new set is written into a hidden staging directory beside the target,
``.NAME.stage-XXXXXXXX`` (same parent, so same filesystem), flushed to disk, and swapped in by
one atomic step, so readers and crashes see the old set or the new one, never a mix:

- target missing: one ``rename``;
- target present, Linux: ``renameat2(RENAME_EXCHANGE)`` swaps the two names atomically, then the
  old set (now under the staging name) is removed;
- elsewhere (other OS, old kernel, a filesystem without the exchange): rename the target to
  ``.NAME.old-XXXXXXXX``, the staging directory to the target, remove the old set. A crash
  between the two renames leaves no target for a moment; the next run puts the old set back.

Leftovers of killed runs (``.NAME.stage-*``, ``.NAME.old-*``) are swept by every run of the same
NAME as it starts writing (before it creates its own staging directory, so killed runs in a row
leave one behind, never a pile) and again at its swap; other names' are left alone
(:func:`sweep_leftovers` sweeps on request, e.g. before a long solve). Writers of one parent
directory are serialised by an exclusive ``flock`` on the parent directory itself (no lock file),
held while a staging directory is created and for the sweep and the swap, not while files are
written. A staging directory is ``flock``-ed by its writer from its creation until the swap, so a
concurrent run's sweep leaves it alone; the kernel drops that lock when its writer dies, so a
killed run's is swept. Where ``flock`` is unavailable (no ``fcntl``: Windows) there is no
exclusion and the sweep takes every leftover but the caller's own.
"""

from __future__ import annotations

import ctypes
import errno
import json
import math
import os
import re
import secrets
import shutil
import sys
import tempfile
from collections.abc import Mapping
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from .errors import OutputError

try:
    import fcntl
except ImportError:  # Windows
    fcntl = None

_UMASK = os.umask(0)
os.umask(_UMASK)


def temp_beside(path: str | Path) -> Path:
    """A new empty temporary file in ``path``'s directory, hidden and named after it."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600; give the usual permissions
    return Path(tmp)


@contextmanager
def atomic_path(path: str | Path):
    """Yield a temporary path next to ``path``; on success rename it to ``path``, on failure
    remove it."""
    tmp = temp_beside(path)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _load_renameat2():
    if sys.platform != "linux":
        return None
    f = getattr(ctypes.CDLL(None, use_errno=True), "renameat2", None)  # glibc >= 2.28
    if f is not None:
        f.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
        f.restype = ctypes.c_int
    return f


_RENAMEAT2 = _load_renameat2()
_RENAME_EXCHANGE = 2
HAS_EXCHANGE = _RENAMEAT2 is not None  # the atomic swap is available (else two renames)


def exchange(dirfd: int, a: str, b: str) -> bool:
    """Swap the entries ``a`` and ``b`` of directory ``dirfd`` atomically; False where the
    system or the filesystem cannot (then nothing was done)."""
    if _RENAMEAT2 is None:
        return False
    if _RENAMEAT2(dirfd, os.fsencode(a), dirfd, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.EOPNOTSUPP):
        return False
    raise OSError(err, os.strerror(err), b)


def _flock(fd: int | None, block: bool = True) -> bool:
    """Take an exclusive flock on ``fd``: False if another holder has it (``block`` false);
    True also where flock is not available (nothing to respect then)."""
    if fcntl is None or fd is None:
        return True
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | (0 if block else fcntl.LOCK_NB))
    except BlockingIOError:
        return False
    except OSError as e:  # e.g. NFS without flock on directories
        if e.errno not in (errno.EBADF, errno.ENOLCK, errno.EOPNOTSUPP, errno.EINVAL):
            raise
    return True


def _open_dir(path) -> int | None:
    """A descriptor of directory ``path`` to lock (None where directories cannot be opened: Windows)."""
    return None if fcntl is None else os.open(path, os.O_RDONLY)


@contextmanager
def _locked(directory):
    """Hold an exclusive lock on ``directory`` (no lock file: the directory itself is locked)."""
    fd = _open_dir(directory)
    try:
        _flock(fd)
        yield fd
    finally:
        if fd is not None:
            os.close(fd)  # releases the lock


def _fsync(path: Path) -> None:
    if os.name == "nt" and path.is_dir():
        return  # Windows cannot open a directory
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    except OSError:
        if not path.is_dir():  # some filesystems cannot fsync a directory: nothing more to do there
            raise
    finally:
        os.close(fd)


def _leftover(name: str, out_name: str) -> str | None:
    """``"stage"`` or ``"old"`` if ``name`` is a leftover directory of target ``out_name``."""
    m = re.fullmatch(rf"\.{re.escape(out_name)}\.(stage|old)-[0-9a-f]{{8}}", name)
    return m and m.group(1)


@contextmanager
def staged_dir(out: str | Path):
    """Yield a new empty hidden directory beside ``out`` to fill and give to :func:`replace_dir`
    (inside the ``with``); it is locked while the block runs and removed if the block fails."""
    out = Path(out)
    with _locked(out.parent):  # created and locked at once: a concurrent sweep never sees it unlocked
        sweep(out)  # killed runs' leftovers go before this run adds its own
        while True:
            stage = out.parent / f".{out.name}.stage-{secrets.token_hex(4)}"
            try:
                os.mkdir(stage)
                break
            except FileExistsError:
                continue
        fd = _open_dir(stage)
        _flock(fd)
    try:
        yield stage
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    finally:
        if fd is not None:
            os.close(fd)


def sweep(out: str | Path, keep: str | None = None) -> list[str]:
    """Remove the leftovers of killed runs writing ``out`` (call under the parent's lock): staging
    directories no live writer holds, except ``keep`` (the caller's), and old sets (put back first
    if ``out`` is missing). Returns the names removed or restored."""
    out = Path(out)
    done = []
    for name in sorted(os.listdir(out.parent)):
        kind = _leftover(name, out.name) if name != keep else None
        p = out.parent / name
        if kind == "old" and not os.path.lexists(out):
            os.rename(p, out)  # killed between the fallback's two renames: the old set comes back
        elif kind == "old":
            shutil.rmtree(p)
        elif kind == "stage":
            fd = _open_dir(p)
            try:
                if not _flock(fd, block=False):
                    continue  # a live writer is still filling it
                shutil.rmtree(p)
            finally:
                if fd is not None:
                    os.close(fd)
        else:
            continue
        done.append(name)
    return done


def sweep_leftovers(out: str | Path) -> list[str]:
    """:func:`sweep` under the parent directory's lock (nothing to do if the parent is missing)."""
    out = Path(out)
    if not out.parent.is_dir():
        return []
    try:
        with _locked(out.parent):
            return sweep(out)
    except OSError as e:
        where = repr(e.filename) if e.filename else f"beside {str(out)!r}"
        raise OutputError(f"cannot remove what a killed run left in {where} ({e.strerror or e}); remove it "
                          "yourself or choose another output directory") from None


def replace_dir(stage: str | Path, out: str | Path, check=None) -> None:
    """Make the filled staging directory ``stage`` (from :func:`staged_dir`) the directory
    ``out``, atomically, removing the previous ``out``. Under an exclusive lock on the parent:
    sweep leftovers of killed runs, call ``check(out)`` (if ``out`` exists; it raises to refuse),
    swap. An error raised before the swap changed nothing in ``out``; a problem after it raises
    :class:`OutputError` saying that the new set is in place and what is left."""
    stage, out = Path(stage), Path(out)
    for f in stage.iterdir():
        _fsync(f)
    _fsync(stage)
    with _locked(out.parent) as pfd:
        sweep(out, keep=stage.name)
        if check is not None and os.path.lexists(out):
            check(out)
        if not os.path.lexists(out):
            os.rename(stage, out)
            old = None
        elif pfd is not None and exchange(pfd, stage.name, out.name):
            old = stage  # the previous set, now under the staging name
        else:
            old = out.parent / f".{out.name}.old-{secrets.token_hex(4)}"
            os.rename(out, old)
            try:
                os.rename(stage, out)
            except BaseException as e:
                try:
                    os.rename(old, out)
                except OSError:
                    raise OutputError(f"cannot move the new set to {str(out)!r} ({e}); the previous set is in "
                                      f"{str(old)!r}, the next run puts it back") from None
                raise
        try:
            _fsync(out.parent)  # make the swap itself durable
            if old is not None:
                shutil.rmtree(old)
        except OSError as e:
            what = f"{e.strerror or e}: {e.filename!r}" if e.filename else f"{e.strerror or e}"
            left = f"; the previous set is left in {str(old)!r}, the next run removes it" if old else ""
            raise OutputError(f"wrote the new set to {str(out)!r}, but then failed ({what}){left}") from None


def to_jsonable(obj):
    """Plain Python for JSON: NumPy scalars and arrays converted, non-finite floats as ``None``,
    anything else that JSON cannot hold as its ``str``."""
    if isinstance(obj, Mapping):  # dicts and the frozen records (cvxdual.records)
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if obj is None or isinstance(obj, (str, int)):
        return obj
    return str(obj)


def json_text(data) -> str:
    return json.dumps(to_jsonable(data), indent=2) + "\n"


def write_text(path: str | Path, text: str) -> Path:
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return Path(path)


def write_json(path: str | Path, data) -> Path:
    return write_text(path, json_text(data))
