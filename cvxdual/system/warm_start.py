"""The warm start of the fast paths: the active contact set of a coarser level, solved by the P1
displacement's fast path and transferred to the pairs of the level asked for."""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import numpy as np

from ..activeset.core import coarse_start, transfer_active
from ..errors import MeshError, SolverError
from ..geometry.grid import Grid
from ..geometry.triangulation import discretize
from .assembly import assemble
from .displacement import nothing_acts, solve_fast

if TYPE_CHECKING:
    from ..scene import Scene

log = logging.getLogger(__name__)


def warm_start_pairs(scene: Scene, triangulation: str, level: int | Grid, pair_x: np.ndarray) -> np.ndarray | None:
    """Initial active set for ``level`` at the pair abscissae ``pair_x``: the converged set of
    level ``level - 2`` (:func:`~cvxdual.activeset.core.coarse_start`), transferred; ``None`` below
    level 2. A coarse level that the fast path cannot solve, or where nothing acts, gives no
    hint: the next level starts cold; so does one that cannot be meshed (an outline's strip is
    deepest there). An adaptive :class:`~cvxdual.geometry.grid.Grid` starts from its last
    cycle's set (cold on the first)."""
    if isinstance(level, Grid):
        return None if level.start is None else transfer_active(*level.start, pair_x)
    def solve_at(lv: int, coarser):
        log.debug("warm start: the active set of level %d", lv)
        try:
            system = assemble(*discretize(scene, triangulation, lv))
        except MeshError:
            return None
        if nothing_acts(system):
            return None
        x = system.mesh.pair_x
        try:
            _, stats = solve_fast(system, None if coarser is None else transfer_active(*coarser, x))
        except SolverError:
            return None
        return x, stats.active

    coarse = coarse_start(level, solve_at)
    return None if coarse is None else transfer_active(*coarse, pair_x)
