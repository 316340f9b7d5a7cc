"""The gmsh child (:mod:`cvxdual.geometry.outline.fence`): ``python -m cvxdual.geometry.outline.worker
PPID``. It reads requests ``(function, args, OMP_NUM_THREADS)`` from stdin and writes each answer
to stdout (a length, then a pickle: ``("ok", result)`` or ``("error", (class, message))``). Before
anything else it caps its address space, ignores Ctrl-C (the parent handles it and kills the
child), moves its own stdout out of gmsh's reach (gmsh prints from C) and watches its parent:
when the parent is gone, it ends."""

from __future__ import annotations

import importlib
import os
import pickle
import resource
import shutil
import signal
import struct
import sys
import threading
import time

from ...errors import MeshError

HEADER = struct.Struct("<Q")
SLACK = 1 << 30  # address space beyond the free memory: libraries and thread stacks are mapped, not used

# the system libraries gmsh's wheel links, and the Debian/Ubuntu packages that provide them
SYSTEM_PACKAGES = {"libGLU": "libglu1-mesa", "libXcursor": "libxcursor1", "libXft": "libxft2",
                   "libXinerama": "libxinerama1", "libX11": "libx11-6", "libXrender": "libxrender1",
                   "libfontconfig": "libfontconfig1", "libXext": "libxext6", "libXfixes": "libxfixes3",
                   "libgomp": "libgomp1"}


def import_gmsh():
    """The gmsh module, or a :class:`MeshError` naming what is missing and how to get it."""
    try:
        import gmsh
    except (ImportError, OSError) as e:  # a missing system library raises OSError from the wheel's loader
        msg = str(e)
        for lib, pkg in SYSTEM_PACKAGES.items():
            if lib in msg:
                raise MeshError(f"outline bodies need gmsh, which cannot load the system library {lib} "
                                f"({msg.split(':')[0]}); install it (Debian/Ubuntu: apt-get install {pkg}) "
                                "or use column bodies") from None
        raise MeshError(f"outline bodies need gmsh, which cannot be imported ({msg}); pip install gmsh, or use "
                        "column bodies") from None
    return gmsh


def _cap_memory() -> None:
    from ...memory import available_memory

    free = available_memory()
    if free == float("inf"):
        return
    with open("/proc/self/statm") as f:  # Linux: the first field is the address space in pages
        used = int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    _, hard = resource.getrlimit(resource.RLIMIT_AS)
    limit = int(used + free + SLACK)
    resource.setrlimit(resource.RLIMIT_AS, (limit if hard == resource.RLIM_INFINITY else min(limit, hard), hard))


def _end(status: int) -> None:
    home = os.environ.get("CVXDUAL_GMSH_HOME")  # the fence's temporary home: what gmsh wrote there
    if home:
        shutil.rmtree(home, ignore_errors=True)
    os._exit(status)


def _watch(parent: int) -> None:
    while True:
        time.sleep(0.5)
        if os.getppid() != parent:
            _end(1)  # the parent is gone (killed, or ended by its time limit)


def _read(f, n: int) -> bytes:
    data = f.read(n)
    if len(data) < n:
        _end(0)  # the parent closed the pipe: nothing more to do
    return data


def main() -> None:
    parent = int(sys.argv[1])
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        _cap_memory()
    except (OSError, ValueError):
        pass  # no /proc: no cap, as before the fence
    out = os.fdopen(os.dup(1), "wb")
    os.dup2(os.open(os.devnull, os.O_WRONLY), 1)  # whatever gmsh prints goes nowhere
    threading.Thread(target=_watch, args=(parent,), daemon=True).start()
    requests = sys.stdin.buffer
    while True:
        (n,) = HEADER.unpack(_read(requests, HEADER.size))
        function, args, threads = pickle.loads(_read(requests, n))
        if threads is None:
            os.environ.pop("OMP_NUM_THREADS", None)
        else:
            os.environ["OMP_NUM_THREADS"] = threads
        try:
            module, name = function.split(":")
            answer = ("ok", getattr(importlib.import_module(module), name)(*args))
        except MeshError as e:
            answer = ("error", ("MeshError", str(e)))
        except MemoryError:
            answer = ("error", ("MeshError", "gmsh ran out of memory (its process is capped at the memory free when "
                                             "it started); lower the level or free memory"))
        except Exception as e:  # gmsh reports its failures as plain exceptions
            answer = ("error", ("MeshError", f"gmsh failed ({type(e).__name__}: {str(e)[:200]})"))
        data = pickle.dumps(answer, pickle.HIGHEST_PROTOCOL)
        out.write(HEADER.pack(len(data)) + data)
        out.flush()


if __name__ == "__main__":
    main()
