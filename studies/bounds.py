"""The built-in bounds study (spec: cvxdual/study/specs/bounds.py): writes reports/bounds.*

    python studies/bounds.py                   # the full study, into reports/
    python studies/bounds.py --quick           # coarse sizes, into out/bounds-quick
    python studies/bounds.py --scheduler tcp://HOST:8786   # on a running Dask scheduler

Same as `cvxdual study bounds --out reports --memory-limit 8GB`; interrupted runs resume
from the cache (.cache/cvxdual).
"""

import sys

from cvxdual.cli import main

if __name__ == "__main__":
    argv = sys.argv[1:]
    if "--out" not in argv and "--quick" not in argv:
        argv += ["--out", "reports"]
    if "--memory-limit" not in argv and "--quick" not in argv:
        argv += ["--memory-limit", "8GB"]  # the eq space at level 5 peaks at 5.9 GB (reports/memory.md)
    sys.exit(main(["study", "bounds", *argv]))
