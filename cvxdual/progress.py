"""Progress of a run and its time limit.

Progress is reported through :mod:`logging`: the logger ``"cvxdual"`` (and its children, e.g.
``"cvxdual.fast"``) writes one INFO record as each phase ends (mesh, assemble, build, solve,
recover, write) and one as a long phase starts; DEBUG records follow the fast path's
iterations. A library stays silent unless its caller configures logging
(``logging.basicConfig(level=logging.INFO)``); the CLI prints the records on stderr.

A :class:`Deadline` bounds a run's wall-clock time. It is checked as each phase ends, its
remainder goes to the QP solver as the solver's own time limit, and where it can (the main
thread of a POSIX process, with no other ``SIGALRM`` handler installed) an alarm interrupts a
phase that runs past it, CVXPY's compilation included. Either way the run raises
:class:`~cvxdual.errors.TimeLimitError` naming the phase.
"""

from __future__ import annotations

import logging
import math
import signal
import threading
import time
from contextlib import contextmanager

from .errors import CvxdualError, TimeLimitError

log = logging.getLogger("cvxdual")


def check_time_limit(seconds) -> float | None:
    """``None`` or a positive finite number of seconds; anything else is refused."""
    if seconds is None:
        return None
    try:
        value = float(seconds)
    except (TypeError, ValueError):
        value = math.nan
    if isinstance(seconds, bool) or not (value > 0 and math.isfinite(value)):
        raise CvxdualError(f"time_limit must be a positive number of seconds, got {seconds!r}",
                             cli=f"--time-limit must be a positive number of seconds, got {seconds!r}")
    return value


class Deadline:
    """The end of a run's time: ``seconds`` from now (``None``: no limit)."""

    def __init__(self, seconds=None):
        self.seconds = check_time_limit(seconds)
        self.start = time.perf_counter()
        self.phase = "start"  # the phase running, named in the error

    def remaining(self) -> float | None:
        """Seconds left (``None`` without a limit); never below 1 ms, so a solver is given a
        positive limit and stops at once."""
        if self.seconds is None:
            return None
        return max(self.seconds - (time.perf_counter() - self.start), 1e-3)

    def expired(self) -> bool:
        return self.seconds is not None and time.perf_counter() - self.start >= self.seconds

    def error(self) -> TimeLimitError:
        took = time.perf_counter() - self.start
        what = f"stopped at the time limit of {self.seconds:g} s during {self.phase} (after {took:.1f} s)"
        return TimeLimitError(f"{what}; raise time_limit, lower the level or use solver='fast'",
                              cli=f"{what}; raise --time-limit, lower --level or use --solver fast")

    def check(self) -> None:
        """Raise :class:`TimeLimitError` if the time is up."""
        if self.expired():
            raise self.error()

    @contextmanager
    def enforced(self):
        """Interrupt the run by ``SIGALRM`` at the deadline, where that is safe (see the module
        docstring); elsewhere the phase ends and :meth:`check` raises."""
        usable = (self.seconds is not None and hasattr(signal, "setitimer")
                  and threading.current_thread() is threading.main_thread()
                  and signal.getsignal(signal.SIGALRM) in (signal.SIG_DFL, None))
        if not usable:
            yield self
            return

        def interrupt(signum, frame):
            raise self.error()

        signal.signal(signal.SIGALRM, interrupt)
        try:
            signal.setitimer(signal.ITIMER_REAL, self.remaining())
            yield self
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, signal.SIG_DFL)


class Phase:
    """One phase of a run: its name, its detail for the progress line, its time."""

    def __init__(self, name: str, deadline: Deadline | None):
        self.name = name
        self.deadline = deadline
        self.detail = ""
        self.start = time.perf_counter()
        self.seconds = 0.0


@contextmanager
def phase(name: str, deadline: Deadline | None = None, start: str | None = None):
    """Time the phase ``name``; log ``start`` (if given) as it begins and one line as it ends
    (with ``p.detail`` set inside the block); then check ``deadline``."""
    p = Phase(name, deadline)
    if deadline is not None:
        deadline.phase = name
    if start:
        log.info("%s: %s ...", name, start)
    yield p
    p.seconds = time.perf_counter() - p.start
    log.info("%s: %.2f s%s", name, p.seconds, f" ({p.detail})" if p.detail else "")
    if deadline is not None:
        deadline.check()
