"""Plane predicates: the sweep's meeting pairs against every pair tested, point in polygon."""

import numpy as np
import pytest

from cvxdual.scene import planar
from cvxdual.scene.planar import inside, meeting_pairs, segments_meet


def brute(segs, tol):
    m = segments_meet(segs[:, 0], segs[:, 1], segs[:, 0], segs[:, 1], tol)
    i, j = np.nonzero(np.triu(m, 1))
    return np.stack([i, j], 1)


@pytest.mark.parametrize("seed", range(4))
def test_sweep_finds_every_meeting_pair(seed, monkeypatch):
    # short segments, long ones (a whole x range: many candidates) and exact touches at shared ends
    rng = np.random.default_rng(seed)
    short = rng.uniform(0, 10, (300, 1, 2)) + rng.normal(0, 0.3, (300, 2, 2))
    long_ = rng.uniform(0, 10, (6, 2, 2))
    chain = np.linspace([0.0, 5.0], [10.0, 6.0], 41)
    segs = np.concatenate([short, long_, np.stack([chain[:-1], chain[1:]], 1)])
    want = brute(segs, 1e-12)
    assert len(want) > 100  # the case has meetings to find
    np.testing.assert_array_equal(meeting_pairs(segs, 1e-12), want)
    monkeypatch.setattr(planar, "PAIR_BLOCK", 97)  # many blocks, some rows longer than a block
    np.testing.assert_array_equal(meeting_pairs(segs, 1e-12), want)


def test_touching_counts_a_gap_does_not():
    # a T junction (one end exactly on the other segment) meets; 1e-3 short of it does not
    t = np.array([[[0.0, 0.0], [1.0, 0.0]], [[0.5, 0.0], [0.5, 1.0]]])
    gap = t.copy()
    gap[1, 0, 1] = 1e-3
    assert meeting_pairs(t, 1e-12).tolist() == [[0, 1]]
    assert meeting_pairs(gap, 1e-12).tolist() == []


def test_inside_square_with_many_points():
    ring = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    pts = np.array([[0.5, 0.5], [1.5, 0.5], [0.5, -0.1], [0.99, 0.01]])
    assert inside(ring, pts).tolist() == [True, False, False, True]
    assert inside(ring, pts[0]) is True
