"""The discrete dual problem as a CVXPY modelling object (docs/reformulate.md).

One stress Variable ``t`` for all pieces; the admissibility ``<lam_h, e(v_h)> >= L(v_h)``
for all ``v_h`` in the cone ``K0h`` is written through the cone's generators (the paper's
(3.5), (3.6)): with ``H = T^T Z^T E`` and ``h = T^T Z^T f``, every row of ``H t - h`` is the
residual force ``T^T R`` of a generator, and

- ``equilibrium``: ``H[J0] t == h[J0]`` (generators ``+-e_j``, ``j`` in ``J0``),
- ``contact``: ``H[J-] t <= h[J-]`` (generators ``-e_m``: compressive contact forces),

with the objective ``1/2 t.A_h t - t.E^T q0``. Paper names are kept (``t`` for ``lam_h``,
``J0``, ``J-``, ``eps``). The model is nondimensionalised (lengths by ``L``, stiffness by
``E_ref``, stresses by ``sigma_ref``; :class:`~cvxdual.system.assembly.Scales`); every expression it
offers to a user (``stress``, ``contact_force``, ...) is in physical units.

The reformulations of docs/reformulate.md change rows, never the rest: Tresca friction
replaces the tangential rows of each pair ``k`` (``R'_x(A_k) = R''_x(B_k) = 0``) by
``R'_x(A_k) + R''_x(B_k) = 0`` and ``|R''_x(B_k)| <= g_k w_k``; adhesion moves the contact rows
to ``R''_y(B_k) <= sigma_a w_k``; ``load_factor`` multiplies ``h``. The multipliers of all rows
are the displacements (slips included), recovered as ``u_h = Z (r0 - delta T y)``.
"""

from __future__ import annotations

import time
from dataclasses import replace

import cvxpy as cp
import numpy as np
import scipy.sparse as sp

from ..convex.base import USER_TOLERANCE, ConvexModel
from ..errors import AccuracyError, ModelError
from ..records import Checks
from ..solution import TOLERANCES, Solution, failed_checks, load_scale
from ..system.assembly import System
from ..system.field import PieceField
from ..voigt import out_of_plane_factor
from .checks import admissibility, complementarity, duality_gap, evaluate, penetration


def _selector(rows: np.ndarray, n: int, sign: float = 1.0) -> sp.csr_matrix:
    """``(len(rows), n)`` matrix picking ``rows`` (times ``sign``)."""
    k = len(rows)
    return sp.csr_matrix((np.full(k, sign), (np.arange(k), rows)), shape=(k, n))


def _per_pair(value, n_pairs: int, what: str, fix: str, allow_inf: bool):
    """A non-negative number, an ``(n_pairs,)`` array or a non-negative cvxpy Parameter."""
    if isinstance(value, cp.Parameter):
        if value.shape not in ((), (n_pairs,)) or not value.is_nonneg():
            raise ModelError(f"{what} as a cvxpy Parameter must be declared nonneg=True with shape () or "
                             f"({n_pairs},), got shape {value.shape}; {fix}")
        return value
    if isinstance(value, (cp.Expression, cp.constraints.Constraint)):
        raise ModelError(f"{what} must be a number, an array or a cvxpy Parameter, not an expression; {fix}")
    if isinstance(value, (str, bytes)):
        raise ModelError(f"{what} must be a number, not the text {value!r}; {fix}")
    try:
        arr = np.broadcast_to(np.asarray(value, dtype=float), (n_pairs,)).copy()
    except (TypeError, ValueError):
        got = np.shape(value) if hasattr(value, "__len__") else type(value).__name__
        raise ModelError(f"{what} must be a number or one value per contact pair ({n_pairs}), got {got}; "
                         f"{fix}") from None
    if isinstance(value, bool) or np.isnan(arr).any() or (arr < 0).any() or (not allow_inf and np.isinf(arr).any()):
        raise ModelError(f"{what} must be non-negative {'numbers (inf allowed)' if allow_inf else 'finite numbers'}, "
                         f"got {value!r}; {fix}")
    return arr


class DualModel(ConvexModel):
    """The CVXPY problem of the discrete dual, a modelling object a user may change
    (:class:`~cvxdual.convex.base.ConvexModel`: changes, solving, misuse errors).

    Handles: ``t`` (scaled stress Variable, ``3 n_pieces``), ``load_factor`` (a non-negative
    Parameter, default 1, multiplying the applied loads; a Variable with ``limit_analysis``),
    ``constraints`` (the package's named rows), ``user_constraints``, ``objective`` and
    ``problem`` (read-only: change them with :meth:`add_constraint`, :meth:`set_objective`,
    :meth:`add_friction`, :meth:`allow_adhesion`).

    Expressions in physical units: ``stress`` ``(n_pieces, 3)``, ``contact_force`` (nodal
    normal force per pair, compressive positive), ``contact_pressure`` (force over the pair's
    tributary length), ``total_contact_force``, ``tangential_force`` (per pair: the ``x`` force
    of the upper body on the lower one; 0 where the pair's ``x`` dofs are fixed),
    ``complementary_energy``, and :meth:`shear_stress`, :meth:`von_mises` per piece.

    ``limit_analysis=True`` builds the static theorem's problem: no elastic energy, the loads
    ``load_factor * f`` with ``load_factor`` a Variable, and the objective ``maximise
    load_factor``; add yield constraints before solving.
    """

    what = "dual QP"

    def __init__(self, system: System, triangulation: str = "type1", limit_analysis: bool = False):
        self._start(limit_analysis)
        self.system = system
        self.triangulation = triangulation
        sc = system.scales
        L, E0, s0 = sc.length, sc.modulus, sc.stress
        n_p = system.n_pieces
        ZT = system.Z.T.tocsr()
        self._H = (system.T.T @ (ZT @ system.E)).tocsr() / L  # rows: T^T R / (s0 L) per unit t
        self._h = (system.T.T @ (ZT @ system.f)) / (s0 * L)
        self.J0, self.Jm = system.index_sets
        self._jxa, self._jxb, self._slides = system.pair_x_dofs
        self._force_unit = s0 * L  # a row of H t - h times this is a nodal force
        self.t = cp.Variable(3 * n_p, name="t")
        A = (system.Ah * (E0 / L**2)).tocsr()
        c = (system.E.T @ system.q0) * (E0 / (s0 * L**2))
        self._energy = 0.5 * cp.quad_form(self.t, A, assume_PSD=True) - c @ self.t  # scaled S(t)
        self._energy_unit = s0**2 * L**2 / E0
        self._default = cp.Maximize(self.load_factor) if self.limit_analysis else cp.Minimize(self._energy)
        self._objective = self._default
        self._g = None  # Tresca thresholds: number array or Parameter
        self._sigma_a = None  # adhesion: number array or Parameter
        self._build()

    # -- rows ---------------------------------------------------------------------------
    def _rows(self, M: sp.csr_matrix):
        """``M (H t - load_factor h)``: generator rows in units of ``s0 L``."""
        return (M @ self._H) @ self.t - self.load_factor * (M @ self._h)

    def _pair_bound(self, value, pairs: np.ndarray):
        """``value_k w_k / (s0 L)`` at ``pairs`` (a traction times the tributary length, scaled)."""
        w = self.system.width[pairs] / self._force_unit
        if isinstance(value, cp.Parameter):
            return cp.multiply(value if value.ndim == 0 else value[pairs], w)
        return value[pairs] * w

    def _build(self) -> None:
        """The package's rows from the current friction and adhesion: ``constraints``, and the
        maps ``M`` of each block into the multipliers ``y`` (``y = sum M^T dual``)."""
        n_r = self.system.n_r
        fric = np.zeros(len(self._slides), bool)  # pairs with |Q| <= g w rows
        stick = np.zeros(len(self._slides), bool)  # pairs with free slip rows dropped (g = inf)
        if self._g is not None:
            g = self._g
            if isinstance(g, cp.Parameter):
                fric = self._slides.copy()
            else:
                stick = self._slides & np.isinf(g)
                fric = self._slides & (g > 0) & ~stick
        tangential = fric | stick  # R'_x(A) + R''_x(B) = 0 replaces both x rows
        drop = self._jxb[tangential]
        eq_rows = np.setdiff1d(self.J0, drop)
        # row R'_x(A_k) of each such pair also takes R''_x(B_k): tangential action = reaction
        at = np.searchsorted(eq_rows, self._jxa[tangential])
        if len(at) and (np.any(at >= len(eq_rows)) or np.any(eq_rows[np.minimum(at, len(eq_rows) - 1)]
                                                               != self._jxa[tangential])
                        or len(np.unique(drop)) < len(drop) or np.isin(drop, self._jxa[tangential]).any()):
            # an anchor (a floating motion's dropped row) or a tied node on a pair's x dof: the
            # combined rows would be wrong, so refuse rather than guess
            raise ModelError("friction needs each contact pair's x dofs to be its own free dofs, not anchors of a "
                             "floating motion or tied nodes; support the bodies in x or solve without friction")
        P = _selector(eq_rows, n_r) + sp.csr_matrix((np.ones(len(at)), (at, drop)), shape=(len(eq_rows), n_r))
        jb = self.Jm
        blocks = {"equilibrium": (P, "==", 0.0), "contact": (_selector(jb, n_r), "<=",
                                                             0.0 if self._sigma_a is None else
                                                             self._pair_bound(self._sigma_a, np.arange(len(jb))))}
        if fric.any():
            pairs = np.flatnonzero(fric)
            bound = self._pair_bound(self._g, pairs)
            blocks["friction_upper"] = (_selector(self._jxb[pairs], n_r), "<=", bound)
            blocks["friction_lower"] = (_selector(self._jxb[pairs], n_r, -1.0), "<=", bound)
        self._blocks = blocks
        self._friction_pairs = fric  # pairs whose dissipation g w |slip| enters the duality gap
        cons = {}
        for name, (M, sense, bound) in blocks.items():
            rows = self._rows(M)
            cons[name] = rows == bound if sense == "==" else rows <= bound
        self._constraints = cons
        self._problem = None

    # -- the rows, read-only ------------------------------------------------------------
    @property
    def constraints(self) -> dict:
        """The package's named rows (a copy): ``equilibrium``, ``contact`` and, with friction,
        ``friction_upper`` / ``friction_lower`` (``+-R''_x(B_k) <= g_k w_k``)."""
        return dict(self._constraints)

    def _own_changes(self) -> list[str]:
        # friction with g = 0 everywhere leaves the rows as they are: no change
        fric = self._g is not None and (isinstance(self._g, cp.Parameter) or bool(np.any(self._g > 0)))
        return (["Tresca friction"] if fric else []) + (["adhesion"] if self._sigma_a is not None else [])

    # -- changes of the rows --------------------------------------------------------------
    def add_friction(self, g) -> DualModel:
        """Tresca friction: ``|R''_x(B_k)| <= g_k w_k`` at every pair whose ``x`` dofs are free,
        the tangential action = reaction kept. ``g`` (a traction, the scene's stress unit) is a
        number, one value per pair, or a non-negative cvxpy Parameter (sweeps compile once);
        ``inf`` means stick (no slip), 0 frictionless."""
        fix = "e.g. model.add_friction(0.1 * p0)"
        if self._g is not None:
            raise ModelError("friction is set already; build a new model to change it, or pass g as a "
                             "cvxpy Parameter and change its value")
        g = _per_pair(g, len(self._slides), "g", fix, allow_inf=True)
        if not self._slides.any():
            raise ModelError("no contact pair has free x dofs (all are supported in x), so friction has "
                             "nothing to act on")
        fl = self.system.floating
        if fl.shape[1] and np.abs(fl[self._jxb[self._slides]] - fl[self._jxa[self._slides]]).max() > 1e-9:
            raise ModelError("a body can slide freely along the contact (a floating x translation), which friction "
                             "alone cannot hold; add an x support to that body")
        self._g = g
        try:
            self._build()
        except ModelError:  # refused: the model stays frictionless
            self._g = None
            self._build()
            raise
        self._changed()
        return self

    def allow_adhesion(self, sigma_a) -> DualModel:
        """Tension cut-off: contact forces down to ``-sigma_a w_k`` (a traction per pair; a number,
        one value per pair or a non-negative Parameter). The tension acts at any opening over the
        whole candidate interval (a cohesive law of infinite range)."""
        if self._sigma_a is not None:
            raise ModelError("adhesion is set already; build a new model, or pass sigma_a as a cvxpy Parameter")
        self._sigma_a = _per_pair(sigma_a, len(self.Jm), "sigma_a", "e.g. model.allow_adhesion(0.01 * p0)",
                                  allow_inf=False)
        self._build()
        self._changed()
        return self

    # -- expressions in physical units --------------------------------------------------
    @property
    def stress(self):
        """``(n_pieces, 3)`` Voigt stresses ``(s11, s22, s12)``."""
        return self.system.scales.stress * cp.reshape(self.t, (self.system.n_pieces, 3), order="C")

    @property
    def contact_force(self):
        """Nodal normal contact force per pair, compressive positive (force per unit thickness)."""
        return -self._force_unit * self._rows(_selector(self.Jm, self.system.n_r))

    @property
    def contact_pressure(self):
        """Contact force per tributary length ``w_k`` of each pair."""
        return cp.multiply(1.0 / self.system.width, self.contact_force)

    @property
    def total_contact_force(self):
        """Sum of the contact forces (a half model carries half of the load)."""
        return cp.sum(self.contact_force)

    @property
    def tangential_force(self):
        """``x`` force of the upper body on the lower one per pair (``R''_x(B_k)``); 0 where the
        pair's ``x`` dofs are fixed. Identically 0 without friction."""
        n = len(self._slides)
        pairs = np.flatnonzero(self._slides)
        place = sp.csr_matrix((np.ones(len(pairs)), (pairs, np.arange(len(pairs)))), shape=(n, len(pairs)))
        return self._force_unit * (place @ self._rows(_selector(self._jxb[pairs], self.system.n_r)))

    @property
    def complementary_energy(self):
        """``S(t) = 1/2 t.A_h t - t.E^T q0`` (energy per unit thickness)."""
        return self._energy_unit * self._energy

    def _out_of_plane(self) -> np.ndarray:
        return out_of_plane_factor(self.system.mesh.scene, self.system.pieces.body)

    # -- results in physical units ------------------------------------------------------
    def stresses(self) -> np.ndarray:
        """``(n_pieces, 3)`` Voigt stresses of the last solve."""
        self._require_solved()
        return self.system.scales.stress * np.asarray(self.t.value).reshape(-1, 3)

    def multipliers(self) -> np.ndarray:
        """``y*``: every block's multipliers mapped back to the generators (``y`` coordinates,
        ``r = r0 - delta T y``); under friction ``y[jxb] - y[jxa]`` is minus the slip over ``delta``."""
        self._require_solved()
        y = np.zeros(self.system.n_r)
        for name, (M, _, _) in self._blocks.items():
            y += M.T @ np.asarray(self._constraints[name].dual_value, dtype=float).ravel()
        return y

    def displacements(self) -> np.ndarray:
        """Nodal displacements ``u_h = Z (r0 - delta T y*)`` from the multipliers ``y*``
        (docs/theory.md#recovery-and-checks). They solve the displacement problem only while
        the objective is the default and no constraint was added."""
        s = self.system
        return s.Z @ (s.r0 - s.scales.displacement * (s.T @ self.multipliers()))

    def solution(self, check: bool = True) -> Solution:
        """The :class:`~cvxdual.Solution` of the last solve, with the checks that still hold for
        the changed problem applied and the others listed, with the reason, in
        ``solution.checks["skipped"]``. A failed check raises :class:`AccuracyError`."""
        self._require_solved()
        t0 = time.perf_counter()
        s = self.system
        lf = float(self.load_factor.value)
        system = s if lf == 1.0 else replace(s, f=lf * s.f)
        t, u = self.stresses(), self.displacements()
        g = self._numeric(self._g)
        sigma_a = self._numeric(self._sigma_a)
        fields = evaluate(system, t, u, self.info, friction=g, adhesion=sigma_a,
                          displacements=self._elastic())
        fields.pop("timings")
        own = fields.pop("checks")  # the scene's exact field may not solve the scene itself
        applied, skipped = self._checks(system, t, u, fields, g, sigma_a, lf)
        if own is not None:
            skipped = {**own["skipped"], **skipped}
        if "error" in skipped:
            fields["error"] = None
        fields["residuals"] = applied
        fields["duality_gap"] = applied.get("duality_gap", float("nan"))
        sol = Solution(triangulation=self.triangulation, level=int(s.mesh.level),
                       field=PieceField.of_system(system, fields.pop("stress")),
                       timings=self._timings(time.perf_counter() - t0),
                       checks=Checks(applied=dict(applied), skipped=skipped), **fields)
        if check:
            tol = {**TOLERANCES, "user_constraints": USER_TOLERANCE}
            txt = failed_checks(applied, tol)
            if txt:
                advice = ("try model.solve('CLARABEL') or tighter solver tolerances" if lf >= 0.1 else
                          f"at load_factor {lf:g} the model's scales (set by the unit load) are {1 / lf:.0g} times "
                          "the solution's: pass tighter tolerances (tol_gap_rel=1e-14, tol_feas=1e-16, "
                          "tol_ktratio=1e-12 worked at 1e-4 on hertz) or build the model from the scene with its "
                          "loads scaled")
                raise AccuracyError(f"solver {self.info.solver} returned 'optimal' but the solution fails "
                                    f"the checks that apply to this model ({txt}); {advice}, or "
                                    "model.solution(check=False) to inspect it")
        return sol

    def _numeric(self, value):
        if value is None:
            return None
        n = len(self._slides)
        return np.broadcast_to(np.asarray(value.value if isinstance(value, cp.Parameter) else value, float), (n,))

    def _checks(self, system, t, u, fields, g, sigma_a, lf) -> tuple[dict, dict]:
        """The residuals that hold for this model (see :meth:`solution`) and the skipped ones."""
        applied, skipped = {}, {}
        R, scale = admissibility(system, t)
        rows = (system.T.T @ R) / self._force_unit
        floor = max(float(scale.max()), 1e-6 * load_scale(system)) / self._force_unit
        worst = 0.0
        for M, sense, bound in self._blocks.values():
            b = np.asarray(bound.value if isinstance(bound, cp.Expression) else bound, float)
            r = M @ rows - b
            r = np.abs(r) if sense == "==" else np.maximum(r, 0.0)
            worst = max(worst, float(r.max(initial=0.0)))
        applied["equilibrium"] = worst / floor
        if self._user:
            applied["user_constraints"] = max(self._violation(c) for _, c in self._user)
        standard = self._elastic()
        why = ("the objective was changed" if self._objective is not self._default else
               "limit analysis has no elastic law" if self.limit_analysis else
               "user constraints change the optimality conditions" if self._user else "")
        if standard:
            c = fields["contact"]
            applied["constitutive"] = fields["residuals"]["constitutive"]
            force = c["force"] + (0.0 if sigma_a is None else sigma_a * system.width)
            applied["complementarity"] = complementarity(system, u, c, force)
            applied["penetration"] = penetration(system, u, c)
            applied["duality_gap"] = duality_gap(system, t, u, self._dissipation(system, u, g, sigma_a))
        else:
            for k in ("constitutive", "complementarity", "penetration", "duality_gap"):
                skipped[k] = f"{why}: the multipliers are not the displacements of an elastic solution"
            skipped["displacement"] = ("the displacement, relative displacements and slips are the multipliers "
                                       "mapped as displacements; the contact zone is judged by the forces alone")
        if fields["exact"] is not None and (lf != 1.0 or self.changes()):
            skipped["error"] = ("the exact field is for the scene's own problem, not for "
                                + ("load_factor != 1" if lf != 1.0 else ", ".join(self.changes())))
        return applied, skipped

    def _dissipation(self, system, u, g, sigma_a) -> float:
        """The primal terms friction and adhesion add to ``J``: ``sum g_k w_k |slip_k|`` and
        ``sigma_a sum w_k opening_k`` (docs/reformulate.md)."""
        up, lo = system.mesh.pairs.T
        q = u.reshape(-1, 2)
        w = system.width
        out = 0.0
        if g is not None and self._friction_pairs.any():
            k = self._friction_pairs
            out += float(np.sum(g[k] * w[k] * np.abs(q[lo[k], 0] - q[up[k], 0])))
        if sigma_a is not None:
            out += float(np.sum(sigma_a * w * (system.eps - (q[lo, 1] - q[up, 1]))))
        return out
