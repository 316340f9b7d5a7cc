"""The peers study (cvxdual/study/peers.py): cvxdual's fast path against dolfinx on the hertz problem,
same meshes, same run; writes reports/peers.md and reports/peers.csv

    python studies/peers.py                  # levels 0-6, into reports/
    python studies/peers.py --quick          # levels 0-2, into out/peers-quick
    python studies/peers.py --no-peer        # cvxdual only

Same as `cvxdual study peers --out reports`. The first run makes dolfinx's virtual environment
(.cache/cvxdual/peers/dolfinx-venv: Python >= 3.12 and `pip install dolfinx-solver-real`, about 350 MB);
where that is impossible the report covers cvxdual alone and says why.
"""

import sys

from cvxdual.cli import main

if __name__ == "__main__":
    argv = sys.argv[1:]
    if "--out" not in argv and "--quick" not in argv:
        argv += ["--out", "reports"]
    sys.exit(main(["study", "peers", *argv]))
