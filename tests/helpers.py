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


def contains(pieces, pts):
    """Brute force, independent of cvxdual.geometry.locate: boolean (m, n_pieces), which pieces contain
    each point (barycentric signs for triangles, bounds for slabs)."""
    import numpy as np

    from cvxdual.geometry.pieces import slab_bound

    m = len(pts)
    hit = np.zeros((m, len(pieces)), bool)
    d = pieces.tri_vertices[None, :, :, :] - pts[:, None, None, :]
    cr = [d[..., a, 0] * d[..., b, 1] - d[..., a, 1] * d[..., b, 0] for a, b in ((0, 1), (1, 2), (2, 0))]
    hit[:, pieces.tri_piece] = (cr[0] >= 0) & (cr[1] >= 0) & (cr[2] >= 0)
    s = pieces.slabs
    if len(s):
        x = np.broadcast_to(pts[:, :1], (m, len(s)))
        idx = np.broadcast_to(np.arange(len(s))[None, :], (m, len(s)))
        xc = np.clip(x, s.xl[idx], s.xr[idx])
        lo = slab_bound(s, pieces.faces, xc, idx, "lo")
        hi = slab_bound(s, pieces.faces, xc, idx, "hi")
        ins = (x >= s.xl[idx]) & (x <= s.xr[idx]) & (pts[:, 1:] >= lo) & (pts[:, 1:] <= hi)
        np.logical_or.at(hit.T, s.piece, ins.T)  # a piece with two slabs: either counts
    return hit


def load_example(name: str):
    """The module ``examples/<name>.py`` (the examples live outside the package)."""
    import importlib.util
    import sys
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "examples" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


# the phases of cvxdual.progress
PROGRESS = ("mesh", "assemble", "build", "solve", "recover", "bounds", "refine", "write")


def without_progress(err: str) -> list[str]:
    """The lines of a CLI run's stderr other than its progress lines (``cvxdual: PHASE: ...``),
    after checking that the progress lines all come first: what a failed run must reduce to is
    one error line, after whatever progress it made."""
    lines = err.strip().splitlines()
    progress = [any(line.startswith(f"cvxdual: {p}: ") for p in PROGRESS) for line in lines]
    assert progress == sorted(progress, reverse=True), err  # no progress line after another line
    return [line for line, p in zip(lines, progress, strict=True) if not p]


# a scene whose lower block is drawn in b.geo beside it (tests of the .geo route)
GEO_SCENE = """name = "geo"
[bodies.top]
position = "upper"
x = [-10.0, 10.0]
face = { kind = "flat", y0 = 0.0 }
material = { E = 70000.0, nu = 0.3 }
outline = [{ name = "right", to = [10.0, 4.0] }, { name = "top", to = [-10.0, 4.0] },
           { name = "left", to = [-10.0, 0.0] }]
[bodies.top.boundary.pressure]
on = "top"
kind = "traction"
traction = { value = [0.0, -100.0] }
[bodies.bottom]
position = "lower"
material = { E = 210000.0, nu = 0.3 }
geo = "b.geo"
[bodies.bottom.boundary.support]
on = "bottom"
kind = "clamped"
"""
