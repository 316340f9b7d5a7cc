"""The built-in stability study (spec: cvxdual/study/specs/stability.*): writes reports/stability.*

    python studies/stability.py                   # the full study, into reports/
    python studies/stability.py --quick           # coarse sizes, into out/stability-quick
    python studies/stability.py --scheduler tcp://HOST:8786   # on a running Dask scheduler

Same as `cvxdual study stability --out reports --memory-limit 8GB`; interrupted runs resume
from the cache (.cache/cvxdual).
"""

import sys

from cvxdual.cli import main

if __name__ == "__main__":
    argv = sys.argv[1:]
    if "--out" not in argv and "--quick" not in argv:
        argv += ["--out", "reports"]
    if "--memory-limit" not in argv and "--quick" not in argv:
        argv += ["--memory-limit", "8GB"]  # hertz at level 6 and wavy at level 5 outgrow 4GB workers
    sys.exit(main(["study", "stability", *argv]))
