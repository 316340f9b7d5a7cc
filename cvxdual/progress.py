"""Progress of a run and its time limit.

Progress is reported through :mod:`logging`: the logger ``"cvxdual"`` (and its children, e.g.
``"cvxdual.system.displacement"``) writes one INFO record as each phase ends (mesh, assemble, build, solve,
recover, write) and one as a long phase starts; DEBUG records follow the fast path's
iterations. A library stays silent unless its caller configures logging
(``logging.basicConfig(level=logging.INFO)``); the CLI prints the records on stderr.

A :class:`Deadline` bounds a run's wall-clock time. It is checked as each phase ends, its
remainder goes to the QP solver as the solver's own time limit, and where it can (the main
thread of a POSIX process, with no other ``SIGALRM`` handler installed) an alarm interrupts a
phase that runs past it, CVXPY's compilation included. Either way the run raises
:class:`~cvxdual.errors.TimeLimitError` naming the phase. The alarm cannot interrupt compiled
code: a solver's setup (SCS factorises for about 13 s at level 6) runs on past the limit
before the error is raised (the CLI ends the process instead, :mod:`cvxdual.cli`).
"""

from __future__ import annotations

import logging
import math
import signal
import threading
import time
from contextlib import contextmanager
from contextvars import ContextVar

from .errors import CvxdualError, TimeLimitError

log = logging.getLogger("cvxdual")


MAX_TIME_LIMIT = 1e6  # seconds (11.6 days): above this a limit means nothing, and setitimer overflows


def check_time_limit(seconds) -> float | None:
    """``None`` or a positive number of seconds up to :data:`MAX_TIME_LIMIT`; anything else is refused."""
    if seconds is None:
        return None
    try:
        value = float(seconds)
    except (TypeError, ValueError):
        value = math.nan
    if isinstance(seconds, bool) or not 0 < value <= MAX_TIME_LIMIT:
        what = f"must be a positive number of seconds up to {MAX_TIME_LIMIT:g}, got {seconds!r}"
        raise CvxdualError(f"time_limit {what}", cli=f"--time-limit {what}")
    return value


_ACTIVE: ContextVar[Deadline | None] = ContextVar("cvxdual_deadline", default=None)


def time_left() -> float | None:
    """Seconds left of the deadline being enforced in this context (``None``: no limit): work
    that runs outside this process (gmsh's child) is given no more."""
    d = _ACTIVE.get()
    return None if d is None else d.remaining()


class _Alarm(BaseException):
    """Raised by the alarm: like KeyboardInterrupt, past every ``except Exception`` (a cached
    import check, a logging handler) to :meth:`Deadline.enforced`, which makes it the error."""


class Deadline:
    """The end of a run's time: ``seconds`` from now (``None``: no limit). ``phase`` (the phase
    running) and ``fast`` (whether the run is on the fast path) shape the error's message."""

    def __init__(self, seconds=None):
        self.seconds = check_time_limit(seconds)
        self.start = time.perf_counter()
        self.phase = "start"
        self.fast = False

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
        fast = ("", "") if self.fast else (" or use solver='fast'", " or use --solver fast")
        return TimeLimitError(f"{what}; raise time_limit, lower the level{fast[0]}",
                              cli=f"{what}; raise --time-limit, lower --level{fast[1]}")

    def check(self) -> None:
        """Raise :class:`TimeLimitError` if the time is up."""
        if self.expired():
            raise self.error()

    @contextmanager
    def enforced(self):
        """Interrupt the run by ``SIGALRM`` at the deadline, where that is safe (see the module
        docstring); elsewhere the phase ends and :meth:`check` raises. Inside, :func:`time_left`
        reads this deadline."""
        token = _ACTIVE.set(self)
        try:
            with self._alarm():
                yield self
        finally:
            _ACTIVE.reset(token)

    @contextmanager
    def caught(self):
        """Inside :meth:`enforced`: the alarm at the deadline raises :meth:`error` here, where the
        caller can keep what it has (a run to a tolerance keeps its best cycle)."""
        try:
            yield self
        except _Alarm:
            raise self.error() from None

    @contextmanager
    def _alarm(self):
        usable = (self.seconds is not None and hasattr(signal, "setitimer")
                  and threading.current_thread() is threading.main_thread()
                  and signal.getsignal(signal.SIGALRM) in (signal.SIG_DFL, None))
        if not usable:
            yield self
            return

        def interrupt(signum, frame):
            raise _Alarm

        signal.signal(signal.SIGALRM, interrupt)
        try:
            signal.setitimer(signal.ITIMER_REAL, self.remaining())
            yield self
        except _Alarm:
            raise self.error() from None
        finally:
            signal.signal(signal.SIGALRM, signal.SIG_IGN)  # first: an alarm from here on is dropped
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
    (with ``p.detail`` set inside the block); then check ``deadline``. A solver's own time-out
    (given the deadline's remainder) becomes the deadline's error, naming the phase."""
    p = Phase(name, deadline)
    if deadline is not None:
        deadline.phase = name
    if start:
        log.info("%s: %s ...", name, start)
    try:
        yield p
    except TimeLimitError:
        if deadline is None or deadline.seconds is None:
            raise
        raise deadline.error() from None
    p.seconds = time.perf_counter() - p.start
    log.info("%s: %.2f s%s", name, p.seconds, f" ({p.detail})" if p.detail else "")
    if deadline is not None:
        deadline.check()
