"""Convergence of ||lam_h - lam*||_0 for both triangulations: writes reports/convergence.*

    python studies/convergence.py            # the full study (about 15 minutes on 2 cores)
    python studies/convergence.py --quick    # coarse levels, into out/convergence-quick

Interrupted runs resume from the cache (.cache/cvxdual). Same as `cvxdual study convergence`.
"""

import sys

from cvxdual.study.convergence import main

if __name__ == "__main__":
    sys.exit(main())
