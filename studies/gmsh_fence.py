"""The cost of gmsh's fence (cvxdual.geometry.outline.fence): writes reports/gmsh_fence.md and .csv.

    python studies/gmsh_fence.py            # into reports/ (about a minute)
    python studies/gmsh_fence.py --quick    # levels 1-3, into out/gmsh_fence-quick

gmsh's work for one outline body (the mesh beyond the strip, refined once) is timed in this
process (gmsh imported here, as before the fence) and through the fence (the same function in the
child process, the request and the answer pickled over a pipe), alternately, the median of
``--repeat`` runs each, at each level; and the child's start (interpreter, NumPy, the package).
Ratios are measured in this one run; the machine is shared, so read them, not the seconds.
"""

import argparse
import statistics
import time
from pathlib import Path

import pandas as pd

import cvxdual as cd
from cvxdual.files import write_text
from cvxdual.geometry.mesh import column_abscissae
from cvxdual.geometry.outline import fence, gmsh_mesh, strip_depth
from cvxdual.study.report import md_table

FENCED = "cvxdual.geometry.outline.mesher:gmsh_mesh"


def request(scene, level):
    """gmsh's work for the lower body of ``scene`` at ``level``: the arguments mesh_rest sends."""
    body = scene.bodies[1]
    cols = column_abscissae(scene, level)
    c = cols[(cols >= body.x_range[0]) & (cols <= body.x_range[1])]
    return body, c, body.face.value(c) + body.sign * strip_depth(c), level


def timed(f, *args) -> tuple[float, object]:
    t = time.perf_counter()
    out = f(*args)
    return time.perf_counter() - t, out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    out = Path(args.out or ("out/gmsh_fence-quick" if args.quick else "reports"))
    levels = range(1, 4) if args.quick else range(1, 6)
    fence.stop()
    start, _ = timed(fence.in_gmsh, FENCED, *request(cd.load_scene("block-with-hole"), 0))
    rows = []
    for name in ("block-with-hole", "rounded-punch"):
        scene = cd.load_scene(name)
        for level in levels:
            req = request(scene, level)
            inside, fenced = [], []
            for _ in range(args.repeat):
                t, a = timed(gmsh_mesh, *req)
                inside.append(t)
                t, b = timed(fence.in_gmsh, FENCED, *req)
                fenced.append(t)
            assert (a.points == b.points).all() and (a.triangles == b.triangles).all()  # the same mesh
            ti, tf = statistics.median(inside), statistics.median(fenced)
            rows.append({"scene": name, "level": level, "triangles": len(a.triangles), "in_process_s": ti,
                         "fenced_s": tf, "ratio": tf / ti})
    df = pd.DataFrame(rows)
    out.mkdir(parents=True, exist_ok=True)
    df.to_csv(out / "gmsh_fence.csv", index=False, float_format="%.4g")
    lines = ["# gmsh's fence: the cost of meshing in a child process", "",
             f"`python studies/gmsh_fence.py{' --quick' if args.quick else ''}` (median of {args.repeat} runs each, "
             "alternating, in one run).", "",
             f"Starting the child (once per process, on the first outline mesh): {start:.2f} s.", "",
             "gmsh's work for the lower body (gmsh's mesh at the sizes of the level below, refined once), in this "
             "process and through the fence (the same mesh, bit for bit):", "",
             md_table(df, ".3g"), ""]
    write_text(out / "gmsh_fence.md", "\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
