"""Sparse symmetric positive definite factorisation, with the backend chosen by what loads and by size.

CHOLMOD (supernodal Cholesky, through CVXOPT) factors every size fastest where it loads: 1.6 to 3.7
times faster than SciPy's SuperLU (symmetric mode) on every matrix of real runs from 53 to 15 000
unknowns (reports/factor_small.md; its import costs a process 6 ms), 2-4 times above
(reports/speed.md, "Time and memory against size"). Where CVXOPT cannot be loaded, SuperLU
factors the small systems and MKL Pardiso (through ``pypardiso``, x86-64 wheels; on one thread
CHOLMOD is 1.4 times faster than it, on two they are within 10%) the large ones. Pardiso is
imported on first use only, with MKL's runtime named to ``pypardiso`` beforehand: left to itself
it searches the whole environment for it by a recursive file search (0.1-0.2 s) at import and
again for every new solver. SuperLU serves every size where neither can be loaded.

:func:`backends` lists every backend that can factor here (QDLDL too, when installed); the
speed study's "limit" tries them all.
"""

from __future__ import annotations

import functools
import glob
import os
import sys

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import SolverError
from ..validate import one_line

# without CHOLMOD: below this many unknowns SuperLU, not Pardiso (whose set-up and threads cost more
# than the factorisation itself there)
LARGE_FROM = 5000
# a pivot below this fraction of the largest: singular to working precision (SPD stiffness
# matrices of the scenes have pivot ratios above 1e-10; a floating mode gives <= 0)
PIVOT_TOL = 1e-13


@functools.cache
def _pypardiso():
    """The ``pypardiso`` module, or None where it cannot be loaded."""
    if "PYPARDISO_MKL_RT" not in os.environ:
        # the pip wheel of MKL puts its runtime here: saves pypardiso's recursive search
        found = sorted(glob.glob(os.path.join(sys.prefix, "lib", "libmkl_rt.so*")), key=len)
        if found:
            os.environ["PYPARDISO_MKL_RT"] = found[0]
    try:  # pragma: no cover - depends on the platform
        import pypardiso  # loads MKL (it makes a solver at import): fails here rather than mid-solve
    except Exception:  # noqa: BLE001 - any import failure (no wheel, no MKL) means: not available
        return None
    return pypardiso


@functools.cache
def _has_cholmod() -> bool:
    try:
        import cvxopt.cholmod  # noqa: F401
    except Exception:  # noqa: BLE001 - not installed or broken: not a backend here
        return False
    return True


def backend(n: int | None = None) -> str:
    """The backend used for ``n`` unknowns (the largest systems' choice if ``n`` is None)."""
    if _has_cholmod():
        return "cholmod"
    if n is not None and n < LARGE_FROM:
        return "superlu"
    return "pardiso" if _pypardiso() is not None else "superlu"


def backends() -> list[str]:
    """Every backend that can factor on this machine."""
    out = ["superlu"] + ["cholmod"] * _has_cholmod() + ["pardiso"] * (_pypardiso() is not None)
    try:
        import qdldl  # noqa: F401
        out.append("qdldl")
    except Exception:  # noqa: BLE001 - not installed or broken: not a backend here
        pass
    return out


class SPDFactor:
    """Factor a sparse SPD matrix once; solve for one or many right-hand sides. With ``lower``
    the matrix given is the lower triangle only (what Cholesky reads; see
    :func:`cvxdual.linalg.sparse.assemble_lower`)."""

    def __init__(self, A: sp.spmatrix, method: str | None = None, lower: bool = False):
        self.n = A.shape[0]
        self.method = method or backend(self.n)
        if self.n == 0:
            return
        if self.method not in backends():
            raise SolverError(f"factorisation backend {self.method!r} is not available here; choose one of "
                              f"{', '.join(backends())}")
        make = _FACTOR[self.method]
        try:
            self._solve = make(sp.csr_matrix(A) if lower else sp.tril(A, format="csr"), self)
        except Exception as e:  # noqa: BLE001 - CHOLMOD raises ArithmeticError(column), the others their own
            why = f"not positive definite at column {e}" if isinstance(e, ArithmeticError) else one_line(e, 120)
            raise SolverError(f"the stiffness matrix could not be factorised by {self.method} ({why}); a body may "
                              "be free to move (add a support) or the active contact set leaves it floating") from None

    def close(self) -> None:
        """Release the factorisation (Pardiso keeps it outside Python's memory management)."""
        ps = getattr(self, "_ps", None)
        if ps is not None:
            ps.free_memory(everything=True)
            self._ps = None

    def __del__(self):
        try:
            self.close()
        except Exception:  # noqa: BLE001 - never raise from a finaliser
            pass

    def solve(self, b: np.ndarray) -> np.ndarray:
        if self.n == 0:
            return np.zeros_like(b)
        x = self._solve(np.asarray(b, float))
        if not np.all(np.isfinite(x)):
            raise SolverError("the factorised stiffness gave a non-finite solution; the problem is singular")
        return x


# every backend takes the lower triangle L of the matrix

def _full(L):
    return L + sp.tril(L, -1, format="csr").T


def _pardiso(L, owner: SPDFactor):
    mod = _pypardiso()
    if mod is None:
        raise SolverError("Pardiso is not available here (pypardiso and MKL are x86-64 only)")
    U = L.T.tocsr()  # the upper triangle, as Pardiso's symmetric modes read
    U.sort_indices()
    owner._ps = ps = mod.PyPardisoSolver(mtype=2)  # real symmetric positive definite
    ps.factorize(U)
    return lambda b: ps.solve(U, b)


class NotPositiveDefiniteError(ValueError):
    """A pivot of an LDL^T or LU factorisation without pivoting is not clearly positive."""


def _check_pivots(d: np.ndarray) -> None:
    # without pivoting a singular or indefinite matrix gives tiny or negative pivots instead of
    # an error (a floating mode: -1e-10 against 1.7e6); Cholesky backends refuse these themselves
    if d.min() <= PIVOT_TOL * d.max():
        raise NotPositiveDefiniteError(f"pivot {d.min():.2g} against a largest {d.max():.2g}")


def _superlu(L, owner: SPDFactor):
    # symmetric mode with no pivoting: SPD needs none, and the minimum-degree ordering of A + A^T
    # is kept (0-30 % faster than the default at small sizes)
    lu = spla.splu(sp.csc_matrix(_full(L)), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                   options={"SymmetricMode": True})
    _check_pivots(lu.U.diagonal())
    return lu.solve


def _cholmod(L, owner: SPDFactor):
    from cvxopt import cholmod, matrix, spmatrix
    C = L.tocsc().tocoo()  # column-sorted triplets: CVXOPT builds its matrix 4x faster from them
    M = spmatrix(matrix(C.data), matrix(C.row.astype(int)), matrix(C.col.astype(int)), L.shape)
    F = cholmod.symbolic(M)
    cholmod.numeric(M, F)

    def solve(b):
        x = matrix(np.array(b, float, order="F").reshape(b.shape[0], -1))
        cholmod.solve(F, x)
        return np.array(x).reshape(b.shape)
    return solve


def _qdldl(L, owner: SPDFactor):
    import qdldl
    s = qdldl.Solver(L.T.tocsc())
    _check_pivots(s.factors()[1])  # (L, D, permutation)
    return lambda b: np.column_stack([s.solve(c) for c in b.T]) if b.ndim == 2 else s.solve(b)


_FACTOR = {"pardiso": _pardiso, "superlu": _superlu, "cholmod": _cholmod, "qdldl": _qdldl}


def start_up(method: str | None = None) -> None:
    """Pay one-time library start-up (BLAS thread discovery, the first factorisation by ``method``,
    default the large systems' backend): for steady-state timings (the speed "limit",
    :func:`cvxdual.system.displacement.limit`, pays it for every backend it times)."""
    with one_blas_thread():
        SPDFactor(sp.identity(8, format="csr"), method or backend()).solve(np.ones(8))


@functools.cache
def _openblas():
    from threadpoolctl import ThreadpoolController
    return ThreadpoolController().select(internal_api="openblas")


def one_blas_thread():
    """A context with OpenBLAS on one thread: the fast paths' dense work is small (Schur
    complements of a few dozen columns, 21 x 21 local systems), and threads spinning against
    MKL's (and other processes') made it 10-100 times slower at random on a shared machine."""
    return _openblas().limit(limits=1)
