"""Fuzzing of outline bodies (scene outlines and .geo files): writes OUT/fuzz_outlines.md, .csv and
OUT/fuzz_outlines_failures/.

    python studies/fuzz_outlines.py --cases 500 --seed 1 --out reports

Each case (studies/outline_fuzzing.py: a seed drawn from ``--seed``, a level of ``--levels``) is a
built-in outline scene with its bodies redrawn, plausible or (30 %) hostile, as a scene dict or with
a body in a .geo file. It is loaded and meshed in a worker process with a time limit and an
address-space limit, and the mesh is compared with the body drawn. Outcomes: ok,
rejected:<CvxdualError subclass>, and the findings: traceback:<type> (any other exception, traceback
saved), internal:<class> (a CvxdualError that says it is internal), hang (no result within
``--timeout``), crash (the worker died), area, coverage (the mesh is not the body), accepted (a case
that must be refused was meshed), attack (a .geo statement left a file), geo-differs (a .geo body
and the same body in a scene file are not both accepted), not-invariant (a body scaled or moved is
not accepted as the body unmoved at its own size is), bad-message (an error message with a newline
or of 500 characters or more), force (a solved case whose contact force is not the applied load),
solve-refused (solve() stops with a MeshError on a scene whose mesh at that level builds),
oracle-error (this study's own failure). Exit status 1 on findings.
"""

from __future__ import annotations

import argparse
import collections
import csv
import io
import json
import re
import resource
import sys
import time
from multiprocessing.connection import wait
from pathlib import Path

import numpy as np
from fuzz import Worker  # studies/fuzz.py: one case at a time in a worker process
from outline_fuzzing import GEO_SHARE, HOSTILE_SHARE, NOT_FINDINGS, make_case, run_case  # studies/, beside this script

from cvxdual.files import write_text

FIELDS = ["id", "seed", "base", "route", "level", "hostile", "must_refuse", "solve", "outcome", "seconds", "detail"]


def worker(conn, memory: int):
    resource.setrlimit(resource.RLIMIT_AS, (memory, memory))
    while (spec := conn.recv()) is not None:
        t0 = time.perf_counter()
        try:
            case = case_of(spec)
            out = {k: case[k] for k in FIELDS[2:8]}
            out.update(run_case(case))
        except Exception as e:  # the generator's own failure
            import traceback
            out = {"outcome": f"oracle-error:{type(e).__name__}", "detail": str(e)[:300],
                   "traceback": traceback.format_exc()}
        conn.send({**out, "seconds": time.perf_counter() - t0})



def specs(n: int, seed: int, levels, hostile: float = HOSTILE_SHARE, geo: float = GEO_SHARE) -> list[dict]:
    seeds = np.random.default_rng(seed).integers(2**32, size=n)
    return [{"id": i, "seed": int(s), "levels": list(levels), "shares": [hostile, geo]} for i, s in enumerate(seeds)]


def case_of(spec: dict) -> dict:
    """The case of a spec (or of a row, which keeps its spec's keys)."""
    return make_case(spec["seed"], spec["levels"], *spec["shares"])


def call(spec: dict) -> str:
    return f"make_case({spec['seed']}, {spec['levels']}, {', '.join(map(str, spec['shares']))})"


def fuzz(todo: list[dict], n_workers: int = 1, timeout: float = 60.0, memory: int = 4 << 30,
         max_tasks: int = 100, progress: bool = True) -> list[dict]:
    """Run the cases ``todo`` in ``n_workers`` worker processes: one row per case."""
    todo, rows = list(todo), []
    workers = [Worker(memory, worker) for _ in range(n_workers)]
    next_print = time.perf_counter() + 60
    while True:
        for w in workers:
            if w.case is None and todo:
                w.send(todo.pop(0))
        busy = [w for w in workers if w.case is not None]
        if not busy:
            break
        ready = wait([w.conn for w in busy], timeout=0.5)
        for i, w in enumerate(workers):
            if w.case is None:
                continue
            res = None
            if w.conn in ready:
                try:
                    res = w.conn.recv()
                except (EOFError, OSError):
                    w.proc.join(1)
                    res = {"outcome": "crash", "detail": f"worker died (exit code {w.proc.exitcode})"}
            elif time.perf_counter() - w.started > timeout:
                res = {"outcome": "hang", "detail": f"no result after {timeout:g} s"}
            if res is None:
                continue
            if "base" not in res:  # a hang, a crash or the generator's failure: the case's fields, drawn here
                try:
                    case = case_of(w.case)
                    res.update({k: case[k] for k in FIELDS[2:8]})
                except Exception as e:
                    res.update(outcome=f"oracle-error:{type(e).__name__}", detail=f"make_case: {e}"[:300])
            rows.append({"traceback": "", "detail": "", "seconds": time.perf_counter() - w.started,
                         **{k: w.case[k] for k in ("id", "seed", "levels", "shares")}, **res})
            w.done += 1
            if res["outcome"] in ("crash", "hang") or w.done >= max_tasks:
                w.stop(kill=res["outcome"] in ("crash", "hang"))
                workers[i] = Worker(memory, worker)
            else:
                w.case = None
        if progress and time.perf_counter() > next_print:
            next_print += 60
            c = collections.Counter(r["outcome"].split(":")[0] for r in rows)
            print(f"{len(rows)} cases: {dict(c)}", flush=True)
    for w in workers:
        w.stop()
    return rows


def is_finding(r: dict) -> bool:
    return r["outcome"].split(":")[0] not in NOT_FINDINGS


def group_key(r: dict) -> str:
    """Similar cases share a key: the outcome and the raising line (exceptions) or the message with
    its numbers and quoted names blanked."""
    if r.get("traceback"):
        frames = re.findall(r'File "([^"]+)", line (\d+), in (\w+)', r["traceback"])
        f = frames[-1] if frames else ("?", "?", "?")
        return f"{r['outcome']} at {Path(f[0]).name}:{f[1]} in {f[2]}"
    detail = re.sub(r"'[^']*'", "'#'", re.sub(r"[-+]?[0-9][0-9.e+-]*", "#", r["detail"]))
    return f"{r['outcome']}: {detail[:150]}"


def repro(case: dict) -> list[str]:
    """Markdown lines that reproduce a case: the scene's redrawn bodies, or its .geo file."""
    md = [f"- `{call(case)}`: {case['base']}, level {case['level']}, route "
          f"{case['route']}, hostile `{case['hostile'] or '-'}`", ""]
    if case["files"]:
        geo = case["files"]["body.geo"]
        lines = geo.splitlines()
        md += [f"  body `{case['geo_body']}` from this .geo file ({len(lines)} lines, {len(geo)} characters):", "",
               "```", *(line[:200] for line in lines[:60]), *(["..."] if len(lines) > 60 else []), "```", ""]
    else:
        for name, b in case["data"]["bodies"].items():
            keep = {k: b[k] for k in ("x", "face", "outline", "holes") if k in b}
            md += [f"  body `{name}`: `{json.dumps(keep)[:3000]}`", ""]
    return md


def cases_md(rows: list[dict], with_repro: bool = True) -> list[str]:
    groups = collections.defaultdict(list)
    for r in rows:
        groups[group_key(r)].append(r)
    md = []
    for key, rs in sorted(groups.items(), key=lambda kv: -len(kv[1])):
        r = rs[0]
        md += [f"### {key} ({len(rs)} cases: {', '.join(str(x['id']) for x in rs[:20])})", "",
               f"- case {r['id']}: {r['detail'][:600]}", ""]
        if with_repro:
            try:
                md += repro({**case_of(r), "levels": r["levels"], "shares": r["shares"]})
            except Exception as e:  # the generator's own failure (an oracle-error finding)
                md += [f"- `{call(r)}` fails: {e!r}"[:300], ""]
        if r.get("traceback"):
            md += ["```", *r["traceback"].rstrip().splitlines()[-8:], "```", ""]
    return md


def table(rows: list[dict], by: str) -> list[str]:
    counts = collections.defaultdict(collections.Counter)
    for r in rows:
        counts["-" if r.get(by) in (None, "") else str(r[by])][r["outcome"].split(":")[0]] += 1
    cols = sorted({o for c in counts.values() for o in c})
    lines = [f"| {by} | " + " | ".join(cols) + " |", "|---" * (len(cols) + 1) + "|"]
    return lines + [f"| {k} | " + " | ".join(str(c.get(o, 0)) for o in cols) + " |" for k, c in sorted(counts.items())]


def report(rows: list[dict], out: Path, args, seconds: float) -> list[dict]:
    findings = [r for r in rows if is_finding(r)]
    out.mkdir(parents=True, exist_ok=True)
    buf = io.StringIO()
    w = csv.DictWriter(buf, FIELDS, extrasaction="ignore")
    w.writeheader()
    w.writerows({**r, "seconds": f"{r['seconds']:.3f}"} for r in sorted(rows, key=lambda r: r["id"]))
    write_text(out / "fuzz_outlines.csv", buf.getvalue())
    md = ["# Fuzzing of outline bodies\n",
          f"`python studies/fuzz_outlines.py --cases {args.cases} --seed {args.seed} --levels "
          f"{' '.join(map(str, args.levels))} --hostile {args.hostile:g} --geo {args.geo:g}`: {len(rows)} cases in "
          f"{seconds / 60:.1f} min ({args.workers} worker), {len(findings)} findings.\n",
          "| outcome | cases |", "|---|---|"]
    md += [f"| {o} | {n} |" for o, n in sorted(collections.Counter(r["outcome"] for r in rows).items())]
    for by in ("route", "base", "level", "hostile"):
        md += [""] + table(rows, by)
    plausible = [r for r in rows if not r.get("hostile") and r["outcome"].startswith("rejected")]
    sections = (("Findings", findings, True),
                ("Refusals of plausible (not hostile) cases: not findings, worth a look", plausible, False))
    for title, sel, rep in sections:
        md += ["", f"## {title}" if sel else f"## {title}: none", ""] + cases_md(sel, rep)
        if rep and sel:
            md += ["Each finding's whole case (scene dict, files) is in fuzz_outlines_failures/ID.json.", ""]
    write_text(out / "fuzz_outlines.md", "\n".join(md) + "\n")
    for r in findings:
        (out / "fuzz_outlines_failures").mkdir(exist_ok=True)
        try:
            case = case_of(r)
        except Exception:
            continue
        keep = {k: case[k] for k in ("seed", "base", "level", "route", "hostile", "must_refuse", "geo_body", "data",
                                     "files")}
        # json.dumps, not write_json: NaN and inf must survive (as NaN/Infinity) to reproduce the case
        write_text(out / "fuzz_outlines_failures" / f"{r['id']}.json",
                   json.dumps({"outcome": r["outcome"], "detail": r["detail"], "traceback": r.get("traceback", ""),
                               "case": keep}, indent=1) + "\n")
    return findings


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cases", type=int, default=300)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--levels", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--out", default="reports")
    p.add_argument("--hostile", type=float, default=HOSTILE_SHARE, help="share of hostile cases")
    p.add_argument("--geo", type=float, default=GEO_SHARE, help="share of cases with a body in a .geo file")
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--timeout", type=float, default=60.0, help="seconds per case")
    p.add_argument("--memory", type=float, default=4.0, help="GB of address space per worker")
    p.add_argument("--max-tasks", type=int, default=100, help="cases per worker process before a fresh one")
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    todo = specs(args.cases, args.seed, args.levels, args.hostile, args.geo)
    rows = fuzz(todo, args.workers, args.timeout, int(args.memory * 2**30), args.max_tasks)
    findings = report(rows, Path(args.out), args, time.perf_counter() - t0)
    print(f"{len(rows)} cases, {len(findings)} findings: {Path(args.out) / 'fuzz_outlines.md'}")
    return 1 if findings else 0


if __name__ == "__main__":
    sys.exit(main())
