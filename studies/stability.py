"""Numerical stability on hard cases: writes reports/stability.csv and reports/stability.md

    python studies/stability.py            # every case on every path and triangulation
    python studies/stability.py --quick    # a few cases at level <= 1, into out/stability-quick

Interrupted runs resume from the cache (.cache/cvxdual). Same as `cvxdual study stability`.
"""

import sys

from cvxdual.study.stability import main

if __name__ == "__main__":
    sys.exit(main())
