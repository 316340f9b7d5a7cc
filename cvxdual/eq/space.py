"""An exactly admissible (equilibrium) stress space (docs/equilibrium.md).

The Johnson-Mercier / Watwood-Hartz element: every mesh triangle ``T`` (a *macro* triangle)
is split at its barycentre ``c`` into the sub-triangles ``T_i = (X_i, X_{i+1}, c)``; on each
the stress is linear, given by its Voigt values ``(s11, s22, s12)`` at the three
sub-triangle vertices (27 numbers per macro triangle, index ``9 i + 3 a + component``).

Reduced parameters (docs/equilibrium.md): the 12 conditions "``sigma n`` continuous across
the three internal edges" leave 15 parameters per macro triangle; we take as parameters
the JM degrees of freedom, the traction ``sigma n_g`` (normal and tangential components in a
frame ``n_g, t_g`` fixed per *global* edge; on the edges of a sliding support guided across
them, the frame of its direction) at both ends of each macro edge (12) plus three
interior "bubbles" with zero boundary traction. Edge parameters are shared by the two
triangles of an edge, so inter-element continuity holds by construction; the boundary
conditions fix parameters (tractions, free sides, zero tangential contact traction) or keep
them free (supports); the upper and lower contact faces share one normal-traction
parameter per contact edge end (action = reaction), whose sign ``<= 0`` is a simple bound.
Only ``div sigma + F = 0`` (6 rows per macro triangle) remains as an equality constraint.

The macro triangles are the straight pieces of either triangulation. On the curved pieces the
stress is a column field ``g(x) e_y (x) e_y`` (:mod:`cvxdual.eq.columns`), ``g`` linear on each
face interval; the Johnson-Mercier traction of the interval's face edge (a chord, a polygon edge,
a type-1 slanted side) is tied to it, ``sigma n = (0, g n_y)``, by merging the edge's two
traction components at each end into one parameter, the vertical stress ``g`` there. On a flat
face that tie is the identity; contact edges carry it on either face, so the shared contact
parameter is the vertical stress at the edge end whatever the faces' shapes.

Notation of the paper (Tran Van Bon 1986) and docs/theory.md: ``lam``/``sigma`` the stress, ``S_EP``
the statically admissible set, ``eps`` the initial gap, ``A = C^-1`` the compliance, ``F`` the
body force, ``P`` the prescribed traction, ``p = -sigma_nn >= 0`` the contact pressure.
Stress parameter vector ``y`` (physical units): ``sigma = S y + sigma0`` on the vertex values.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from ..errors import MeshError, SceneError
from ..geometry.mesh import Mesh
from ..geometry.pieces import Pieces
from ..geometry.quadrature import gauss01
from ..geometry.triangles import bary_gradients, edge_keys, sub_vertices
from ..geometry.triangulation import discretize
from ..linalg.sparse import assemble_blocks
from ..scene.scene import Scene
from ..system.assembly import Scales
from ..system.boundary import sliding_normal
from ..voigt import compliances
from .balance import balance_loads, make_scales
from .columns import FaceIntervals, check_column_data, column_energy, face_intervals, slab_interval
from .edges import MeshEdges, edge_ids, mesh_edges, outward_normals
from .element import (
    MASS0,
    divergence_rows,
    edge_blocks,
    inverse2,
    local_basis,
    mapped_values,
    piola,
    traction_rows,
)

N_GAUSS = 10  # per edge: tractions and gap products (degree 19; exact for the built-in data)
FREE, FIXED, CONTACT = 0, 1, 2  # kinds of the raw edge parameters


@dataclass(frozen=True)
class EquilibriumSpace:
    """The equilibrium stress space of a mesh and its pieces, with its admissibility data
    (physical units); built complete by :meth:`from_pieces` and never changed afterwards.

    Geometry: ``X (n_T, 3, 2)`` macro triangles (the straight pieces), ``body (n_T,)``. The local
    basis of triangle ``t`` is the reference basis mapped by ``piola[t]`` (``(n_T, 3, 3)``, Voigt)
    with edge coefficient blocks ``coef[t]`` (``(n_T, 6, 2, 2)``: the inverse edge-dof blocks, the
    face edges' ties merged in; :mod:`cvxdual.eq.element`); local slot ``i`` of ``t`` is raw parameter
    ``dofs[t, i]``. Raw parameters ``z`` (``4 n_E`` edge dofs, then ``3 n_T`` bubbles) =
    ``Tm y + z_fix``; vertex values ``sigma = P z = S y + sigma0`` (``P``: :attr:`raw_map`, ``S``:
    :attr:`stress_map`, built on demand: the fast route never forms them); column values
    ``g = z[column_dofs]`` ``(n_col, 2)`` at both ends of every column interval ``columns``
    (indices into ``faces``; energy ``column_energy_blocks``). :attr:`div`: rows ``h_T div sigma``
    with right-hand side ``div_rhs = -h_T F``. ``contact_y (n_c, 2)``: the
    ``y`` index of the vertical stress at both ends of each contact edge (``contact_x (n_c, 2)``).
    """

    mesh: Mesh
    pieces: Pieces
    triangulation: str  # of the pieces: "type1" or "type2"
    tri: np.ndarray  # (n_T, 3) nodes of the macro triangles
    X: np.ndarray
    body: np.ndarray
    piola: np.ndarray
    coef: np.ndarray
    dofs: np.ndarray
    edges: MeshEdges
    Tm: sp.csr_matrix
    z_fix: np.ndarray
    kind: np.ndarray
    div_rhs: np.ndarray
    contact_y: np.ndarray
    contact_x: np.ndarray
    traction_edges: dict
    faces: FaceIntervals
    face_edge: np.ndarray  # (m,) global edge of each face interval's face edge
    columns: np.ndarray  # (n_col,) the face intervals with curved pieces
    column_dofs: np.ndarray  # (n_col, 2) raw parameter of g at the left and right end
    column_energy_blocks: np.ndarray  # (n_col, 2, 2) their energy: 1/2 g.Q g
    slab_column: np.ndarray  # (n_slabs,) the column of each slab of ``pieces``
    scales: Scales
    load_imbalance: float
    load_correction: float = 0.0  # relative size of the change that balanced the loads (eq.balance)

    @classmethod
    def from_pieces(cls, mesh: Mesh, pieces: Pieces, triangulation: str) -> "EquilibriumSpace":
        """The space of ``mesh`` and its ``pieces`` (of ``triangulation``: :func:`~cvxdual.geometry.discretize`)."""
        return build_space(mesh, pieces, triangulation)

    @classmethod
    def from_scene(cls, scene: Scene, level: int | None = None, triangulation: str = "type1") -> "EquilibriumSpace":
        mesh, pieces, _ = discretize(scene, triangulation, level)
        return cls.from_pieces(mesh, pieces, triangulation)

    @property
    def scene(self) -> Scene:
        return self.mesh.scene

    @property
    def n_tri(self) -> int:
        return len(self.X)

    @property
    def n_y(self) -> int:
        return self.Tm.shape[1]

    @cached_property
    def sub_geometry(self) -> tuple[np.ndarray, np.ndarray]:
        """Barycentric gradients ``(n_T, 3, 3, 2)`` and areas ``(n_T, 3)`` of the sub-triangles."""
        return bary_gradients(sub_vertices(self.X))

    def local_basis(self, t: np.ndarray | slice = slice(None)) -> np.ndarray:
        """``(len(t), 27, 15)``: vertex values of the local basis of triangles ``t``."""
        return local_basis(self.piola[t], self.coef[t])

    @property
    def basis(self) -> np.ndarray:
        """``(n_T, 27, 15)``: every local basis (405 numbers a triangle: formed on request only)."""
        return self.local_basis()

    @cached_property
    def raw_map(self) -> sp.csr_matrix:
        """``P``: vertex values ``(27 n_T)`` of the raw parameters (the CVXPY model's map)."""
        return self.vertex_map()

    def vertex_map(self, t: np.ndarray | None = None) -> sp.csr_matrix:
        """``P`` restricted to the rows of triangles ``t`` (all by default; the others' rows empty)."""
        t = np.arange(self.n_tri) if t is None else np.asarray(t, int)
        rows = 27 * t[:, None] + np.arange(27)[None, :]
        return assemble_blocks(rows, self.dofs[t], self.local_basis(t), (27 * self.n_tri, len(self.kind)))

    @cached_property
    def div(self) -> sp.csr_matrix:
        """Rows ``h_T div sigma`` on the vertex values (6 per macro triangle)."""
        n_T = self.n_tri
        return assemble_blocks(6 * np.arange(n_T)[:, None] + np.arange(6)[None, :],
                               27 * np.arange(n_T)[:, None] + np.arange(27)[None, :],
                               divergence_rows(self.X)[0], (6 * n_T, 27 * n_T))

    @cached_property
    def stress_map(self) -> sp.csr_matrix:
        return (self.raw_map @ self.Tm).tocsr()

    @property
    def sigma0(self) -> np.ndarray:
        return self.raw_values(self.z_fix).ravel()

    def raw_values(self, z: np.ndarray) -> np.ndarray:
        """Vertex stresses ``(n_T, 27)`` of raw parameters ``z``, triangle by triangle."""
        return mapped_values(self.piola, self.coef, np.asarray(z, float)[self.dofs])

    def vertex_values(self, y: np.ndarray) -> np.ndarray:
        """Vertex stresses ``(n_T, 27)`` of parameters ``y``."""
        return self.raw_values(self.Tm @ y + self.z_fix)

    def stresses(self, y: np.ndarray) -> np.ndarray:
        """``(n_sub, 3, 3)``: Voigt values at the vertices of sub-triangle ``3 t + i``."""
        return self.vertex_values(y).reshape(3 * self.n_tri, 3, 3)

    @cached_property
    def column_map(self) -> sp.csr_matrix:
        """``C`` with column values ``g = C y + g0`` (``(2 n_col,)``, left and right ends)."""
        return self.Tm[self.column_dofs.ravel()].tocsr()

    @property
    def column0(self) -> np.ndarray:
        return self.z_fix[self.column_dofs.ravel()]

    def column_values(self, y: np.ndarray) -> np.ndarray:
        """``(n_col, 2)``: the vertical stress ``g`` of every column at its left and right end."""
        return (self.column_map @ y + self.column0).reshape(-1, 2)

    def column_energy_matrix(self) -> sp.csr_matrix:
        """``Qc`` with ``1/2 g.Qc g = 1/2 int A_22 g^2`` over the columns, ``g`` as in :meth:`column_values`."""
        idx = 2 * np.arange(len(self.columns))[:, None] + np.arange(2)[None, :]
        n = 2 * len(self.columns)
        return assemble_blocks(idx, idx, self.column_energy_blocks, (n, n))

    # the whole field: vertex values, then column values (what the energy and the stress caps see)
    @cached_property
    def field_map(self) -> sp.csr_matrix:
        return sp.vstack([self.stress_map, self.column_map]).tocsr()

    @property
    def field0(self) -> np.ndarray:
        return np.concatenate([self.sigma0, self.column0])

    def field_energy_matrix(self) -> sp.csr_matrix:
        """The energy of the whole field: :meth:`energy_matrix` and :meth:`column_energy_matrix`."""
        return sp.block_diag([self.energy_matrix(), self.column_energy_matrix()], format="csr")

    def sub_points(self) -> np.ndarray:
        """``(n_sub, 3, 2)`` sub-triangle vertices, in the order of :meth:`stresses`."""
        return sub_vertices(self.X).reshape(3 * self.n_tri, 3, 2)

    def energy_matrix(self) -> sp.csr_matrix:
        """``Q`` with ``1/2 sigma.Q sigma = 1/2 int sigma:A sigma`` on vertex values (exact P1 mass)."""
        _, area = self.sub_geometry
        A = compliances(self.scene)[self.body]  # (n_T, 3, 3)
        blk = area[:, :, None, None, None, None] * MASS0[None, None, :, None, :, None] * A[:, None, None, :, None, :]
        idx = 9 * np.arange(3 * self.n_tri)[:, None] + np.arange(9)[None, :]
        n = 27 * self.n_tri
        return assemble_blocks(idx, idx, blk.reshape(3 * self.n_tri, 9, 9), (n, n))

    def divergence_residual(self, sigma: np.ndarray) -> np.ndarray:
        """``(n_T, 6)``: ``h_T (div sigma + F)`` on every sub-triangle of vertex values ``sigma``
        (the rows of :attr:`div` minus ``div_rhs``, without forming them)."""
        g, _ = self.sub_geometry  # (n_T, 3, 3, 2)
        s = np.asarray(sigma, float).reshape(self.n_tri, 3, 3, 3)
        grad = s.transpose(0, 1, 3, 2) @ g  # (n_T, 3, 3, 2): d s_c / d x_k on every sub-triangle
        h = np.linalg.norm(self.X - np.roll(self.X, 1, axis=1), axis=2).max(1)
        d = np.stack([grad[:, :, 0, 0] + grad[:, :, 2, 1], grad[:, :, 2, 0] + grad[:, :, 1, 1]], -1)
        return (h[:, None, None] * d).reshape(self.n_tri, 6) - self.div_rhs.reshape(self.n_tri, 6)

    def energy(self, sigma: np.ndarray, g: np.ndarray | None = None) -> float:
        """``1/2 int sigma:A sigma`` of vertex values ``sigma`` and column values ``g``
        (:meth:`energy_matrix` and :meth:`column_energy_matrix`, without forming them)."""
        _, area = self.sub_geometry
        s = np.asarray(sigma, float).reshape(self.n_tri, 3, 3, 3)  # triangle, sub, vertex, Voigt
        A = compliances(self.scene)[self.body]
        MsA = (MASS0 @ s) @ A[:, None]  # (sum_b M_ab sigma_b) A at every vertex (A symmetric)
        e = float(area.ravel() @ (s * MsA).sum((2, 3)).ravel())
        if g is not None and len(self.columns):
            gv = np.asarray(g, float).reshape(-1, 2)
            e += float(np.einsum("ci,cij,cj->", gv, self.column_energy_blocks, gv))
        return 0.5 * e

    def gap_weights(self) -> np.ndarray:
        """``(n_c, 2)``: ``int phi_e eps dx`` of the two end hats of each contact edge, so that
        ``int_a^b sigma_nn eps dx = sum w * sigma_nn`` (Gauss, exact for a parabolic gap)."""
        u, w = gauss01(N_GAUSS)
        x0, x1 = self.contact_x[:, :1], self.contact_x[:, 1:]
        eps = self.scene.gap_at(x0 + u[None, :] * (x1 - x0)) * w[None, :] * (x1 - x0)
        return np.stack([eps @ (1.0 - u), eps @ u], axis=1)


# -- building the space ------------------------------------------------------------------

def part_edges(mesh: Mesh, edges: dict, k: int, part, skip: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """Edges of a boundary part: both ends in the part's interval (x on face/far, y on
    left/right), the same selection as the P0 assembly; node pairs with keys in ``skip``
    (:func:`edge_keys`: the vertical sides of curved pieces, no edges of the straight mesh) are
    left out and counted (the second value)."""
    nodes = mesh.bodies[k].side_nodes(part.on)
    inside = np.ones(len(nodes), bool)
    if part.interval is not None:
        lo, hi = part.interval
        c = mesh.points[nodes, 0 if part.on in ("face", "far") else 1]
        tol = 1e-12 * (abs(lo) + abs(hi) + 1.0)  # interval ends are nodes: only rounding separates them
        inside = (c >= lo - tol) & (c <= hi + tol)
    keep = inside[:-1] & inside[1:]
    a, b = nodes[:-1][keep], nodes[1:][keep]
    ok = np.ones(len(a), bool) if skip is None else ~np.isin(edge_keys(a, b, mesh.n_nodes), skip)
    return edge_ids(edges, a[ok], b[ok], mesh.n_nodes), int((~ok).sum())


def project_traction(mesh: Mesh, edges: dict, k: int, ids: np.ndarray, n_out: np.ndarray, traction,
                     exact) -> tuple[np.ndarray, np.ndarray]:
    """L2 projection of a traction onto linear functions on each edge: end values ``(m, 2, 2)``
    (global end order ``lo, hi``) and the squared oscillation ``||P - Pi P||^2`` per edge."""
    u, w = gauss01(N_GAUSS)
    pa, pb = mesh.points[edges["lo"][ids]], mesh.points[edges["hi"][ids]]
    ell = edges["length"][ids]
    if traction.kind == "uniform":
        val = np.broadcast_to(np.array(traction.value, float), (len(ids), 2))
        return np.stack([val, val], 1).copy(), np.zeros(len(ids))
    if exact is None:
        raise SceneError(f"body {mesh.scene.bodies[k].name!r}: traction 'exact' needs an [exact] field")
    x = pa[:, None, :] + u[None, :, None] * (pb - pa)[:, None, :]
    s = exact.stress(k, x.reshape(-1, 2)).reshape(len(ids), len(u), 3)
    P = np.einsum("mij,mgj->mgi", traction_rows(n_out), s)
    b0 = np.einsum("g,g,mgi->mi", w, 1 - u, P) * ell[:, None]
    b1 = np.einsum("g,g,mgi->mi", w, u, P) * ell[:, None]
    c0, c1 = (2 * (2 * b0 - b1)) / ell[:, None], (2 * (2 * b1 - b0)) / ell[:, None]
    res = P - (c0[:, None, :] * (1 - u)[None, :, None] + c1[:, None, :] * u[None, :, None])
    return np.stack([c0, c1], 1), ell * np.einsum("g,mgi->m", w, res**2)


def _covering(part, x: np.ndarray) -> np.ndarray:
    """Which intervals ``x (m, 2)`` a face part covers (both ends inside, as :func:`part_edges`)."""
    if part.interval is None:
        return np.ones(len(x), bool)
    lo, hi = part.interval
    tol = 1e-12 * (abs(lo) + abs(hi) + 1.0)
    return (x[:, 0] >= lo - tol) & (x[:, 1] <= hi + tol)


def classify(mesh: Mesh, edges: dict, X: np.ndarray, exact, faces: FaceIntervals, face_edge: np.ndarray) -> dict:
    """Kind (free, fixed, contact) and fixed value of every raw edge dof ``4 g + 2 e + k``
    (``e`` the global end, ``k`` 0 normal, 1 tangential; on a sliding support guided across its
    edges, ``k`` 0 across the direction and 1 along it: ``axis``): boundary edges default to traction
    free; traction parts fix their projected data; supports free the reaction components. Face
    edges of contact and column intervals are *tied* (see the module docstring): their normal
    dof at each end is the vertical stress there (one parameter per contact edge end shared by
    both faces, a free or zero one on a column outside the contact), their tangential dofs 0."""
    n_raw = 4 * len(edges["keys"]) + 3 * len(X)
    kind, val = np.full(n_raw, FREE), np.zeros(n_raw)
    bnd = edges["boundary"]
    kind[(4 * bnd[:, None] + np.arange(4)).ravel()] = FIXED
    a, b = mesh.scene.contact
    tol = 1e-12 * mesh.scene.length_scale  # contact ends are columns: only rounding separates them
    in_contact = (faces.x[:, 0] >= a - tol) & (faces.x[:, 1] <= b + tol)
    tied = faces.column | in_contact
    owned = np.zeros(len(edges["keys"]), bool)  # edges whose dofs the face intervals set
    owned[face_edge[tied]] = True
    vertical = faces.vertical >= 0
    v_ids = edge_ids(edges, faces.vertical[vertical], faces.right[vertical], mesh.n_nodes, missing=True)
    owned[v_ids[v_ids >= 0]] = True
    skip = edge_keys(faces.vertical[vertical], faces.right[vertical], mesh.n_nodes)[v_ids < 0]  # on a side
    column_kind = np.where(faces.column, FIXED, -1)  # a column off the contact: traction free unless supported
    axis, held = guided_axes(mesh, edges, skip, owned)
    trac = {"ids": [], "c": [], "osc2": [], "body": []}
    for k, bm in enumerate(mesh.bodies):
        for part in bm.body.boundary:
            ids, skipped = part_edges(mesh, edges, k, part, skip)
            if part.kind == "traction" and (skipped or np.any(owned[ids])) and not _zero(part) and part.on != "face":
                raise SceneError(f"body {bm.body.name!r}: part {part.name!r} loads the vertical side of a curved "
                                 "type-1 piece, where the column stress carries nothing; use type2 or the P0 stress "
                                 "space")
            ids = ids[~owned[ids]]
            if part.on == "face":
                cover = faces.column & ~in_contact & (faces.body == k) & _covering(part, faces.x)
                if part.kind == "clamped":
                    column_kind[cover] = FREE  # a vertical traction is one a clamp can take
                elif part.kind == "traction" and cover.any() and not _zero(part):
                    raise SceneError(f"body {bm.body.name!r}: traction part {part.name!r} loads a curved stretch of "
                                     "the face, where the equilibrium space carries vertical stresses only; move the "
                                     "load off the curved stretch or use the P0 stress space")
            n_out, s_o = outward_normals(edges, X, mesh.points, ids)
            if part.kind == "traction":
                c, osc2 = project_traction(mesh, edges, k, ids, n_out, part.traction, exact)
                a = axis[ids]
                ta = np.stack([-a[:, 1], a[:, 0]], 1)
                for e in range(2):  # sigma n_g = s_o c in the edge's frame
                    val[4 * ids + 2 * e] += s_o * np.einsum("mi,mi->m", c[:, e], a)
                    val[4 * ids + 2 * e + 1] += s_o * np.einsum("mi,mi->m", c[:, e], ta)
                for key, v in (("ids", ids), ("c", c), ("osc2", osc2), ("body", np.full(len(ids), k))):
                    trac[key].append(v)
            else:  # clamped frees both components, sliding the one across its direction (both if held)
                for e in range(2):
                    kind[4 * ids + 2 * e] = FREE
                    both = ids if part.kind == "clamped" else ids[held[ids]]
                    kind[4 * both + 2 * e + 1] = FREE
    # the face edges' ends at the interval's left and right abscissa (global ends 0 = lo, 1 = hi)
    left_end = (edges["hi"][face_edge] == faces.left).astype(int)
    ends = np.stack([left_end, 1 - left_end], 1)
    raw_n = 4 * face_edge[:, None] + 2 * ends  # (m, 2) normal dofs at left, right
    kind[raw_n[tied] + 1] = FIXED
    val[raw_n[tied]] = val[raw_n[tied] + 1] = 0.0
    off = tied & ~in_contact
    kind[raw_n[off]] = column_kind[off][:, None]
    cidx = np.full(n_raw, -1)
    n_c = 0
    for k in range(2):
        j = np.flatnonzero(in_contact & (faces.body == k))  # the contact intervals in x order, one per contact edge
        kind[raw_n[j]] = CONTACT
        cidx[raw_n[j]] = 2 * np.arange(len(j))[:, None] + np.arange(2)[None, :]
        n_c = len(j)
    cat = {key: np.concatenate(v) if v else np.empty(0) for key, v in trac.items()}
    cat["c"] = cat["c"].reshape(-1, 2, 2)
    contact_x = faces.x[in_contact & (faces.body == 0)]
    if len(contact_x) != n_c or not np.allclose(contact_x, faces.x[in_contact & (faces.body == 1)], rtol=0, atol=tol):
        raise MeshError("internal: the contact intervals of the two faces differ")  # pragma: no cover
    return {"kind": kind, "value": val, "axis": axis, "contact": cidx, "traction": cat, "contact_x": contact_x,
            "tied": np.flatnonzero(tied), "raw_n": raw_n}


def guided_axes(mesh: Mesh, edges: dict, skip: np.ndarray, owned: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The frame of every edge's dofs, ``axis`` ``(n_edges, 2)``: its normal ``n_g``, or on a sliding
    support guided across the edge the normal ``m`` of its direction; and ``held``: edges under two
    sliding supports whose normals differ (both components are reactions there, as when clamped)."""
    guide = np.zeros((len(edges["keys"]), 2))
    held = np.zeros(len(edges["keys"]), bool)
    for k, bm in enumerate(mesh.bodies):
        for part in bm.body.boundary:
            if part.kind != "sliding":
                continue
            ids, _ = part_edges(mesh, edges, k, part, skip)
            ids = ids[~owned[ids]]
            m = sliding_normal(bm.body, part)
            prev = guide[ids]
            held[ids[np.abs(prev[:, 0] * m[1] - prev[:, 1] * m[0]) > 1e-12]] = True  # rounding only: parallel
            guide[ids] = m
    ng = edges["ng"]
    across = (np.abs(ng[:, 0] * guide[:, 1] - ng[:, 1] * guide[:, 0]) > 1e-12) & ~held
    axis = ng.copy()
    axis[across] = guide[across]
    return axis, held


def _zero(part) -> bool:
    """A traction part with zero uniform data (which a column's traction-free stretch meets)."""
    return part.kind == "traction" and part.traction.kind == "uniform" and not np.any(part.traction.value)


def tie_blocks(coef: np.ndarray, edges: dict, face_edge: np.ndarray) -> np.ndarray:
    """The edge coefficient blocks with the ties of the face edges ``face_edge`` merged in: at each
    end of such an edge the normal basis column becomes ``n_gy^2 N_n + n_gx n_gy N_t`` (the vertex
    values of ``sigma n_g = (0, g n_gy)``, the column field's traction, per unit ``g``) and the
    tangential column 0 (its dof is fixed at 0). On a horizontal edge this is the identity."""
    coef = coef.copy()
    t, j = edges["owner"][face_edge].T
    ng = edges["ng"][face_edge]
    mix = np.stack([ng[:, 1] ** 2, ng[:, 0] * ng[:, 1]], 1)  # (m, 2)
    for le in range(2):
        blk = coef[t, 2 * j + le]  # (m, 2, 2)
        coef[t, 2 * j + le, :, 0] = np.einsum("mab,mb->ma", blk, mix)
        coef[t, 2 * j + le, :, 1] = 0.0
    return coef


def local_dofs(edges: dict, n_T: int) -> np.ndarray:
    """``(n_T, 15)``: the raw parameter of each local slot (edge dofs by global end, then bubbles)."""
    e = np.arange(2)[None, None, :, None] ^ edges["flip"][:, :, None, None]  # global end of local end
    edof = 4 * edges["id"][:, :, None, None] + 2 * e + np.arange(2)[None, None, None, :]
    return np.concatenate([edof.reshape(n_T, 12), 4 * len(edges["keys"]) + 3 * np.arange(n_T)[:, None]
                           + np.arange(3)[None, :]], axis=1)


def build_space(mesh: Mesh, pieces: Pieces, triangulation: str) -> EquilibriumSpace:
    """Assemble the space of ``mesh`` and its ``pieces`` (see :class:`EquilibriumSpace`);
    balance the loads."""
    from ..reference.exact import exact_field
    scene = mesh.scene
    straight = pieces.kind == 0
    tri = pieces.nodes[straight]
    X = mesh.points[tri]
    body = pieces.body[straight].astype(int)
    faces = face_intervals(mesh, pieces)
    check_column_data(scene, faces)
    edges = mesh_edges(tri, mesh.points, mesh.n_nodes)
    face_edge = edge_ids(edges, faces.left, faces.right, mesh.n_nodes)
    ng_local = edges["ng"][edges["id"]]  # (n_T, 3, 2)
    cl = classify(mesh, edges, X, exact_field(scene), faces, face_edge)
    edges = edges.replace(axis=cl["axis"])
    Q = piola(X)
    coef = tie_blocks(inverse2(edge_blocks(Q, ng_local, edges["axis"][edges["id"]])), edges, face_edge[cl["tied"]])
    kind = cl["kind"]
    free = np.flatnonzero(kind == FREE)
    n_c = len(cl["contact_x"])
    ycol = np.full(len(kind), -1)
    ycol[free] = np.arange(len(free))
    con = kind == CONTACT
    ycol[con] = len(free) + cl["contact"][con]
    live = ycol >= 0
    Tm = sp.csr_matrix((np.ones(int(live.sum())), (np.flatnonzero(live), ycol[live])),
                       shape=(len(kind), len(free) + 2 * n_c))
    z_fix = np.where(kind == FIXED, cl["value"], 0.0)
    h = np.linalg.norm(X - np.roll(X, 1, axis=1), axis=2).max(1)  # as in divergence_rows
    F = np.array([b.body_force for b in scene.bodies])[body]
    div_rhs = -(h[:, None, None] * F[:, None, :]).repeat(3, axis=1).reshape(-1)
    contact_y = len(free) + np.arange(2 * n_c).reshape(n_c, 2)
    columns = np.flatnonzero(faces.column)
    slab_iv = slab_interval(mesh, pieces, faces)
    where = np.full(len(faces), -1)
    where[columns] = np.arange(len(columns))
    compliance = compliances(scene)
    space = EquilibriumSpace(mesh=mesh, pieces=pieces, triangulation=triangulation, tri=tri, X=X, body=body,
                             piola=Q, coef=coef, dofs=local_dofs(edges, len(X)), edges=edges, Tm=Tm, z_fix=z_fix,
                             kind=kind, div_rhs=div_rhs, contact_y=contact_y, contact_x=cl["contact_x"],
                             traction_edges=cl["traction"], faces=faces, face_edge=face_edge, columns=columns,
                             column_dofs=cl["raw_n"][columns],
                             column_energy_blocks=column_energy(pieces, faces, slab_iv, compliance)[columns],
                             slab_column=where[slab_iv], scales=Scales(1.0, 1.0, 1.0), load_imbalance=0.0)
    z_fix, imbalance, correction = balance_loads(space)
    space = replace(space, z_fix=z_fix, load_imbalance=imbalance, load_correction=correction)
    return replace(space, scales=make_scales(space))


# -- rigid motions and load balance -------------------------------------------------------
