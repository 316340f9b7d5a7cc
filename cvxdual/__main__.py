"""``python -m cvxdual``: the command line (:mod:`cvxdual.cli`), as the ``cvxdual`` script."""

from .cli import main

if __name__ == "__main__":
    raise SystemExit(main())
