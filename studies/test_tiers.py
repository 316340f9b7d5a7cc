"""The test tiers, measured: writes reports/test_tiers.md and .csv.

    python studies/test_tiers.py          # both tiers, then the quick tier under coverage (~12 min)
    python studies/test_tiers.py --mark   # also mark @pytest.mark.slow the slowest functions until
                                          # the rest fits --budget seconds of test time

The quick tier is ``pytest -m "not slow"``; the whole suite is the README's test command. Both run
here one after the other on the same machine (wall time of the pytest process, and each test's
own time from ``--durations=0``). The quick tier is then run under ``coverage`` (if installed:
``pip install coverage``; not a dependency of the package) to show that it still runs code of
every module of ``cvxdual``: modules with no line run are listed.
"""

import argparse
import ast
import collections
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

from cvxdual.files import write_text
from cvxdual.study.report import md_table

ROOT = Path(__file__).resolve().parent.parent
DURATION = re.compile(r"^([\d.]+)s (call|setup|teardown)\s+(tests/[^:\s]+)::(\S+)$", re.M)


def run(args: list[str]) -> tuple[float, str]:
    """Wall seconds and output of ``python -m pytest -q --durations=0 args`` (``args`` starts with ``pytest``)."""
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", *args, "-q", "--durations=0"], cwd=ROOT, capture_output=True,
                       text=True)
    out = p.stdout + p.stderr
    if p.returncode:
        raise SystemExit(f"{' '.join(args)} failed:\n{out[-3000:]}")
    return time.perf_counter() - t0, out


def per_function(out: str) -> collections.Counter:
    """Seconds per test function (its parameters, setup and teardown summed)."""
    tot = collections.Counter()
    for sec, _, f, node in DURATION.findall(out):
        tot[(f, node.split("::")[-1].split("[")[0])] += float(sec)
    return tot


def counted(out: str) -> int:
    m = re.search(r"(\d+) passed", out)
    return int(m.group(1)) if m else 0


def mark(tot: collections.Counter, budget: float) -> list[tuple[str, str]]:
    """Decorate the slowest functions ``@pytest.mark.slow`` until the rest fits ``budget``."""
    rest, slow = sum(tot.values()), []
    for key, sec in tot.most_common():
        if rest <= budget:
            break
        slow.append(key)
        rest -= sec
    byfile = collections.defaultdict(set)
    for f, name in slow:
        byfile[f].add(name)
    for f, names in byfile.items():
        path = ROOT / f
        src = path.read_text()
        lines = src.splitlines(keepends=True)
        spots = [(min([d.lineno for d in n.decorator_list] + [n.lineno]), n.col_offset)
                 for n in ast.walk(ast.parse(src)) if isinstance(n, ast.FunctionDef) and n.name in names
                 and not any(ast.unparse(d) == "pytest.mark.slow" for d in n.decorator_list)]
        for line, col in sorted(spots, reverse=True):
            lines.insert(line - 1, " " * col + "@pytest.mark.slow\n")
        path.write_text("".join(lines))
    return slow


def unrun_modules() -> list[str] | None:
    """``cvxdual`` modules of which the quick tier runs no line (None: coverage not installed)."""
    try:
        import coverage  # noqa: F401
    except ImportError:
        return None
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "COVERAGE_FILE": str(Path(tmp) / ".coverage")}
        report = Path(tmp) / "cov.json"
        # the test process only: subprocesses (python -m cvxdual, Dask workers, gmsh's fence) are not counted
        for args in (["run", "--source=cvxdual", "-m", "pytest", "-q", "-m", "not slow"],
                     ["json", "-q", "-o", str(report)]):
            subprocess.run([sys.executable, "-m", "coverage", *args], cwd=ROOT, env=env, capture_output=True, text=True)
        files = json.loads(report.read_text())["files"]
    every = {str(p.relative_to(ROOT)) for p in (ROOT / "cvxdual").rglob("*.py")}
    ran = {f for f, v in files.items() if v["summary"]["covered_lines"] > 0 or v["summary"]["num_statements"] == 0}
    return sorted(every - ran)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mark", action="store_true")
    p.add_argument("--budget", type=float, default=75.0, help="seconds of test time the quick tier may take")
    p.add_argument("--out", default="reports")
    args = p.parse_args(argv)
    if args.mark:
        _, out = run(["pytest"])
        print(f"marked {len(mark(per_function(out), args.budget))} functions slow")
    full_wall, full = run(["pytest"])
    quick_wall, quick = run(["pytest", "-m", "not slow"])
    unrun = unrun_modules()
    tot = per_function(full)
    rows = pd.DataFrame([{"tier": "whole suite", "tests": counted(full), "wall_s": full_wall,
                          "test_time_s": sum(tot.values())},
                         {"tier": "quick (-m 'not slow')", "tests": counted(quick), "wall_s": quick_wall,
                          "test_time_s": sum(per_function(quick).values())}])
    quick_tot = per_function(quick)
    top = "\n".join(f"| {f}::{n} | {s:.2f} |" for (f, n), s in quick_tot.most_common(10))
    lines = ["# Test tiers", "", "Made by `python studies/test_tiers.py`: both tiers run one after the other here.", "",
             md_table(rows.round(1)), "",
             "The slowest functions left in the quick tier:", "", "| test | s |", "|---|---|", top, "",
             "Modules of `cvxdual` the quick tier runs no line of in its own process (under `coverage`): "
             + ("coverage not installed, not measured" if unrun is None else (", ".join(unrun) or "none"))
             + ".", ""]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_text(out / "test_tiers.csv", rows.to_csv(index=False, float_format="%.2f"))
    write_text(out / "test_tiers.md", "\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
