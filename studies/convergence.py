"""The convergence study (spec: studies/specs/convergence.toml): writes reports/convergence.*

    python studies/convergence.py                   # the full study, into reports/
    python studies/convergence.py --quick           # coarse sizes, into out/convergence-quick
    python studies/convergence.py --scheduler tcp://HOST:8786   # on a running Dask scheduler

Same as `cvxdual study run studies/specs/convergence.toml --out reports --workers 1 --memory-limit 20GB`;
interrupted runs resume from the cache (.cache/cvxdual).
"""

import sys

from run_study import run_spec

# level-7 references: up to 16 GB each by the size estimate; one at a time
FULL = {"--workers": "1", "--memory-limit": "20GB"}

if __name__ == "__main__":
    sys.exit(run_spec("convergence", FULL))
