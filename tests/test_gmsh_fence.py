"""gmsh behind its fence (cvxdual.geometry.outline.fence): it runs in a child process, so a crash,
a time-out, Ctrl-C or two threads cannot take the caller down or leave it a wrong mesh; the caller
never imports gmsh and its own gmsh session is untouched; nothing is written under $HOME."""

import hashlib
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import cvxdual as cd
from cvxdual.geometry.mesh import build_mesh, column_abscissae
from cvxdual.geometry.outline import fence, forget_meshes, strip_depth

ROOT = Path(__file__).resolve().parents[1]
SLOW_LEVEL = 6  # block-with-hole: gmsh meshes for several seconds at this level
FENCED = "cvxdual.geometry.outline.mesher:gmsh_mesh"


def digest(mesh) -> str:
    return hashlib.sha256(mesh.points.tobytes() + mesh.triangles().tobytes()).hexdigest()


def rest_request(scene, level):
    """The arguments of gmsh's work for the lower body of ``scene`` at ``level``, as mesh_rest sends them."""
    body = scene.bodies[1]
    cols = column_abscissae(scene, level)
    c = cols[(cols >= body.x_range[0]) & (cols <= body.x_range[1])]
    return body, c, body.face.value(c) + body.sign * strip_depth(c), level


def children_of(pid: int) -> list[int]:
    """gmsh children started by process ``pid`` that still run (the child is given its parent's pid)."""
    out = []
    for p in Path("/proc").iterdir():
        try:
            argv = (p / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if b"cvxdual.geometry.outline.worker" in argv and str(pid).encode() in argv:
            out.append(int(p.name))
    return out


@pytest.mark.slow
def test_the_caller_never_imports_gmsh_and_keeps_its_own_session(tmp_path):
    """A caller with a gmsh session of its own (a model named 'mine') meshes an outline body: gmsh
    runs in the child and the caller's model is still there. A caller without one never imports
    gmsh, and nothing is written under its $HOME (gmsh writes ~/.fltk where it runs)."""
    code = ("import gmsh, cvxdual as cd; gmsh.initialize(readConfigFiles=False); gmsh.model.add('mine');"
            "cd.geometry.build_mesh(cd.load_scene('block-with-hole'), 0);"
            "print(gmsh.isInitialized(), gmsh.model.getCurrent())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    assert out.stdout.split() == ["1", "mine"]
    home = tmp_path / "home"
    home.mkdir()
    code = ("import sys, cvxdual as cd; cd.geometry.build_mesh(cd.load_scene('block-with-hole'), 0);"
            "print('gmsh' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120,
                         env={**os.environ, "HOME": str(home)})
    assert out.stdout.split() == ["False"]
    assert list(home.iterdir()) == []


@pytest.mark.slow
def test_a_killed_gmsh_is_one_error_and_the_next_mesh_is_right():
    """gmsh's process dies (SIGKILL, as the kernel's OOM killer or a segfault would end it) while it
    meshes: the caller gets one MeshError naming the signal, and the next mesh is the same as a
    fresh process makes."""
    scene = cd.load_scene("block-with-hole")
    expected = digest(build_mesh(scene, 1))
    forget_meshes()
    found = []

    def mesh():
        try:
            fence.in_gmsh(FENCED, *rest_request(scene, SLOW_LEVEL))
        except cd.CvxdualError as e:
            found.append(e)

    t = threading.Thread(target=mesh)
    t.start()
    time.sleep(1.0)  # the child is meshing by now (it takes several seconds at this level)
    os.kill(fence.pid(), signal.SIGKILL)
    t.join(30)
    assert len(found) == 1 and isinstance(found[0], cd.MeshError), found
    msg = str(found[0])
    assert "SIGKILL" in msg and "\n" not in msg
    forget_meshes()
    assert digest(build_mesh(scene, 1)) == expected


def test_time_limit_ends_gmsh_within_its_margin():
    """The run stops at its time limit while gmsh meshes (the size probe and the mesh run under it)
    and ends gmsh's process; the margin is the acceptance's 2 s."""
    forget_meshes()
    t = time.perf_counter()
    with pytest.raises(cd.TimeLimitError):
        cd.solve("block-with-hole", level=SLOW_LEVEL, solver="fast", time_limit=1.0)
    assert time.perf_counter() - t < 1.0 + 2.0
    assert fence.pid() is None


def test_two_threads_load_and_mesh_side_by_side():
    """Two threads loading a scene (one from a .geo file) and meshing it 20 times each (no cache:
    every call reaches gmsh): each gets the mesh a single caller gets, bit for bit."""
    sources = {"a": str(ROOT / "examples" / "block-with-hole-geo.toml"), "b": "rounded-punch"}
    want = {k: fence.in_gmsh(FENCED, *rest_request(cd.load_scene(s), 0)) for k, s in sources.items()}
    bad = []

    def work(key):
        for _ in range(20):
            got = fence.in_gmsh(FENCED, *rest_request(cd.load_scene(sources[key]), 0))
            w = want[key]
            if not (np.array_equal(got.points, w.points) and np.array_equal(got.triangles, w.triangles)):
                bad.append(key)

    ts = [threading.Thread(target=work, args=(k,)) for k in sources]
    for t in ts:
        t.start()
    for t in ts:
        t.join(120)
    assert bad == [] and not any(t.is_alive() for t in ts)


def test_ctrl_c_stops_the_command_while_gmsh_meshes():
    """Ctrl-C (SIGINT to the command) while gmsh meshes: the command says 'interrupted', exits 130
    within 2 s, and gmsh's process is gone (it is in its own session: the terminal's Ctrl-C
    reaches the command, which ends it)."""
    # as from a terminal: SIGINT at its default, also where the tests themselves run as a background
    # job of a shell without job control (`.ci/run &`), whose children inherit SIGINT ignored
    proc = subprocess.Popen([sys.executable, "-m", "cvxdual", "solve", "--scene", "block-with-hole", "--level",
                             str(SLOW_LEVEL), "--solver", "fast", "--no-output"], stderr=subprocess.PIPE, text=True,
                            cwd=ROOT, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 60
    while not children_of(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)  # inside gmsh's meshing
    assert proc.poll() is None and children_of(proc.pid)
    proc.send_signal(signal.SIGINT)
    t = time.perf_counter()
    _, err = proc.communicate(timeout=30)
    assert time.perf_counter() - t < 2.0
    assert proc.returncode == 130 and "interrupted" in err
    time.sleep(0.2)  # the child's own exit after its parent's
    assert children_of(proc.pid) == []


def test_only_the_packages_functions_run_in_the_child():
    with pytest.raises(ValueError, match="package's own functions"):
        fence.in_gmsh("os:system", "true")
