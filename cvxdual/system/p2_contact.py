"""The faces' middle unknowns of the P2 kinematic side (docs/equilibrium.md, section 12.4): at every face
middle of the contact interval the unknown is the middle Bernstein coefficient of ``v_y`` on the true
face, so that the sufficient pointwise condition on each interval is a pair constraint for the
active-set core; a change of variables local to the elements (:func:`face_middles`,
:func:`middle_maps`, :func:`element_maps`)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import MeshError
from ..geometry.triangles import edge_keys, sub_vertices
from .p2 import N_BOUNDARY, SUB_NODES, shapes_at
from .p2_layout import P2Layout


def face_middles(system_parts, ja: np.ndarray, jb: np.ndarray) -> tuple[np.ndarray, sp.csr_matrix, np.ndarray]:
    """The faces' middle unknowns: for every contact interval and face (upper, then lower), the r index
    ``m`` of its middle's y value, the row ``gamma`` ``(len(m), n_r)`` with ``gamma . r`` the middle
    Bernstein coefficient ``2 a(x_m) - (a(x_0) + a(x_1)) / 2`` of the face's ``v_y`` on the true face
    (``a`` at the ends: the vertex values; in the middle: the trace's middle value, or on a segment its
    triangle's quadratic at the arc's point, interior dofs condensed) and its constant part ``beta``
    (the interior dofs' load) ``(len(m),)``."""
    lay, sup, rdof, cond, ui, faces, n_r = system_parts
    mid = np.concatenate([ja[1::2], jb[1::2]])
    ends = np.stack([np.concatenate([ja[0:-1:2], jb[0:-1:2]]), np.concatenate([ja[2::2], jb[2::2]])], 1)
    k = np.arange(len(mid))
    rows, cols, vals = [k, k, k], [mid, ends[:, 0], ends[:, 1]], [np.full(len(mid), 2.0), np.full(len(mid), -0.5),
                                                                 np.full(len(mid), -0.5)]
    beta = np.zeros(len(mid))
    n_c = len(ja) // 2
    slabs = middle_slabs(lay, n_c)
    seg = np.flatnonzero(lay.on_element(slabs))
    if len(seg):
        t, j = lay.slab_tri[slabs[seg]], lay.slab_sub[slabs[seg]]
        P = sub_vertices(lay.coords[lay.tri[t]])[np.arange(len(t)), j]
        xm = 0.5 * (lay.pair_x[0:-1:2] + lay.pair_x[2::2])[seg % n_c]
        ym = np.where(seg < n_c, faces[0].value(xm), faces[1].value(xm))
        N, _ = shapes_at(P, np.stack([xm, ym], 1)[:, None])
        a20 = np.zeros((len(seg), 20))
        a20[np.arange(len(seg))[:, None], 2 * SUB_NODES[j] + 1] = N[:, 0]
        a12 = a20[:, :N_BOUNDARY] - np.einsum("mik,mi->mk", cond.R[t], a20[:, N_BOUNDARY:])
        beta[seg] = np.einsum("mi,mi->m", a20[:, N_BOUNDARY:], ui[t])
        nodes = lay.nodes[t]  # (m, 6): coefficients in the nodes' frames (q_c = sum_k frame[k, c] r_k)
        coef = np.einsum("mnkc,mnc->mnk", sup.frame[nodes], a12.reshape(-1, 6, 2))
        r = rdof[2 * nodes[:, :, None] + np.arange(2)]
        live = r >= 0
        vals[0][seg] = 0.0  # the middle's own 2: now in the quadratic's coefficients
        rows.append(np.broadcast_to(seg[:, None, None], r.shape)[live])
        cols.append(r[live])
        vals.append(2.0 * coef[live])
    gamma = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(len(mid), n_r))
    return mid, gamma, beta


def middle_slabs(lay: P2Layout, n_c: int) -> np.ndarray:
    """``(2 n_c,)``: the slab under each contact interval of the upper, then the lower face, or -1."""
    out = np.full(2 * n_c, -1)
    if not len(lay.slab_nodes):
        return out
    key = edge_keys(lay.slab_nodes[:, 0], lay.slab_nodes[:, 2], lay.n_nodes)
    order = np.argsort(key)
    pn = lay.pair_nodes
    want = np.concatenate([edge_keys(pn[0:-1:2, b], pn[2::2, b], lay.n_nodes) for b in (0, 1)])
    i = order[np.clip(np.searchsorted(key[order], want), 0, len(order) - 1)]
    return np.where(key[i] == want, i, -1)


def middle_maps(mid: np.ndarray, gamma: sp.csr_matrix) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """``W`` and ``W^-1`` ``(n_r, n_r)`` with ``r = W r'``: ``r'`` is ``r`` but at the middles ``mid``, where it is
    ``gamma . r``; ``r_m = (r'_m - sum_(k != m) gamma_k r_k) / gamma_m`` (the other unknowns stay)."""
    n_r = gamma.shape[1]
    g = gamma.tocoo()
    own = gamma[np.arange(len(mid)), mid].A1
    if np.any(np.abs(own) < 1e-3 * abs(gamma).max(axis=1).toarray().ravel()):
        raise MeshError("internal: a face middle's own coefficient vanishes")  # pragma: no cover
    keep = np.ones(n_r, bool)
    keep[mid] = False
    eye = sp.diags(keep.astype(float), format="csr")
    inv = eye + sp.csr_matrix((g.data, (mid[g.row], g.col)), shape=(n_r, n_r))
    off = g.col != mid[g.row]
    W = eye + sp.csr_matrix((np.concatenate([1.0 / own, -g.data[off] / own[g.row[off]]]),
                             (np.concatenate([mid, mid[g.row[off]]]), np.concatenate([mid, g.col[off]]))),
                            shape=(n_r, n_r))
    return W.tocsr(), inv.tocsr()


def element_maps(kloc: np.ndarray, local: np.ndarray, mid: np.ndarray, W: sp.csr_matrix) -> np.ndarray:
    """Element matrices ``W_e^T k W_e`` in the variables of :func:`middle_maps`: ``W_e`` the rows of ``W`` on the
    element's unknowns (each r index at its first local position). Every element holding a middle holds
    every unknown its row names (the face edge's triangle, its slab): checked."""
    where = np.full(W.shape[0], -1)
    where[mid] = np.arange(len(mid))
    hit_e, hit_i = np.nonzero((local >= 0) & (where[np.maximum(local, 0)] >= 0))
    if not len(hit_e):
        return kloc
    loc = local[hit_e]  # (h, 12)
    first = np.ones(loc.shape, bool)
    for p in range(1, loc.shape[1]):  # 12 positions: an r index may repeat (generality)
        first[:, p] = ~np.any(loc[:, :p] == loc[:, p:p + 1], axis=1)
    first &= loc >= 0
    rows = W[local[hit_e, hit_i]]  # (h, n_r)
    block = rows[np.arange(len(hit_e))[:, None], np.maximum(loc, 0)].toarray() * first
    if not np.allclose(block.sum(1), rows.sum(1).A1, rtol=1e-12, atol=1e-12 * abs(rows).max()):
        raise MeshError("internal: a face middle's map names an unknown outside its element")  # pragma: no cover
    elems = np.unique(hit_e)
    We = np.broadcast_to(np.eye(kloc.shape[1]), (len(elems), kloc.shape[1], kloc.shape[1])).copy()
    We[np.searchsorted(elems, hit_e), hit_i] = block
    out = kloc.copy()
    out[elems] = We.transpose(0, 2, 1) @ kloc[elems] @ We
    return out
