"""Assembly of the discrete dual problem (docs/theory.md#discretisation), vectorised over pieces.

Names follow the paper where that helps a reader holding it: ``E`` with
``<lam_h, e(v_h)> = q . E t``, ``A_h = blockdiag(|P| A_P)``, the load vector ``f``, the tie
map ``Z`` (``q = Z r``), the pair change of variables ``T`` (the paper's ``F``: ``r = T y``
with ``y_k1 = r'_y(A_k)``, ``y_k2 = r''_y(B_k) - r'_y(A_k)``), the index sets ``J0``/``J-``
and the discrete ``u0`` (``q0``). Everything here is in the scene's physical units.

Vectors: ``q`` has two dofs per node (``2k`` = x, ``2k+1`` = y); ``t`` stacks the Voigt stress
``(s11, s22, s12)`` of piece ``p`` at ``3p .. 3p+2``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from ..errors import SceneError
from ..geometry.mesh import Mesh
from ..geometry.pieces import Pieces
from ..linalg.sparse import assemble_blocks
from ..voigt import compliances, stiffnesses
from .boundary import Supports, free_dofs, load_vector, prolongation, supports, to_frames
from .rigid import rigid_modes

STRAIN_RANGE = (1e-30, 1e6)  # load / stiffness ratios the package computes with


@dataclass(frozen=True)
class Scales:
    """Reference length, stiffness and stress used to nondimensionalise the QP."""

    length: float
    modulus: float
    stress: float

    @property
    def displacement(self) -> float:
        return self.stress * self.length / self.modulus

    @property
    def energy(self) -> float:
        """Energy per unit thickness: ``stress^2 length^2 / modulus``."""
        return self.stress**2 * self.length**2 / self.modulus


@dataclass(frozen=True)
class System:
    """The assembled discrete problem of one scene, mesh and triangulation; built complete by
    :func:`assemble` and never changed afterwards."""

    mesh: Mesh
    pieces: Pieces
    E: sp.csr_matrix  # (n_dofs, 3 n_pieces)
    Ah: sp.csr_matrix  # (3 n_pieces, 3 n_pieces)
    C: np.ndarray  # (n_pieces, 3, 3) Hooke matrix of each piece
    f: np.ndarray  # (n_dofs,) load vector, balanced on the floating modes
    load_imbalance: float  # relative work of the raw loads on the floating modes
    load_correction: float  # |df| / |f| of the change that balanced them (system.rigid.balance_correction)
    supports: Supports  # fixed components and node frames
    rdof: np.ndarray  # (n_dofs,) index in r of each node's frame component, or -1 if fixed
    Z: sp.csr_matrix  # (n_dofs, n_r): q = Z r
    ja: np.ndarray  # (n_pairs,) r index of the upper pair node's y dof
    jb: np.ndarray  # (n_pairs,) r index of the lower pair node's y dof
    eps: np.ndarray  # (n_pairs,) initial gap at the pairs
    width: np.ndarray  # (n_pairs,) tributary lengths w_k
    anchors: np.ndarray  # r indices whose equilibrium rows are dropped (floating modes)
    floating: np.ndarray  # (n_r, m) rigid motions keeping the bodies together
    separating: np.ndarray  # (n_r, m2) other rigid motions allowed by supports
    scales: Scales

    @property
    def n_dofs(self) -> int:
        return self.E.shape[0]

    @property
    def n_r(self) -> int:
        return self.Z.shape[1]

    @property
    def n_pieces(self) -> int:
        return len(self.pieces)

    @property
    def r0(self) -> np.ndarray:
        """Discrete ``u0`` in r: the gap on the lower pair node's y dof."""
        r0 = np.zeros(self.n_r)
        r0[self.jb] = self.eps
        return r0

    @property
    def q0(self) -> np.ndarray:
        return self.Z @ self.r0

    @cached_property
    def T(self) -> sp.csr_matrix:
        """``r = T y``: ``r_a = y_a``, ``r_b = y_a + y_b`` for every pair (a, b)."""
        n = self.n_r
        return (sp.identity(n, format="csr")
                + sp.csr_matrix((np.ones(len(self.jb)), (self.jb, self.ja)), shape=(n, n)))

    @cached_property
    def pair_x_dofs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(jxa, jxb, slides)``: r indices of the ``x`` dofs of each pair's upper and lower
        node (-1 if fixed) and whether both are free (the pair has a tangential unknown)."""
        up, lo = self.mesh.pairs.T
        jxa, jxb = self.rdof[2 * up], self.rdof[2 * lo]
        return jxa, jxb, (jxa >= 0) & (jxb >= 0)

    @cached_property
    def index_sets(self) -> tuple[np.ndarray, np.ndarray]:
        """``J0`` (equality rows, minus anchors) and ``J-`` (sign rows) in y coordinates."""
        minus = np.zeros(self.n_r, bool)
        minus[self.jb] = True
        keep = ~minus
        keep[self.anchors] = False
        return np.flatnonzero(keep), self.jb.copy()

    def strains(self, q: np.ndarray) -> np.ndarray:
        """Piecewise strains ``g_P = B_P q`` ``(n_pieces, 3)``."""
        return np.einsum("pij,pj->pi", self.pieces.B, q[self.pieces.dofs])

    def stresses_from_displacement(self, q: np.ndarray) -> np.ndarray:
        """``t_P = C_P B_P q`` ``(n_pieces, 3)``."""
        return np.einsum("pij,pj->pi", self.C, self.strains(q))

    def local_stiffness(self) -> np.ndarray:
        """``|P| B_P^T C_P B_P`` of every piece, ``(n_pieces, 6, 6)``."""
        p = self.pieces
        k = np.matmul(p.B.transpose(0, 2, 1), np.matmul(self.C, p.B))
        k *= p.area[:, None, None]
        return k

    def frame_stiffness(self) -> np.ndarray:
        """:meth:`local_stiffness` in the nodes' frames: on the components ``rdof`` indexes."""
        return to_frames(self.supports, self.pieces.nodes, self.local_stiffness())

    @property
    def local_rdofs(self) -> np.ndarray:
        """``(n_pieces, 6)``: the r index of each piece's local dofs (-1 if fixed)."""
        return self.rdof[self.pieces.dofs]

    @property
    def load_r(self) -> np.ndarray:
        """The loads in r: ``Z^T f``."""
        return self.Z.T @ self.f

    def apply_stiffness(self, r: np.ndarray) -> np.ndarray:
        """``K r = Z^T E A_h^-1 E^T Z r`` without forming ``K``."""
        return self.Z.T @ (self.E @ self.stresses_from_displacement(self.Z @ r).ravel())

    def stiffness(self) -> sp.csr_matrix:
        """``K = E A_h^-1 E^T = sum_P |P| B_P^T C_P B_P`` on all dofs."""
        d = self.pieces.dofs
        return assemble_blocks(d, d, self.local_stiffness(), (self.n_dofs, self.n_dofs))

    def energy(self, q: np.ndarray) -> float:
        """Primal energy ``1/2 a(q, q) - L(q)``."""
        g = self.strains(q)
        return 0.5 * float(np.sum(self.pieces.area * np.einsum("pi,pij,pj->p", g, self.C, g))) - float(self.f @ q)


def stress_operators(mesh: Mesh, pieces: Pieces) -> tuple[sp.csr_matrix, sp.csr_matrix, np.ndarray]:
    """``E`` (column block ``P`` is ``|P| B_P^T``), ``A_h`` and the Hooke matrix ``C_P`` of every piece."""
    n_p = len(pieces)
    # built directly in compressed form (no COO sort and sum: no two pieces share a column):
    # column 3P + c of E holds |P| B_P[c, :] at the piece's six (distinct) dofs; A_h is block diagonal
    idx = np.int32 if 18 * n_p < 2**31 - 1 else np.int64  # E's entries: 18 a piece
    cols = lambda k: np.arange(0, k * 3 * n_p + 1, k, dtype=idx)  # noqa: E731 - k entries per column
    E = sp.csc_matrix(((pieces.area[:, None, None] * pieces.B).reshape(-1),
                       np.repeat(pieces.dofs, 3, axis=0).astype(idx).reshape(-1), cols(6)),
                      shape=(2 * mesh.n_nodes, 3 * n_p)).tocsr()
    compliance = compliances(mesh.scene)[pieces.body]
    r3 = np.arange(3 * n_p, dtype=idx).reshape(n_p, 3)
    Ah = sp.csr_matrix(((pieces.area[:, None, None] * compliance).reshape(-1),  # row-major blocks: CSR as is
                        np.repeat(r3, 3, axis=0).reshape(-1), cols(3)), shape=(3 * n_p, 3 * n_p))
    C = stiffnesses(mesh.scene)[pieces.body]
    return E, Ah, C


def assemble(mesh: Mesh, pieces: Pieces, ties: np.ndarray | None = None) -> System:
    """Assemble ``E``, ``A_h``, ``f``, ``Z`` and the contact data; check and balance the loads.

    ``ties`` (optional, ``(m, 2)`` node pairs ``(slave, master)``) ties whole nodes together
    (type-1 non-convex pieces).
    """
    scene = mesh.scene
    E, Ah, C = stress_operators(mesh, pieces)
    if not (np.all(np.isfinite(E.data)) and np.all(np.isfinite(Ah.data))):
        raise SceneError("the element matrices are not finite: the scene's sizes or moduli are too far apart "
                         "for double precision; rescale the units")
    sup = supports(mesh).tied(ties)
    rdof = free_dofs(sup, ties)
    Z = prolongation(sup, rdof)
    up, lo = mesh.pairs[:, 0], mesh.pairs[:, 1]
    ja, jb = rdof[2 * up + 1], rdof[2 * lo + 1]
    if np.any(ja < 0) or np.any(jb < 0) or len(np.intersect1d(mesh.pairs, sup.rotated)):
        raise SceneError("a support acts on a contact node (it holds its y displacement, or guides it along a "
                         "slanted line or direction); set a [contact] interval that stops short of the supported "
                         "part, or move the support off the contact interval")
    eps = scene.gap_at(mesh.pair_x)
    modes = rigid_modes(mesh, pieces, sup, rdof, ja, jb, Z, load_vector(mesh, pieces))
    return System(mesh=mesh, pieces=pieces, E=E, Ah=Ah, C=C, f=modes.f, load_imbalance=modes.load_imbalance,
                  load_correction=modes.load_correction,
                  supports=sup, rdof=rdof, Z=Z, ja=ja, jb=jb, eps=eps, width=tributary(mesh.pair_x),
                  anchors=modes.anchors, floating=modes.floating, separating=modes.separating,
                  scales=problem_scales(scene, modes.f, eps))


def tributary(x: np.ndarray) -> np.ndarray:
    """``w_k = int phi_k dx`` over the contact interval for hat functions on the pair abscissae."""
    d = np.diff(x)
    w = np.zeros_like(x)
    w[:-1] += 0.5 * d
    w[1:] += 0.5 * d
    return w


def problem_scales(scene, f: np.ndarray, eps: np.ndarray) -> Scales:
    """Length, stiffness and stress scales: the stress from the loads or an interference fit."""
    L = scene.length_scale
    Eref = max(b.material.modulus for b in scene.bodies)
    s_load = float(np.sum(np.abs(f))) / L
    s_fit = Eref * float(max(0.0, -np.min(eps))) / L
    s = max(s_load, s_fit)
    if s == 0.0:
        s = Eref * 1e-6  # unloaded: any scale works, the solution is zero
    strain = s / Eref
    # Strains beyond this range have no meaning in linear elasticity at the top, and at the
    # bottom make the displacement and energy scales (strain^1, strain^2 times the sizes)
    # leave double precision in the checks.
    if not (STRAIN_RANGE[0] <= strain <= STRAIN_RANGE[1]):
        raise SceneError(f"the loads are {strain:.3g} times the stiffness (a strain of that size), outside "
                         f"[{STRAIN_RANGE[0]:g}, {STRAIN_RANGE[1]:g}]; check the units of E and of the loads")
    return Scales(L, Eref, s)
