"""The built-in speed study (spec: cvxdual/study/specs/speed.*): writes reports/speed.*

    python studies/speed.py                   # the full study, into reports/
    python studies/speed.py --quick           # coarse sizes, into out/speed-quick
    python studies/speed.py --scheduler tcp://HOST:8786   # on a running Dask scheduler

Same as `cvxdual study speed --out reports`; interrupted runs resume from the cache (.cache/cvxdual).
"""

import sys

from cvxdual.cli import main

if __name__ == "__main__":
    argv = sys.argv[1:]
    if "--out" not in argv and "--quick" not in argv:
        argv += ["--out", "reports"]
    sys.exit(main(["study", "speed", *argv]))
