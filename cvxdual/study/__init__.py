"""Study runners behind ``studies/*.py`` and ``cvxdual study ...``: convergence, speed, stability."""
