"""The peers study: cvxdual's fast path against dolfinx on the hertz problem,
same meshes, same run; writes reports/peers.md and reports/peers.csv

    python studies/peers.py                  # levels 0-6, into reports/
    python studies/peers.py --quick          # levels 0-2, into out/peers-quick
    python studies/peers.py --no-peer        # cvxdual only

The first run makes dolfinx's virtual environment
(.cache/cvxdual/peers/dolfinx-venv: Python >= 3.12 and `pip install dolfinx-solver-real`, about 350 MB);
where that is impossible the report covers cvxdual alone and says why.

The ``hertz`` problem is solved by cvxdual's fast path and by an established FE code, dolfinx
(FEniCSx; PETSc SNES with MUMPS), on the same meshes and in the same run; the report gives the
time each needs to reach 5% ... 0.25% error in the peak pressure and in the pressure profile,
and the ratios (``peers.md``, ``peers.csv``).

1. The peer's virtual environment (dolfinx's wheel needs Python >= 3.12) is made on first use and
   reused; where it cannot be, the report covers cvxdual alone and says why.
2. Each code runs in one worker process with the same thread settings (:data:`THREADS`: they must
   be set before NumPy loads), and the two take turns level by level, so that both see the same
   background load. cvxdual's worker (:func:`cvx_worker`) times the fast path (the smallest solve
   and total over ``--repeats`` runs below level 4, one run above, after an untimed warm-up solve)
   and writes the discrete problem to an npz (mesh, supports, anchor, pairs, gaps, tributary
   widths, loads, its pressures); the peer's (``studies/peers_dolfinx.py``) solves it.
3. The errors against the exact Hertz pressure are computed here from both codes' pressures
   (untimed). The peer must converge and agree with cvxdual to :data:`AGREEMENT` at every level,
   else the study fails after writing its report.
"""

from __future__ import annotations

import argparse
import csv
import glob
import io
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from cvxdual.errors import CvxdualError
from cvxdual.files import write_json, write_text
from cvxdual.outputs.output_set import check_writable
from cvxdual.study.cases import ISOLATED_THREADS
from cvxdual.validate import one_line

PEER_PACKAGE = "dolfinx-solver-real==0.11.0.post0"
MIN_PYTHON = (3, 12)  # the oldest Python with a wheel of PEER_PACKAGE
THREADS = ISOLATED_THREADS  # one thread per code, as the studies' isolated cases
TARGETS = (0.05, 0.02, 0.01, 0.005, 0.0025)
METRICS = {"peak": "peak pressure", "l2": "L2 pressure profile"}
BASES = ("solve", "total")  # the time compared: the solver alone, or mesh to pressures
# max |p - p_cvx| / max |p_cvx|: both solve one discrete problem, so only rounding separates them;
# it reaches 5e-10 at level 6 (pressure = force / width amplifies the residual's rounding at x = 0)
AGREEMENT = 1e-9
REPEAT_BELOW = 4  # levels repeated --repeats times (best of); above, one run
DEFAULT_VENV = ".cache/cvxdual/peers/dolfinx-venv"
MARKER = ".cvxdual-peer"  # written into the venv once the install imports: the venv is complete
WORKER = Path(__file__).with_name("peers_dolfinx.py")
TIMEOUT = 3 * 3600  # a hung worker or pip ends the study rather than blocking it


class PeerError(CvxdualError):
    """The peer failed or disagrees with cvxdual, or cvxdual's side failed."""


def add_parser(subparsers) -> argparse.ArgumentParser:
    p = subparsers.add_parser("peers", help="cvxdual against dolfinx on the hertz problem: time to accuracy",
                              description="The hertz problem solved by cvxdual's fast path and by dolfinx "
                              "(FEniCSx; PETSc SNES with MUMPS) on the same meshes, in the same run: the time each "
                              "needs to reach 5% to 0.25% error in the peak pressure and the pressure profile.")
    p.add_argument("--out", default=None, help="output directory (default: out/peers, or out/peers-quick)")
    p.add_argument("--levels", type=int, nargs="+", default=list(range(7)), metavar="L",
                   help="mesh levels (default: 0 1 2 3 4 5 6)")
    p.add_argument("--quick", action="store_true", help="levels 0-2 only")
    p.add_argument("--repeats", type=int, default=5, metavar="N",
                   help=f"runs per level below level {REPEAT_BELOW}, best of N (default: 5; one run above)")
    p.add_argument("--python", default=None, metavar="PATH",
                   help="Python >= 3.12 to make the peer's venv with (default: python3.12.. on PATH, or pyenv's)")
    p.add_argument("--venv", default=DEFAULT_VENV, metavar="DIR",
                   help=f"the peer's virtual environment, made if missing (default: {DEFAULT_VENV})")
    p.add_argument("--no-peer", action="store_true", help="cvxdual only")
    p.set_defaults(func=main)
    return p


# -- metrics ---------------------------------------------------------------------------------

def pressure_errors(p: np.ndarray, exact: np.ndarray, width: np.ndarray, p0: float) -> tuple[float, float]:
    """Peak error ``|max p - p0| / p0`` and profile error ``||p - p*||_w / ||p*||_w``, the norm
    weighted by the tributary widths (the trapezoidal L2 norm of the nodal pressures on the faces)."""
    l2 = np.sqrt(np.sum(width * (p - exact) ** 2) / np.sum(width * exact**2))
    return abs(float(np.max(p)) - p0) / p0, float(l2)


def time_to_accuracy(rows: list[dict], metric: str, target: float, basis: str) -> dict | None:
    """The fastest of ``rows`` (one code, ok levels) with ``{metric}_error <= target``:
    ``{"time", "level"}``, or None if no level reaches it."""
    best = min((r for r in rows if r[f"{metric}_error"] <= target), key=lambda r: r[f"{basis}_s"], default=None)
    return None if best is None else {"time": best[f"{basis}_s"], "level": best["level"]}


def accuracy_table(cvx: list[dict], peer: list[dict] | None) -> list[dict]:
    """Every (metric, target, basis): the time to it of both codes and their ratio cvxdual / peer."""
    out = [{"metric": m, "target": t, "basis": b, "cvxdual": time_to_accuracy(cvx, m, t, b),
            "peer": None if peer is None else time_to_accuracy(peer, m, t, b)}
           for m in METRICS for t in TARGETS for b in BASES]
    return [{**a, "ratio": a["cvxdual"]["time"] / a["peer"]["time"] if a["cvxdual"] and a["peer"] else None}
            for a in out]


# -- cvxdual's side (runs in its own process: see run_cvx) ------------------------------------

def export_level(system, path: Path, **extra) -> None:
    """Write the discrete problem of ``system`` (a ``hertz``-like scene: flat faces, straight
    triangles, no ties) for the peer: nodes, triangles, materials, fixed dofs (``2 node + comp``),
    anchor dofs, pairs, gaps, tributary widths, balanced nodal loads, the exact ``a, p0``."""
    from cvxdual.reference import exact_field
    mesh, scene = system.mesh, system.mesh.scene
    mats = [b.material for b in scene.bodies]
    if {k for k, v in system.pieces.counts().items() if v} != {"triangle"} or system.n_r != (system.rdof >= 0).sum() \
            or len(system.supports.rotated) or any(m.plane != "strain" for m in mats):
        raise PeerError("the peer needs straight triangles, no ties, supports on axis-aligned lines and plane strain "
                        "(the hertz scene)")
    free = np.flatnonzero(system.rdof >= 0)
    r2dof = np.empty(system.n_r, int)
    r2dof[system.rdof[free]] = free
    ex = exact_field(scene)
    np.savez(path, points=mesh.points, triangles=mesh.triangles(), tri_body=mesh.triangle_body(),
             E=np.array([m.E for m in mats]), nu=np.array([m.nu for m in mats]),
             fixed_dofs=np.flatnonzero(system.supports.fixed.ravel()),
             anchor_dofs=r2dof[np.asarray(system.anchors, int)],
             pairs=mesh.pairs, pair_x=mesh.pair_x, eps=system.eps, width=system.width, f=system.f,
             a=ex.hertz.a, p0=ex.hertz.p0, xc=ex.xc, y_face=ex.y_face, **extra)


def cvx_worker(import_s: float, argv: list[str]) -> None:
    """``DIR L...``, then ``L RUNS`` per line on stdin: time the fast path at level ``L`` (best of ``RUNS``), export it
    (and the peer's warm-start cascade L-2, L-4, ...) to ``DIR/hertz_L{L}.npz``, write ``DIR/cvx_L{L}.json``
    and say ``peers:done L``. ``DIR/cvx.json``: versions, import and warm-up times."""
    import scipy

    import cvxdual
    from cvxdual.linalg.factor import backend
    from cvxdual.pipeline import build_system, solve
    from cvxdual.reference import exact_field
    data, levels = Path(argv[0]), [int(v) for v in argv[1:]]
    scene = cvxdual.load_scene("hertz")
    t0 = time.perf_counter()
    # the warm-up pays the backend's start-up (CHOLMOD at every size; without it Pardiso from factor.LARGE_FROM)
    solve(scene, "type1", min(max(levels), 3), solver="fast", fallback=False)
    write_json(data / "cvx.json", {
        "import_s": import_s, "warmup_s": time.perf_counter() - t0, "threads": {k: os.environ.get(k) for k in THREADS},
        "versions": {"cvxdual": cvxdual.__version__, "numpy": np.__version__, "scipy": scipy.__version__,
                     "python": platform.python_version(), "backend": backend()},
        "exact": {k: getattr(exact_field(scene).hertz, k) for k in ("a", "p0")}})
    print("peers:ready", flush=True)
    done = set()
    for line in sys.stdin:
        L, n_runs = map(int, line.split())
        for k in sorted(set(range(L % 2, L, 2)) - done):  # levels of the peer's warm-start cascade only
            export_level(build_system(scene, "type1", k), data / f"hertz_L{k}.npz")
        runs = []
        for _ in range(n_runs):
            sol = solve(scene, "type1", L, solver="fast", fallback=False)
            t = dict(sol.timings)
            # the error against the exact field is the study's job (computed from the pressures)
            t["total"] -= t.get("error", 0.0)
            t["recover"] = t["total"] - sum(t.get(k, 0.0) for k in ("mesh", "assemble", "build", "solve"))
            runs.append(t)
        s, c = sol.system, sol.contact
        export_level(s, data / f"hertz_L{L}.npz", cvx_pressure=c["pressure"])
        done |= set(range(L % 2, L + 1, 2))
        write_json(data / f"cvx_L{L}.json", {
            "level": L, "n_unknowns": s.n_r - len(s.anchors), "n_active": c["n_active"],
            "iterations": sol.solver.iterations, "repeats": len(runs),
            "times": {k: min(r[k] for r in runs) for k in ("solve", "total")},
            "phases": min(runs, key=lambda r: r["total"])})
        del sol, s, c
        print(f"peers:done {L}", flush=True)


class Worker:
    """A worker process (cvxdual's or the peer's) fed one level per line on stdin. It answers
    ``peers:done L`` once ``DIR/{name}_L{L}.json`` is written; other output is ignored, stderr goes to
    ``DIR/{name}.log``. Workers take turns, so both codes run under the same background load."""

    def __init__(self, name: str, cmd: list[str], data: Path, env: dict):
        self.name, self.data = name, data
        self.log = open(data / f"{name}.log", "w+")  # noqa: SIM115 - closed by close()
        self.p = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self.log, text=True,
                                  env=env)

    def level(self, L: int | None, runs: int = 1) -> dict | None:
        """Level ``L``'s results, best of ``runs``; ``None``: wait until the worker is ready (imported,
        warmed up)."""
        timer = threading.Timer(TIMEOUT, self.p.kill)  # a hung worker ends the study rather than blocking it
        timer.start()
        try:
            if L is not None:
                self.p.stdin.write(f"{L} {runs}\n")
                self.p.stdin.flush()
            for line in self.p.stdout:
                if line.strip() == ("peers:ready" if L is None else f"peers:done {L}"):
                    return None if L is None else json.loads((self.data / f"{self.name}_L{L}.json").read_text())
        except OSError:  # the worker is gone (broken pipe): say why below
            pass
        finally:
            timer.cancel()
        self.p.kill()
        self.p.wait()
        self.log.seek(0)
        raise PeerError(_failure(self.p.returncode, self.log.read()))

    def close(self) -> dict | None:
        """End the worker; its ``DIR/{name}.json`` (versions, import and warm-up times), if written."""
        try:
            self.p.stdin.close()
            self.p.wait(timeout=60)
        except (OSError, subprocess.TimeoutExpired):
            self.p.kill()
            self.p.wait()
        self.p.stdout.close()
        self.log.close()
        head = self.data / f"{self.name}.json"
        return json.loads(head.read_text()) if head.exists() else None


def _run(cmd: list[str], env=None, timeout=TIMEOUT) -> str | None:
    """Run ``cmd`` quietly: None if it worked, else one line saying why."""
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout)
    except (OSError, subprocess.SubprocessError) as e:
        return one_line(f"{type(e).__name__}: {e}", 300)
    return None if r.returncode == 0 else _failure(r.returncode, r.stderr + "\n" + r.stdout)


def _failure(status: int, output: str) -> str:
    """A failed process in one line: its exit status and the last line it printed."""
    last = [ln for ln in output.splitlines() if ln.strip()]
    return one_line(f"exit status {status}: {last[-1] if last else 'no output'}", 300)


# -- the peer ----------------------------------------------------------------------------------

def python_version(exe: str) -> tuple[int, int] | None:
    """``(major, minor)`` of the Python ``exe``, or None if it does not run."""
    try:
        r = subprocess.run([exe, "-c", "import sys; print(*sys.version_info[:2])"], capture_output=True,
                           text=True, timeout=60)
        return tuple(int(v) for v in r.stdout.split()[:2]) if r.returncode == 0 else None
    except (OSError, subprocess.SubprocessError, ValueError):
        return None


def find_python() -> str | None:
    """A Python >= 3.12: python3.12 ... python3.19 on PATH, then pyenv's versions."""
    found = [shutil.which(f"python3.{m}") for m in range(MIN_PYTHON[1], 20)]
    for home in dict.fromkeys([str(Path.home()), "/root"]):
        found += sorted(glob.glob(f"{home}/.pyenv/versions/3.1[2-9]*/bin/python"))
    for exe in dict.fromkeys(e for e in found if e):
        v = python_version(exe)
        if v and v >= MIN_PYTHON:
            return exe
    return None


def peer_venv(venv: Path, python: str | None) -> tuple[str | None, str]:
    """``(the venv's python, how it was obtained)``, or ``(None, why the peer is skipped)``."""
    if python:
        v = python_version(python)
        if v is None:
            return None, f"--python {python} does not run"
        if v < MIN_PYTHON:
            return None, f"--python {python} is Python {v[0]}.{v[1]}; {PEER_PACKAGE} needs Python >= 3.12"
    py = venv / "bin" / "python"
    if py.exists() and (venv / MARKER).is_file() and (venv / MARKER).read_text().strip() == PEER_PACKAGE:
        return str(py), f"reused {venv}"
    python = python or find_python()
    if python is None:
        return None, ("no Python >= 3.12 found (python3.12 to python3.19 on PATH, pyenv's versions; "
                      "give one with --python PATH)")
    t0 = time.perf_counter()
    venv.parent.mkdir(parents=True, exist_ok=True)
    for what, cmd in (("making the venv", [python, "-m", "venv", "--clear", str(venv)]),
                      (f"pip install {PEER_PACKAGE}", [str(py), "-m", "pip", "install", "--disable-pip-version-check",
                                                        "--no-input", PEER_PACKAGE]),
                      ("importing dolfinx", [str(py), "-I", "-c", "import dolfinx_solver, dolfinx"])):
        err = _run(cmd)
        if err:
            return None, f"{what} with {python} failed ({err})"
    write_text(venv / MARKER, PEER_PACKAGE + "\n")
    return str(py), f"made {venv} with {python} ({time.perf_counter() - t0:.0f} s)"


# -- the study ---------------------------------------------------------------------------------

def level_rows(cvx: dict, peer: dict | None, data: Path) -> list[dict]:
    """One row per code and level: sizes, iterations, times, errors, agreement, status."""
    from cvxdual.reference import hertz_pressure
    peer_rows = {r["level"]: r for r in peer["rows"]} if peer else {}
    rows = []
    for c in cvx["rows"]:
        L = c["level"]
        with np.load(data / f"hertz_L{L}.npz") as z:
            x, w, pc, a, p0, xc = (z[k] for k in ("pair_x", "width", "cvx_pressure", "a", "p0", "xc"))
        exact, p0 = hertz_pressure(x - xc, a, p0), float(p0)
        codes = [("cvxdual", c, pc)]
        if peer is not None:
            r = peer_rows.get(L, {"error": "no result"})
            codes.append(("dolfinx", r, None if "error" in r else np.asarray(r["pressure"])))
        for code, r, p in codes:
            row = {"code": code, "level": L, "n_pairs": len(x)}
            if p is None:
                rows.append({**row, "status": f"failed: {one_line(r['error'], 200)}"})
                continue
            diff = None if code == "cvxdual" else float(np.abs(p - pc).max() / np.abs(pc).max())
            reason = r.get("reason", 1)
            status = ("ok" if diff is None or (reason > 0 and diff <= AGREEMENT) else
                      f"failed: SNES converged reason {reason}" if reason <= 0 else
                      f"failed: pressures differ from cvxdual's by {diff:.2g} > {AGREEMENT:g}")
            peak, l2 = pressure_errors(p, exact, w, p0)
            rows.append({**row, "n_unknowns": r["n_unknowns"], "n_active": r["n_active"],
                         "iterations": r["iterations"], "solve_s": r["times"]["solve"], "total_s": r["times"]["total"],
                         "peak_pressure": float(p.max()), "peak_error": peak, "l2_error": l2, "rel_diff": diff,
                         "status": status, "phases": r["phases"]})
    return rows


# cvxdual's worker: this file imported as a module from its folder (on the worker's PYTHONPATH)
CVX_CODE = ("import sys, time; t = time.perf_counter(); import cvxdual; t = time.perf_counter() - t; "
            "from peers import cvx_worker; cvx_worker(t, sys.argv[1:])")
HERE = Path(__file__).resolve().parent


def main(args) -> int:
    levels = [0, 1, 2] if args.quick else sorted(set(args.levels))
    if any(L < 0 for L in levels) or args.repeats < 1:
        raise PeerError("--levels must be non-negative integers and --repeats at least 1")
    out = check_writable(Path(args.out or ("out/peers-quick" if args.quick else "out/peers")))
    venv = check_writable(Path(args.venv), "peer venv directory", "--venv")
    if venv.exists() and any(venv.iterdir()) and not (venv / "pyvenv.cfg").exists():
        raise PeerError(f"--venv {str(venv)!r} exists and is not a virtual environment; give another --venv")
    env = {**os.environ, **THREADS, "PYTHONPATH": os.pathsep.join(
        [str(HERE.parent), str(HERE), *filter(None, [os.environ.get("PYTHONPATH")])])}
    py, note = (None, "not run (--no-peer)") if args.no_peer else peer_venv(venv, args.python)
    note = f"skipped: {note}" if py is None and not args.no_peer else note
    print(f"peers: levels {', '.join(map(str, levels))}; dolfinx: {note}", flush=True)
    load = [os.getloadavg()[0]]
    with tempfile.TemporaryDirectory(prefix="cvxdual-peers-") as tmp:
        data = Path(tmp)
        workers = {"cvx": Worker("cvx", [sys.executable, "-c", CVX_CODE, str(data), *map(str, levels)], data, env)}
        if py is not None:
            workers["peer"] = Worker("peer", [py, "-I", str(WORKER), "--data", str(data), "--jit-cache",
                                              str(venv / "jit-cache")], data, env)
        rows, stopped = {"cvx": [], "peer": []}, set()
        try:
            for L in [None, *levels]:  # both ready (nothing runs beside the timed code), then turns level by level
                print(f"peers: level {L}" if L is not None else "peers: starting", flush=True)
                for name in [n for n in workers if n not in stopped]:  # cvxdual first: it exports the level
                    res = None
                    try:
                        res = workers[name].level(L, args.repeats if L is not None and L < REPEAT_BELOW else 1)
                    except PeerError as e:
                        at = "at start-up" if L is None else f"at level {L}"
                        if name == "cvx":
                            raise PeerError(f"cvxdual's side of the peers study failed {at} ({e})") from None
                        note = f"{note}; failed: the dolfinx worker stopped {at} ({e})"
                        stopped.add(name)
                    rows[name] += [res] if res else []
        finally:
            head = {name: w.close() for name, w in workers.items()}
        cvx = {**head["cvx"], "rows": rows["cvx"]}
        peer = {**head["peer"], "rows": rows["peer"]} if head.get("peer") else None
        load.append(os.getloadavg()[0])
        rows = level_rows(cvx, peer, data)
    failed = [r for r in rows if r["status"] != "ok"]
    acc = accuracy_table([r for r in rows if r["code"] == "cvxdual"],
                         None if peer is None else [r for r in rows if r["code"] == "dolfinx" and r["status"] == "ok"])
    out.mkdir(parents=True, exist_ok=True)
    write_report(out, rows, acc, cvx, peer, note, levels, args.repeats, load)
    print(f"peers: wrote {out}/peers.md, peers.csv")
    if "failed:" in note or failed:
        what = note if "failed:" in note else f"dolfinx level {failed[0]['level']} {failed[0]['status']}"
        raise PeerError(f"peers study: {what}; see {out / 'peers.md'}")
    return 0


# -- the report --------------------------------------------------------------------------------

CSV_COLUMNS = ("code", "level", "n_unknowns", "n_pairs", "n_active", "iterations", "solve_s", "total_s",
               "peak_pressure", "peak_error", "l2_error", "rel_diff", "status")
PHASES = {"cvxdual": ("mesh", "assemble", "solve", "recover"),
          "dolfinx": ("mesh", "forms_jit", "assemble", "transform", "warm_start", "init", "snes", "post")}
SETUP = """\
# cvxdual against dolfinx: time to accuracy on `hertz`

Generated by `python studies/peers.py` (CSV: `peers.csv`), levels {levels}. Peer: {note}.

## Setup

- Problem: the built-in `hertz` scene (plane-strain half model of linearised Hertz contact, exact McEwen tractions
  on the truncated sides; a = {a:.5g}, p0 = {p0:.6g}). Both codes solve one discrete problem: conforming P1
  displacements with node-to-node contact on cvxdual's type-1 meshes, exported by the study per level (nodes,
  triangles, materials, supports, anchor, pairs, gaps, tributary widths). cvxdual's P0 stress dual is its Lagrangian
  dual; the fast path solves this displacement form directly (docs/theory.md).
- cvxdual {cv[cvxdual]} (Python {cv[python]}, NumPy {cv[numpy]}, SciPy {cv[scipy]}, factorisation {cv[backend]}):
  `solve("hertz", "type1", L, solver="fast")`, a primal-dual active set method warm-started from level L-2.
- {peer_line}
- Threads: {threads} for both codes, each in one worker process started by the study with this
  environment (set before NumPy loads); the two take turns level by level, so both see the same background load.
  Machine: {cores} cores, shared; 1-minute load average {load[0]:.2f} at the start, {load[1]:.2f} at the end.
- Times: the smallest solve and the smallest total over {repeats} runs below level {below}, one run from level
  {below}, after one untimed warm-up solve per code; phases are those of the run with the smallest total. Not
  counted: imports ({imports}) and warm-up solves ({warmups}; dolfinx's compiles or loads the forms).
- cvxdual *solve*: `timings["solve"]`, the active-set solve and its warm-start cascade (levels L-2, L-4, ...
  meshed, assembled and solved). *total*: `timings["total"]` less `timings["error"]`: mesh generation, assembly,
  solve, recovery of stresses and contact quantities, the accuracy checks (residuals, duality gap).
- dolfinx *solve*: the first LU solve with the guessed pairs closed, SNES, and the warm-start cascade (levels L-2,
  ... run whole). *total*: dolfinx mesh from the exported arrays, forms (JIT cache), assembly of K and loads,
  T^T K T and supports, solve, contact forces; not reading the npz (mesh generation counts in cvxdual's total only).
- Errors, computed by the study from each code's nodal pressures p_k = F_k / w_k (untimed, one formula for both):
  peak |max p - p0| / p0; profile sqrt(sum w_k (p_k - p*(x_k))^2 / sum w_k p*(x_k)^2), w_k the tributary widths,
  the trapezoidal L2 norm of the nodal values over the face. The nodal values are what both codes produce; a
  continuous norm of an interpolant would add the interpolation error of p*'s square-root edge, which no solver
  controls.
- Required at every level, else the study fails: SNES converged (reason > 0) and
  max |p - p_cvx| / max |p_cvx| <= {agreement:g}.

## Per level

| level | code | unknowns | pairs | active | iterations | solve s | total s | peak p | peak error | L2 error \
| rel diff to cvxdual | status |
|---|---|---|---|---|---|---|---|---|---|---|---|---|
"""


def _g(v, spec=".3g") -> str:
    return "-" if v is None else format(v, spec)


def _pct(v) -> str:
    return "-" if v is None else f"{100 * v:.3g}%"


def _cell(hit: dict | None, top: int) -> str:
    return f"not reached up to level {top}" if hit is None else f"{hit['time']:.3g} s (L{hit['level']})"


def _phases(r: dict) -> str:
    return ", ".join(f"{k} {r['phases'].get(k, 0.0):.3g}" for k in PHASES[r["code"]])


def verdict(acc: list[dict]) -> dict:
    """Per time basis, the (metric, target) entries met, missed, and open (reached by neither code)."""
    out = {}
    for basis in BASES:
        rows = [a for a in acc if a["basis"] == basis]
        out[basis] = {"met": [a for a in rows if a["cvxdual"] and (a["ratio"] or 0.0) <= 1.0],
                      "missed": [a for a in rows if a["peer"] and (a["ratio"] is None or a["ratio"] > 1.0)],
                      "open": [a for a in rows if not a["cvxdual"] and not a["peer"]]}
    return out


def why(basis: str, c: dict, p: dict) -> str:
    """A missed level, explained from both codes' phases (of their runs with the smallest total)."""
    cp, pp = c["phases"], p["phases"]
    ratio = c[f"{basis}_s"] / p[f"{basis}_s"]
    text = (f"Missed on {basis} time at level {c['level']}: cvxdual {c[f'{basis}_s']:.3g} s against dolfinx "
            f"{p[f'{basis}_s']:.3g} s. ")
    if basis == "total":
        rest_c, rest_p = cp["total"] - cp["solve"], pp["total"] - pp["solve"]
        text += (f"Of the difference the solve makes {cp['solve'] - pp['solve']:+.3g} s and the rest "
                 f"{rest_c - rest_p:+.3g} s: cvxdual's mesh generation, NumPy assembly, recovery and accuracy "
                 f"checks ({rest_c:.3g} s) against dolfinx's mesh from arrays, compiled assembly, T^T K T and forces "
                 f"({rest_p:.3g} s). ")
    else:
        text += (f"Both are sparse factorisations of the same {c['n_unknowns']} unknowns after a warm-start cascade: "
                 f"cvxdual {c['iterations']} active-set iterations on its factorisation with Schur updates, dolfinx "
                 f"a first MUMPS solve ({pp['init']:.3g} s), {p['iterations']} SNES iterations ({pp['snes']:.3g} s) "
                 f"and its cascade ({pp['warm_start']:.3g} s). ")
    return text + (f"A difference of {100 * (ratio - 1):.0f}% is inside the spread of runs on this shared machine "
                   "(last note): a tie rather than a measured loss." if ratio <= 1.3 else "")


def write_report(out: Path, rows, acc, cvx, peer, note, levels, repeats, load) -> None:
    buf = io.StringIO()
    w = csv.DictWriter(buf, CSV_COLUMNS, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    write_text(out / "peers.csv", buf.getvalue())
    top, pv, byk = max(levels), (peer or {}).get("versions"), {(r["code"], r["level"]): r for r in rows}
    ok_peer = [r for r in rows if r["code"] == "dolfinx" and r["status"] == "ok"]
    peer_line = (f"dolfinx {pv['dolfinx']} (`{PEER_PACKAGE}`, Python {peer['python']}, PETSc {pv['petsc']}, UFL "
                 f"{pv['ufl']}, basix {pv['basix']}, FFCx {pv['ffcx']}, NumPy {pv['numpy']}): K from the UFL form, "
                 + ("loads assembled by dolfinx from the McEwen traction in UFL (degree 15, 8 Gauss points per edge "
                    "as cvxdual)" if peer["load"] == "ufl" else "cvxdual's nodal loads")
                 + "; contact as bounds after the change of variables r = T y (y_jb the pair's relative "
                 "displacement); PETSc SNES `vinewtonrsls` with MUMPS LU, warm-started from level L-2 by cvxdual's "
                 "transfer rule (levels 0 and 1: every pair closed first)." if peer else f"dolfinx: {note}.")
    both = [("cvxdual", cvx)] + ([("dolfinx", peer)] if peer else [])
    t = [SETUP.format(levels=f"{levels[0]}-{top}", note=note, cv=cvx["versions"], peer_line=peer_line,
                      threads=", ".join(f"{k}={v}" for k, v in THREADS.items()), cores=os.cpu_count(), load=load,
                      repeats=repeats, below=REPEAT_BELOW, agreement=AGREEMENT, **cvx["exact"],
                      imports=", ".join(f"{c} {d['import_s']:.2f} s" for c, d in both),
                      warmups=", ".join(f"{c} {d['warmup_s']:.2f} s" for c, d in both)).rstrip("\n")]
    t += [f"| {r['level']} | {r['code']} | {_g(r.get('n_unknowns'), 'd')} | {r['n_pairs']} | "
          f"{_g(r.get('n_active'), 'd')} | {_g(r.get('iterations'), 'd')} | {_g(r.get('solve_s'))} | "
          f"{_g(r.get('total_s'))} | {_g(r.get('peak_pressure'), '.6g')} | {_pct(r.get('peak_error'))} | "
          f"{_pct(r.get('l2_error'))} | {_g(r.get('rel_diff'), '.2g')} | {r['status']} |" for r in rows]
    t += ["", "Unknowns: free displacement dofs after supports and anchor. Iterations: at the level itself, "
          "active-set (cvxdual) or SNES (dolfinx). Phases, s (cvxdual's recover without the exact-field error; "
          "dolfinx's warm_start is its cascade, counted in solve):", "", "| level | code | phases |", "|---|---|---|"]
    t += [f"| {r['level']} | {r['code']} | {_phases(r)} |" for r in rows if r.get("phases")]
    t += ["", "## Time to accuracy", "", "The fastest level reaching each target; ratio = cvxdual / dolfinx.", "",
          "| metric | target | cvxdual solve | dolfinx solve | ratio | cvxdual total | dolfinx total | ratio |",
          "|" + "---|" * 8]
    for s, o in zip(acc[::2], acc[1::2], strict=True):  # (solve, total) of each (metric, target)
        cells = [f"{_cell(a['cvxdual'], top)} | {_cell(a['peer'], top) if peer else '-'} | {_g(a['ratio'])}"
                 for a in (s, o)]
        t.append(f"| {METRICS[s['metric']]} | {100 * s['target']:g}% | {' | '.join(cells)} |")
    t += ["", "## Target", "", "Time to every accuracy target from 5% to 0.25% (both metrics): cvxdual at most "
          "the fastest peer's time on the same problem.", ""]
    notes = []
    for basis, v in verdict(acc).items():
        miss = "; ".join(f"{METRICS[a['metric']]} {100 * a['target']:g}% ({_cell(a['cvxdual'], top)} against "
                         f"{_cell(a['peer'], top)})" for a in v["missed"])
        t.append(f"- {basis} time: " + (f"met at {len(v['met'])} of {len(v['met']) + len(v['missed'])}"
                                        + (f"; missed: {miss}" if miss else "")
                                        + (f"; {len(v['open'])} reached by neither up to level {top}" if v["open"]
                                           else "") if ok_peer else "not assessed (no peer result)"))
        notes += [why(basis, byk[("cvxdual", lv)], byk[("dolfinx", lv)])
                  for lv in sorted({a["peer"]["level"] for a in v["missed"]})]
    if peer is None:
        notes.append(f"Peer {note}. The tables have cvxdual's rows only; the target is not assessed.")
    if ok_peer:
        notes.append(f"Largest pressure difference between the codes {max(r['rel_diff'] for r in ok_peer):.2g} "
                     f"(at most {AGREEMENT:g} required); active pairs equal at "
                     f"{sum(r['n_active'] == byk[('cvxdual', r['level'])]['n_active'] for r in ok_peer)} of "
                     f"{len(ok_peer)} levels. Both reach each target at the same level (one discrete problem), "
                     "so the ratios compare the codes' speed only.")
    notes.append(f"From level {REPEAT_BELOW} each time is one run; on this shared machine times vary by 10-30% and "
                 "more between runs, so ratios that close to 1 are ties rather than wins or losses.")
    t += ["", "## Notes", "", *[f"- {n}" for n in notes], ""]
    write_text(out / "peers.md", "\n".join(t))


def build_parser() -> argparse.ArgumentParser:
    sub = argparse.ArgumentParser(prog="python studies/peers.py").add_subparsers(dest="command")
    return add_parser(sub)


if __name__ == "__main__":
    args = build_parser().parse_args()
    if args.out is None and not args.quick:
        args.out = "reports"
    try:
        sys.exit(main(args))
    except CvxdualError as e:
        print(f"peers: error: {one_line(e, 400)}", file=sys.stderr)
        sys.exit(1)
