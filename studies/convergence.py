"""The built-in convergence study (spec: cvxdual/study/specs/convergence.*): writes reports/convergence.*

    python studies/convergence.py                   # the full study, into reports/
    python studies/convergence.py --quick           # coarse sizes, into out/convergence-quick
    python studies/convergence.py --scheduler tcp://HOST:8786   # on a running Dask scheduler

Same as `cvxdual study convergence --out reports --workers 1 --memory-limit 20GB`; interrupted
runs resume from the cache (.cache/cvxdual).
"""

import sys

from cvxdual.cli import main

if __name__ == "__main__":
    argv = sys.argv[1:]
    if "--out" not in argv and "--quick" not in argv:
        argv += ["--out", "reports"]
    if "--quick" not in argv:  # level-7 references: up to 16 GB each by the size estimate; one at a time
        for flag, value in (("--workers", "1"), ("--memory-limit", "20GB")):
            if flag not in argv:
                argv += [flag, value]
    sys.exit(main(["study", "convergence", *argv]))
