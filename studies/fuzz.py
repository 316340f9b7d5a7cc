"""Fuzzing of the built-in scenes (issue 13): writes OUT/fuzz.md, OUT/fuzz.csv, OUT/fuzz_failures/

    python studies/fuzz.py --minutes 10 --levels 0 1 2 --seed 1 --out reports

Until the time budget ends, random cases (a built-in scene perturbed by fuzzing.perturb,
a level, a triangulation, the fast path or CLARABEL, sometimes stress space "eq" on flat-face
scenes; a fifth of the cases a run to a certified 5 % instead of a level, capped at
:data:`TOL_PIECES` pieces, whose best result is checked too when it stops short) run through
cvxdual.solve, each in a worker process with a time limit (a hang or a killed worker costs one
case) and an address-space limit (a huge mesh raises MemoryError
instead of exhausting the machine). Outcomes: ok, rejected:<CvxdualError subclass>, timeout,
fallback (the fast path failed and solve() handed over to CLARABEL, which solved), and the
findings: exception:<type> (any other exception; traceback saved), nan (a returned result fails
fuzzing.check_result), fast-accuracy-while-clarabel-ok (the fast path raised
AccuracyError/SolverError where CLARABEL solves within tolerances), bad-message (a CvxdualError
message of several lines or >= 500 characters), out-of-memory (a MemoryError, even one turned
into a CvxdualError: the size check let the case through), crash (the worker died).
Exit status 1 if there are findings.
"""

import argparse
import collections
import csv
import io
import json
import multiprocessing as mp
import re
import resource
import sys
import time
import traceback
from multiprocessing.connection import wait
from pathlib import Path

import numpy as np
from fuzzing import check_result, perturb  # studies/fuzzing.py, beside this script

import cvxdual as cd
from cvxdual.files import write_text
from cvxdual.scene.scenefile import builtin_data, builtin_names, load_scene

HOSTILITY = (0.0, 0.0, 0.1, 0.3, 1.0)  # most cases plausible, so that many reach the solvers
TOL, TOL_SHARE, TOL_PIECES = 0.05, 0.2, 20_000  # runs to a tolerance: the adaptive path's input handling
NOT_FINDINGS = ("ok", "rejected", "timeout", "fallback")


def solve(data: dict, case: dict, solver: str):
    if case.get("tol") is None:
        return cd.solve(load_scene(data), case["triangulation"], case["level"], solver,
                        stress_space=case["stress_space"])
    return cd.solve(load_scene(data), case["triangulation"], None, solver, stress_space=case["stress_space"],
                    tol=case["tol"], max_pieces=TOL_PIECES)


def run_case(case: dict) -> dict:
    """Outcome of one case (in a worker process)."""
    out = {"outcome": "ok", "detail": "", "traceback": ""}
    try:
        data = perturb(builtin_data(case["scene"]), np.random.default_rng(case["seed"]), case["hostility"])
        sol = solve(data, case, case["solver"])
        problems = check_result(sol)
        if sol.solver.fallback:  # the fast path failed and CLARABEL solved instead: not a finding
            out.update(outcome="fallback", detail=sol.solver.fallback[:300])
        if problems:
            nan = any("non-finite" in p or "nan" in p or "inf" in p for p in problems)
            out.update(outcome="nan" if nan else "bad-result", detail="; ".join(problems))
    except cd.CvxdualError as e:
        msg = str(e)
        out.update(outcome=f"rejected:{type(e).__name__}", detail=msg.splitlines()[0][:300] if msg else "")
        best = getattr(e, "solution", None)  # a run to a tolerance that stopped short: its best result
        if best is not None and (problems := check_result(best)):
            out.update(outcome="bad-result", detail="(best result) " + "; ".join(problems)[:280])
        elif isinstance(e.__context__, MemoryError):  # the size check let through a run that does not fit
            out.update(outcome="out-of-memory", detail=f"{type(e).__name__} after MemoryError: {msg[:250]}")
        elif "\n" in msg or len(msg) >= 500:
            out.update(outcome="bad-message", detail=f"{type(e).__name__} of {len(msg)} chars: {msg[:300]!r}")
        elif case["solver"] == "fast" and isinstance(e, (cd.AccuracyError, cd.SolverError)):
            try:
                if not check_result(solve(data, case, "CLARABEL")):
                    out["outcome"] = "fast-accuracy-while-clarabel-ok"
            except cd.CvxdualError:
                pass
            except Exception as e2:
                out.update(outcome=f"exception:{type(e2).__name__}", detail=f"(CLARABEL check) {e2}"[:300],
                           traceback=traceback.format_exc())
    except Exception as e:
        out.update(outcome=f"exception:{type(e).__name__}", detail=str(e).splitlines()[0][:300] if str(e) else "",
                   traceback=traceback.format_exc())
    return out


def worker(conn, memory: int):
    resource.setrlimit(resource.RLIMIT_AS, (memory, memory))
    while (case := conn.recv()) is not None:
        t0 = time.perf_counter()
        out = run_case(case)
        conn.send({**out, "seconds": time.perf_counter() - t0})


class Worker:
    """A worker process running ``target(conn, memory)`` (default: :func:`worker`), one case at a time."""

    def __init__(self, memory: int, target=None):
        self.conn, child = mp.Pipe()
        self.proc = mp.get_context("fork").Process(target=target or worker, args=(child, memory), daemon=True)
        self.proc.start()
        child.close()
        self.case, self.started, self.done = None, 0.0, 0

    def send(self, case):
        self.case, self.started = case, time.perf_counter()
        self.conn.send(case)

    def stop(self, kill: bool = False):
        if not kill:
            try:
                self.conn.send(None)
            except OSError:
                pass
            self.proc.join(5)
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join()
        self.conn.close()


def cases(seed: int, levels: list[int]):
    rng = np.random.default_rng(seed)
    tol_rng = np.random.default_rng([seed, 42])  # apart, so that the level cases stay those of earlier runs
    names = builtin_names()
    flat = {n for n in names if all(b["face"]["kind"] == "flat" for b in builtin_data(n)["bodies"].values())}
    for i in range(sys.maxsize):
        scene = names[rng.integers(len(names))]
        case = {"id": i, "scene": scene, "seed": int(rng.integers(2**32)),
                "hostility": HOSTILITY[rng.integers(len(HOSTILITY))], "level": int(rng.choice(levels)),
                "triangulation": str(rng.choice(["type1", "type2"])), "solver": str(rng.choice(["fast", "CLARABEL"])),
                "stress_space": "eq" if scene in flat and rng.random() < 0.25 else "p0", "tol": None}
        if tol_rng.random() < TOL_SHARE:  # from its first cycle's level, in the equilibrium space (tol's default)
            case.update(level=None, stress_space="eq", tol=TOL)
        yield case


def fuzz(minutes: float, levels: list[int], seed: int, n_workers: int, timeout: float, memory: int,
         max_tasks: int) -> list[dict]:
    end = time.perf_counter() + 60 * minutes
    gen, rows, workers = cases(seed, levels), [], [Worker(memory) for _ in range(n_workers)]
    next_print = time.perf_counter() + 60
    while True:
        now = time.perf_counter()
        for w in workers:
            if w.case is None and now < end:
                w.send(next(gen))
        busy = [w for w in workers if w.case is not None]
        if not busy:
            break
        ready = wait([w.conn for w in busy], timeout=1.0)
        for i, w in enumerate(workers):
            if w.case is None:
                continue
            res = None
            if w.conn in ready:
                try:
                    res = w.conn.recv()
                except (EOFError, OSError):
                    w.proc.join(1)
                    res = {"outcome": "crash", "detail": f"worker died (exit code {w.proc.exitcode})", "traceback": ""}
            elif time.perf_counter() - w.started > timeout:
                res = {"outcome": "timeout", "detail": f"no result after {timeout:g} s", "traceback": ""}
            if res is None:
                continue
            rows.append({**w.case, "seconds": time.perf_counter() - w.started, **res})
            w.done += 1
            if res["outcome"] in ("crash", "timeout") or w.done >= max_tasks:
                w.stop(kill=res["outcome"] in ("crash", "timeout"))
                workers[i] = Worker(memory)
            else:
                w.case = None
        if time.perf_counter() > next_print:
            next_print += 60
            c = collections.Counter(r["outcome"].split(":")[0] for r in rows)
            print(f"{(time.perf_counter() - end) / 60 + minutes:5.1f} min, {len(rows)} cases: {dict(c)}", flush=True)
    for w in workers:
        w.stop()
    return rows


def diff(base, new, path="") -> list[str]:
    """``path: old -> new`` lines between two scene dicts."""
    if isinstance(base, dict) and isinstance(new, dict):
        return [line for k in {**base, **new} for line in diff(base.get(k, "<absent>"), new.get(k, "<absent>"),
                                                             f"{path}.{k}" if path else str(k))]
    same = type(base) is type(new) and (base == new or base != base and new != new)  # NaN == NaN here
    return [] if same else [f"{path}: {base!r} -> {new!r}"[:300]]


def group_key(r: dict) -> str:
    """Similar findings share a key: the outcome and the raising line (exceptions) or the
    message with its numbers blanked."""
    if r["traceback"]:
        frames = re.findall(r'File "([^"]+)", line (\d+), in (\w+)', r["traceback"])
        f = frames[-1] if frames else ("?", "?", "?")
        return f"{r['outcome']} at {Path(f[0]).name}:{f[1]} in {f[2]}"
    return f"{r['outcome']}: {re.sub(r'[-+]?[0-9][0-9.e+-]*', '#', r['detail'])[:150]}"


def cases_md(rows: list[dict]) -> list[str]:
    """Markdown of ``rows`` in groups of similar cases, the first of each with its reproduction."""
    groups = collections.defaultdict(list)
    for r in rows:
        groups[group_key(r)].append(r)
    md = []
    for key, rs in sorted(groups.items(), key=lambda kv: -len(kv[1])):
        r = rs[0]
        data = perturb(builtin_data(r["scene"]), np.random.default_rng(r["seed"]), r["hostility"])
        md += [f"### {key} ({len(rs)} cases: {', '.join(str(x['id']) for x in rs[:20])})", "",
               f"- case {r['id']}: scene `{r['scene']}` seed {r['seed']} hostility {r['hostility']}, "
               + (f"to tol {r['tol']:g}" if r.get("tol") else f"level {r['level']}")
               + f", {r['triangulation']}, solver {r['solver']}, stress space {r['stress_space']}",
               f"- error: {r['detail']}", "- changes to the built-in scene:", "",
               *[f"      {line}" for line in diff(builtin_data(r["scene"]), data)], ""]
        if r["traceback"]:
            md += ["```", *r["traceback"].rstrip().splitlines()[-8:], "```", ""]
    return md


def table(counter: dict, title: str) -> list[str]:
    cols = sorted({o for c in counter.values() for o in c})
    lines = [f"| {title} | " + " | ".join(cols) + " |", "|---" * (len(cols) + 1) + "|"]
    return lines + [f"| {k} | " + " | ".join(str(c.get(o, 0)) for o in cols) + " |" for k, c in sorted(counter.items())]


def report(rows: list[dict], out: Path, args) -> list[dict]:
    findings = [r for r in rows if r["outcome"].split(":")[0] not in NOT_FINDINGS]
    out.mkdir(parents=True, exist_ok=True)
    fields = ["id", "scene", "seed", "hostility", "level", "tol", "triangulation", "solver", "stress_space",
              "outcome", "seconds", "detail"]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fields, extrasaction="ignore")
    w.writeheader()
    w.writerows({**r, "seconds": f"{r['seconds']:.3f}"} for r in rows)
    write_text(out / "fuzz.csv", buf.getvalue())
    by = {k: collections.defaultdict(collections.Counter) for k in ("scene", "solver", "level")}
    for r in rows:
        for k in ("scene", "solver", "level"):
            v = r[k] if k != "level" or r["tol"] is None else f"tol {r['tol']:g}"  # a run to a tolerance
            by[k][f"{v}"][r["outcome"].split(":")[0]] += 1
    md = ["# Fuzzing of the built-in scenes\n",
          f"`python studies/fuzz.py --minutes {args.minutes:g} --levels {' '.join(map(str, args.levels))} "
          f"--seed {args.seed}`: {len(rows)} cases, {len(findings)} findings.\n", "| outcome | cases |", "|---|---|"]
    md += [f"| {o} | {n} |" for o, n in sorted(collections.Counter(r["outcome"] for r in rows).items())]
    for k in ("scene", "solver", "level"):
        md += [""] + table(by[k], k)
    for title, selected in (("Findings", findings), ("Timeouts and fast-path fallbacks (not findings)",
                                                     [r for r in rows if r["outcome"] in ("timeout", "fallback")])):
        md += ["", f"## {title}" if selected else f"## {title}: none", ""] + cases_md(selected)
    write_text(out / "fuzz.md", "\n".join(md) + "\n")
    for r in findings:
        (out / "fuzz_failures").mkdir(exist_ok=True)
        data = perturb(builtin_data(r["scene"]), np.random.default_rng(r["seed"]), r["hostility"])
        # json.dumps, not write_json: NaN and inf must survive (as NaN/Infinity) to reproduce the case
        case = {k: r[k] for k in fields if k != "seconds"}
        write_text(out / "fuzz_failures" / f"{r['id']}.json",
                   json.dumps({"case": {**case, "traceback": r["traceback"]}, "scene": data}, indent=2) + "\n")
    return findings


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--minutes", type=float, default=10.0)
    p.add_argument("--levels", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="reports")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--timeout", type=float, default=60.0, help="seconds per case")
    p.add_argument("--memory", type=float, default=4.0, help="GB of address space per worker")
    p.add_argument("--max-tasks", type=int, default=200, help="cases per worker process before a fresh one")
    args = p.parse_args(argv)
    rows = fuzz(args.minutes, args.levels, args.seed, args.workers, args.timeout, int(args.memory * 2**30),
                args.max_tasks)
    findings = report(rows, Path(args.out), args)
    print(f"{len(rows)} cases, {len(findings)} findings: {Path(args.out) / 'fuzz.md'}")
    return 1 if findings else 0


if __name__ == "__main__":
    sys.exit(main())
