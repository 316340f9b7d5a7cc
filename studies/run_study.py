"""What the study scripts beside this file share: run a spec of ``studies/specs/`` through
``cvxdual study run``, into ``reports/`` unless ``--out`` or ``--quick`` is given, with the
options its full run needs (``full``) unless the command line sets them."""

import sys
from pathlib import Path

from cvxdual.cli import main

SPECS = Path(__file__).resolve().parent / "specs"


def run_spec(name: str, full: dict[str, str] | None = None, argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    spec = next(p for p in (SPECS / f"{name}.toml", SPECS / f"{name}.py") if p.is_file())
    if "--quick" not in argv:
        if "--out" not in argv:
            argv += ["--out", "reports"]
        for flag, value in (full or {}).items():
            if flag not in argv:
                argv += [flag, value]
    return main(["study", "run", str(spec), *argv])
