"""A study's outputs: the tidy table (CSV), the markdown report with fitted rates, and the
plots of error against h and against time.

Plots take an ``ax=`` and return it; figures are :class:`matplotlib.figure.Figure` objects (no
pyplot), so nothing here changes matplotlib's global backend or state.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..files import atomic_path, write_text
from ..kinds import Space
from .cases import IDENTITY

LINE_KEYS = ("triangulation", "stress_space", "overrides", "solver", "units", "case")


def fit_rate(h, e) -> float:
    """Slope of ``log e`` against ``log h`` (``np.polyfit``), or NaN with fewer than two points."""
    h, e = np.asarray(h, float), np.asarray(e, float)
    ok = (h > 0) & (e > 0) & np.isfinite(e) & np.isfinite(h)
    if ok.sum() < 2:
        return float("nan")
    return float(np.polyfit(np.log(h[ok]), np.log(e[ok]), 1)[0])


def ok_rows(df: pd.DataFrame) -> pd.DataFrame:
    return df[df["status"].astype(str).str.startswith("optimal")]


def measured_rows(df: pd.DataFrame) -> pd.DataFrame:
    """The solved rows with a finite relative L2 error (none when no row has one: every case failed)."""
    d = ok_rows(df)
    if "error_l2_rel" not in d:
        return d.iloc[:0]
    return d[np.isfinite(pd.to_numeric(d["error_l2_rel"], errors="coerce").to_numpy(float))]


def series_keys(df: pd.DataFrame) -> list[str]:
    """The columns that tell series apart: scene, triangulation, and whatever else varies."""
    keys = ["scene", "triangulation"]
    for c in ("stress_space", "kinematic", "overrides", "solver", "units", "case"):
        if c in df.columns and df[c].astype(str).nunique() > 1:
            keys.append(c)
    return keys


def rates(df: pd.DataFrame, last: int | None = None, keys: list[str] | None = None) -> pd.DataFrame:
    """Fitted rates of the relative L2 and energy errors against h, per series (all levels, or
    the last ``last``)."""
    d = measured_rows(df)
    keys = keys or series_keys(df)
    out = []
    for k, g in d.groupby(keys, sort=False):
        g = g.sort_values("level")
        if last is not None:
            g = g.iloc[-last:]
        r = dict(zip(keys, k if isinstance(k, tuple) else (k,), strict=True))
        r.update({"levels": f"{int(g['level'].min())}-{int(g['level'].max())}",
                  "rate_l2": fit_rate(g["h"], g["error_l2_rel"]),
                  "rate_energy": fit_rate(g["h"], g["error_energy_rel"]) if "error_energy_rel" in g else np.nan})
        out.append(r)
    return pd.DataFrame(out, columns=keys + ["levels", "rate_l2", "rate_energy"])


def rates_table(df: pd.DataFrame) -> pd.DataFrame:
    """The report's table: rates over all levels and the last three, finest pieces and error."""
    keys = series_keys(df)
    all_r, last_r = rates(df, keys=keys), rates(df, 3, keys=keys)
    d = measured_rows(df)
    if d.empty:
        return pd.DataFrame()
    fin = d.loc[d.groupby(keys, sort=False)["level"].idxmax()]
    tab = all_r.merge(last_r[keys + ["levels", "rate_l2"]], on=keys, suffixes=("", "_last3"))
    # against a finer reference on outline bodies with curves: the share of the body the finest
    # error's integral left out (the meshes' polygons differ); the largest is at the coarsest level
    dropped = ["ref_dropped_share"] if "ref_dropped_share" in d and \
        (pd.to_numeric(d["ref_dropped_share"], errors="coerce") > 0).any() else []
    tab = tab.merge(fin[keys + ["n_pieces", "error_l2_rel"] + dropped], on=keys)
    tab = tab[keys + ["levels", "rate_l2", "rate_energy", "levels_last3", "rate_l2_last3", "n_pieces", "error_l2_rel"]
              + dropped]
    return tab.rename(columns={"levels": "levels (all)", "levels_last3": "levels (last 3)",
                               "rate_l2": "rate L2 (all)", "rate_l2_last3": "rate L2 (last 3)",
                               "rate_energy": "rate energy (all)", "n_pieces": "finest pieces",
                               "error_l2_rel": "finest rel. L2 error", "ref_dropped_share": "finest dropped share"})


REFERENCE_MARGIN = 2.0  # an error this close to the reference's own is not the case's alone


def _near_reference(d: pd.DataFrame, keys: list[str]) -> list[str]:
    """The rows of ``d`` (measured) whose error against a finer reference is within
    :data:`REFERENCE_MARGIN` times the reference's estimated error, as ``"series level L (e
    against est)"``."""
    if "reference_error_est" not in d or d.empty:
        return []
    e = pd.to_numeric(d["error_l2_rel"], errors="coerce")
    est = pd.to_numeric(d["reference_error_est"], errors="coerce")
    near = d[(est > 0) & (e < REFERENCE_MARGIN * est) & (d["reference"].astype(str) != "exact")]
    return [" ".join(str(r[k]) for k in keys if str(r[k])) + f" level {int(r['level'])} "
            f"({float(r['error_l2_rel']):.2g} against {float(r['reference_error_est']):.2g})"
            for _, r in near.sort_values(keys + ["level"]).iterrows()]


def md_table(df: pd.DataFrame, floatfmt: str = ".3g") -> str:
    cols = list(df.columns)
    lines = ["| " + " | ".join(str(c) for c in cols) + " |", "|" + "---|" * len(cols)]
    for _, r in df.iterrows():
        cells = []
        for c in cols:
            v = r[c]
            if isinstance(v, (float, np.floating)):
                cells.append("-" if not np.isfinite(v) else format(v, floatfmt))
            elif v is None:
                cells.append("-")
            else:
                cells.append(str(v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _label(keys: tuple, names: list[str]) -> str:
    return ", ".join(str(v) for v in keys if str(v) != "") if names else ""


def _plain(v: float) -> str:
    """``v`` in plain digits from 0.001 to 9999, else as ``1e4``, ``2e-5`` (not ``10000``, ``1e+06``)."""
    if v == 0 or 1e-3 <= abs(v) < 1e4:
        return f"{v:g}"
    m, e = f"{v:e}".split("e")
    return f"{m.rstrip('0').rstrip('.')}e{int(e)}"


def _log_labels_fit(locator, lim, inches: float, horizontal: bool) -> bool:
    """Whether the labels (:func:`_plain`) of ``locator``'s ticks in ``lim`` keep 0.1 in apart on
    an axis ``inches`` long (a label's width estimated at 0.6 em per character)."""
    from matplotlib import rcParams
    from matplotlib.font_manager import FontProperties
    lo, hi = sorted(lim)
    t = np.asarray(locator.tick_values(lo, hi))
    t = t[(t >= lo * (1 - 1e-9)) & (t <= hi * (1 + 1e-9))]
    if len(t) < 2:
        return True
    em = FontProperties(size=rcParams["xtick.labelsize" if horizontal else "ytick.labelsize"]).get_size_in_points() / 72
    size = np.array([0.6 * em * len(_plain(v)) for v in t]) if horizontal else np.full(len(t), 1.2 * em)
    pos = np.log(t / lo) / np.log(hi / lo) * inches
    return bool(np.all(np.diff(pos) >= (size[1:] + size[:-1]) / 2 + 0.1))


def plain_log_ticks(ax, shrink: float = 0.8) -> None:
    """Log axes labelled in plain numbers (0.01, 0.02, 0.05, 0.1, ...: spans under a decade
    still get labels) as densely as they fit without touching: 1, 1.5, 2, 3, 5, 7 per decade,
    else 1, 2, 5, else each decade, else every few decades (3x10^0 4x10^0 crowded into each
    other, and so did 0.01 0.02 0.05 over four decades). Call it after plotting; ``shrink``: the
    share of the axes' current size left after a layout engine makes room for labels."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter
    w, h = ax.get_position().size * ax.figure.get_size_inches() * shrink
    for axis, lim, inches, horizontal in ((ax.xaxis, ax.get_xlim(), w, True), (ax.yaxis, ax.get_ylim(), h, False)):
        for loc in (LogLocator(subs=(1.0, 1.5, 2.0, 3.0, 5.0, 7.0)), LogLocator(subs=(1.0, 2.0, 5.0)),
                    LogLocator(subs=(1.0,), numticks=99), LogLocator(numticks=max(2, int(inches / 0.7)))):
            if _log_labels_fit(loc, lim, inches, horizontal):
                break
        axis.set_major_locator(loc)
        axis.set_major_formatter(FuncFormatter(lambda v, _: _plain(v)))
        axis.set_minor_formatter(NullFormatter())


def _length_unit(df: pd.DataFrame, scene: str | None) -> str:
    """The length unit of ``scene``'s rows: from the ``units`` column where the study converted
    units, else the built-in scene's own (``"scene units"`` for another scene)."""
    from .. import builtin_scenes, load_scene
    units = df.loc[df["scene"] == scene, "units"].dropna().astype(str) if "units" in df else pd.Series(dtype=str)
    units = units[units != ""]
    if len(units):
        return units.iloc[0].split(",")[0].strip()
    return load_scene(scene).units[0] if scene in builtin_scenes() else "scene units"


def plot_error(df: pd.DataFrame, x: str = "h", ax=None, scene: str | None = None, reference_error: float | None = None,
               xlabel: str | None = None):
    """Relative L2 error against ``x`` (``h`` or ``t_total``) for one scene, a line per series;
    returns ``ax``."""
    if ax is None:
        from matplotlib.figure import Figure
        ax = Figure(figsize=(4.2, 4)).add_subplot()
    d = ok_rows(df)
    if scene is not None:
        d = d[d["scene"] == scene]
    keys = [k for k in series_keys(df) if k != "scene"]
    marks = ("o-", "s--", "^-.", "d:", "v-", "x--")
    for n, (k, g) in enumerate(d.groupby(keys, sort=False) if keys else [((), d)]):
        g = g.sort_values("level")
        k = k if isinstance(k, tuple) else (k,)
        r = fit_rate(g["h"], g["error_l2_rel"])
        ax.loglog(g[x], g["error_l2_rel"], marks[n % len(marks)], ms=4,
                  label=f"{_label(k, keys)} (rate {r:.2f})")
    if reference_error is not None and np.isfinite(reference_error) and reference_error > 0:
        ax.axhline(reference_error, color="gray", lw=0.8, ls=":", label="reference error (est.)")
    plain_log_ticks(ax)
    ax.set_title(scene or "")
    if xlabel is None:
        xlabel = {"h": f"mesh size h, largest element [{_length_unit(df, scene)}]",
                  "t_total": "wall time per solve [s]"}.get(x, x)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("relative L2 stress error [-]")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    return ax


def _reference_error(df: pd.DataFrame, refs: dict | None, scene) -> float | None:
    """The estimated error of ``scene``'s reference: from ``refs`` (the run's), else from the
    ``reference_error_est`` column (a table read back from its CSV), where there is one."""
    est = [v.get("error_est") for k, v in (refs or {}).items() if k == scene or k.startswith(f"{scene} ")]
    if not est and "reference_error_est" in df:
        col = pd.to_numeric(df.loc[df["scene"] == scene, "reference_error_est"], errors="coerce").dropna()
        est = list(col[col > 0].unique())
    return est[0] if len(est) == 1 else None


def error_figure(df: pd.DataFrame, x: str, refs: dict | None = None, xlabel: str | None = None):
    """A :class:`~matplotlib.figure.Figure` with one :func:`plot_error` panel per scene."""
    from matplotlib.figure import Figure
    scenes = list(dict.fromkeys(ok_rows(df)["scene"])) or [None]
    fig = Figure(figsize=(4.2 * len(scenes), 4), layout="constrained")
    axes = fig.subplots(1, len(scenes), squeeze=False)[0]
    for ax, scene in zip(axes, scenes, strict=True):
        plot_error(df, x, ax=ax, scene=scene, reference_error=_reference_error(df, refs, scene), xlabel=xlabel)
    return fig


def write_plots(df: pd.DataFrame, name: str, out: Path) -> list[Path]:
    """``NAME_h.png`` and ``NAME_time.png`` in ``out``: the error against h and against time.
    ``df`` may be the run's table or its CSV read back (``pd.read_csv``): the plots are the same."""
    refs = df.attrs.get("references", {})
    return [save_figure(error_figure(df, x, refs), Path(out) / f"{name}{suffix}.png")
            for x, suffix in (("h", "_h"), ("t_total", "_time"))]


def save_figure(fig, path: Path) -> Path:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    return path


def write_csv(df: pd.DataFrame, path: Path) -> Path:
    cols = [c for c in df.columns if not str(c).startswith("_") and c != "stress_key"]
    with atomic_path(path) as tmp:
        df[cols].to_csv(tmp, index=False, float_format="%.6g")
    return path


def setup_lines(df: pd.DataFrame, refs: dict) -> list[str]:
    out = []
    rule = _metric(df, "rule")
    by = [c for c in ("scene", "overrides", "units") if c in df.columns]
    for k, g in df.groupby(by, sort=False):
        k = k if isinstance(k, tuple) else (k,)
        scene = k[0]
        label = scene + (f" ({k[1]})" if len(k) > 1 and k[1] else "") + (f" [{k[2]}]" if len(k) > 2 and k[2] else "")
        ref = str(g["reference"].iloc[0])
        levels = sorted(g["level"].unique())
        n = pd.to_numeric(g.get("n_pieces", pd.Series(dtype=float)), errors="coerce").dropna()
        size = f", {int(n.min())} to {int(n.max())} pieces" if len(n) else ""
        if ref == "exact":
            how = "against the exact field" + (f", {rule}x{rule} Gauss points per piece" if rule else "")
        elif ref == "none":
            how = "no reference"
        elif label in refs:
            r = refs[label]
            eq = Space.parse(r.get("stress_space") or Space.P0) is Space.EQ
            how = (f"against a reference: {r['triangulation'].replace('type', 'type ')}, level {r['level']} "
                   f"({r['n_pieces']} pieces), " + ("equilibrium stresses, " if eq else "")
                   + f"{'fast path' if r.get('solver') == 'fast' else r.get('solver')}, "
                   f"{_metric(df, 'ref_rule', 2)}x{_metric(df, 'ref_rule', 2)} points per reference piece "
                   f"({_metric(df, 'ref_fine', 6)}x{_metric(df, 'ref_fine', 6)} on those straddling studied "
                   f"pieces); its estimated relative error is {_num(r.get('error_est'), '.2g')} (last "
                   f"differences {_num(r.get('d_before'), '.3g')}, {_num(r.get('d_last'), '.3g')}, "
                   f"rate {_num(r.get('rate'), '.2f')})"
                   + (f"; certified by its bounds: relative energy error at most {_num(r.get('certified'), '.2g')} "
                      "(with the displacement's error)" if eq else ""))
        else:
            how = f"against a reference ({ref})"
        out.append(f"- `{label}`: levels {min(levels)}-{max(levels)}{size}; {how}{_dropped(g)}.")
    return out


def _dropped(g: pd.DataFrame) -> str:
    """What the integrals over the common part of the studied and reference meshes left out, in
    the rows ``g`` (outline bodies' curves are polygons that differ between levels), if anything."""
    if "ref_dropped_area" not in g:
        return ""
    area = pd.to_numeric(g["ref_dropped_area"], errors="coerce")
    share = pd.to_numeric(g["ref_dropped_share"], errors="coerce")
    if not np.isfinite(area).any():
        return ""
    if not (area > 0).any():
        return "; the meshes cover the same region (nothing dropped)"
    lo, hi = share[area > 0].min(), share.max()
    return (f"; integrated over the common part of both meshes, which leaves out {area.min():.3g} to "
            f"{area.max():.3g} of area ({100 * lo:.2g}% to {100 * hi:.2g}% of the bodies', "
            "`ref_dropped_area`, `ref_dropped_share`): the polygons standing for curves differ between levels")


def _num(v, fmt: str) -> str:
    """``v`` formatted, or ``n/a`` where it is not a finite number (a rate is NaN, stored as
    None, when the differences do not decrease: a converged or round-off-level reference)."""
    ok = isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) and np.isfinite(v)
    return format(v, fmt) if ok else "n/a"


def _metric(df: pd.DataFrame, name: str, default=None):
    return df.attrs.get("metrics", {}).get(name, default)


def shown_path(path: Path) -> str:
    """``path`` as a reader can retype it: relative to the working directory when inside it."""
    try:
        return Path(path).resolve().relative_to(Path.cwd()).as_posix()
    except ValueError:
        return Path(path).name


def markdown(df: pd.DataFrame, study, out_name: str) -> str:
    """The markdown report: setup, fitted rates, monotonicity, failures, and the spec's sections."""
    refs = df.attrs.get("references", {})
    cfg = {"setup": True, "rates": True, "plots": True, **(study.report or {})}
    src = shown_path(study.path) if study.path is not None else "a dict"
    lines = [f"# {study.title}", "",
             f"Generated by `cvxdual study run {src}" + (" --quick" if study.quick else "")
             + f"` (CSV: `{out_name}.csv`" + (f"; plots: `{out_name}_h.png`, `{out_name}_time.png`" if cfg["plots"]
                                             else "") + ")." + (f" {study.description.strip()}" if study.description
                                                                 else ""), ""]
    if cfg["setup"]:
        lines += ["## Setup", ""] + setup_lines(df, refs)
        chk = df[np.isfinite(pd.to_numeric(df.get("error_l2_rel_finer_rule", pd.Series(dtype=float)),
                                           errors="coerce"))] if "error_l2_rel_finer_rule" in df else df.iloc[:0]
        if len(chk):
            dev = (chk["error_l2_rel_finer_rule"].astype(float) / chk["error_l2_rel"].astype(float) - 1).abs()
            lines += ["", f"Quadrature check: at the finest level of each series a finer rule "
                      f"({_metric(df, 'check_rule', 10)}x{_metric(df, 'check_rule', 10)} for the exact field, "
                      f"{_metric(df, 'ref_check_rule', 3)}x{_metric(df, 'ref_check_rule', 3)} and "
                      f"{_metric(df, 'ref_check_fine', 8)}x{_metric(df, 'ref_check_fine', 8)} against references) "
                      f"changes the relative error by at most {100 * dev.max():.2g}%."]
        lines.append("")
    if cfg["rates"]:
        tab = rates_table(df)
        lines += ["## Fitted rates (relative L2 error against h, least squares in log-log)", "",
                  md_table(tab) if len(tab) else "No series with errors.", ""]
        d = measured_rows(df)
        keys = series_keys(df)
        mono = {" ".join(str(x) for x in (k if isinstance(k, tuple) else (k,)) if str(x)):
                bool(np.all(np.diff(g.sort_values("level")["error_l2_rel"].astype(float)) < 0))
                for k, g in d.groupby(keys, sort=False)}
        if mono:
            lines += ["Errors decrease monotonically with h: "
                      + ", ".join(f"{k} {'yes' if v else 'NO'}" for k, v in mono.items()) + ".", ""]
        near = _near_reference(d, keys)
        if near:
            lines += [f"Errors within {REFERENCE_MARGIN:g} times the reference's own estimated error "
                      "(`reference_error_est`) measure the reference as much as the case, and flatten the "
                      "rates of the last levels: " + ", ".join(near) + ".", ""]
    bad = df[~df["status"].astype(str).str.startswith("optimal")]
    if len(bad) and cfg.get("failures", True):
        lines += ["## Failed cases", "", md_table(bad[failure_columns(bad, study)]), ""]
    return "\n".join(lines)


CASE_KEYS = tuple(k for k in IDENTITY if k != "study")  # the columns that name a case (one study per table)


def failure_columns(bad: pd.DataFrame, study=None) -> list[str]:
    """The failed-cases table's columns: every key of a case (its tags too) that is not empty in
    every failed row, then ``status`` and ``worker``: each row names its case whole."""
    tags = list(dict.fromkeys(k for c in (getattr(study, "cases", None) or []) for k, _ in c.tags))
    keys = [c for c in (*CASE_KEYS, *tags) if c in bad.columns
            and not bad[c].isna().all() and not (bad[c].astype(str) == "").all()]
    return keys + [c for c in ("status", "worker") if c in bad.columns]


def write_report(df: pd.DataFrame, study, out: str | Path) -> list[Path]:
    """Write ``NAME.csv``, ``NAME_h.png``, ``NAME_time.png`` and ``NAME.md`` to ``out``."""
    from ..outputs.output_set import prepare_dir
    out = prepare_dir(out)
    name = study.name
    cfg = {"plots": True, **(study.report or {})}
    written = [write_csv(df, out / f"{name}.csv")]
    if cfg["plots"] and len(ok_rows(df)):
        written += write_plots(df, name, out)
    text = markdown(df, study, name)
    if study.report_hook is not None:
        extra = study.report_hook(df, study, out)
        if extra:
            text += "\n" + extra.strip() + "\n"
    write_text(out / f"{name}.md", text.rstrip() + "\n")
    written.append(out / f"{name}.md")
    return written
