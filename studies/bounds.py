"""The bounds study (spec: studies/specs/bounds.py): writes reports/bounds.*

    python studies/bounds.py                   # the full study, into reports/
    python studies/bounds.py --quick           # coarse sizes, into out/bounds-quick
    python studies/bounds.py --scheduler tcp://HOST:8786   # on a running Dask scheduler

Same as `cvxdual study run studies/specs/bounds.py --out reports --workers 1 --memory-limit 16GB`;
interrupted runs resume from the cache (.cache/cvxdual).
"""

import sys

from run_study import run_spec

# the curved scenes' eq references at level 6 need up to ~10 GB (reports/memory.md): one at a time
FULL = {"--workers": "1", "--memory-limit": "16GB"}

if __name__ == "__main__":
    sys.exit(run_spec("bounds", FULL))
