"""SuperLU against CHOLMOD on the small systems of real runs: every SPD matrix a run factorises
(the P1 stiffness, the equilibrium space's condensed system, the P2 certificate's), captured from
runs of built-in scenes at levels 0-2, each factorised and solved once per backend, the fastest of
:data:`REPEATS`, on one BLAS thread. Also the one-time cost CHOLMOD adds to a process: importing
``cvxopt.cholmod`` in a fresh interpreter. Writes reports/factor_small.{md,csv}.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import cvxdual as cd  # noqa: E402
from cvxdual.files import write_text  # noqa: E402
from cvxdual.linalg import factor  # noqa: E402
from cvxdual.study.report import md_table  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RUNS = [("patch", "type1", 0), ("hertz", "type1", 0), ("hertz", "type1", 1), ("hertz", "type1", 2),
        ("cylinder-on-block", "type2", 0), ("cylinder-on-block", "type2", 1), ("cylinder-on-block", "type2", 2),
        ("block-with-hole", "type2", 0), ("block-with-hole", "type2", 1)]
REPEATS = 7
BACKENDS = ("superlu", "cholmod")


def captured(scene, tri, level) -> list:
    """The matrices (and whether each is given as its lower triangle) a run with the P2 certificate factorises."""
    mats = []
    make = factor.SPDFactor.__init__

    def record(self, A, method=None, lower=False):
        mats.append((A.copy(), lower))
        make(self, A, method, lower)

    factor.SPDFactor.__init__ = record
    try:
        cd.solve(scene, triangulation=tri, level=level, stress_space="eq")
    finally:
        factor.SPDFactor.__init__ = make
    return mats


def timed(A, lower, method) -> float:
    best = np.inf
    for _ in range(REPEATS):
        t = time.perf_counter()
        factor.SPDFactor(A, method, lower).solve(np.ones(A.shape[0]))
        best = min(best, time.perf_counter() - t)
    return best


def import_seconds() -> float:
    code = "import time; t = time.perf_counter(); import cvxopt.cholmod; print(time.perf_counter() - t)"
    return float(np.median([float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                                 check=True).stdout) for _ in range(5)]))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", default=str(ROOT / "reports"))
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    missing = [b for b in BACKENDS if b not in factor.backends()]
    if missing:
        raise SystemExit(f"needs {', '.join(missing)}")
    cd.solve("patch", stress_space="eq", level=0)  # imports and first calls, untimed
    factor.start_up("cholmod")
    rows = []
    with factor.one_blas_thread():
        for scene, tri, level in RUNS:
            for i, (A, lower) in enumerate(captured(scene, tri, level)):
                t = {m: timed(A, lower, m) for m in BACKENDS}
                rows.append(dict(scene=scene, triangulation=tri, level=level, matrix=i, unknowns=A.shape[0],
                                 nonzeros=A.nnz, superlu_ms=1e3 * t["superlu"], cholmod_ms=1e3 * t["cholmod"],
                                 ratio=t["superlu"] / t["cholmod"]))
    df = pd.DataFrame(rows)
    write_text(out / "factor_small.csv", df.to_csv(index=False))
    imp = import_seconds()
    saved = (df.superlu_ms - df.cholmod_ms)[df.unknowns < factor.LARGE_FROM].sum()
    text = ["# SuperLU against CHOLMOD on small systems (`studies/factor_small.py`)", "",
            f"Every SPD matrix the runs below factorise (equilibrium stresses with the P2 certificate), factorised "
            f"and solved once by each backend, the fastest of {REPEATS}, one BLAS thread.", "",
            md_table(df, floatfmt=".3g"), "",
            f"- CHOLMOD is faster on {int((df.ratio > 1).sum())} of {len(df)} matrices, {df.ratio.min():.2f} to "
            f"{df.ratio.max():.2f} times ({df.unknowns.min()} to {df.unknowns.max()} unknowns).",
            f"- Importing `cvxopt.cholmod` in a fresh interpreter: {1e3 * imp:.0f} ms (median of 5), once a process. "
            f"These runs' matrices below {factor.LARGE_FROM} unknowns together save {saved:.0f} ms with CHOLMOD.", ""]
    write_text(out / "factor_small.md", "\n".join(text))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
