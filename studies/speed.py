"""The speed study (spec: studies/specs/speed.py): writes reports/speed.*

    python studies/speed.py                   # the full study, into reports/
    python studies/speed.py --quick           # coarse sizes, into out/speed-quick
    python studies/speed.py --scheduler tcp://HOST:8786   # on a running Dask scheduler

Same as `cvxdual study run studies/specs/speed.py --out reports --workers 1 --memory-limit 16GB`;
interrupted runs resume from the cache (.cache/cvxdual).
"""

import sys

from run_study import run_spec

# cylinder-in-groove's level-7 reference needs ~12 GB (size estimate), and one case at a
# time keeps a neighbouring case out of every timing
FULL = {"--workers": "1", "--memory-limit": "16GB"}

if __name__ == "__main__":
    sys.exit(run_spec("speed", FULL))
