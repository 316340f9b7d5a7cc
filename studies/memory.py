"""Peak memory of whole solves against the size estimate of cvxdual.sizing: writes
reports/memory.md and reports/memory.csv.

    python studies/memory.py                 # hertz and the curved scenes, levels 3-6
    python studies/memory.py --quick         # levels 2-3 only, into out/memory-quick

Each case runs in a fresh interpreter (peak resident memory, ``VmHWM``, is a high-water
mark: a worker that ran other cases first would report theirs), so this study does not use
the Dask runner. The estimate is what ``solve`` checks before allocating; the ratio
``measured / estimated`` should stay below 1 (an estimate that errs on the safe side).
"""

import argparse
import json
import subprocess
import sys
from pathlib import Path

import pandas as pd

from cvxdual import load_scene
from cvxdual.files import write_text
from cvxdual.sizing import estimate
from cvxdual.study.report import md_table

CHILD = r"""
import json, sys
import cvxdual as cd
from cvxdual.sizing import peak_mb
scene, tri, level, solver, space = sys.argv[1:6]
sol = cd.solve(scene, tri, int(level), solver, stress_space=space, max_memory="none")
peak = peak_mb() * 2**20  # VmHWM: ru_maxrss would carry this study's own peak across exec
print(json.dumps({"triangles": len(sol.mesh.triangles()), "peak": peak}))
"""

CASES = [  # (scene, triangulation, solver, stress space, levels)
    ("hertz", "type1", "CLARABEL", "p0", (3, 4, 5)),
    ("hertz", "type1", "fast", "p0", (3, 4, 5, 6)),
    ("hertz", "type1", "fast", "eq", (3, 4, 5)),
    ("cylinder-on-block", "type2", "fast", "eq", (3, 4, 5, 6)),
    ("cylinder-in-groove", "type1", "fast", "eq", (4, 5)),
    ("wavy", "type2", "fast", "eq", (4, 5)),
    ("hertz", "type1", "CLARABEL", "eq", (2, 3)),
    ("cylinder-in-groove", "type2", "CLARABEL", "p0", (3, 4)),
    ("cylinder-in-groove", "type2", "fast", "p0", (4, 5)),
    ("wavy", "type1", "fast", "p0", (4, 5)),
]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    out = Path(args.out or ("out/memory-quick" if args.quick else "reports"))
    rows = []
    for scene, tri, solver, space, levels in CASES:
        for level in (lv for lv in levels if not args.quick or lv <= 3):
            est = estimate(load_scene(scene), level, solver == "fast", space)
            r = subprocess.run([sys.executable, "-c", CHILD, scene, tri, str(level), solver, space],
                               capture_output=True, text=True)
            got = json.loads(r.stdout.strip().splitlines()[-1]) if r.returncode == 0 else {}
            rows.append({"scene": scene, "triangulation": tri, "solver": solver, "stress_space": space, "level": level,
                         "triangles": got.get("triangles"), "triangles_estimated": int(est.triangles),
                         "peak_mb": got.get("peak", float("nan")) / 1e6, "estimated_mb": est.bytes / 1e6,
                         "error": "" if r.returncode == 0 else r.stderr.strip().splitlines()[-1][:200]})
            rows[-1]["ratio"] = rows[-1]["peak_mb"] / rows[-1]["estimated_mb"]
            print(" ".join(f"{k}={v}" for k, v in rows[-1].items()), flush=True)
    df = pd.DataFrame(rows)
    out.mkdir(parents=True, exist_ok=True)
    write_text(out / "memory.csv", df.to_csv(index=False, float_format="%.4g"))
    worst = df.ratio.max()
    text = ["# Peak memory against the size estimate", "", __doc__.split("\n\n")[2].replace("\n", " "), "",
            f"Largest measured / estimated: **{worst:.2f}**"
            + (" (the estimate errs on the safe side everywhere)." if worst <= 1 else " (the estimate is too low)."),
            "", md_table(df), ""]
    write_text(out / "memory.md", "\n".join(text))
    return 0 if worst <= 1 and not df.error.any() else 1


if __name__ == "__main__":
    sys.exit(main())
