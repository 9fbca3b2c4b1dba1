"""The equilibrium equations of the nonlinear statics, F(q, lambda) = 0 and c(q) = 0 (see
:mod:`closedloop.elastostatics.tangent` for their terms), on unit-free coordinates: the
residuals, Jacobians and stability measures that
:func:`closedloop.elastostatics.statics.solve_equilibrium` iterates on.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from closedloop.common.arrays import frozen
from closedloop.common.conditioning import RANK_RTOL, rule_rank, svd
from closedloop.elastostatics.springs import spring_split
from closedloop.elastostatics.tangent import (
    closure_gap,
    settled_tangent,
    stability_margin,
    tangent_stiffness,
)
from closedloop.kinematics.constraints import frame_jacobian
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.model.elastic import deflection, deflection_jacobian, spring_law
from closedloop.model.gravity import Load, as_load


@dataclass(frozen=True)
class SolverUnits:
    """Per-entry scales that make the equilibrium solver unit-free: L [m] (the model's
    characteristic length) for the closure rows in metres and the translational
    coordinates, 1 for the others (rad). The solver's rank decisions, tolerances and step
    limits then do not depend on the length unit or the size of the mechanism.

    Attributes:
        rows: (m,) scale of each closure row; coords: (nv,) of each tangent coordinate;
        q: (nq,) of each configuration entry (the translations of a free flyer or planar
        joint, the coordinate of a prismatic one).
    """

    rows: np.ndarray
    coords: np.ndarray
    q: np.ndarray

    @classmethod
    def of(cls, clm: ClosedLoopModel) -> SolverUnits:
        """The scales of ``clm``, from its length and which of its coordinates are
        translations."""
        L, model = clm.length, clm.model
        coords = np.where(clm.linear_coordinates, L, 1.0)
        q = np.ones(model.nq)
        for jm in model.joints[1:]:
            if jm.nq == jm.nv:
                q[jm.idx_q : jm.idx_q + jm.nq] = coords[jm.idx_v : jm.idx_v + jm.nv]
            else:  # free flyer, planar: translations first, alike in q and v
                t = int(clm.linear_coordinates[jm.idx_v : jm.idx_v + jm.nv].sum())
                q[jm.idx_q : jm.idx_q + t] = L
        return cls(np.where(clm.linear_rows, L, 1.0), coords, q)

    def limit(self, value: float | None, default: float) -> np.ndarray:
        """(nv,) per-coordinate bound: ``value`` [rad or m] as given, or ``default`` in
        rad and units of L."""
        return self.coords * default if value is None else np.full(self.coords.size, value)


def _free_coordinates(clm: ClosedLoopModel) -> tuple:
    """What the equations of a model read of its free coordinates (once per model): their
    indices, the :class:`SolverUnits`, their scales [m or rad per unit] (dq_free =
    free_scales * y), the indices into them of the sprung ones (k > 0), and the square
    root of their springs on y (sqrt(k) per coordinate, or the columns of the root factor
    K_q = R^T R of the spring blocks)."""
    free = np.flatnonzero(np.isfinite(clm.stiffness))
    u = SolverUnits.of(clm)
    units = SolverUnits(frozen(u.rows), frozen(u.coords), frozen(u.q))
    scales = units.coords[free]
    sprung = np.flatnonzero(clm.stiffness[free] > 0.0)
    coords = free[sprung]
    root = (
        clm.spring_root[:, coords] * scales[sprung]
        if clm.spring_blocks
        else np.sqrt(clm.stiffness[coords]) * scales[sprung]
    )
    return frozen(free), units, frozen(scales), frozen(sprung), frozen(root)


def solver_units(clm: ClosedLoopModel) -> SolverUnits:
    """The :class:`SolverUnits` of ``clm`` (once per model, read-only)."""
    return clm.memo("equilibrium_equations", _free_coordinates, clm)[1]


class EquilibriumEquations:
    """The equilibrium equations F = 0, c = 0 of one model, loaded frame and rest q.

    Works on the free coordinates (finite stiffness); locked ones keep their rest values.
    Used by :func:`closedloop.elastostatics.statics.solve_equilibrium`.

    Attributes:
        free: (n_free,) the free coordinates' indices; units: the :class:`SolverUnits`;
        free_scales: (n_free,) scale of each free coordinate [m or rad per unit]:
        dq_free = free_scales * y; sprung: the free coordinates with a spring (k > 0),
        indices into the free ones; root: the square root of their springs on y. Read-only,
        shared by the equations of one model.
    """

    def __init__(self, clm: ClosedLoopModel, q_rest: np.ndarray, frame: str):
        self.clm, self.q_rest, self.frame = clm, q_rest, frame
        self.free, self.units, self.free_scales, self.sprung, self.root = clm.memo(
            "equilibrium_equations", _free_coordinates, clm
        )

    def evaluate(self, q: np.ndarray, w: Load | np.ndarray) -> dict:
        """State at q under the load w (a :class:`Load`, or a wrench (6,)): residuals,
        multipliers, SVD of J_c.

        Keys: ``c`` (m,) closure residual, ``Jc`` (m, nv) its Jacobian; ``closure`` its
        infinity norm [m, rad]; ``F``
        the generalised force g + G - J^T w on the free coordinates [N m, N] (G: the
        weight, if any); ``force`` the
        infinity norm of its unbalanced part F + J_c^T lambda (the vector: ``unbalanced``);
        ``spring``, ``load`` the spring and load generalised forces on the free
        coordinates; ``lam`` (m,) least-squares multipliers; ``Ur``,
        ``sr``, ``R``, ``N``: the SVD of the unit-free J_c on the free coordinates (row
        space, null space), rows in metres over L and translational coordinates y = x / L
        (:class:`SolverUnits`), so that its rank rule does not depend on the size.
        Leaves the kinematics of q in ``clm.data``.
        """
        clm, free = self.clm, self.free
        c, Jc = closure_gap(clm, q)
        A = Jc[:, free]
        J = frame_jacobian(clm, q, self.frame, "world", update=False)
        e = deflection(clm, self.q_rest, q)
        g = deflection_jacobian(clm, self.q_rest, q).T @ spring_law(clm, e)[0]
        load = self.generalised_load(q, w, J)
        F = (g - load)[free]
        rows, cols = self.units.rows, self.free_scales
        if A.size:  # unit-free: A_s = diag(1 / rows) A diag(cols), F_y = diag(cols) F
            U, s, Vt = svd(A / rows[:, None] * cols)  # LAPACK's, without numpy's call cost
            r = rule_rank(s)
        else:
            U, s, Vt, r = np.zeros((A.shape[0], 0)), np.zeros(0), np.eye(free.size), 0
        Ur, sr, R, N = U[:, :r], s[:r], Vt[:r].T, Vt[r:].T
        F_y = cols * F
        lam = -Ur @ ((R.T @ F_y) / sr) / rows
        unbalanced = (F_y - R @ (R.T @ F_y)) / cols  # F + A^T lam, its component along N
        return {
            "c": c,
            "Jc": Jc,
            "closure": float(np.max(np.abs(c), initial=0.0)),
            "F": F,
            "force": float(np.max(np.abs(unbalanced), initial=0.0)),
            "unbalanced": unbalanced,
            "spring": g[free],
            "load": load[free],
            "lam": lam,
            "Ur": Ur,
            "sr": sr,
            "R": R,
            "N": N,
        }

    def generalised_load(self, q: np.ndarray, w: Load | np.ndarray, J: np.ndarray) -> np.ndarray:
        """(nv,) J^T w - G(q): the wrench and the weight as generalised forces [N m, N]."""
        w = as_load(w)
        return J.T @ w.wrench - w.forces(q, self.clm.model.nv)

    def _restricted(self, q, w, st: dict) -> np.ndarray:
        w = as_load(w)
        H = tangent_stiffness(
            self.clm, q, self.q_rest, self.frame, w.wrench, st["lam"], gravity=w, update=False
        )
        return H[np.ix_(self.free, self.free)]

    def step(self, q, w, st: dict, load: np.ndarray | None = None) -> tuple[np.ndarray, int]:
        """(nv,) tangent step at q (state ``st`` of :meth:`evaluate` under w), and the number
        of admissible directions it left out (a stiffness below RANK_RTOL^2 of the largest:
        spring-free, or beyond the resolution of the solve).

        Without ``load``: the Newton step, a minimum-norm Gauss-Newton correction of the
        closures plus the Newton step of N^T F on the admissible motions. With ``load``
        (a :class:`Load` or a wrench (6,)): the rate dq/ds of the equilibrium when the
        load grows by s ``load``. NaN when the equations overflow the double range (a
        load near 1e308 N).
        """
        free, cols = self.free, self.free_scales
        H = cols[:, None] * self._restricted(q, w, st) * cols  # on y = x / cols
        R = st["R"]
        if load is None:  # restores the closures
            dy = -R @ ((st["Ur"].T @ (st["c"] / self.units.rows)) / st["sr"])
            rhs = -(cols * st["F"] + H @ dy)
        else:
            J = frame_jacobian(self.clm, q, self.frame, "world", update=False)
            dy, rhs = np.zeros(free.size), cols * self.generalised_load(q, load, J)[free]
        # on the admissible motions: the sprung ones normalised by their springs and set on
        # the scale of the stiffest (a soft spring beside a stiff one is solved for, however
        # far apart), the spring-free ones as they are; a direction resisted less than
        # RANK_RTOL^2 of that scale is left out (spring-free, or beyond the solve)
        B, _ = self.motions(st)
        with np.errstate(over="ignore", invalid="ignore"):  # a load beyond the doubles
            lhs, rhs = B.T @ H @ B, B.T @ rhs
        if not (np.all(np.isfinite(lhs)) and np.all(np.isfinite(rhs))):
            return np.full(self.clm.model.nv, np.nan), B.shape[1]  # the callers stop on NaN
        x, _, rank, _ = np.linalg.lstsq(lhs, rhs, rcond=RANK_RTOL**2)
        dy += B @ x
        v = np.zeros(self.clm.model.nv)
        v[free] = cols * dy
        return v, B.shape[1] - rank

    def motions(self, st: dict) -> tuple[np.ndarray, float]:
        """(B, top^2): B (n_free, d) the admissible motions of ``st`` on y = x / cols, the
        sprung ones normalised by their springs and set on the scale of the stiffest (B^T
        K_q B = top^2 I on them), then the spring-free ones, orthonormal; top^2 the scale
        [N m] (the basis of :meth:`step`'s solve)."""
        T, Z, top = self._sprung_motions(st)
        return np.hstack([T * top, Z]), top * top

    def _sprung_motions(self, st: dict) -> tuple[np.ndarray, np.ndarray, float]:
        """The admissible motions of ``st`` (on y = x / cols) split as the spring factor of
        :func:`closedloop.elastostatics.springs.spring_factor` splits them: T (n_free, r) those that
        move a sprung coordinate, with T^T K_q T = I; Z (n_free, d - r) orthonormal, the
        spring-free ones (by the rank rule on the sprung rows, not on the springs' values);
        and the largest singular value of the spring factor [sqrt(N m)]."""
        N = st["N"]
        V, sig, Z = spring_split(N[self.sprung], self.root)
        return N @ (V / sig), N @ Z, float(sig[0]) if sig.size else 1.0

    def margin(self, q: np.ndarray, w: Load | np.ndarray) -> float:
        """Stability margin at an equilibrium q (nq,) under the load w (the first value of
        :meth:`stability`)."""
        return self.stability(q, w)[0]

    def stability(self, q: np.ndarray, w: Load | np.ndarray) -> tuple[float, float]:
        """(margin, tau) at an equilibrium q (nq,) under the load w, both dimensionless.

        tau is the smallest singular value of the spring-scaled tangent stiffness M (the
        matrix whose symmetric part gives the margin) with the sign of det M: 1 unloaded,
        0 where K_t turns singular (a limit load or a bifurcation), and it changes sign
        only there; also for a world-fixed moment, whose M is not symmetric and whose
        margin may turn negative while M stays regular. Near a limit load it falls like
        the square root of the load still to go.

        The margin, as in :class:`closedloop.elastostatics.preload.PreloadedCompliance`: the
        smallest eigenvalue of the symmetric part of N^T K_t N on the motions with a restoring
        spring, scaled by their spring stiffness; 1 unloaded, 0 where K_t turns singular,
        < 0 if unstable. Spring-free motions the load does not act on (a rod spinning about
        its axis) are left out; the sprung ones are those that move a sprung coordinate.
        The spring-free ones that the load acts on (a link
        hanging on a passive joint) settle with them (:func:`settled_tangent`,
        :func:`stability_margin`).
        """
        st = self.evaluate(q, w)
        T, Z, top = self._sprung_motions(st)
        T, Z = self.free_scales[:, None] * T, self.free_scales[:, None] * Z / top  # on x
        H = self._restricted(q, w, st)
        M = settled_tangent(T.T @ H @ T, H, T, Z)[0]  # T^T K_q T = I on the sprung ones
        if not M.size:
            return 1.0, 1.0
        tau = np.linalg.slogdet(M)[0] * np.linalg.svd(M, compute_uv=False)[-1]
        return stability_margin(M, T.shape[1]), float(tau)
