"""What the CVXPY models of both stress spaces share: :class:`~cvxdual.convex.base.ConvexModel`
(named constraints, user changes, load sweeps on cached solver data, misuse errors), the solver
names, options and the mapping of CVXPY's statuses to cvxdual's exceptions (``solvers``), and
the one place that calls CVXPY's internals (``cvxpy_internals``). The models themselves live
with their stress spaces: :class:`cvxdual.p0.dual.DualModel`, :class:`cvxdual.eq.model.EquilibriumModel`.
Importing this package does not load CVXPY; ``base`` does."""
