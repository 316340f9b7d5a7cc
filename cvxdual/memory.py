"""The memory this process can still allocate (the size checks, the gmsh child's limit)."""

from __future__ import annotations

import math
import resource
from pathlib import Path


def available_memory() -> float:
    """Bytes this process can still allocate: the smallest of MemAvailable, the cgroup's
    remaining limit and the address-space rlimit's headroom (``inf`` where none is known)."""
    out = [math.inf]
    try:
        info = dict(line.split(":", 1) for line in Path("/proc/meminfo").read_text().splitlines())
        out.append(float(info["MemAvailable"].split()[0]) * 1024)
    except (OSError, KeyError, ValueError):
        pass
    try:
        cg = Path("/sys/fs/cgroup")
        limit = (cg / "memory.max").read_text().strip()
        if limit != "max":
            out.append(float(limit) - float((cg / "memory.current").read_text()))
    except (OSError, ValueError):
        pass
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft != resource.RLIM_INFINITY:
        try:
            vm = next(line for line in Path("/proc/self/status").read_text().splitlines() if line.startswith("VmSize"))
            out.append(soft - float(vm.split()[1]) * 1024)
        except (OSError, StopIteration, ValueError):
            out.append(float(soft))
    return max(min(out), 0.0)
