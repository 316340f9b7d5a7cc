"""Size estimates before allocation: a run that will not fit in memory is refused up front,
with the estimate and how to override it, instead of dying in an allocation or an OOM kill.

The mesh is counted without being built (:func:`~cvxdual.geometry.mesh.mesh_size`), and memory is
``BASE + triangles * cost`` with per-triangle costs measured as peak resident memory of whole
solves (``studies/memory.py`` measures them again and compares with this estimate, in
``reports/memory.md``). The estimate is for Clarabel and the fast path; first-order and dense
CVXPY solvers can need much more, so for them it is a lower bound.

The limit is the memory available to this process (the smallest of the system's available
memory, a cgroup limit and an address-space rlimit), or ``max_memory`` / the environment
variable ``CVXDUAL_MAX_MEMORY`` (``"64GB"``, ``"none"``).
"""

from __future__ import annotations

import math
import os
import re
import resource
from dataclasses import dataclass

from .errors import TooLargeError
from .geometry.mesh import mesh_size
from .geometry.triangulation import column_breaks
from .kinds import Kinematic, Space
from .memory import available_memory
from .validate import short

BASE_BYTES = 200e6  # the interpreter with NumPy, SciPy, CVXPY and a solver loaded (measured: 120-180 MB)
# Peak resident bytes per mesh triangle, measured at levels 2-6 (studies/memory.py, reports/memory.md),
# rounded up. "cvxpy": the P0 dual through CVXPY and Clarabel; "fast": the P0 fast path; on top
# of the P0 fast solve, the equilibrium space by its fast route ("eq") or through CVXPY ("eq_cvxpy"), and the
# P2 kinematic side of a certificate ("p2").
# "p2": measured 0.7 kB a triangle more at the peak (hertz level 5, eq route: 2367 against 2261 MB); its
# own arrays (element blocks, about 5 kB a triangle) are freed before the equilibrium stresses' peak
BYTES_PER_TRIANGLE = {"cvxpy": 12e3, "fast": 5e3, "eq": 12e3, "eq_cvxpy": 100e3, "p2": 2e3}
ENV = "CVXDUAL_MAX_MEMORY"
PLAUSIBLE_MEMORY = 1e14  # bytes: more than any one machine has (100 TB)
_UNITS = {"": 1, "B": 1, "KB": 1e3, "MB": 1e6, "GB": 1e9, "TB": 1e12, "KIB": 2**10, "MIB": 2**20, "GIB": 2**30,
          "TIB": 2**40}


# the rows of BYTES_PER_TRIANGLE a run adds up, by stress space and path (fast or not): the eq
# space needs the P1 displacement by the fast path first, then its own stresses
RUN_ROWS = {(Space.P0, True): ("fast",), (Space.P0, False): ("cvxpy",),
            (Space.EQ, True): ("fast", "eq"), (Space.EQ, False): ("fast", "eq_cvxpy")}


@dataclass(frozen=True)
class Estimate:
    """The size of one run, estimated before anything is built."""

    triangles: float
    nodes: float
    bytes: float

    def describe(self) -> str:
        return f"about {_count(self.triangles)} triangles, {_count(2 * self.nodes)} dofs, {_bytes(self.bytes)}"


def estimate(scene, level: int, fast: bool, stress_space: str = "p0", bounds: bool = False,
             kinematic: str = "p2") -> Estimate:
    """Estimated triangles, nodes and peak memory of solving ``scene`` at ``level``."""
    n = mesh_size(scene, level, column_breaks(scene))
    return _estimate(n["triangles"], n["nodes"], stress_space, fast, bounds, kinematic)


def _estimate(triangles: float, nodes: float, stress_space, fast: bool, bounds: bool, kinematic) -> Estimate:
    cost = sum(BYTES_PER_TRIANGLE[r] for r in _rows(stress_space, fast, bounds, kinematic))
    return Estimate(triangles, nodes, BASE_BYTES + cost * triangles)


def _rows(stress_space, fast: bool, bounds: bool, kinematic) -> tuple[str, ...]:
    """The rows of :data:`BYTES_PER_TRIANGLE` a run adds up."""
    space = Space.parse(stress_space)
    rows = RUN_ROWS[space, bool(fast)]
    if bounds and space is Space.P0:  # bounds of a P0 run: the equilibrium stresses by the fast route
        rows += ("eq",)
    if (bounds or space is Space.EQ) and Kinematic.parse(kinematic) is Kinematic.P2:
        rows += ("p2",)
    return rows


def memory_limit(max_memory=None) -> tuple[float, object]:
    """The limit in bytes and what gave it (``max_memory``, else ``$CVXDUAL_MAX_MEMORY``; ``None``:
    neither, the memory available)."""
    given = max_memory if max_memory is not None else os.environ.get(ENV)
    return (parse_size(given) if given is not None else available_memory()), given


def check_mesh_size(n_triangles: float, fast: bool, stress_space: str, bounds: bool, kinematic: str,
                    max_memory=None) -> Estimate:
    """The estimate of a run on a mesh of ``n_triangles`` (an adaptive cycle's, counted from its grid),
    or :class:`~cvxdual.errors.TooLargeError` above the limit."""
    est = _estimate(n_triangles, 0.5 * n_triangles, stress_space, fast, bounds, kinematic)
    limit = memory_limit(max_memory)[0]
    if est.bytes > limit:
        raise TooLargeError(f"a mesh of {est.describe()} is more than the memory limit ({_bytes(limit)})")
    return est


def parse_size(value) -> float:
    """Bytes from ``1e9``, ``"16GB"``, ``"500 MiB"``; ``None``/``"none"``/``inf``: no limit."""
    if value is None:
        return math.inf
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        if value > 0:
            return float(value)
    elif isinstance(value, str):
        text = value.strip().upper()
        if text in ("NONE", "INF", "UNLIMITED"):
            return math.inf
        m = re.fullmatch(r"([0-9]*\.?[0-9]+(?:E[+-]?[0-9]+)?)\s*([KMGT]I?B|B)?", text)
        if m and float(m.group(1)) > 0:
            return float(m.group(1)) * _UNITS[m.group(2) or ""]
    raise TooLargeError(f"a memory limit must be a positive size such as 16GB or 500MB, or 'none'; got {short(value)}")


def check_size(scene, level: int, fast: bool, stress_space: str = "p0", bounds: bool = False,
               max_memory=None, kinematic: str = "p2") -> Estimate:
    """The :func:`estimate`, or :class:`~cvxdual.errors.TooLargeError` if it exceeds the limit."""
    est = estimate(scene, level, fast, stress_space, bounds, kinematic)
    limit, given = memory_limit(max_memory)
    if est.bytes > limit:
        where = "the given limit" if given is not None else "the memory available"
        what = f"{short(scene.name, 40)} at level {level}: {est.describe()}, more than {where} ({_bytes(limit)})"
        lower = _largest_level(scene, level, fast, stress_space, bounds, kinematic, limit)
        fits = _largest_columns(scene, level, fast, stress_space, bounds, kinematic, limit)
        # past what any machine has, raising the limit is no fix (a hostile level or column count)
        plausible = est.bytes <= PLAUSIBLE_MEMORY
        raise_api = f" or raise the limit with max_memory='64GB' (or {ENV})" if plausible else ""
        raise_cli = " or raise the limit with --max-memory 64GB" if plausible else ""
        if lower is not None:
            what += f"; level {lower} fits"
            cols = "" if fits is None else f", give fewer mesh columns (mesh.columns = {fits} fits at level {level})"
            raise TooLargeError(f"{what}; lower the level{cols}{raise_api}",
                                cli=f"{what}; lower --level{cols}{raise_cli}")
        # even level 0 is too large: no level helps; the mesh's columns are too many (or its layers)
        what += f"; even level 0 is too large with {_count(scene.mesh.columns)} mesh columns"
        if fits is not None:
            raise TooLargeError(f"{what}: give fewer mesh columns (mesh.columns = {fits} fits at level {level})"
                                + raise_api, cli=f"{what}: give fewer mesh columns (mesh.columns = {fits} fits "
                                f"at level {level})" + raise_cli)
        run = (fast, stress_space, bounds, kinematic, limit)
        both = next(((lv, n) for lv in reversed(range(min(level, 12)))
                     if (n := _largest_columns(scene, lv, *run)) is not None), None)
        if both is not None:
            fix = f"give fewer mesh columns and a lower level (mesh.columns = {both[1]} fits at level {both[0]})"
            raise TooLargeError(f"{what}: {fix}{raise_api}", cli=f"{what}: {fix.replace('level (', '--level (')}"
                                f"{raise_cli}")
        layers = ", ".join(f"{b.name} {_count(b.layers)}" for b in scene.bodies)
        what += f", and so is one mesh column with the bodies' layers ({layers}): give the bodies fewer layers"
        raise TooLargeError(what + raise_api, cli=what + raise_cli)
    return est


def _largest_columns(scene, level, fast, stress_space, bounds, kinematic, limit) -> int | None:
    """The largest ``mesh.columns`` below the scene's whose mesh fits ``limit`` at ``level``, or
    ``None`` if even one column does not."""
    from dataclasses import replace

    def fits(n: int) -> bool:
        return estimate(replace(scene, mesh=replace(scene.mesh, columns=n)), level, fast, stress_space,
                        bounds, kinematic).bytes <= limit

    lo, hi = 1, scene.mesh.columns  # fits(lo) is checked, fits(hi) is false
    if hi <= 1 or not fits(lo):
        return None
    while hi - lo > 1:  # at most 64 estimates (columns are at most 1e100, about 2^332: 333)
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if fits(mid) else (lo, mid)
    return lo


def peak_mb() -> float:
    """This process's peak resident memory in MB. On Linux ``VmHWM`` of its own address space:
    ``ru_maxrss`` also carries the parent's peak across ``exec`` (a worker that once held a
    9 GB reference made every case it launched report 9 GB)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0  # kB
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux reports KiB


def _largest_level(scene, level, fast, stress_space, bounds, kinematic, limit) -> int | None:
    fits = [L for L in range(min(level, 12))
            if estimate(scene, L, fast, stress_space, bounds, kinematic).bytes <= limit]
    return max(fits) if fits else None


def _count(n: float) -> str:
    return f"{n:.3g}" if n < 1e6 or not math.isfinite(n) else f"{n / 1e6:.3g}M" if n < 1e9 else f"{n:.2e}"


def _bytes(b: float) -> str:
    if not math.isfinite(b):
        return "unbounded memory"
    return f"{b / 1e9:.3g} GB" if b >= 1e9 else f"{b / 1e6:.3g} MB"
