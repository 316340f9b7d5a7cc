"""The study cache: checked entries keyed by content, so an interrupted study resumes.

Entries are untrusted. Each is authenticated by an HMAC-SHA256 under the cache's own secret,
``KEY_FILE`` in the cache directory (32 random bytes, created with the first entry, mode 0600):
a row edited by hand, or forged with a recomputed plain checksum, or copied from another cache,
fails its MAC. Whoever can read the key file (its owner, root) can forge entries: the MAC
guards the rows against anyone who can write them but not read the key, and against damage.
A row is a JSON file ``rows/KEY.json`` holding its format, its own key and the MAC of its
format, key and canonical JSON; arrays are ``arrays/KEY.npz`` of float arrays with a metadata
record (format, key, shapes, dtypes, SHA-256 checksums, and the MAC of these). Reading an entry
is one function per kind (:func:`read_row`, :func:`read_arrays`: they raise on anything wrong) and one place,
:meth:`Cache._load`, where any failure to load or check means "not cached": the entry is
recomputed, then overwritten, never used and never a traceback. Callers add the checks of what
the entry must be for them (``required``/``shapes`` and a ``check`` callable: the types and
identity of a row, the mesh size of a reference, a nonzero norm). Every file is written
atomically. Workers read and write reference arrays here: with a remote scheduler the cache
directory must be on a filesystem shared by the client and every worker.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import math
import os
import re
import secrets
import shutil
import tempfile
from pathlib import Path

import numpy as np

from ..errors import CvxdualError
from ..files import atomic_path, write_text
from ..files import to_jsonable as clean

ROW_FORMAT = "cvxdual-study-row/2"  # /1: a plain SHA-256 checksum, which anyone could recompute
ARRAY_FORMAT = "cvxdual-study-arrays/2"
KEY_FILE = "key"  # the cache's secret, in its root: 64 hex digits


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


def _canonical(obj) -> bytes:
    return json.dumps(obj, sort_keys=True, separators=(",", ":")).encode()


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


def read_row(path: Path, key: str, mac) -> dict:
    """The row in ``path`` (raises unless it is a row entry of ``key`` whose MAC ``mac(format, key,
    row)`` matches)."""
    d = json.loads(path.read_text(encoding="utf-8"), parse_float=_finite_float, parse_constant=_no_constant)
    _ensure(isinstance(d, dict))
    row = d.get("row")
    _ensure(d.get("format") == ROW_FORMAT and d.get("key") == key and isinstance(row, dict)
            and isinstance(d.get("mac"), str) and hmac.compare_digest(d["mac"], mac(ROW_FORMAT, key, row)))
    return row


def read_arrays(path: Path, key: str, mac) -> dict:
    """The arrays in ``path`` (raises unless it is an arrays entry of ``key`` whose metadata has a
    matching MAC and whose float arrays have the recorded names, shapes, dtypes and checksums,
    and finite values). Never unpickles."""
    with np.load(path, allow_pickle=False) as z:  # (an .npy file loads as an array: no context manager)
        _ensure(isinstance(z, np.lib.npyio.NpzFile) and "__meta__" in z.files)
        meta = json.loads(str(z["__meta__"]))
        arrays = {k: z[k] for k in z.files if k != "__meta__"}
    _ensure(isinstance(meta, dict) and meta.get("format") == ARRAY_FORMAT and meta.get("key") == key
            and isinstance(meta.get("mac"), str)
            and hmac.compare_digest(meta["mac"], mac(ARRAY_FORMAT, key, meta.get("arrays"))))
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
        self._secret: bytes | None = None

    def _key(self, create: bool) -> bytes | None:
        """The cache's secret (:data:`KEY_FILE`), created if missing and ``create``; ``None`` if
        missing. A key file that is not a key raises :class:`CvxdualError` (nothing signed with it
        can be checked: remove it, and the entries are recomputed)."""
        if self._secret is not None:
            return self._secret
        p = self.root / KEY_FILE
        if not os.path.lexists(p):
            if not create:
                return None
            self.root.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=f".{KEY_FILE}.", dir=self.root)  # mode 0600
            try:
                os.write(fd, secrets.token_hex(32).encode())
                os.fsync(fd)
                os.close(fd)
                try:
                    os.link(tmp, p)  # atomic and complete: of concurrent workers, the first key wins
                except FileExistsError:
                    pass
            finally:
                os.unlink(tmp)
        try:
            text = p.read_text(encoding="ascii").strip()
        except (OSError, UnicodeDecodeError) as e:
            text = f"unreadable: {getattr(e, 'strerror', None) or e}"
        if not re.fullmatch(r"[0-9a-f]{64}", text):
            raise CvxdualError(f"the study cache's key {str(p)!r} is not a key (64 hex digits; {text[:40]!r}); "
                               "remove it, and the cache's entries are recomputed")
        self._secret = bytes.fromhex(text)
        return self._secret

    def mac(self, *parts) -> str:
        """The HMAC-SHA256 of ``parts`` (JSON) under the cache's key, created if missing."""
        return hmac.new(self._key(create=True), _canonical(list(parts)), hashlib.sha256).hexdigest()

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
            if self._key(create=False) is None:  # no key yet: nothing was ever written (a bad key: nothing checks)
                return None
            entry = read(p, key, self.mac)
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
            write_text(p, json.dumps({"format": ROW_FORMAT, "key": key, "mac": self.mac(ROW_FORMAT, key, row),
                                      "row": row}, indent=1) + "\n")
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
        rec = {k: {"shape": list(a.shape), "dtype": str(a.dtype), "sha256": _array_digest(a)}
               for k, a in arrays.items()}
        meta = {"format": ARRAY_FORMAT, "key": key, "arrays": rec, "mac": self.mac(ARRAY_FORMAT, key, rec)}
        with atomic_path(p) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, __meta__=np.array(json.dumps(meta)), **arrays)
