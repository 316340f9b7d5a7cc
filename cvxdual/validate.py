"""Validation of user numbers: every check raises :class:`~cvxdual.errors.SceneError` naming
the value, so bad input never surfaces as a NumPy or Python error."""

from __future__ import annotations

import math
import numbers

from .errors import SceneError


def number(value, what: str) -> float:
    """A finite real number (``bool`` and strings are rejected)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise SceneError(f"{what} must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise SceneError(f"{what} must be finite, got {value!r}")
    return v


def integer(value, what: str, minimum: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise SceneError(f"{what} must be an integer, got {value!r}")
    if minimum is not None and value < minimum:
        raise SceneError(f"{what} must be at least {minimum}, got {value!r}")
    return int(value)


def pair(value, what: str) -> tuple[float, float]:
    """Two finite numbers ``[lo, hi]``."""
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 2:
        raise SceneError(f"{what} must be a pair of numbers [lo, hi], got {value!r}")
    return number(value[0], what), number(value[1], what)


def table(value, what: str) -> dict:
    if not isinstance(value, dict):
        raise SceneError(f"{what}: expected a table (key = value pairs), got {value!r}")
    return value
