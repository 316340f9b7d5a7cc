"""Writing results: ``summary.json``, ``contact.csv``, ``solution.vtu`` and, on request, the
figures, as one set.

The output directory holds one set and is replaced whole (:func:`write_outputs`): the set is
written into a hidden staging directory beside it and swapped in atomically by
:func:`cvxdual.files.replace_dir`, so it is always the previous set or the new one, never a mix,
and files of an earlier set that the new one lacks (figures, after a run without ``--plots``) are
gone.
Because the directory is replaced, a directory holding anything else is refused
(:func:`check_output_dir`), and so are the filesystem root, the current and the home directory.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from ..errors import OutputError
from ..files import json_text, replace_dir, staged_dir, temp_beside
from ..solution import CONTACT_COLUMNS, FLAG_COLUMNS
from ..validate import short
from .figures import DPI, Plot, figures, parse_plots
from .vtu import write_vtu

# PNGs with fast compression (files 20-35% larger, half the compression time)
PNG_OPTIONS = {"compress_level": 1}
SET_FILES = ("summary.json", "contact.csv", "solution.vtu", *(p.file for p in Plot))
# per-file temporaries of earlier versions (files.temp_beside), removed with the set they are in
_OLD_TEMP = re.compile(r"\.(" + "|".join(re.escape(n) for n in (*SET_FILES, "probe")) + r")\.[^/]+\.tmp")


def check_writable(out: str | Path, what: str = "output directory", option: str = "--out") -> Path:
    """Check, without creating anything, that directory ``out`` can be created and written."""
    out = Path(out)
    p = out
    while not p.exists():
        if p.parent == p:
            break
        p = p.parent
    if p.exists() and not p.is_dir():
        raise OutputError(f"cannot write to {what} {str(out)!r}: {str(p)!r} is not a directory; "
                          f"choose another {option}")
    if not os.access(p, os.W_OK | os.X_OK):
        raise OutputError(f"cannot write to {what} {str(out)!r}: {str(p)!r} is not writable; "
                          f"choose another {option}")
    return out


def foreign_entries(out: str | Path) -> list[str]:
    """The entries of directory ``out`` that are not files of an output set (directories end in '/')."""
    bad = []
    for e in os.scandir(out):
        if not ((e.name in SET_FILES or _OLD_TEMP.fullmatch(e.name)) and e.is_file(follow_symlinks=False)):
            bad.append(e.name + ("/" if e.is_dir(follow_symlinks=False) else ""))
    return sorted(bad)


def _check_owned(out: Path, shown: str) -> None:
    bad = foreign_entries(out)
    if bad:
        names = [short(b, 30) for b in bad[:3]]
        more = f" and {len(bad) - 3} more" if len(bad) > 3 else ""
        raise OutputError(f"refusing to write outputs to {shown!r}: it holds {', '.join(names)}{more}, not written "
                          "by cvxdual, and the output directory is replaced whole; nothing was changed there; "
                          "choose an empty or cvxdual-written --out")


def check_output_dir(out: str | Path) -> Path:
    """Check, creating nothing, that ``out`` can take an output set (:func:`write_outputs`): a new
    or empty directory or one holding an output set only, writable, with a writable parent, and
    not the filesystem root, the current directory (or above it) or the home directory. Returns
    the real path (symbolic links resolved): the directory that will be replaced."""
    check_writable(out)
    shown = str(out)
    real = Path(out).resolve()
    try:
        home = Path.home().resolve()
    except RuntimeError:  # no home directory known
        home = None
    special = ("the filesystem root" if real == Path(real.anchor) else
               "the current directory or above it" if Path.cwd().resolve().is_relative_to(real) else
               "the home directory" if real == home else None)
    if special:
        raise OutputError(f"refusing to write outputs to {shown!r}: it is {special}, and the output directory is "
                          "replaced whole; choose an empty or cvxdual-written --out")
    if real.exists():
        if not os.access(real.parent, os.W_OK | os.X_OK):
            raise OutputError(f"cannot replace output directory {shown!r}: its parent {str(real.parent)!r} is not "
                              "writable; choose another --out")
        _check_owned(real, shown)
    return real


def prepare_dir(out: str | Path) -> Path:
    """Create ``out`` (and parents) and check it is writable."""
    out = check_writable(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        temp_beside(out / "probe").unlink()
    except OSError as e:
        raise OutputError(f"cannot write to output directory {str(out)!r} ({e.strerror or e}); "
                          "choose a writable --out") from None
    return out


def write_contact_csv(sol, path) -> None:
    """``contact.csv``, one row per pair (written without pandas: it costs 0.2 s to import)."""
    cols = np.column_stack(list(sol.contact_columns().values())).astype(float)
    fmt = ["%d" if k in FLAG_COLUMNS else "%.12g" for k in CONTACT_COLUMNS]
    np.savetxt(path, cols, fmt=fmt, delimiter=",", header=",".join(CONTACT_COLUMNS), comments="")


def write_outputs(sol, out: str | Path, plots=False) -> list[Path]:
    """Write every output of ``sol`` as the set in directory ``out``; return the paths written.
    ``plots``: the figures too (:mod:`cvxdual.outputs.figures`; matplotlib's import and drawing
    take longer than a whole small run, so they are written on request): ``True`` for the default
    set, or which (``"stress,mesh"``, a list of names or :class:`~cvxdual.outputs.figures.Plot`;
    :func:`~cvxdual.outputs.figures.parse_plots`, which refuses an unknown name before anything
    is written).

    The set replaces ``out`` whole (see the module docstring): any failure leaves the previous
    set (or none), never a mix, and the error says so."""
    out = Path(out)
    plots = parse_plots(plots)
    real = check_output_dir(out)
    writers = {
        "summary.json": lambda p: p.write_text(json_text(sol.summary())),
        "contact.csv": lambda p: write_contact_csv(sol, p),
        "solution.vtu": lambda p: write_vtu(sol, p),
    }
    if plots:
        for name, fig in figures(sol, plots).items():  # noqa: B007 - fig is bound in the lambda
            writers[name] = lambda p, fig=fig: fig.savefig(p, dpi=DPI, format="png", pil_kwargs=PNG_OPTIONS)
    assert set(writers) <= set(SET_FILES)
    try:
        real.parent.mkdir(parents=True, exist_ok=True)
        with staged_dir(real) as stage:
            for name, write in writers.items():
                write(stage / name)
            replace_dir(stage, real, check=lambda d: _check_owned(d, str(out)))
    except OutputError:
        raise  # says itself what was changed
    except Exception as e:  # noqa: BLE001 - any failure before the swap: the staging directory is gone
        what = e.strerror if isinstance(e, OSError) and e.strerror else f"{type(e).__name__}: {e}"
        raise OutputError(f"cannot write outputs to {str(out)!r} ({what}); nothing was changed in {str(out)!r}; "
                          "choose a writable --out") from None
    return [out / name for name in writers]
