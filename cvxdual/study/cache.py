"""The study cache: checked entries keyed by content, so an interrupted study resumes.

Entries are untrusted. A row is a JSON file ``rows/KEY.json`` holding its format, its own key
and a SHA-256 checksum of its canonical JSON; arrays are ``arrays/KEY.npz`` of float arrays with
a metadata record (format, key, shapes, dtypes, checksums). Reading an entry is one function
per kind (:func:`read_row`, :func:`read_arrays`: they raise on anything wrong) and one place,
:meth:`Cache._load`, where any failure to load or check means "not cached": the entry is
recomputed, then overwritten, never used and never a traceback. Callers add the checks of what
the entry must be for them (``required``/``shapes`` and a ``check`` callable: the types and
identity of a row, the mesh size of a reference, a nonzero norm). Every file is written
atomically. Workers read and write reference arrays here: with a remote scheduler the cache
directory must be on a filesystem shared by the client and every worker.
"""

from __future__ import annotations

import hashlib
import json
import math
import shutil
from pathlib import Path

import numpy as np

from ..files import atomic_path, write_text
from ..files import to_jsonable as clean

ROW_FORMAT = "cvxdual-study-row/1"
ARRAY_FORMAT = "cvxdual-study-arrays/1"


def code_version() -> str:
    """A hash of the package's code (every ``cvxdual/**/*.py``, the study code included) and of
    the versions of the libraries that compute the numbers: cached results are reused only by
    the code and solvers that produced them."""
    from importlib.metadata import PackageNotFoundError, version
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for f in sorted(root.rglob("*.py")):
        h.update(str(f.relative_to(root)).encode())
        h.update(f.read_bytes())
    for dist in ("numpy", "scipy", "cvxpy", "clarabel", "pypardiso"):
        try:
            h.update(f"{dist}=={version(dist)}".encode())
        except PackageNotFoundError:
            h.update(f"{dist} absent".encode())
    return h.hexdigest()[:16]


def content_key(*parts) -> str:
    """A stable hash of ``parts`` (reprs of frozen dataclasses and plain values)."""
    return hashlib.sha256(repr(parts).encode()).hexdigest()[:24]


def _digest(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def _array_digest(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()


class BadEntryError(Exception):
    """A cache entry that fails a check (caught by :meth:`Cache._load`: the entry is not cached)."""


def _ensure(ok) -> None:
    if not ok:
        raise BadEntryError


def _finite_float(text: str) -> float:
    v = float(text)
    _ensure(math.isfinite(v))  # 1e999 parses as inf: rows never hold non-finite numbers (None instead)
    return v


def _no_constant(name: str):
    raise BadEntryError(name)  # NaN, Infinity, -Infinity


def read_row(path: Path, key: str) -> dict:
    """The row in ``path`` (raises unless it is a row entry of ``key`` with a matching checksum)."""
    d = json.loads(path.read_text(encoding="utf-8"), parse_float=_finite_float, parse_constant=_no_constant)
    _ensure(isinstance(d, dict))
    row = d.get("row")
    _ensure(d.get("format") == ROW_FORMAT and d.get("key") == key and isinstance(row, dict)
            and d.get("checksum") == _digest(row))
    return row


def read_arrays(path: Path, key: str) -> dict:
    """The arrays in ``path`` (raises unless it is an arrays entry of ``key`` whose float arrays
    have the recorded names, shapes, dtypes and checksums, and finite values). Never unpickles."""
    with np.load(path, allow_pickle=False) as z:  # (an .npy file loads as an array: no context manager)
        _ensure(isinstance(z, np.lib.npyio.NpzFile) and "__meta__" in z.files)
        meta = json.loads(str(z["__meta__"]))
        arrays = {k: z[k] for k in z.files if k != "__meta__"}
    _ensure(isinstance(meta, dict) and meta.get("format") == ARRAY_FORMAT and meta.get("key") == key)
    rec = meta.get("arrays")
    _ensure(isinstance(rec, dict) and set(rec) == set(arrays))
    for name, a in arrays.items():
        m = rec[name]
        _ensure(isinstance(m, dict) and a.dtype.kind == "f" and list(a.shape) == m.get("shape")
                and str(a.dtype) == m.get("dtype") and _array_digest(a) == m.get("sha256")
                and np.all(np.isfinite(a)))
    return arrays


def has_shapes(arrays: dict, shapes: dict) -> bool:
    """Whether ``arrays`` has every array of ``shapes`` (``{name: shape}``, ``-1`` for any size)."""
    for name, shape in shapes.items():
        a = arrays.get(name)
        if a is None or a.ndim != len(shape) or any(s not in (-1, n) for s, n in zip(shape, a.shape, strict=True)):
            return False
    return True


def is_key(key) -> bool:
    """A content key as the cache writes them: ASCII letters and digits only (never a path)."""
    return isinstance(key, str) and key.isascii() and key.isalnum()


class Cache:
    """Rows and arrays under ``root`` (``None``: nothing is cached)."""

    def __init__(self, root: str | Path | None):
        self.root = None if root is None else Path(root)

    def _path(self, kind: str, key: str, suffix: str) -> Path | None:
        if self.root is None:
            return None
        if not is_key(key):
            raise ValueError(f"bad cache key {key!r}")
        return self.root / kind / f"{key}{suffix}"

    def _load(self, kind: str, key: str, suffix: str, read, check) -> dict | None:
        """The entry, or ``None`` if it is missing or anything about it is wrong: the one place
        where an untrusted entry becomes "not cached"."""
        p = self._path(kind, key, suffix)
        if p is None:
            return None
        try:
            entry = read(p, key)
            ok = bool(check(entry))
        except Exception:  # noqa: BLE001 - untrusted: any failure to load or check means "not cached"
            return None
        return entry if ok else None

    def _target(self, kind: str, key: str, suffix: str) -> Path | None:
        """The path to write an entry to, with a directory in its place removed."""
        p = self._path(kind, key, suffix)
        if p is None:
            return None
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p)
        p.parent.mkdir(parents=True, exist_ok=True)
        return p

    # -- rows ------------------------------------------------------------------------------
    def get_row(self, key: str, required: tuple = (), check=None) -> dict | None:
        """The row stored under ``key`` if it loads and checks, has the fields ``required`` and
        ``check(row)`` is true (an exception in ``check`` counts as false); else ``None``."""
        return self._load("rows", key, ".json", read_row,
                          lambda row: all(k in row for k in required) and (check is None or check(row)))

    def put_row(self, key: str, row: dict) -> dict:
        row = clean(row)
        p = self._target("rows", key, ".json")
        if p is not None:
            write_text(p, json.dumps({"format": ROW_FORMAT, "key": key, "checksum": _digest(row), "row": row},
                                     indent=1) + "\n")
        return row

    # -- arrays ----------------------------------------------------------------------------
    def get_arrays(self, key: str, shapes: dict | None = None, check=None) -> dict | None:
        """The float arrays stored under ``key`` if they load and check, have ``shapes``
        (``{name: shape}``, ``-1`` for any size) and ``check(arrays)`` is true; else ``None``."""
        return self._load("arrays", key, ".npz", read_arrays,
                          lambda arrays: has_shapes(arrays, shapes or {}) and (check is None or check(arrays)))

    def put_arrays(self, key: str, **arrays) -> None:
        p = self._target("arrays", key, ".npz")
        if p is None:
            return
        arrays = {k: np.ascontiguousarray(v, dtype=float) for k, v in arrays.items()}
        meta = {"format": ARRAY_FORMAT, "key": key,
                "arrays": {k: {"shape": list(a.shape), "dtype": str(a.dtype), "sha256": _array_digest(a)}
                           for k, a in arrays.items()}}
        with atomic_path(p) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, __meta__=np.array(json.dumps(meta)), **arrays)
