"""The bounds study (spec: studies/specs/bounds.py): writes reports/bounds.*

    python studies/bounds.py                   # the full study, into reports/
    python studies/bounds.py --quick           # coarse sizes, into out/bounds-quick
    python studies/bounds.py --scheduler tcp://HOST:8786   # on a running Dask scheduler

Same as `cvxdual study run studies/specs/bounds.py --out reports --memory-limit 8GB`;
interrupted runs resume from the cache (.cache/cvxdual).
"""

import sys

from run_study import run_spec

# the eq space at level 5 peaks at 2.6 GB (reports/memory.md)
FULL = {"--memory-limit": "8GB"}

if __name__ == "__main__":
    sys.exit(run_spec("bounds", FULL))
