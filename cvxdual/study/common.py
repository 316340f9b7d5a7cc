"""Shared pieces of the studies: progress, an on-disk cache for resuming, atomic outputs, rates."""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path

import numpy as np

from ..output import atomic_path, atomic_write_json, atomic_write_text


def code_version() -> str:
    """A hash of the package's numerical code (``cvxdual/*.py``, not the study runners): cached
    results are reused only by the code that produced them."""
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha1()
    for f in sorted(root.glob("*.py")):
        h.update(f.name.encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:12]


def scene_key(scene, *extra) -> str:
    """A short stable hash of a scene (frozen dataclasses have a deterministic repr), extras and
    the code version."""
    return hashlib.sha1(repr((scene, *extra, code_version())).encode()).hexdigest()[:12]


class Cache:
    """Finished results on disk: JSON rows and NumPy arrays, written atomically, so an
    interrupted study resumes where it stopped."""

    def __init__(self, root: str | Path | None):
        self.root = None if root is None else Path(root)
        if self.root is not None:
            self.root.mkdir(parents=True, exist_ok=True)

    def _path(self, key: str, suffix: str) -> Path | None:
        return None if self.root is None else self.root / f"{key}{suffix}"

    def get_row(self, key: str) -> dict | None:
        p = self._path(key, ".json")
        if p is None or not p.exists():
            return None
        return json.loads(p.read_text())

    def put_row(self, key: str, row: dict) -> None:
        p = self._path(key, ".json")
        if p is not None:
            atomic_write_json(p, row)

    def get_array(self, key: str) -> dict | None:
        p = self._path(key, ".npz")
        if p is None or not p.exists():
            return None
        with np.load(p) as z:
            return {k: z[k] for k in z.files}

    def put_array(self, key: str, **arrays) -> None:
        p = self._path(key, ".npz")
        if p is not None:
            with atomic_path(p) as tmp:
                with open(tmp, "wb") as fh:
                    np.savez(fh, **arrays)


class Progress:
    """One line per task on stderr: count, label, time, elapsed and an estimate of what is left."""

    def __init__(self, total: int, name: str, enabled: bool = True, stream=None):
        self.total, self.name, self.enabled = total, name, enabled
        self.stream = stream or sys.stderr
        self.done = 0
        self.t0 = time.perf_counter()
        self.work_done = 0.0

    def step(self, label: str, seconds: float, cached: bool = False) -> None:
        self.done += 1
        if not self.enabled:
            return
        el = time.perf_counter() - self.t0
        left = self.total - self.done
        eta = "" if cached or not self.done else f", about {el / self.done * left:.0f} s left"
        what = "cached" if cached else f"{seconds:.1f} s"
        bar = "#" * int(20 * self.done / self.total)
        print(f"{self.name} [{bar:<20}] {self.done}/{self.total} {label}: {what} (elapsed {el:.0f} s{eta})",
              file=self.stream, flush=True)


def fit_rate(h, e) -> float:
    """Slope of ``log e`` against ``log h`` (least squares), or NaN with fewer than two points."""
    h, e = np.asarray(h, float), np.asarray(e, float)
    ok = (h > 0) & (e > 0) & np.isfinite(e)
    if ok.sum() < 2:
        return float("nan")
    return float(np.polyfit(np.log(h[ok]), np.log(e[ok]), 1)[0])


def write_csv(df, path: Path) -> Path:
    with atomic_path(path) as tmp:
        df.to_csv(tmp, index=False, float_format="%.6g")
    return path


def save_fig(fig, path: Path) -> Path:
    import matplotlib.pyplot as plt
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)
    return path


def write_text(path: Path, text: str) -> Path:
    atomic_write_text(path, text)
    return path


def md_table(df, floatfmt: str = ".3g") -> str:
    cols = list(df.columns)
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for _, r in df.iterrows():
        cells = []
        for c in cols:
            v = r[c]
            if isinstance(v, (float, np.floating)):
                cells.append("-" if not np.isfinite(v) else format(v, floatfmt))
            else:
                cells.append(str(v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def study_main(name: str, doc: str, run, argv=None, quick_help: str = "coarse sizes only") -> int:
    """The command line every study shares: ``--quick``, ``--out``, ``--cache``, ``--quiet``.
    The default output is ``reports/`` (``out/NAME-quick`` with ``--quick``)."""
    p = argparse.ArgumentParser(prog=f"studies/{name}.py", description=doc.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help=quick_help)
    p.add_argument("--out", default=None, help=f"output directory (default: reports/, or out/{name}-quick)")
    p.add_argument("--cache", default=".cache/cvxdual", help="cache directory for resuming ('' to disable)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    a = p.parse_args(argv)
    run(a.out or (f"out/{name}-quick" if a.quick else "reports"), quick=a.quick, cache_dir=a.cache or None,
        progress=not a.quiet)
    return 0
