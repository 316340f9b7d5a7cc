"""The study cache treats its entries as untrusted (issue 13): every way an entry can be broken,
for each kind of entry the study reads (case rows, reference info rows, reference fields,
saved stresses), is "not cached" (``None``, never an exception), and a rewrite repairs it; a
study whose cache files are corrupted reruns with the same figures, recomputing exactly the
corrupted entries; a zero reference is a clear failed row, never NaN figures."""

from __future__ import annotations

import json
import os
import pickle
import random
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cvxdual import CvxdualError
from cvxdual.study import load_spec, run
from cvxdual.study.cache import ARRAY_FORMAT, KEY_FILE, ROW_FORMAT, Cache, _array_digest
from cvxdual.study.cases import (
    base_row,
    field_key,
    load_case_row,
    load_reference_info,
    load_reference_stress,
    load_saved_stress,
    scene_of,
)
from cvxdual.study.report import markdown

SPEC = {"name": "tiny", "scenes": ["patch"], "levels": [0, 1], "triangulations": ["type1"],
        "solvers": ["CLARABEL", "fast"], "reference": {"level": 2}, "compare": ["CLARABEL", "fast"]}
N = 40  # pieces of the studied mesh in the unit tests (any size: nothing is solved there)


# -- writing entries as an attacker who holds the cache's key would: format, key, a correct MAC --
def _cache_of(path: Path) -> Cache:
    return Cache(path.parent.parent)  # ROOT/rows/KEY.json, ROOT/arrays/KEY.npz


def forge_row(path: Path, key: str, row, **over) -> None:
    entry = {"format": ROW_FORMAT, "key": key, "mac": _cache_of(path).mac(ROW_FORMAT, key, row), "row": row, **over}
    path.write_text(json.dumps(entry))  # json.dumps writes NaN and Infinity literals as they are


def forge_arrays(path: Path, key: str, meta=None, **arrays) -> None:
    if meta is None:
        rec = {k: {"shape": list(a.shape), "dtype": str(a.dtype), "sha256": _array_digest(a)}
               for k, a in arrays.items()}
        meta = {"format": ARRAY_FORMAT, "key": key, "arrays": rec, "mac": _cache_of(path).mac(ARRAY_FORMAT, key, rec)}
    with open(path, "wb") as fh:
        np.savez(fh, __meta__=np.array(json.dumps(meta)), **arrays)


def read_row_entry(path: Path) -> dict:
    return json.loads(path.read_text())


def read_npz(path: Path) -> dict:
    with np.load(path) as z:
        return {k: z[k] for k in z.files if k != "__meta__"}


# -- corruptions of any file --------------------------------------------------------------------
def truncate(frac):
    def f(p, ctx):
        raw = p.read_bytes()
        p.write_bytes(raw[:max(1, int(len(raw) * frac)) if frac < 1 else len(raw) - 2])  # not just the newline
    return f


def empty(p, ctx):
    p.write_bytes(b"")


def garbage(p, ctx):
    p.write_bytes(random.Random(p.name).randbytes(max(64, p.stat().st_size)))


def not_utf8(p, ctx):
    p.write_bytes(b"\xff\xfe\x00{" + bytes(range(128, 256)))


def flip_byte(p, ctx):  # an edited entry: its MAC (or the zip's CRC) no longer matches
    raw = bytearray(p.read_bytes())
    at = len(raw) // 2
    if p.suffix == ".npz":  # in the middle of the stress data (the file's middle may be a zip header field)
        with zipfile.ZipFile(p) as z:
            info = z.getinfo("stress.npy")
        h = info.header_offset  # a local file header: 30 bytes, then the name and the extra field
        names, extra = int.from_bytes(raw[h + 26:h + 28], "little"), int.from_bytes(raw[h + 28:h + 30], "little")
        at = h + 30 + names + extra + info.compress_size // 2
    raw[at] ^= 0x5A
    p.write_bytes(bytes(raw))


def directory(p, ctx):
    p.unlink()
    p.mkdir()
    (p / "inside").write_text("x")


def symlink_loop(p, ctx):
    p.unlink()
    p.symlink_to(p.name)  # a link to itself: ELOOP


def dangling_symlink(p, ctx):
    p.unlink()
    p.symlink_to(p.parent / "nowhere")


def unreadable(p, ctx):
    if os.geteuid() == 0:
        pytest.skip("root reads a chmod 000 file")
    p.chmod(0)


def other_entry(p, ctx):  # a valid entry of another key (another case, level or reference) copied here
    p.write_bytes(ctx["other"].read_bytes())


def other_entry_symlink(p, ctx):
    p.unlink()
    p.symlink_to(ctx["other"])


def other_kind(p, ctx):  # a valid entry of the other kind (rows <-> arrays) under this name
    p.write_bytes(ctx["other_kind"].read_bytes())


GENERIC = {"empty": empty, "truncated 1 byte": truncate(0.0), "truncated 1/3": truncate(1 / 3),
           "truncated 2/3": truncate(2 / 3), "truncated last 2 bytes": truncate(1.0), "garbage": garbage,
           "not utf-8": not_utf8, "edited byte": flip_byte, "directory": directory, "symlink loop": symlink_loop,
           "dangling symlink": dangling_symlink, "unreadable": unreadable, "other key's entry": other_entry,
           "symlink to other key's entry": other_entry_symlink, "other kind of entry": other_kind}


# -- corruptions of rows (JSON) ----------------------------------------------------------------
def text(s):
    def f(p, ctx):
        p.write_text(s)
    return f


def edit_entry(**over):  # the entry's own fields changed (format, key, MAC, row), MAC kept
    def f(p, ctx):
        d = read_row_entry(p)
        for k, v in over.items():
            if v is DROP:
                d.pop(k)
            else:
                d[k] = v
        p.write_text(json.dumps(d))
    return f


DROP = object()


def forge(**over):  # the row changed and the MAC recomputed with the key: only the content checks remain
    def f(p, ctx):
        d = read_row_entry(p)
        row = {**d["row"], **{k: v for k, v in over.items() if v is not DROP}}
        for k in [k for k, v in over.items() if v is DROP]:
            row.pop(k)
        forge_row(p, d["key"], row)
    return f


def forge_text(old: str, new: str, **over):  # a literal JSON cannot hold from Python (1e999)
    def f(p, ctx):
        forge(**over)(p, ctx)
        p.write_text(p.read_text().replace(old, new))
    return f


def row_is_list(p, ctx):
    d = read_row_entry(p)
    forge_row(p, d["key"], list(d["row"].items()))


ROWS = {"json list": text("[1, 2]"), "json string": text('"row"'), "json number": text("3.5"),
        "json null": text("null"), "json empty dict": text("{}"), "deep nesting": text("[" * 100000),
        "wrong format tag": edit_entry(format="cvxdual-study-row/0"), "no format": edit_entry(format=DROP),
        "no key": edit_entry(key=DROP), "no MAC": edit_entry(mac=DROP), "no row": edit_entry(row=DROP),
        "key is a number": edit_entry(key=7), "MAC is a number": edit_entry(mac=12345),
        "row is a list": row_is_list, "row is a string": edit_entry(row="optimal")}
CASE_ROWS = {"another level's row": forge(level=1), "another solver's row": forge(solver="fast"),
             "another study's row": forge(study="other"),
             "error is a dict": forge(error_l2_rel={"value": 0.1}), "level is a string": forge(level="0"),
             "n_pieces is a float": forge(n_pieces=40.0), "h is null": forge(h=None),
             "status is a number": forge(status=1), "error is NaN": forge(error_l2_rel=float("nan")),
             "error is Infinity": forge(error_l2=float("inf")),
             "error is 1e999": forge_text("Infinity", "1e999", error_l2=float("inf")),
             "error is null (NaN) against a finer reference": forge(error_l2_rel=None),
             "reference error est. is null": forge(reference_error_est=None),
             "negative error": forge(error_energy_rel=-0.5), "residual is a list": forge(res_equilibrium=[0.0]),
             "time is a string": forge(t_solve="fast"), "missing required field": forge(worker=DROP),
             "missing error": forge(error_l2=DROP),
             "stress key of another case": forge(stress_key="sother"), "stress key a path": forge(stress_key="../x"),
             "stress key a number": forge(stress_key=3), "no stress key": forge(stress_key=DROP),
             # issue 26: the flag says what the residuals say, whatever it was edited to
             "residual above its tolerance, flag true": forge(res_equilibrium=123.0),
             "residuals within, flag false": forge(within_tolerances=False),
             "a residual missing, flag true": forge(res_duality_gap=DROP),
             "flag a string": forge(within_tolerances="true")}
INFO_ROWS = {"another level's info": forge(level=3), "another triangulation's": forge(triangulation="type1"),
             "error est. is null": forge(error_est=None), "error est. negative": forge(error_est=-1e-3),
             "error est. is a string": forge(error_est="small"), "rate is a dict": forge(rate={"p": 1}),
             "d_last NaN": forge(d_last=float("nan")), "n_pieces 0": forge(n_pieces=0),
             "missing error est.": forge(error_est=DROP), "another stress space's": forge(stress_space="eq"),
             "negative certified bound": forge(certified=-0.1), "certified is a string": forge(certified="1%")}


# -- corruptions of arrays (npz) ---------------------------------------------------------------
def write_with(fn):
    def f(p, ctx):
        with open(p, "wb") as fh:
            fn(fh, ctx)
    return f


class Boom:
    """Unpickling this writes a file: the cache must never unpickle."""

    def __init__(self, path):
        self.path = str(path)

    def __reduce__(self):
        return (Path.write_text, (Path(self.path), "unpickled"))


def pickled_file(p, ctx):
    p.write_bytes(pickle.dumps(Boom(ctx["tripwire"])))


def object_meta(p, ctx):
    with open(p, "wb") as fh:
        np.savez(fh, __meta__=np.array([Boom(ctx["tripwire"])], dtype=object), stress=ctx["arrays"]["stress"])


def object_array(p, ctx):  # consistent meta, one array of pickled objects
    a = np.empty(ctx["arrays"]["stress"].shape, dtype=object)
    a[...] = Boom(ctx["tripwire"])
    meta = {"format": ARRAY_FORMAT, "key": ctx["key"],
            "arrays": {k: {"shape": list(v.shape), "dtype": "object", "sha256": ""} for k, v in ctx["arrays"].items()}}
    with open(p, "wb") as fh:
        np.savez(fh, __meta__=np.array(json.dumps(meta)), **{**ctx["arrays"], "stress": a})


def npy_file(p, ctx):
    with open(p, "wb") as fh:
        np.save(fh, ctx["arrays"]["stress"])


def zip_not_npz(p, ctx):
    with zipfile.ZipFile(p, "w") as z:
        z.writestr("stress.txt", "1 2 3")


def plain_npz(p, ctx):  # the arrays without the metadata record
    with open(p, "wb") as fh:
        np.savez(fh, **ctx["arrays"])


def meta(value):
    def f(p, ctx):
        with open(p, "wb") as fh:
            np.savez(fh, __meta__=np.array(value if isinstance(value, str) else json.dumps(value)), **ctx["arrays"])
    return f


def meta_edit(**over):  # the metadata changed, its MAC kept (or the MAC changed)
    def f(p, ctx):
        rec = {k: {"shape": list(a.shape), "dtype": str(a.dtype), "sha256": _array_digest(a)}
               for k, a in ctx["arrays"].items()}
        good = {"format": ARRAY_FORMAT, "key": ctx["key"], "arrays": rec,
                "mac": _cache_of(p).mac(ARRAY_FORMAT, ctx["key"], rec)}
        forge_arrays(p, ctx["key"], {**good, **over}, **ctx["arrays"])
    return f


def forge_a(fn):  # the arrays changed by fn, metadata and checksums recomputed
    def f(p, ctx):
        forge_arrays(p, ctx["key"], **fn(dict(ctx["arrays"])))
    return f


def _set(name, value):
    def fn(a):
        a[name] = value(a[name]) if callable(value) else value
        return a
    return fn


def _rename(a):
    a["sigma"] = a.pop("stress")
    return a


def _nan(v):
    v = v.copy()
    v[3, 1] = np.nan
    return v


def _inf(v):
    v = v.copy()
    v[0, 0] = -np.inf
    return v


ARRAYS = {"pickle file": pickled_file, "object array meta": object_meta, "object array": object_array,
          "npy file": npy_file, "zip, not npz": zip_not_npz, "npz without metadata": plain_npz,
          "metadata not json": meta("{broken"), "metadata a list": meta([1, 2]),
          "metadata wrong format": meta_edit(format="cvxdual-study-arrays/0"), "metadata wrong key": meta_edit(key="x"),
          "metadata without arrays": meta_edit(arrays=None), "metadata arrays a list": meta_edit(arrays=["stress"]),
          "metadata without MAC": meta_edit(mac=None), "metadata MAC of other arrays": meta_edit(mac="0" * 64),
          "metadata names differ": meta_edit(arrays={"other": {}}),
          "wrong array name": forge_a(_rename), "array missing": forge_a(lambda a: {"other": np.ones(3)}),
          "shape (n+1, 3)": forge_a(_set("stress", lambda v: np.vstack([v, v[:1]]))),
          "shape (n, 2)": forge_a(_set("stress", lambda v: v[:, :2].copy())),
          "flattened": forge_a(_set("stress", lambda v: v.ravel().copy())),
          "a coarser level's": forge_a(_set("stress", lambda v: v[: len(v) // 4].copy())),
          "strings": forge_a(_set("stress", lambda v: v.astype(str))),
          "integers": forge_a(_set("stress", lambda v: np.ones(v.shape, dtype=np.int64))),
          "complex": forge_a(_set("stress", lambda v: v.astype(complex))),
          "NaN": forge_a(_set("stress", _nan)), "-Inf": forge_a(_set("stress", _inf))}
FIELD_ARRAYS = {"all zero": forge_a(_set("stress", lambda v: np.zeros_like(v)))}
SAVED_ARRAYS = {"area of another size": forge_a(_set("area", lambda v: v[:-1].copy())),
                "area is 2-d": forge_a(_set("area", lambda v: v[:, None].copy()))}


# -- the entries under test --------------------------------------------------------------------
def tiny_cases():
    cases = [replace(c, scene="patch") for c in load_spec(SPEC).cases]
    return {(c.level, c.solver): c for c in cases}


def valid_row(case, key: str) -> dict:
    return {**base_row(case), "status": "optimal", "n_pieces": N, "h": 2.5, "error_l2": 1e-3,
            "error_l2_rel": 1e-5, "error_energy": 2e-3, "error_energy_rel": 2e-5, "reference_error_est": 1e-9,
            "res_equilibrium": 1e-15, "res_constitutive": 1e-10, "res_complementarity": 1e-10,
            "res_penetration": 0.0, "res_duality_gap": 1e-9, "t_solve": 0.1, "t_total": 0.2, "iterations": 7,
            "within_tolerances": True,
            "worker": "tcp://127.0.0.1:1", "stress_key": "s" + key, "key": key, "cached": False}


def valid_info(ref) -> dict:
    return {"level": ref.level, "triangulation": ref.triangulation, "solver": ref.solver, "n_pieces": 4 * N,
            "d_last": 1e-4, "d_before": 4e-4, "rate": 2.0, "error_est": 3e-5, "stress_space": ref.stress_space,
            "certified": None}


def _arrays(n: int, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    return {"stress": rng.normal(size=(n, 3)), "area": rng.uniform(0.1, 1.0, n)}


class Entries:
    """A cache holding one valid entry of each kind, a second of each kind (another key), and
    the loader of each kind as the study uses it."""

    def __init__(self, root: Path):
        self.cache = Cache(root)
        cases = tiny_cases()
        self.case, other = cases[0, "CLARABEL"], cases[1, "CLARABEL"]
        self.ref = self.case.reference
        c = self.cache
        c.put_row("caseA", valid_row(self.case, "caseA"))
        c.put_row("caseB", valid_row(other, "caseB"))
        c.put_row("infoA", valid_info(self.ref))
        c.put_row("infoB", {**valid_info(self.ref), "level": 3, "n_pieces": 16 * N})
        c.put_arrays("fieldA", stress=_arrays(4 * N, 1)["stress"])
        c.put_arrays("fieldB", stress=_arrays(N, 2)["stress"])  # a coarser level's reference
        c.put_arrays("scaseA", **_arrays(N, 3))
        c.put_arrays("scaseB", **_arrays(N, 4))
        self.originals = {p: p.read_bytes() for p in root.rglob("*") if p.is_file()}

    def path(self, name: str) -> Path:
        kind, suffix = ("rows", ".json") if name.startswith(("case", "info")) else ("arrays", ".npz")
        return self.cache.root / kind / f"{name}{suffix}"

    def load(self, name: str):
        c = self.cache
        return {"caseA": lambda: load_case_row(c, "caseA", self.case),
                "infoA": lambda: load_reference_info(c, "infoA", self.ref),
                "fieldA": lambda: load_reference_stress(c, "fieldA", 4 * N),
                "scaseA": lambda: load_saved_stress(c, "scaseA", N)}[name]()

    def restore(self, name: str) -> None:
        """Rewrite the valid entry as the study does after recomputing it (over whatever is there)."""
        c = self.cache
        if name == "caseA":
            c.put_row("caseA", valid_row(self.case, "caseA"))
        elif name == "infoA":
            c.put_row("infoA", valid_info(self.ref))
        elif name == "fieldA":
            c.put_arrays("fieldA", stress=_arrays(4 * N, 1)["stress"])
        else:
            c.put_arrays("scaseA", **_arrays(N, 3))


KINDS = ([("caseA", k, f) for k, f in {**GENERIC, **ROWS, **CASE_ROWS}.items()]
         + [("infoA", k, f) for k, f in {**GENERIC, **ROWS, **INFO_ROWS}.items()]
         + [("fieldA", k, f) for k, f in {**GENERIC, **ARRAYS, **FIELD_ARRAYS}.items()]
         + [("scaseA", k, f) for k, f in {**GENERIC, **ARRAYS, **SAVED_ARRAYS}.items()])


@pytest.mark.parametrize("name, kind, corrupt", KINDS, ids=[f"{n}-{k}" for n, k, _ in KINDS])
def test_broken_entry_is_not_cached(tmp_path, name, kind, corrupt):
    e = Entries(tmp_path / "cache")
    assert e.load(name) is not None  # the valid entry loads
    p = e.path(name)
    other = {"caseA": "caseB", "infoA": "infoB", "fieldA": "fieldB", "scaseA": "scaseB"}[name]
    ctx = {"other": e.path(other), "other_kind": e.path("scaseB" if p.suffix == ".json" else "caseB"),
           "tripwire": tmp_path / "unpickled", "key": name}
    if p.suffix == ".npz":
        ctx["arrays"] = read_npz(p)
    corrupt(p, ctx)
    assert e.load(name) is None  # not cached, and no exception
    assert not ctx["tripwire"].exists()  # nothing was unpickled
    if name == "scaseA":  # a case whose saved stresses are broken is recomputed with them
        assert e.load("caseA") is None
    e.restore(name)  # the recomputed entry is written over the broken one
    assert e.load(name) is not None and (name != "scaseA" or e.load("caseA") is not None)
    for q, raw in e.originals.items():  # and no other entry was touched
        if q != p:
            assert q.read_bytes() == raw


def test_cache_keys_and_plain_entries(tmp_path):
    c = Cache(tmp_path)
    for bad in ("../x", "a/b", "", "ключ", None):
        with pytest.raises(ValueError, match="bad cache key"):
            c.get_row(bad)
    assert load_saved_stress(c, "../x", 3) is None and load_saved_stress(c, "sx", None) is None
    c.put_arrays("ints", a=np.arange(4))  # stored as floats: the cache holds float arrays only
    assert c.get_arrays("ints")["a"].dtype == np.float64
    assert c.get_row("nothing") is None and c.get_arrays("nothing") is None
    assert Cache(None).get_arrays("x") is None and Cache(None).put_row("x", {"a": np.float64(1)}) == {"a": 1.0}


# -- issue 26: forged rows ------------------------------------------------------------------------
def _plain_checksum(row) -> str:
    import hashlib
    return hashlib.sha256(json.dumps(row, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def test_forged_row_without_the_key_is_refused(tmp_path):
    """The audit's row: edited by hand (res_equilibrium = 123, within_tolerances = true) with its
    SHA-256 checksum recomputed. Without the cache's key there is no MAC to recompute."""
    e = Entries(tmp_path / "cache")
    p = e.path("caseA")
    d = read_row_entry(p)
    row = {**d["row"], "res_equilibrium": 123.0, "within_tolerances": True}
    for entry in ({"format": "cvxdual-study-row/1", "key": "caseA", "checksum": _plain_checksum(row), "row": row},
                  {"format": ROW_FORMAT, "key": "caseA", "mac": _plain_checksum(row), "row": row},
                  {**d, "row": row}):  # the old MAC kept
        p.write_text(json.dumps(entry))
        assert e.load("caseA") is None
    # a valid row of another cache (another key), copied over this one's
    other = Cache(tmp_path / "other")
    other.put_row("caseA", valid_row(e.case, "caseA"))
    p.write_bytes((tmp_path / "other" / "rows" / "caseA.json").read_bytes())
    assert e.load("caseA") is None
    e.restore("caseA")
    assert e.load("caseA") is not None


def test_forged_row_with_the_key_is_refused_by_its_residuals(tmp_path):
    """Whoever holds the key can sign any row: a flag that its residuals contradict is still refused."""
    e = Entries(tmp_path / "cache")
    forge(res_equilibrium=123.0, within_tolerances=True)(e.path("caseA"), {})
    assert e.load("caseA") is None
    forge(res_equilibrium=123.0, within_tolerances=False)(e.path("caseA"), {})  # honest about its residuals
    assert e.load("caseA")["within_tolerances"] is False


def test_the_cache_key(tmp_path):
    root = tmp_path / "cache"
    c = Cache(root)
    assert c.get_row("x") is None and not root.exists()  # reading creates nothing
    c.put_row("x", {"a": 1})
    key = root / KEY_FILE
    assert key.stat().st_mode & 0o777 == 0o600 and len(key.read_text()) == 64
    assert Cache(root).get_row("x") == {"a": 1}  # another process's Cache reads it with the same key
    assert sorted(p.name for p in root.iterdir()) == [KEY_FILE, "rows"]  # no temporary left
    key.write_text("not a key")
    assert Cache(root).get_row("x") is None  # nothing checks: not cached
    with pytest.raises(CvxdualError, match="is not a key .* remove it, and the cache's entries are recomputed"):
        Cache(root).put_row("x", {"a": 1})
    key.unlink()
    assert Cache(root).get_row("x") is None  # signed with a key that is gone
    Cache(root).put_row("x", {"a": 2})
    assert Cache(root).get_row("x") == {"a": 2}


# -- end to end: a tiny study, its cache corrupted, rerun ----------------------------------------
FIGURES = ["key", "scene", "triangulation", "level", "solver", "status", "n_pieces", "h", "error_l2", "error_l2_rel",
           "error_energy", "error_energy_rel", "reference_error_est", "paths_agree_l2_rel", "rate"]


def _figures(df: pd.DataFrame) -> pd.DataFrame:
    return df[FIGURES].sort_values(["level", "solver"]).reset_index(drop=True)


def _stamps(root: Path) -> dict:
    """Each cache file's identity: an entry rewritten (atomically: a new file renamed into place)
    gets a new inode, and a file broken in place a new mtime."""
    return {str(p.relative_to(root)): (p.lstat().st_ino, p.lstat().st_mtime_ns)
            for p in sorted(root.glob("*/*"))}


def _clear_memo():
    from cvxdual.study import cases
    cases._MEMO.clear()


def _forge_content(p: Path, ctx) -> None:
    """A wrong entry with its own key and a correct checksum: another level's row, a coarser
    reference field, saved stresses of another size."""
    if p.suffix == ".json":
        d = read_row_entry(p)
        forge_row(p, d["key"], {**d["row"], "level": d["row"]["level"] + 1})
    else:
        a = read_npz(p)
        forge_arrays(p, p.stem, **{k: v[: len(v) // 2].copy() for k, v in a.items()})


def _forge_value(p: Path, ctx) -> None:
    """NaN where a number belongs (a row), a zero reference or NaN stresses (arrays)."""
    if p.suffix == ".json":
        d = read_row_entry(p)
        row = {**d["row"], ("error_est" if "error_est" in d["row"] else "error_l2_rel"): float("nan")}
        forge_row(p, d["key"], row)
    else:
        a = read_npz(p)
        forge_arrays(p, p.stem, **{k: np.zeros_like(v) if p.stem.startswith("f") else np.full_like(v, np.nan)
                                   for k, v in a.items()})


E2E = [truncate(0.5), empty, garbage, directory, symlink_loop, other_entry, flip_byte, _forge_content, _forge_value]


@pytest.fixture(scope="module")
def first(client, tmp_path_factory):
    d = tmp_path_factory.mktemp("tiny")
    df = run(SPEC, None, client=client, cache=d / "cache", quiet=True)
    assert (df.status == "optimal").all() and not df.cached.any() and df.paths_agree_l2_rel.notna().all()
    return d / "cache", df


def _rerun(client, cache: Path, first_df: pd.DataFrame) -> pd.DataFrame:
    df = run(SPEC, None, client=client, cache=cache, quiet=True)
    pd.testing.assert_frame_equal(_figures(df), _figures(first_df), check_exact=True)  # to the last digit
    assert df.attrs["references"] == first_df.attrs["references"]
    study = load_spec(SPEC)
    assert markdown(df, study, "tiny") == markdown(first_df, study, "tiny")
    return df


def _reference():
    return scene_of("patch", (), None), tiny_cases()[0, "fast"].reference


def _loads(cache: Path, df: pd.DataFrame) -> None:
    """Every entry of the study loads with its checks (as the study reads it)."""
    from cvxdual import discretize
    store = Cache(cache)
    cases = tiny_cases()
    for _, r in df.iterrows():
        assert load_case_row(store, r.key, cases[r.level, r.solver]) is not None
    scene, ref = _reference()
    for level in (0, 1, 2):
        n = len(discretize(scene, ref.triangulation, level)[1])
        assert load_reference_stress(store, field_key(repr(scene), ref, level), n) is not None
    (info,) = (cache / "rows").glob("r*.json")
    assert load_reference_info(store, info.stem, ref) is not None


@pytest.mark.slow
def test_rerun_after_corrupting_every_file(client, first, tmp_path):
    """Every cache file broken (three rounds, each file a different way each round): the rerun
    recomputes every entry, with the same figures; the workers' in-memory reference (the last
    one they loaded) is written back where its file is broken."""
    cache, df0 = first
    files = sorted(cache.glob("*/*"))
    assert len(files) == 4 + 1 + 3 + 4  # case rows, reference info, reference fields, saved stresses
    for shift in (0, 3, 6):
        copies = {}
        for p in files:  # another valid entry of the same kind (same directory and prefix where there is one)
            same = [q for q in files if q.parent == p.parent and q.name[0] == p.name[0] and q != p] or \
                [q for q in files if q.parent == p.parent and q != p]
            copies[p] = tmp_path / f"{shift}-{p.name}"
            copies[p].write_bytes(same[0].read_bytes())
        for i, p in enumerate(files):
            E2E[(i + shift) % len(E2E)](p, {"other": copies[p]})
        df = _rerun(client, cache, df0)
        assert not df.cached.any()  # every row recomputed
        _loads(cache, df)


def test_rerun_recomputes_exactly_the_corrupted_entries(client, first):
    cache, df0 = first
    scene, ref = _reference()
    field = {L: f"arrays/{field_key(repr(scene), ref, L)}.npz" for L in (0, 1, 2)}
    keys = _figures(df0).set_index(["level", "solver"])["key"]
    (info,) = [f"rows/{p.name}" for p in (cache / "rows").glob("r*.json")]
    row = {k: f"rows/{k}.json" for k in keys}
    saved = {k: f"arrays/s{k}.npz" for k in keys}
    a, b = keys[0, "CLARABEL"], keys[1, "fast"]
    rounds = [  # (what is broken and how, the cases recomputed, the entries rewritten)
        ({row[a]: _forge_content, field[2]: _forge_value, saved[b]: garbage}, {a, b},
         {row[a], saved[a], field[2], row[b], saved[b]}),
        ({info: truncate(0.5)}, set(), {info}),  # no row needs it, the report does
        ({info: _forge_value, field[0]: directory, field[1]: _forge_content}, set(), {info, field[0], field[1]}),
        ({row[b]: flip_byte}, {b}, {row[b], saved[b]}),
    ]
    for broken, recomputed, rewritten in rounds:
        for rel, how in broken.items():
            how(cache / rel, {})
        client.run(_clear_memo)  # workers as new: the reference is read from the cache
        before = _stamps(cache)
        df = _rerun(client, cache, df0)
        assert set(df.key[~df.cached]) == recomputed
        after = _stamps(cache)
        assert set(after) == set(before) and {f for f in after if after[f] != before[f]} == rewritten
        _loads(cache, df)


def test_zero_reference_is_a_failed_row(client, tmp_path):
    """A freshly computed zero reference (an unloaded scene): a failed row that says why, no NaN
    figures, and nothing cached. (A zero exact field is refused with the scene itself.)"""
    unloaded = {"bodies": {"top": {"boundary": {"pressure": {"traction": {"value": [0.0, 0.0]}}}}}}
    spec = {"name": "zero", "levels": [0], "triangulations": ["type1"], "solvers": ["fast"],
            "cases": [{"name": "unloaded", "overrides": unloaded,
                       "scenes": [{"source": "patch", "reference": {"level": 2}}]}]}
    df = run(spec, tmp_path / "out", client=client, cache=tmp_path / "cache", quiet=True).set_index("case")
    assert len(df) == 1 and not df.status.str.startswith("optimal").any()
    assert "## Failed cases" in (tmp_path / "out" / "zero.md").read_text()  # the report says so
    assert "zero everywhere" in df.status["unloaded"] and "reference" in df.status["unloaded"]
    assert not list(tmp_path.glob("cache/arrays/*.npz"))  # no zero reference was cached
    zero_exact = {**spec, "cases": [{"name": "zero exact", "overrides": {"exact": {"stress": [0.0, 0.0, 0.0]}},
                                     "scenes": [{"source": "patch", "reference": "exact"}]}]}
    with pytest.raises(CvxdualError, match="zero stress"):
        run(zero_exact, None, client=client, cache=tmp_path / "cache", quiet=True)
