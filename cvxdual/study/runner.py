"""Running a study on Dask: a local cluster of worker processes, or any running scheduler.

Each case runs in a worker process with a memory limit (one thread per worker, one case per
thread at a time). A case on a worker that dies is rerun once elsewhere; if it kills a second
worker (it exceeds the memory limit itself) it becomes a failed row (``status = "killed: ..."``)
and the study goes on. The client writes every finished row to the cache as it arrives: killing the client
loses only the cases that were running, and a rerun reuses every cached row (``cached`` is
true in those rows). Finer-level references are computed once per scene variant, before the
cases that need them, and passed between workers through the cache directory: with a remote
scheduler, client and workers must share that filesystem.
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import shutil
import sys
import tempfile
import time
import uuid
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from ..validate import one_line
from ..voigt import VOIGT_WEIGHT
from .cache import Cache
from .cases import (
    REQUIRED,
    base_row,
    case_key,
    load_case_row,
    load_reference_info,
    load_saved_stress,
    reference_info_task,
    reference_key,
    reference_level_task,
    run_case,
    scene_of,
)
from .spec import DEFAULT_CACHE, DEFAULT_MEMORY, Study, StudyError, load_module, load_spec

CONNECT_TIMEOUT = "20s"


def run(spec, out: str | Path | None = None, *, scheduler: str | None = None, workers: int | None = None,
        memory_limit: str | None = DEFAULT_MEMORY, cache: str | Path | None = DEFAULT_CACHE, quiet: bool = False,
        quick: bool = False, client=None) -> pd.DataFrame:
    """Run the study ``spec`` (a spec file, a dict or a loaded :class:`Study`)
    and return its table; with ``out``, also write ``NAME.csv``, ``NAME.md`` and the plots there.

    ``scheduler``: the address of a running Dask scheduler (default: a local cluster of
    ``workers`` processes, each limited to ``memory_limit``); ``client``: an existing
    ``distributed.Client`` to use instead. ``cache``: the directory of cached rows and
    references (``None``: a temporary one, removed at the end)."""
    study = spec if isinstance(spec, Study) else load_spec(spec, quick)
    tmp = None
    if cache is None or cache == "":
        tmp = tempfile.mkdtemp(prefix="cvxdual-study-")
        root = Path(tmp)
    else:
        root = Path(cache).resolve()  # content keys: one directory serves every study (shared references)
    try:
        from ..outputs.output_set import check_writable
        for d in (root, root / "rows", root / "arrays"):  # the cache's layout: refused before any case runs
            check_writable(d, "the study cache", "--cache")
        if out is not None:
            check_writable(out)
        df = _run(study, root, scheduler, workers, memory_limit, quiet, client)
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    if out is not None:
        from .report import write_report
        write_report(df, study, out)
    return df


def _hooks_hash(study: Study) -> str:
    """A hash of the hooks file when it can change rows (it has ``measure``); a report-only hook
    changes no row, so editing it keeps the cache."""
    if not study.hooks_path or getattr(load_module(Path(study.hooks_path)), "measure", None) is None:
        return ""
    return hashlib.sha256(Path(study.hooks_path).read_bytes()).hexdigest()[:16]


def _run(study: Study, root: Path, scheduler, workers, memory_limit, quiet: bool, client) -> pd.DataFrame:
    store = Cache(root)
    scenes: dict = {}
    cases, keys, reprs = [], [], []
    hh = _hooks_hash(study)
    for c in study.cases:
        vk = (c.scene_source, repr(c.overrides), c.units)
        if vk not in scenes:
            scenes[vk] = scene_of(c.scene_source, c.overrides, c.units)  # bad scenes fail here, in one line
        sc = scenes[vk]
        c = replace(c, scene=c.scene or sc.name)
        r = repr(sc)
        cases.append(c)
        reprs.append(r)
        # whether the exact field applies is not in the scene's repr (it depends on where it was declared)
        keys.append(case_key(c, f"{r} exact field: {sc.exact_mismatch or 'applies'}", hh))
    rows: dict = {}
    todo = []
    for i, k in enumerate(keys):
        hit = load_case_row(store, k, cases[i])
        if hit is not None:
            rows[k] = {**hit, "key": k, "cached": True}
        else:
            todo.append(i)
    refs: dict = {}
    need_refs = {reference_key(reprs[i], cases[i].reference, cases[i].metrics): i for i in range(len(cases))
                 if cases[i].reference.kind == "finer"}
    for rk, i in need_refs.items():
        hit = load_reference_info(store, rk, cases[i].reference)
        if hit is not None:
            refs[rk] = hit
    missing = [i for rk, i in need_refs.items() if rk not in refs]  # recomputed even if every row is cached
    if todo or missing:
        with _silent_logs(quiet), _client(client, scheduler, workers, memory_limit, quiet) as cl:
            _execute(cl, study, cases, keys, reprs, todo, refs, store, rows, quiet, missing)
    ordered = [rows[k] for k in keys]
    if study.compare:
        _compare(ordered, study.compare, store)
    df = pd.DataFrame(ordered)
    front = [c for c in REQUIRED + ("cached", "key") if c in df.columns]
    df = df[front + [c for c in df.columns if c not in front]]
    add_local_rates(df)
    df.attrs["references"] = {_variant_label(cases[i]): refs[rk] for rk, i in need_refs.items() if rk in refs}
    df.attrs["study"] = study.name
    df.attrs["metrics"] = dict(cases[0].metrics)
    return df


def _variant_label(case) -> str:
    return case.scene + (f" ({case.overrides_text})" if case.overrides_text else "") + \
        (f" [{case.units[2]}, {case.units[3]}]" if case.units else "")


SILENT = logging.CRITICAL + 10  # a handler level no record reaches
NOISY = ("distributed", "tornado", "bokeh")  # the loggers Dask's processes write to stderr with


@contextlib.contextmanager
def _silent_logs(quiet: bool):
    """With ``quiet``, no log line of Dask in this process (the scheduler and nannies of a local
    cluster run here: a failed task's traceback, a restarted worker) until the block ends; a
    failed case is a row of the table and of the report instead. Every stream handler of those
    loggers is raised above CRITICAL (as ``distributed`` silences its own), then restored."""
    if not quiet:
        yield
        return
    import distributed  # noqa: F401 - it sets up its handlers on import: silence those too
    names = [n for n in list(logging.Logger.manager.loggerDict)
             if n in NOISY or n.startswith(tuple(f"{r}." for r in NOISY))]
    handlers = {h for n in names for h in getattr(logging.getLogger(n), "handlers", ())
                if isinstance(h, logging.StreamHandler)}
    old = {h: h.level for h in handlers}
    try:
        for h in handlers:
            h.setLevel(SILENT)
        yield
    finally:
        for h, level in old.items():
            h.setLevel(level)


def _quiet_worker_plugin():
    """A worker plugin that sends the worker process's stderr (log lines, warnings, whatever a
    library prints) to the null device: for the local cluster's own workers under ``--quiet``,
    including those the nanny restarts (a plugin is set up on every worker that joins)."""
    from distributed.diagnostics.plugin import WorkerPlugin

    class QuietWorker(WorkerPlugin):
        name = "cvxdual-quiet"

        def setup(self, worker):
            import os
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, 2)
            os.close(null)

    return QuietWorker()


# what a local worker logs when the scheduler drops its comm while it retires: dask/distributed's
# shutdown race (a heartbeat in flight meets the closed stream), harmless, with a traceback that
# broke a docs test twice; closing the workers before the scheduler (_close) does not prevent it
HEARTBEAT_RACE = "Failed to communicate with scheduler during heartbeat."


def heartbeat_race_plugin():
    """A worker plugin that drops :data:`HEARTBEAT_RACE` from the worker's log (nothing else)."""
    import logging as _logging

    from distributed.diagnostics.plugin import WorkerPlugin

    class HeartbeatRace(WorkerPlugin):
        name = "cvxdual-heartbeat-race"

        def setup(self, worker):
            class Drop(_logging.Filter):
                def filter(self, record):
                    return record.msg != HEARTBEAT_RACE

            _logging.getLogger("distributed.worker").addFilter(Drop())

    return HeartbeatRace()


@contextlib.contextmanager
def _client(client, scheduler, workers, memory_limit, quiet: bool = False):
    """The Dask client: the one given, one connected to ``scheduler``, or a local cluster's
    (whose workers write nothing to stderr with ``quiet``)."""
    import dask
    from distributed import Client, LocalCluster
    if client is not None:
        _no_retries(client)
        yield client
        return
    if scheduler:
        if not isinstance(scheduler, str) or (":" not in scheduler and not Path(scheduler).is_file()):
            raise StudyError(f"--scheduler {scheduler!r}: give an address such as tcp://127.0.0.1:8786")
        try:
            with dask.config.set({"distributed.comm.timeouts.connect": CONNECT_TIMEOUT}):
                cl = Client(scheduler, timeout=CONNECT_TIMEOUT) if ":" in scheduler else \
                    Client(scheduler_file=scheduler, timeout=CONNECT_TIMEOUT)
        except (OSError, TimeoutError) as e:
            raise StudyError(f"cannot connect to the Dask scheduler at {scheduler!r} ({e}); start one with "
                             "`dask scheduler` or omit --scheduler for a local cluster") from None
        try:
            _no_retries(cl)
            yield cl
        finally:
            cl.close()
        return
    n = workers or min(2, _cpus())
    with dask.config.set(local_config()):
        try:
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, memory_limit=memory_limit,
                                   dashboard_address=":0",  # any free port
                                   silence_logs=SILENT if quiet else logging.ERROR)
        except ValueError as e:
            raise StudyError(f"cannot start a local Dask cluster ({e}); check --workers and --memory-limit "
                             "(e.g. 4GB)") from None
        try:
            with Client(cluster) as cl:
                cl.register_plugin(heartbeat_race_plugin())
                if quiet:
                    cl.register_plugin(_quiet_worker_plugin())
                yield cl
        finally:
            _close(cluster)


WORKERS_CLOSE = 10.0  # seconds the workers get to close before the scheduler does (0.15 s measured)


def _close(cluster) -> None:
    """Close the workers, then the scheduler: a worker whose scheduler went first logs a heartbeat
    traceback on the way out (dask/distributed's known shutdown race; it broke a docs test)."""
    try:
        cluster.scale(0)
        end = time.monotonic() + WORKERS_CLOSE
        while cluster.workers and time.monotonic() < end:
            time.sleep(0.05)
    finally:
        cluster.close()


# A worker that dies fails every case it holds; a case is blamed (a "killed" row) only when it is
# on a second worker that dies, so the cases that merely shared a worker with it are rerun.
ALLOWED_FAILURES = 1


def local_config() -> dict:
    """Dask settings of the local cluster: one case per worker thread at a time, a case that kills
    two workers is not retried again, no pausing or spilling (a case's memory is the solver's,
    not Dask data)."""
    return {"distributed.scheduler.allowed-failures": ALLOWED_FAILURES,
            "distributed.scheduler.worker-saturation": 1.0, "distributed.worker.memory.target": False,
            "distributed.worker.memory.spill": False, "distributed.worker.memory.pause": False,
            "distributed.worker.memory.terminate": 0.95}


def _cpus() -> int:
    import os
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover
        return max(1, os.cpu_count() or 1)


def _set_no_retries(dask_scheduler=None):
    dask_scheduler.allowed_failures = ALLOWED_FAILURES


def _no_retries(client) -> None:
    try:
        client.run_on_scheduler(_set_no_retries)
    except Exception:  # noqa: BLE001 - a scheduler that refuses it keeps its own setting
        pass


def _execute(client, study, cases, keys, reprs, todo, refs, store, rows, quiet, missing=()) -> None:
    from distributed import as_completed
    from distributed.client import FutureCancelledError
    from tqdm import tqdm
    root = str(store.root)
    ref_futs: dict = {}
    all_futs = []
    order = {}
    for i in dict.fromkeys([*todo, *missing]):
        c = cases[i]
        v = (c.scene_source, repr(c.overrides), c.units)
        order.setdefault(v, len(order))
        if c.reference.kind != "finer":
            continue
        rk = reference_key(reprs[i], c.reference, c.metrics)
        if rk in refs or rk in ref_futs:
            continue
        ref = c.reference
        prio = 1000 - order[v]
        levels = [client.submit(reference_level_task, c.scene_source, c.overrides, c.units, ref, L, root,
                                pure=False, priority=prio, key=f"reference-{c.scene}-L{L}-{uuid.uuid4().hex[:8]}")
                  for L in (ref.level, ref.level - 1, ref.level - 2)]
        info = client.submit(reference_info_task, c.scene_source, c.overrides, c.units, ref, c.metrics, root, *levels,
                             pure=False, priority=prio, key=f"reference-{c.scene}-info-{uuid.uuid4().hex[:8]}")
        ref_futs[rk] = info
        for f in levels + [info]:
            order[f.key] = ("ref", rk)
            all_futs.append(f)
    case_futs = {}
    for i in todo:
        c = cases[i]
        rk = reference_key(reprs[i], c.reference, c.metrics) if c.reference.kind == "finer" else None
        ref_arg = None if rk is None else refs.get(rk, ref_futs.get(rk))
        v = (c.scene_source, repr(c.overrides), c.units)
        f = client.submit(run_case, c, ref_arg, root, keys[i], pure=False, priority=-order[v] * 1000 - c.level,
                          key=f"case-{c.scene}-{c.triangulation}-L{c.level}-{c.solver}-{uuid.uuid4().hex[:8]}")
        case_futs[f.key] = i
        all_futs.append(f)
    bar = tqdm(total=len(all_futs), desc=study.name, unit="task", file=sys.stderr, disable=quiet,
               dynamic_ncols=True, leave=True)
    try:
        for f in as_completed(all_futs):
            if f.key in case_futs:
                i = case_futs[f.key]
                row = _result_row(f, cases[i], FutureCancelledError)
                row.update(key=keys[i], cached=False)
                transient = row.pop("_transient", False) or str(row.get("status", "")).startswith(("killed", "timeout"))
                row = store.put_row(keys[i], row) if not transient else _plain(row)
                rows[keys[i]] = {**row, "cached": False}
                bar.set_postfix_str(f"{cases[i].scene} {cases[i].triangulation} L{cases[i].level} "
                                    f"{cases[i].solver}: {str(row.get('status'))[:30]}", refresh=False)
            else:
                kind, rk = order[f.key]
                if f.key == ref_futs[rk].key and f.status == "finished":
                    refs[rk] = f.result()
            bar.update(1)
            f.release()
    finally:
        bar.close()


def _plain(row: dict) -> dict:
    from ..files import to_jsonable as clean
    return clean(row)


def _result_row(f, case, cancelled_error) -> dict:
    from distributed.scheduler import KilledWorker
    try:
        return f.result()
    except KilledWorker:
        return {**base_row(case), "status": "killed: the worker died running this case (memory limit exceeded, "
                "or a crash); raise --memory-limit or use a coarser level", "worker": ""}
    except cancelled_error:
        return {**base_row(case), "status": "killed: cancelled (the scheduler lost the case)", "worker": ""}
    except Exception as e:  # noqa: BLE001 - e.g. the reference of this case failed
        return {**base_row(case), "status": one_line(f"failed: {type(e).__name__}: {e}", 300), "worker": "",
                "_transient": not isinstance(e, StudyError)}


def _compare(rows: list[dict], solvers: tuple, store: Cache) -> None:
    """``paths_agree_l2_rel``: the relative L2 distance between the stresses of rows that differ
    only in solver, each against the last solver of ``solvers`` (which gets the first one's)."""
    *others, ref_name = solvers
    groups: dict = {}
    for r in rows:
        k = tuple(str(r.get(c)) for c in ("case", "group", "scene", "overrides", "units", "triangulation",
                                          "stress_space", "kinematic", "level"))
        groups.setdefault(k, {})[r.get("solver")] = r
    for g in groups.values():
        b = g.get(ref_name)
        sb = _stress(b, store)
        if sb is None:
            continue
        w = sb["area"][:, None] * VOIGT_WEIGHT
        norm = max(float(np.sqrt(np.sum(w * sb["stress"] ** 2))), 1e-300)
        for name in others:
            sa = _stress(g.get(name), store)
            if sa is None or sa["stress"].shape != sb["stress"].shape:
                continue
            g[name]["paths_agree_l2_rel"] = float(np.sqrt(np.sum(w * (sa["stress"] - sb["stress"]) ** 2))) / norm
            b.setdefault("paths_agree_l2_rel", g[name]["paths_agree_l2_rel"])


def _stress(row: dict | None, store: Cache) -> dict | None:
    if row is None or not row.get("stress_key") or row["stress_key"] != "s" + str(row.get("key")):
        return None
    return load_saved_stress(store, row["stress_key"], row.get("n_pieces"))


def add_local_rates(df: pd.DataFrame) -> None:
    """``rate``: ``log(e_prev / e) / log(h_prev / h)`` between consecutive levels of a series."""
    from .report import series_keys
    df["rate"] = np.nan
    if df.empty or "error_l2_rel" not in df:
        return
    e_all = pd.to_numeric(df["error_l2_rel"], errors="coerce")
    for _, g in df.groupby(series_keys(df), sort=False):
        g = g.sort_values("level")
        e, h = e_all[g.index].to_numpy(float), pd.to_numeric(g["h"], errors="coerce").to_numpy(float)
        with np.errstate(divide="ignore", invalid="ignore"):
            df.loc[g.index[1:], "rate"] = np.log(e[:-1] / e[1:]) / np.log(h[:-1] / h[1:])
