"""The built-in speed study (spec: cvxdual/study/specs/speed.*): writes reports/speed.*

    python studies/speed.py                   # the full study, into reports/
    python studies/speed.py --quick           # coarse sizes, into out/speed-quick
    python studies/speed.py --scheduler tcp://HOST:8786   # on a running Dask scheduler

Same as `cvxdual study speed --out reports --workers 1 --memory-limit 16GB`; interrupted runs
resume from the cache (.cache/cvxdual).
"""

import sys

from cvxdual.cli import main

if __name__ == "__main__":
    argv = sys.argv[1:]
    if "--out" not in argv and "--quick" not in argv:
        argv += ["--out", "reports"]
    if "--quick" not in argv:
        # cylinder-in-groove's level-7 reference needs ~12 GB (size estimate), and one case at a
        # time keeps a neighbouring case out of every timing
        for flag, value in (("--workers", "1"), ("--memory-limit", "16GB")):
            if flag not in argv:
                argv += [flag, value]
    sys.exit(main(["study", "speed", *argv]))
