"""The study cache: checked entries keyed by content, so an interrupted study resumes.

Entries are untrusted. A row is a JSON file ``rows/KEY.json`` holding its format, its own key
and a SHA-256 checksum of its canonical JSON; arrays are ``arrays/KEY.npz`` with a metadata
record (format, key, shapes, checksums). Anything that fails to load or check is treated as
missing (recomputed, then overwritten), never used and never a traceback. Every file is
written atomically. Workers read and write reference arrays here: with a remote scheduler
the cache directory must be on a filesystem shared by the client and every worker.
"""

from __future__ import annotations

import hashlib
import json
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


class Cache:
    """Rows and arrays under ``root`` (``None``: nothing is cached)."""

    def __init__(self, root: str | Path | None):
        self.root = None if root is None else Path(root)

    def _path(self, kind: str, key: str, suffix: str) -> Path | None:
        if self.root is None:
            return None
        if not key.isalnum():
            raise ValueError(f"bad cache key {key!r}")
        return self.root / kind / f"{key}{suffix}"

    # -- rows ------------------------------------------------------------------------------
    def get_row(self, key: str, required: tuple = ()) -> dict | None:
        p = self._path("rows", key, ".json")
        if p is None:
            return None
        try:
            d = json.loads(p.read_text())
            row = d["row"]
            ok = (d.get("format") == ROW_FORMAT and d.get("key") == key and isinstance(row, dict)
                  and d.get("checksum") == _digest(row) and all(k in row for k in required))
        except Exception:  # noqa: BLE001 - untrusted: any failure to load or check means "not cached"
            return None
        return row if ok else None

    def put_row(self, key: str, row: dict) -> dict:
        row = clean(row)
        p = self._path("rows", key, ".json")
        if p is not None:
            p.parent.mkdir(parents=True, exist_ok=True)
            write_text(p, json.dumps({"format": ROW_FORMAT, "key": key, "checksum": _digest(row),
                                             "row": row}, indent=1) + "\n")
        return row

    # -- arrays ----------------------------------------------------------------------------
    def get_arrays(self, key: str, shapes: dict | None = None) -> dict | None:
        """The arrays stored under ``key``, if every check passes: format, key, the recorded
        shapes (and ``shapes``: ``{name: shape}``, ``-1`` for any), finite values, checksums."""
        p = self._path("arrays", key, ".npz")
        if p is None:
            return None
        try:
            with np.load(p, allow_pickle=False) as z:
                meta = json.loads(str(z["__meta__"]))
                arrays = {k: z[k] for k in z.files if k != "__meta__"}
            if meta.get("format") != ARRAY_FORMAT or meta.get("key") != key:
                return None
            if set(meta["arrays"]) != set(arrays):
                return None
            for name, a in arrays.items():
                m = meta["arrays"][name]
                if list(a.shape) != m["shape"] or str(a.dtype) != m["dtype"] or _array_digest(a) != m["sha256"]:
                    return None
                if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
                    return None
            for name, shape in (shapes or {}).items():
                a = arrays.get(name)
                if a is None or a.ndim != len(shape) or \
                        any(s not in (-1, n) for s, n in zip(shape, a.shape, strict=True)):
                    return None
        except Exception:  # noqa: BLE001 - untrusted: any failure to load or check means "not cached"
            return None
        return arrays

    def put_arrays(self, key: str, **arrays) -> None:
        p = self._path("arrays", key, ".npz")
        if p is None:
            return
        arrays = {k: np.ascontiguousarray(v) for k, v in arrays.items()}
        meta = {"format": ARRAY_FORMAT, "key": key,
                "arrays": {k: {"shape": list(a.shape), "dtype": str(a.dtype), "sha256": _array_digest(a)}
                           for k, a in arrays.items()}}
        p.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(p) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, __meta__=np.array(json.dumps(meta)), **arrays)
