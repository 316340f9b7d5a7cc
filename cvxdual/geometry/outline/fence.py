"""gmsh behind a fence: every gmsh call runs in one child process, never in the caller's. gmsh is
a large C++ library with one global model per process. It can crash (a segfault, an ``abort``),
ignore Ctrl-C inside a long call, run out of memory, and it holds state between calls; a caller
may also run a gmsh session of its own. So the package never imports gmsh in the caller's
process: :func:`in_gmsh` sends a request (a module-level function of the package and its
arguments, pickled) to a child started with ``python -m cvxdual.geometry.outline.worker`` and
waits for the answer, which is bounded in time by the deadline being enforced
(:func:`cvxdual.progress.time_left`: past it the child is killed and
:class:`~cvxdual.errors.TimeLimitError` raised); bounded in memory (the child caps its own address
space at what the machine has free when it starts, :func:`cvxdual.memory.available_memory`, so a
runaway mesh ends the child, not the caller); interruptible (the parent waits in Python, where
Ctrl-C and the deadline's alarm reach it, and kills the child on the way out; the child is in its
own session, so a terminal's Ctrl-C goes to the parent alone, and it ends itself when the parent
dies); and one at a time (a lock serialises the callers' threads: the child holds one gmsh). The
child is started on first use (about 0.7 s: the interpreter, NumPy and the package) and kept for
the next requests; after a crash, a kill or a time-out the next request starts a new one. Its
``HOME`` is a temporary folder removed with it, so gmsh writes nothing under the user's."""

from __future__ import annotations

import atexit
import os
import pickle
import select
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import threading

from ...errors import CvxdualError, MeshError, TimeLimitError

HEADER = struct.Struct("<Q")  # each message: its length, then the pickle
_LOCK = threading.Lock()  # one request at a time: the child holds one gmsh
_CHILD: list = []  # the running child, if any: [Popen, home folder]


def in_gmsh(function: str, *args, what: str = "gmsh"):
    """``function(*args)`` (``"module:name"`` inside the package) in the gmsh child; its result,
    or the :class:`~cvxdual.errors.CvxdualError` it raised, raised here. ``what`` names the work
    in messages ("meshing body 'bottom'")."""
    from ...progress import time_left

    if not function.startswith("cvxdual."):
        raise ValueError(f"the gmsh child runs the package's own functions only, not {function!r}")
    left = time_left()
    if not _LOCK.acquire(timeout=-1 if left is None else left):
        raise _time_up(f"waiting for gmsh ({what})")
    try:
        child = _child()
        try:
            _send(child, pickle.dumps((function, args, os.environ.get("OMP_NUM_THREADS")), pickle.HIGHEST_PROTOCOL))
            kind, payload = pickle.loads(_receive(child, what))
        except BaseException:  # a time-out, Ctrl-C, the deadline's alarm, a dead child: no half-read pipe kept
            stop()
            raise
    finally:
        _LOCK.release()
    if kind == "ok":
        return payload
    cls, message = payload
    raise (MeshError if cls == "MeshError" else CvxdualError)(message)


def pid() -> int | None:
    """The running child's process id (``None``: none runs)."""
    return _CHILD[0][0].pid if _CHILD and _CHILD[0][0].poll() is None else None


def stop() -> None:
    """End the child (it is started again on the next request)."""
    if not _CHILD:
        return
    proc, home = _CHILD.pop()
    if proc.poll() is None:
        proc.kill()
    proc.wait()
    for f in (proc.stdin, proc.stdout):
        f.close()
    shutil.rmtree(home, ignore_errors=True)


atexit.register(stop)


def _child() -> subprocess.Popen:
    if _CHILD and _CHILD[0][0].poll() is None:
        return _CHILD[0][0]
    stop()
    home = tempfile.mkdtemp(prefix="cvxdual-gmsh-")
    env = {**os.environ, "HOME": home, "CVXDUAL_GMSH_HOME": home,
           "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}  # the caller's own cvxdual, wherever it is
    proc = subprocess.Popen([sys.executable, "-m", "cvxdual.geometry.outline.worker", str(os.getpid())],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env,
                            cwd=home, start_new_session=True, close_fds=True)
    _CHILD.append((proc, home))
    return proc


def _send(proc: subprocess.Popen, data: bytes) -> None:
    try:
        proc.stdin.write(HEADER.pack(len(data)) + data)
        proc.stdin.flush()
    except BrokenPipeError:
        raise MeshError(_died(proc, "before it read the request")) from None


def _receive(proc: subprocess.Popen, what: str) -> bytes:
    """The child's answer, waited for in Python (a signal interrupts the wait) up to the deadline."""
    from ...progress import time_left

    fd = proc.stdout.fileno()
    buf = bytearray()
    need = HEADER.size
    while len(buf) < need:
        left = time_left()
        if left is not None and left <= 1e-3:
            raise _time_up(f"while gmsh was {what} (gmsh was ended)")
        ready, _, _ = select.select([fd], [], [], None if left is None else left)
        if not ready:
            continue  # the loop's test raises
        chunk = os.read(fd, max(need - len(buf), 1 << 16))
        if not chunk:
            raise MeshError(_died(proc, f"while {what}"))
        buf += chunk
        if need == HEADER.size and len(buf) >= HEADER.size:
            need += HEADER.unpack_from(buf)[0]
    return bytes(buf[HEADER.size:need])


def _time_up(when: str) -> TimeLimitError:
    what = f"stopped at the time limit {when}"
    return TimeLimitError(f"{what}; raise time_limit or lower the level",
                          cli=f"{what}; raise --time-limit or lower --level")


def _died(proc: subprocess.Popen, when: str) -> str:
    try:
        code = proc.wait(timeout=5)
    except subprocess.TimeoutExpired:
        code = None
    if code is not None and code < 0:
        how = f"was ended by signal {signal.Signals(-code).name}"
    else:
        how = f"ended with status {code}"
    return (f"gmsh's process {how} {when} (a crash, or out of memory); the caller is unharmed: check the outline, "
            "lower the level, or report the scene")
