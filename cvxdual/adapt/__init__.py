"""Solving to a certified tolerance: Dorfler marking of the certificate's contributions on an
adaptive column grid (:mod:`~cvxdual.adapt.marking`) and the cycles (:mod:`~cvxdual.adapt.cycles`);
docs/adaptive.md."""
