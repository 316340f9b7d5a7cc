"""The acceptance experiment of output sets (issues 13 and 26): `kill -9` at random moments of a level-6 write.

    python studies/kill_write.py                    # 20 trials + 14 kills in a row at level 6, reports/kill_write.md
    python studies/kill_write.py --level 2 --trials 5 --in-a-row 4 --report out/kill_write.md    # a quick check

Two distinguishable sets: `hertz` at level 6 with the fast solver (A) and the same with a lower
load (B, `exact.load=30000`), each written once into a reference directory and hashed; T is the
mean time of two full writes over an existing set by a forked child, as in the trials. Per
trial, the target holds one set; a forked child writes the other into it and is killed (SIGKILL)
at a uniformly random moment in [0, 1.1 T]. The target must then be byte-identical to A or to B.
A complete write follows (the next run), which must leave the target holding its set and nothing
else in the parent directory (no staging directories, no temporaries).

Kills in a row (issue 26): N writers, alternating sets, each killed at a uniformly random moment
of [0.05 T, 0.95 T] with no completed run between them; the parent directory is polled every
few milliseconds while each writer runs, and the largest number of staging directories (killed
runs' and the live writer's, ``.set.stage-*`` and ``.set.old-*``) seen at any time must be at
most one. A completed run follows and must leave nothing. Exits 1 if any trial saw a mix or
leftovers after the next run, or the kills in a row ever left more than one staging directory.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import random
import shutil
import signal
import sys
import time
from pathlib import Path

import cvxdual
from cvxdual import files
from cvxdual.files import write_text
from cvxdual.outputs.output_set import write_outputs
from cvxdual.scene.scenefile import load_scene, parse_assignment

ROOT = Path(__file__).resolve().parents[1]


def digest(d: Path) -> dict[str, str] | None:
    """File name -> sha256 of directory ``d`` (None if it is missing)."""
    if not d.is_dir():
        return None
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(d.iterdir())}


def leftovers(parent: Path, target: Path) -> str:
    """Everything in ``parent`` but ``target``, and hidden entries inside ``target``, with sizes."""
    extra = [p for p in parent.iterdir() if p != target]
    if target.is_dir():
        extra += [p for p in target.iterdir() if p.name.startswith(".")]
    if not extra:
        return "none"
    size = sum(f.stat().st_size for p in extra for f in ([p] if p.is_file() else p.rglob("*")) if f.is_file())
    return f"{', '.join(sorted(p.name for p in extra))} ({size / 1e6:.1f} MB)"


def forked_write(sol, target: Path) -> float:
    """Seconds for a forked child to write ``sol`` to ``target`` (the trials' conditions)."""
    t0 = time.perf_counter()
    pid = os.fork()
    if pid == 0:
        code = 1
        try:
            write_outputs(sol, target)
            code = 0
        finally:
            os._exit(code)
    _, status = os.waitpid(pid, 0)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0, "a full write failed"
    return time.perf_counter() - t0


def stagings(parent: Path, target: Path) -> int:
    """Staging directories of ``target`` in ``parent`` (a writer's own, or a killed one's)."""
    try:
        names = os.listdir(parent)
    except FileNotFoundError:
        return 0
    return sum(n.startswith((f".{target.name}.stage-", f".{target.name}.old-")) for n in names)


def killed_write(sol, target: Path, delay: float) -> tuple[bool, float, int]:
    """Fork a child writing ``sol`` to ``target`` and SIGKILL it ``delay`` s after the fork,
    polling the staging directories meanwhile; returns (killed before it finished, seconds after
    the fork when the kill was sent, most staging directories seen, after the kill too)."""
    parent = target.parent
    most = stagings(parent, target)
    t0 = time.perf_counter()
    pid = os.fork()
    if pid == 0:
        try:
            write_outputs(sol, target)
        finally:
            os._exit(0)
    while time.perf_counter() < t0 + delay:
        most = max(most, stagings(parent, target))
        time.sleep(POLL)
    at = time.perf_counter() - t0
    os.kill(pid, signal.SIGKILL)
    _, status = os.waitpid(pid, 0)
    return os.WIFSIGNALED(status), at, max(most, stagings(parent, target))


POLL = 0.005  # seconds between two looks at the parent directory


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--level", type=int, default=6)
    ap.add_argument("--in-a-row", type=int, default=14, help="kills with no completed run between them")
    ap.add_argument("--seed", type=int, default=13)
    ap.add_argument("--work", type=Path, default=ROOT / "out" / "kill_write", help="scratch directory (removed)")
    ap.add_argument("--report", type=Path, default=ROOT / "reports" / "kill_write.md")
    args = ap.parse_args(argv)
    rng = random.Random(args.seed)
    started = time.perf_counter()

    scene_a = load_scene("hertz")
    scene_b = load_scene("hertz", [parse_assignment("exact.load=30000.0")])
    print(f"solving hertz at level {args.level} (two loads) ...", flush=True)
    sols = {k: cvxdual.solve(s, level=args.level, solver="fast") for k, s in (("A", scene_a), ("B", scene_b))}
    shutil.rmtree(args.work, ignore_errors=True)
    parent = args.work / "target"
    parent.mkdir(parents=True)
    target = parent / "set"
    refs = {}
    for k, sol in sols.items():
        write_outputs(sol, args.work / f"ref{k}")
        refs[k] = digest(args.work / f"ref{k}")
    assert refs["A"] != refs["B"]
    write_outputs(sols["A"], target)
    times = [forked_write(sols[k], target) for k in ("B", "A", "B", "A")]  # T: as in the trials, ends with A
    T, T_min = sum(times) / len(times), min(times)
    size = sum(p.stat().st_size for p in (args.work / "refA").iterdir()) / 1e6
    print(f"full write T = {T:.2f} s ({size:.1f} MB, {len(refs['A'])} files)", flush=True)

    rows, bad, trial_bad = [], 0, 0
    for i in range(1, args.trials + 1):
        held = next(k for k, h in refs.items() if h == digest(target))
        other = "B" if held == "A" else "A"
        killed, at, _ = killed_write(sols[other], target, rng.uniform(0.0, 1.1 * T))
        got = digest(target)
        outcome = next((k for k, h in refs.items() if h == got), "missing" if got is None else "MIX")
        before = leftovers(parent, target)
        write_outputs(sols[other], target)  # the next run
        after = leftovers(parent, target)
        ok = outcome in refs and after == "none" and digest(target) == refs[other]
        bad += not ok
        trial_bad += not ok
        rows.append(f"| {i} | {held} -> {other} | {at:.2f} | {at / T:.0%} | {'killed' if killed else 'had finished'} "
                    f"| {outcome} | {before} | {after} | {'yes' if ok else 'NO'} |")
        print(rows[-1], flush=True)

    # kills in a row: no completed run between them (a writer that finished before its kill is a
    # completed run: the count starts again)
    t_row = time.perf_counter()
    row_rows, most_ever, in_row, attempt = [], 0, 0, 0
    while in_row < args.in_a_row and attempt < 3 * args.in_a_row:
        attempt += 1
        other = "B" if attempt % 2 else "A"
        killed, at, most = killed_write(sols[other], target, rng.uniform(0.05 * T_min, 0.9 * T_min))
        in_row = in_row + 1 if killed else 0
        got = digest(target)
        outcome = next((k for k, h in refs.items() if h == got), "missing" if got is None else "MIX")
        most_ever = max(most_ever, most)
        bad += outcome not in refs or most > 1
        row_rows.append(f"| {attempt} | {in_row if killed else '-'} | {other} | {at:.2f} | {at / T:.0%} "
                        f"| {'killed' if killed else 'had finished (count starts again)'} | {outcome} | {most} "
                        f"| {leftovers(parent, target)} |")
        print(row_rows[-1], flush=True)
    bad += in_row < args.in_a_row
    t_row = time.perf_counter() - t_row
    last = "A" if digest(target) != refs["A"] else "B"
    write_outputs(sols[last], target)  # the next completed run
    after_row = leftovers(parent, target)
    bad += after_row != "none" or digest(target) != refs[last]
    shutil.rmtree(args.work)
    total = time.perf_counter() - started

    swap = "renameat2(RENAME_EXCHANGE)" if files.HAS_EXCHANGE else "two renames (fallback)"
    text = "\n".join([
        "# Output sets under `kill -9`",
        "",
        f"Generated by `studies/kill_write.py` (seed {args.seed}). Target: the output set of `hertz` at level "
        f"{args.level} (`--solver fast`), {len(refs['A'])} files, {size:.1f} MB; set A at the scene's load, set B "
        f"with `exact.load=30000`. Full write T = {T:.2f} s (the mean of {len(times)} by a forked writer, "
        f"{', '.join(f'{t:.2f}' for t in times)} s); swap by {swap}.",
        "",
        "Per trial, a forked writer of the other set is killed (SIGKILL) at a uniformly random moment of "
        "[0, 1.1 T] after the fork; the target is then compared, file by file (sha256), with the reference sets. "
        "'Leftovers' are the entries of the target's parent other than the target (and hidden files in it), "
        "before and after the next complete run.",
        "",
        "| trial | set: held -> written | kill at [s] | of T | writer | target after the kill | leftovers before "
        "the next run | leftovers after it | ok |",
        "|---|---|---|---|---|---|---|---|---|",
        *rows,
        "",
        f"{args.trials - trial_bad} of {args.trials} trials ok: " + (
            "the target was always the old set or the new one, and the next run left nothing behind."
            if not trial_bad else "SOME TRIALS FAILED."),
        "",
        f"## {args.in_a_row} kills in a row",
        "",
        f"Each writer (of the set named) killed at a uniformly random moment of [0.05 T_min, 0.9 T_min] after the "
        f"fork (T_min = {T_min:.2f} s, the shortest of the {len(times)} full writes), with no completed run between "
        f"the kills (a writer that finished first would be one: the count starts again); 'most staging "
        f"directories' is the largest count of "
        f"`.set.stage-*` and `.set.old-*` in the parent seen while the writer ran (polled every {POLL * 1e3:.0f} ms) "
        "and after the kill: a killed run's, or the live writer's own. Each run removes the leftovers of killed "
        "runs before it creates its staging directory (and `cvxdual solve` before its solve); before issue 26 they "
        "went only at a completed run's swap, and 14 kills in a row left 14 (1.66 GB).",
        "",
        "| writer | kills in a row | set written | kill at [s] | of T | writer | target after the kill "
        "| most staging directories | leftovers after the kill |",
        "|---|---|---|---|---|---|---|---|---|",
        *row_rows,
        "",
        f"Most staging directories at any time: {most_ever} (at most 1 required); {in_row} kills in a row, "
        f"{attempt} writers in {t_row:.0f} s. Leftovers after the next completed run: {after_row}.",
        "",
        f"Whole experiment: {total / 60:.1f} min.",
        "",
    ])
    write_text(args.report, text)
    print(f"wrote {args.report}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
