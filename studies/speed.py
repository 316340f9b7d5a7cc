"""Speed against error: writes reports/speed.csv, speed_scaling.png, speed_pareto.png, speed.md

    python studies/speed.py            # the full study (about 40 minutes on 2 cores)
    python studies/speed.py --quick    # small sizes, into out/speed-quick

Interrupted runs resume from the cache (.cache/cvxdual). Same as `cvxdual study speed`.
"""

import sys

from cvxdual.study.speed import main

if __name__ == "__main__":
    sys.exit(main())
