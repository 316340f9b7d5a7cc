"""The stability study (spec: studies/specs/stability.py): writes reports/stability.*

    python studies/stability.py                   # the full study, into reports/
    python studies/stability.py --quick           # coarse sizes, into out/stability-quick
    python studies/stability.py --scheduler tcp://HOST:8786   # on a running Dask scheduler

Same as `cvxdual study run studies/specs/stability.py --out reports --memory-limit 8GB`;
interrupted runs resume from the cache (.cache/cvxdual).
"""

import sys

from run_study import run_spec

# hertz at level 6 and wavy at level 5 outgrow 4GB workers
FULL = {"--memory-limit": "8GB"}

if __name__ == "__main__":
    sys.exit(run_spec("stability", FULL))
