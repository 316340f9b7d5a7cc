"""Validation of user values: every check raises :class:`~cvxdual.errors.SceneError` naming
the value (shortened), so bad input never surfaces as a NumPy or Python error.

Numbers are finite reals of magnitude zero or within ``[TINY, HUGE]``: beyond that the
products formed by assembly (areas, stiffness times strain, energies) overflow or underflow
double precision, so such a value is refused with the range rather than computed into NaN.
"""

from __future__ import annotations

import math
import numbers
import re

from .errors import SceneError

HUGE = 1e100  # squares and triple products stay far below the double range (1.8e308)
TINY = 1e-100  # and far above its underflow (2.2e-308)
MAX_SHOWN = 60  # characters of a value echoed in a message


def one_line(text: str, limit: int) -> str:
    """``text`` with its whitespace runs collapsed, cut to ``limit`` characters."""
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[: limit - 4] + " ..."


def short(value, limit: int = MAX_SHOWN) -> str:
    """``repr(value)`` cut to ``limit`` characters, so a message stays one readable line."""
    try:
        text = repr(value)
    except RecursionError:  # a deeply nested value
        text = f"<deeply nested {type(value).__name__}>"
    except Exception:  # noqa: BLE001 - a failing __repr__ must not replace the real error
        text = f"<{type(value).__name__}>"
    return one_line(text, limit)


# what a value too small to compute with should be instead, by the values its caller accepts
# (the advice must admit what it advises: "give 0" for a quantity that must be positive would not)
SMALL_FIX = {"any": f"give 0 or a magnitude of at least {TINY:g}",
             "nonzero": f"give a magnitude of at least {TINY:g}",
             "nonnegative": f"give 0 or a value of at least {TINY:g}",
             "positive": f"give a positive value of at least {TINY:g}"}


def number(value, what: str, accepts: str | float = "any") -> float:
    """A finite real number of magnitude 0 or in ``[TINY, HUGE]`` (``bool`` and strings are rejected).
    ``accepts`` (``"any"``, ``"nonzero"``, ``"nonnegative"``, ``"positive"`` or the smallest value
    accepted) only shapes the advice for a value too small to compute with: the caller checks its
    own range after, with its own message."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise SceneError(f"{what} must be a number, got {short(value)}")
    try:
        v = float(value)
    except OverflowError:
        v = math.inf
    if not math.isfinite(v) or abs(v) > HUGE:
        raise SceneError(f"{what} must be a finite number of magnitude at most {HUGE:g}, got {short(value)}")
    if v != 0.0 and abs(v) < TINY:
        fix = SMALL_FIX[accepts] if isinstance(accepts, str) else f"give a value of at least {max(accepts, TINY):g}"
        raise SceneError(f"{what} = {v:g} is too small to compute with; {fix}")
    return v


def integer(value, what: str, minimum: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise SceneError(f"{what} must be an integer, got {short(value)}")
    if abs(value) > HUGE:
        raise SceneError(f"{what} must be an integer of magnitude at most {HUGE:g}, got {short(value)}")
    if minimum is not None and value < minimum:
        raise SceneError(f"{what} must be at least {minimum}, got {short(value)}")
    return int(value)


def pair(value, what: str) -> tuple[float, float]:
    """Two numbers ``[lo, hi]`` (see :func:`number`)."""
    if isinstance(value, (str, bytes, dict)) or not hasattr(value, "__len__") or len(value) != 2:
        raise SceneError(f"{what} must be a pair of numbers [lo, hi], got {short(value)}")
    return number(value[0], what), number(value[1], what)


def text(value, what: str) -> str:
    """A string (names and descriptions are data: never used as paths as they are)."""
    if not isinstance(value, str):
        raise SceneError(f"{what} must be a string, got {short(value)}")
    return value


def table(value, what: str) -> dict:
    if not isinstance(value, dict):
        raise SceneError(f"{what}: expected a table (key = value pairs), got {short(value)}")
    return value


def file_stem(name: str, default: str = "scene") -> str:
    """``name`` as one safe path component: characters other than letters, digits, ``-``, ``_``
    and ``.`` become ``_``, leading dots are dropped and the length is capped, so a name can
    never point outside the directory it is put in (``"../x"`` -> ``"_x"``)."""
    stem = re.sub(r"[^A-Za-z0-9._-]", "_", str(name)).lstrip(".")[:80]
    return stem or default
