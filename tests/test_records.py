"""The typed records where the layers meet (cvxdual.records, cvxdual.eq.edges.MeshEdges): frozen,
read as the dicts they replaced (same keys, same order, same JSON), and round-trip."""

import dataclasses
import functools
import json
import pickle
from collections.abc import Mapping

import numpy as np
import pytest

import cvxdual as cd
from cvxdual.eq.bounds import exact_errors
from cvxdual.eq.edges import MeshEdges, mesh_edges
from cvxdual.files import json_text, to_jsonable
from cvxdual.p0.norms import stress_error
from cvxdual.records import (
    BoundContributions,
    Bounds,
    Contact,
    DisplacementFix,
    ErrorNorms,
    ExactErrors,
    Record,
)
from cvxdual.system.p2_displacement import P2Displacement

# the keys, in order, of the dicts the records replaced (as the producers built them)
P0_CONTACT = ["x", "gap", "relative_displacement", "force", "pressure", "active", "tangential_force", "slip", "stick",
              "reaction", "n_active", "x_min", "x_max", "max_pressure", "total_force"]
EQ_CONTACT = ["x", "gap", "relative_displacement", "force", "pressure", "active", "edge_pressure", "tangential_force",
              "slip", "stick", "n_active", "x_min", "x_max", "max_pressure", "total_force"]
BOUNDS = ["energy_upper", "energy_lower", "gap", "gap_identity", "error_bound", "complementary_energy", "contributions",
          "data_oscillation", "residuals", "displacement", "displacement_fix", "guaranteed", "reasons", "kinematic",
          "error_bound_rel"]
CONTRIBUTIONS = ["element", "sub", "column", "contact", "continuation"]
FIX = ["max_shift", "n_shifted", "min_slack_before", "min_slack", "exact_min", "support_violation",
       "displacement_scale"]
ERROR_NORMS = ["l2", "l2_rel", "energy", "energy_rel", "rule"]
EXACT_ERRORS = ["l2", "l2_rel", "stress_A", "displacement_a", "combined", "reference_A", "l2_rel_displacement", "rule"]
EDGES = ["keys", "lo", "hi", "ng", "id", "flip", "count", "boundary", "owner", "length"]


@functools.lru_cache(maxsize=None)
def p0():
    return cd.solve("hertz", level=1, solver="fast", bounds=True)


@functools.lru_cache(maxsize=None)
def eq():
    return cd.solve("hertz", level=1, stress_space="eq")


@functools.lru_cache(maxsize=None)
def records() -> dict:
    """One record of every kind, from the two solved scenes, with the keys its dict had."""
    a, b = p0(), eq()
    ex = cd.exact_field(a.scene)
    s = b.space
    return {"p0 contact": (a.contact, P0_CONTACT), "eq contact": (b.contact, EQ_CONTACT),
            "bounds": (b.bounds, BOUNDS), "p0 bounds": (a.bounds, BOUNDS),
            "contributions": (b.bounds["contributions"], CONTRIBUTIONS),
            "displacement fix": (b.bounds["displacement_fix"], FIX),
            "error norms": (stress_error(a.system, a.stress, ex.stress, 2), ERROR_NORMS),
            "exact errors": (exact_errors(s, b.stress, b.displacement, ex, n=2, g=b.column_stress), EXACT_ERRORS),
            "edges": (mesh_edges(s.tri, s.mesh.points, s.mesh.n_nodes), EDGES)}


KINDS = ["p0 contact", "eq contact", "bounds", "p0 bounds", "contributions", "displacement fix", "error norms",
         "exact errors", "edges"]


def old_dict(rec: Record, keys: list[str]) -> dict:
    """The dict the producer returned before: its keys, in its order, built from the fields."""
    field = {k: f for f, k in rec.KEY_OF.items()}
    return {k: getattr(rec, field.get(k, k)) for k in keys}


def test_the_solutions_hold_records():
    a, b = p0(), eq()
    assert type(a.contact) is Contact and type(b.contact) is Contact
    assert type(a.bounds) is Bounds and type(b.bounds) is Bounds
    assert type(b.bounds["contributions"]) is BoundContributions
    assert type(b.bounds["displacement_fix"]) is DisplacementFix
    assert isinstance(b.bounds["residuals"], dict)  # a per-name map of the constraint blocks


@pytest.mark.parametrize("kind", KINDS)
def test_records_are_frozen(kind):
    rec, keys = records()[kind]
    with pytest.raises(dataclasses.FrozenInstanceError):
        setattr(rec, dataclasses.fields(rec)[0].name, None)
    with pytest.raises(TypeError):  # no item assignment either
        rec[keys[0]] = None
    with pytest.raises(TypeError):  # unhashable, as the dicts were (array fields)
        hash(rec)


@pytest.mark.parametrize("kind", KINDS)
def test_the_mapping_view_keeps_the_keys_and_their_order(kind):
    rec, keys = records()[kind]
    assert isinstance(rec, Mapping)
    assert list(rec) == keys and list(rec.keys()) == keys and list(dict(rec)) == keys and len(rec) == len(keys)
    field = {k: f for f, k in rec.KEY_OF.items()}
    assert all(rec[k] is getattr(rec, field.get(k, k)) for k in keys)
    assert [k for k, _ in rec.items()] == keys
    with pytest.raises(KeyError):
        rec["no such key"]
    assert rec.get("no such key", 7) == 7


@pytest.mark.parametrize("kind", KINDS)
def test_json_of_a_record_is_the_old_dicts(kind):
    rec, keys = records()[kind]
    old = old_dict(rec, keys)
    new = rec.as_dict()
    assert json_text(new) == json_text({k: v.as_dict() if isinstance(v, Record) else v for k, v in old.items()})
    if not any(isinstance(v, Record) for v in rec.values()):  # flat: the shallow dict too
        assert json.dumps(to_jsonable(dict(rec))) == json.dumps(to_jsonable(old))
    assert json.loads(json_text(new)) == to_jsonable(new)  # round trip through JSON


def test_summary_is_the_same_as_with_dicts():
    """summary.json of solutions holding records equals that of the same solutions holding the
    dicts built from the records' fields (what the producers returned before)."""
    for sol, contact in ((p0(), P0_CONTACT), (eq(), EQ_CONTACT)):
        b = sol.bounds
        plain = dataclasses.replace(sol, contact=old_dict(sol.contact, contact),
                                    bounds={**old_dict(b, BOUNDS), "reasons": list(b["reasons"]),
                                            "contributions": dict(b["contributions"]),
                                            "displacement_fix": dict(b["displacement_fix"])})
        assert json_text(sol.summary()) == json_text(plain.summary())


@pytest.mark.parametrize("kind", KINDS)
def test_records_round_trip(kind):
    rec, _ = records()[kind]
    field = {k: f for f, k in rec.KEY_OF.items()}
    again = type(rec)(**{field.get(k, k): v for k, v in rec.items()})  # from its own mapping
    back = pickle.loads(pickle.dumps(rec))
    for other in (again, back):
        assert type(other) is type(rec) and list(other) == list(rec)
        for k in rec:
            v, w = rec[k], other[k]
            if isinstance(v, np.ndarray):
                np.testing.assert_array_equal(w, v)
            elif isinstance(v, P2Displacement):  # the P2 bounds' displacement: its values
                np.testing.assert_array_equal(w.q, v.q)
                np.testing.assert_array_equal(w.interior, v.interior)
            elif not isinstance(v, (Record, dict)):
                assert w == v or (v != v and w != w), k  # NaN == NaN here


def test_optional_keys_are_left_out_while_none_and_others_stay():
    c = p0().contact
    e = eq().contact
    assert "reaction" in c and "edge_pressure" not in c and c.edge_pressure is None
    assert "edge_pressure" in e and "reaction" not in e
    assert "stick" in c and "stick" in e  # always keys: contact.csv's columns
    none = c.replace(x_min=None, x_max=None)  # no active pair: still keys, with None
    assert none["x_min"] is None and "x_max" in none and list(none) == P0_CONTACT
    assert list(DisplacementFix()) == [] and dict(DisplacementFix()) == {}


def test_scalar_records_equal_their_dicts():
    rec, keys = records()["error norms"]
    assert rec == old_dict(rec, keys) and rec == rec.replace()
    assert rec != rec.replace(rule=rec.rule + 1)


def test_mesh_edges_keeps_the_keys_key_and_takes_its_axis():
    edges = records()["edges"][0]
    assert type(edges) is MeshEdges and edges["keys"] is edges.key
    axis = np.ones((len(edges.key), 2))
    assert list(edges.replace(axis=axis)) == EDGES + ["axis"]
    assert list({**edges, "axis": axis}) == EDGES + ["axis"]  # as the space extends it


def test_no_field_hides_a_mapping_method():
    classes = [Contact, ErrorNorms, ExactErrors, BoundContributions, DisplacementFix, Bounds, MeshEdges]
    methods = {n for n in dir(Mapping) if not n.startswith("_")} | {"replace", "as_dict"}
    for cls in classes:
        assert not {f.name for f in dataclasses.fields(cls)} & methods, cls.__name__
