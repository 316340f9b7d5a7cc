"""The active-set core of both fast solvers (``core``): the iteration to a fixed point with one
iteration limit and cycle test, the cover of floating bodies and the coarse-level warm start.
Each stress space keeps its own linear algebra: :mod:`cvxdual.system.displacement` (the displacement form,
Schur-complement updates of one factorisation) and :mod:`cvxdual.eq.active_set` (the hybridised
equilibrium dual)."""

from .core import MAX_ITER, ActiveSetStats, coarse_start, cover, iterate, transfer_active

__all__ = ["MAX_ITER", "ActiveSetStats", "coarse_start", "cover", "iterate", "transfer_active"]
