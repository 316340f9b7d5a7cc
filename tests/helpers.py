"""Shared test helpers: solved scenes are cached per session (solving is the slow part)."""

from __future__ import annotations

import functools

import cvxdual as cd


@functools.lru_cache(maxsize=None)
def solved(scene: str, level: int, triangulation: str = "type1"):
    return cd.solve(cd.load_scene(scene), triangulation, level)


@functools.lru_cache(maxsize=None)
def primal(scene: str, level: int, triangulation: str = "type1"):
    model = cd.PrimalModel(solved(scene, level, triangulation).system)
    model.solve()
    return model
