"""``cvxdual study run SPEC``: run the study of a spec file."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .spec import DEFAULT_CACHE, DEFAULT_MEMORY

EPILOG = """examples:
  cvxdual study run my_study.toml --out out/my_study
  cvxdual study run my_study.toml --scheduler tcp://10.0.0.5:8786   # a running `dask scheduler`
  cvxdual study run studies/specs/convergence.toml --quick          # the project's convergence study
A spec is a TOML (or Python) file: see docs/studies.md and the project's specs in studies/specs/.
Finished cases are cached (--cache), so an interrupted study resumes where it stopped."""


def _options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default=None, help="output directory (default: out/NAME, or out/NAME-quick)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="address of a running Dask scheduler (default: a local cluster of worker processes)")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="worker processes of the local cluster (default: min(2, CPUs))")
    p.add_argument("--memory-limit", default=DEFAULT_MEMORY, metavar="SIZE",
                   help=f"memory limit per local worker; a case over it is a failed row (default: {DEFAULT_MEMORY})")
    p.add_argument("--cache", default=DEFAULT_CACHE, metavar="DIR",
                   help=f"cache of finished cases, for resuming ('' to disable; default: {DEFAULT_CACHE})")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--quick", action="store_true", help="the spec's quick variant (coarse levels)")


def add_parser(sub) -> argparse.ArgumentParser:
    """Add ``study`` to the subparsers ``sub`` of the main parser."""
    st = sub.add_parser("study", help="run a study: a spec of scenes, levels, solvers and overrides on Dask",
                        description="Run a study (a spec of cases) on a Dask cluster and write its table, "
                        "report and plots.", epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    ss = st.add_subparsers(dest="study_command", required=True)
    r = ss.add_parser("run", help="run the study of a spec file (TOML or Python)",
                      description="Run the study of a spec file (TOML or Python).")
    r.add_argument("spec", help="spec file (.toml or .py)")
    _options(r)
    return st


def main(args) -> int:
    from .runner import run
    from .spec import load_spec
    study = load_spec(args.spec, quick=args.quick)
    out = Path(args.out) if args.out else Path("out") / (study.name + ("-quick" if args.quick else ""))
    df = run(study, out, scheduler=args.scheduler, workers=args.workers, memory_limit=args.memory_limit,
             cache=args.cache or None, quiet=args.quiet)
    ok = df["status"].astype(str).str.startswith("optimal")
    cached = int(df["cached"].sum()) if "cached" in df else 0
    print(f"study {study.name}: {len(df)} cases, {int(ok.sum())} solved, {int((~ok).sum())} failed, "
          f"{cached} from the cache; wrote {out}/")
    if len(df) and not ok.any():
        print(f"cvxdual: error: study {study.name}: no case was solved; see the status column of "
              f"{out / (study.name + '.csv')}", file=sys.stderr)
        return 1
    return 0
