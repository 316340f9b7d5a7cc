"""Sparse linear algebra shared by the stress spaces and the fast paths: scatters of element
blocks into sparse matrices (``sparse``) and sparse SPD factorisations with the backend chosen
by size (``factor``)."""

from .factor import SPDFactor, backends

__all__ = ["SPDFactor", "backends"]
