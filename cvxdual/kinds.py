"""Names of kinds as types: the stress spaces (:class:`Space`) and a solver's statuses
(:class:`Status`). Both are string enums, so they print, compare and serialise (JSON, CSV) as the
strings users type and read; :meth:`Space.parse` is the one place a user's string becomes a space."""

from __future__ import annotations

from enum import StrEnum

from .errors import CvxdualError


class Space(StrEnum):
    """A stress space: ``P0`` the paper's piecewise-constant stresses, ``EQ`` the exactly
    admissible equilibrium stresses with certified bounds (docs/equilibrium.md)."""

    P0 = "p0"
    EQ = "eq"

    @classmethod
    def parse(cls, name) -> Space:
        """The space named ``name`` (any case, or a :class:`Space`); an unknown name is one line."""
        try:
            return cls(str(name).lower())
        except ValueError:
            raise CvxdualError(f"unknown stress space {str(name)!r}; choose one of "
                               f"{', '.join(s.value for s in cls)}") from None


SPACE_NAMES = tuple(s.value for s in Space)  # as users write them


class Status(StrEnum):
    """What a solver reports; every returned solution is ``OPTIMAL``."""

    OPTIMAL = "optimal"
    OPTIMAL_INACCURATE = "optimal_inaccurate"


class Kinematic(StrEnum):
    """The kinematic sides of a certificate, by the names users write (:mod:`cvxdual.system.kinematic`)."""

    P1 = "p1"
    P2 = "p2"

    @classmethod
    def parse(cls, name) -> Kinematic:
        try:
            return cls(str(name).lower())
        except ValueError:
            raise CvxdualError(f"unknown kinematic side {str(name)[:40]!r}; choose 'p1' or 'p2'",
                               cli=f"unknown --kinematic {str(name)[:40]!r}; choose p1 or p2") from None


class Stop(StrEnum):
    """Why a run to a tolerance stopped (:mod:`cvxdual.adapt`): the tolerance met, or what came first."""

    TOLERANCE = "tolerance"
    MAX_PIECES = "max_pieces"
    MEMORY = "memory"
    TIME_LIMIT = "time_limit"
    NO_REFINEMENT = "no_refinement"


class Meshed(StrEnum):
    """How an outline body's part beyond the strip was meshed (:mod:`cvxdual.geometry.outline`): by gmsh,
    or, in a run to a tolerance, by refining the last cycle's mesh in place."""

    GMSH = "gmsh"
    IN_PLACE = "in_place"
