"""Stiffness indices of a 6x6 Cartesian stiffness K or compliance C.

Conventions (those of :mod:`closedloop.elastostatics.compliance`): SI units; twists ordered
(dx, dy, dz [m], rx, ry, rz [rad]) and wrenches (fx, fy, fz [N], nx, ny, nz [N m]), both
at one reference point and in one set of axes; ``w = K x`` and ``x = C w`` (x: twist).
Subscripts ``t`` and ``r`` name the translational and rotational 3x3 blocks.

Units matter for some indices and not for others:

* ``determinant`` (det K, [N^6/rad^3]) and the eigenscrews (eigenvalue [N/rad], pitch
  [m/rad], axis line) do not depend on the length unit, the reference point or the axes.
* ``eigenvalues`` and ``condition_number`` of the SI matrix mix N/m with N m/rad: they
  change with the length unit (m vs mm) and with the reference point, and only compare
  matrices given in the same units at the same point. With a characteristic length L the
  twist (d, L r) and the wrench (f, n / L) share units, ``K_h = T^-1 K T^-1`` with
  ``T = diag(1, 1, 1, L, L, L)`` is uniform in N/m, and its eigenvalues and condition
  number (``homogenised_*``) read as "stiffnesses of points at distance L" (L: e.g. the
  tool size or the workspace radius; the number still depends on L and on the point).

Translational and rotational parts (Schur complements). "Free": no load on the other
part, which moves as it likes; "blocked": the other part is held still.

* ``translational_stiffness`` (rotations free) ``K_tt - K_tr K_rr^-1 K_rt = C_tt^-1``
  [N/m], exists when C_tt is invertible; ``translational_stiffness_blocked`` (rotations
  blocked) ``K_tt = (C_tt - C_tr C_rr^-1 C_rt)^-1``, needs K.
* ``rotational_stiffness`` (translations free) ``K_rr - K_rt K_tt^-1 K_tr = C_rr^-1``
  [N m/rad], exists when C_rr is invertible and does not depend on the reference point;
  ``rotational_stiffness_blocked`` (translations blocked) ``K_rr``, needs K.
* ``min/max_translational_stiffness``: extreme eigenvalues of the "free" translational
  stiffness and their unit directions (axes of C); the minimum exists whenever C_tt is
  nonzero. Likewise for rotations.

Principal stiffnesses and eigenscrews (Lipkin and Patterson's decomposition of K): see
:mod:`closedloop.analysis.screws`. Many compliances at once (a map's): see
:mod:`closedloop.analysis.batch_indices`.

A rank-deficient C (rigid directions) has no K; indices that need K raise
:class:`~closedloop.exceptions.RigidDirectionsError`, the others are still returned. A non-symmetric
C (a tangent compliance under a preload moment, :meth:`StiffnessIndices.from_result`) has K = C^-1,
its determinant and 2-norm condition numbers (as
:func:`~closedloop.analysis.batch_indices.batch_indices`); the indices of a symmetric matrix
(eigenvalues, principal stiffnesses, eigenscrews) raise
:class:`~closedloop.exceptions.InvalidInputError`, as do the eigenscrews of a K that is not positive
definite (an unstable equilibrium).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from closedloop.analysis.batch_indices import R, T, block_spectrum
from closedloop.analysis.screws import Eigenscrew, PrincipalStiffness, eigenscrews, unit_direction
from closedloop.analysis.spectra import (
    RESOLVED_RTOL,
    finite_determinant,
    inverse_pair_eigenvalues,
    lu_determinant,
)
from closedloop.common.arrays import readonly
from closedloop.common.conditioning import (
    SCALED_TOL,
    Spectrum,
    check_length,
    scaled_asymmetry,
    spectrum_from_compliance,
    spectrum_from_factor,
    twist_scaling,
)
from closedloop.elastostatics.compliance import TWIST_LABELS, UNITS, describe_directions
from closedloop.exceptions import (
    InvalidInputError,
    RigidDirectionsError,
    SingularConfigurationError,
)


def _check_matrix(M, what: str) -> np.ndarray:
    M = np.array(M, dtype=float)
    if M.shape != (6, 6):
        raise InvalidInputError(f"{what} must be a (6, 6) matrix, got shape {M.shape}")
    if not np.all(np.isfinite(M)):
        raise InvalidInputError(f"{what} contains non-finite values")
    return M


def _check_length(length) -> float | None:
    return None if length is None else check_length(length)


@dataclass(frozen=True)
class StiffnessIndices:
    """Stiffness indices of one Cartesian compliance (see the module docstring).

    Build with :meth:`from_compliance`, :meth:`from_stiffness` or :meth:`from_result`.
    The rank, the rigid directions, K and the scaled condition number follow the one rule
    of :mod:`closedloop.common.conditioning`.

    Attributes:
        C: (6, 6) compliance [m/N, rad/N, m/(N m), rad/(N m)], symmetric PSD, read-only.
        rank: rank of C.
        rigid_directions: (6, 6 - rank) orthonormal basis of the twists no wrench produces.
        length: characteristic length [m] of the ``homogenised_*`` indices, or None.
        spectrum: the rank decision, scaled condition number and K (with the length of
            the scaling: ``length``, or 1 m when None).
    """

    C: np.ndarray
    rank: int
    rigid_directions: np.ndarray
    length: float | None = None
    spectrum: Spectrum | None = field(default=None, repr=False)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def _of(cls, C, spectrum: Spectrum, length: float | None) -> StiffnessIndices:
        return cls(readonly(C), spectrum.rank, spectrum.rigid_directions, length, spectrum)

    @classmethod
    def from_compliance(cls, C, *, length: float | None = None) -> StiffnessIndices:
        """Indices of compliance C (6, 6) [SI]; it may be rank deficient.

        Args:
            C: symmetric positive semi-definite compliance.
            length: characteristic length [m] of the mechanism: the scaling of the rank
                rule and the length of the homogenised indices (optional; the rank rule
                then uses 1 m, and depends on the length unit).

        Raises:
            InvalidInputError: C is not a finite symmetric PSD (6, 6) matrix.
        """
        C = _check_matrix(C, "compliance")
        length = _check_length(length)
        spectrum = spectrum_from_compliance(C, 1.0 if length is None else length)
        return cls._of(0.5 * (C + C.T), spectrum, length)

    @classmethod
    def from_stiffness(cls, K, *, length: float | None = None) -> StiffnessIndices:
        """Indices of stiffness K (6, 6) [SI], symmetric positive definite.

        Raises:
            InvalidInputError: K is not a finite symmetric positive definite (6, 6) matrix.
        """
        K = _check_matrix(K, "stiffness")
        length = _check_length(length)
        scale = 1.0 if length is None else length
        d = twist_scaling(scale)
        # symmetric and positive definite as judged on the scaled K_s = D^-1 K D^-1 (the
        # rule of the compliances, unit-free: entries that vanish but for rounding count
        # like the others), not by whether a Cholesky factorisation happens to fail
        with np.errstate(over="ignore", invalid="ignore"):
            K_s = K / np.outer(d, d)
        if not np.isfinite(K_s).all():
            raise InvalidInputError(
                f"stiffness scaled to the length L = {scale:g} m (K L^2 for translations) "
                f"leaves the float range (largest entry {np.abs(K).max():.3g}); give a "
                "smaller length or a smaller stiffness"
            )
        asymmetry = scaled_asymmetry(K_s, 1.0)  # K_s is scaled already
        if asymmetry > SCALED_TOL:
            raise InvalidInputError(
                f"stiffness is not symmetric: scaled asymmetry max|K_s - K_s^T| / max|K_s| "
                f"= {asymmetry:.2e} > {SCALED_TOL:g}"
            )
        K_s = 0.5 * (K_s + K_s.T)
        kappa, U = np.linalg.eigh(K_s)
        if not kappa[-1] > 0.0 or kappa[0] <= RESOLVED_RTOL * kappa[-1]:
            raise InvalidInputError(
                f"stiffness is not positive definite to working precision: the eigenvalues "
                f"of the scaled K run from {kappa[0]:.3g} to {kappa[-1]:.3g} (the smallest "
                f"must exceed {RESOLVED_RTOL:g} times the largest)"
            )
        B_s = U / np.sqrt(kappa)  # C_s = K_s^-1 = B_s B_s^T
        B = B_s / d[:, None]
        return cls._of(B @ B.T, spectrum_from_factor(B_s, scale), length)

    @classmethod
    def from_result(cls, result, *, length: float | None = None) -> StiffnessIndices:
        """Indices of a :class:`closedloop.elastostatics.compliance.ComplianceResult`, same point
        and axes.

        Its rank, rigid directions, K and scaled condition number are kept: they come
        from a square-root factor of C, which resolves near-singular poses better than C
        itself, and so ``K`` exists here exactly when ``result.K`` does.
        """
        spectrum = Spectrum(
            int(result.rank),
            readonly(result.rigid_directions),
            float(result.condition_number),
            float(result.length),
            result.stiffness_matrix if result.is_full_rank else None,
        )
        return cls._of(result.C, spectrum, _check_length(length))

    # ------------------------------------------------------------------ helpers
    @property
    def is_full_rank(self) -> bool:
        """True when the stiffness K exists."""
        return self.rank == 6

    def _require_full_rank(self, what: str) -> None:
        if not self.is_full_rank:
            raise RigidDirectionsError(
                f"{what}: the compliance has rank {self.rank} < 6, the stiffness does not "
                f"exist (infinitely stiff along {describe_directions(self.rigid_directions)})",
                self.rigid_directions,
            )

    @property
    def is_symmetric(self) -> bool:
        """True when C is symmetric to :data:`SCALED_TOL` (judged on the scaled C_s); a
        preload moment makes a tangent compliance non-symmetric (:meth:`from_result`)."""
        return scaled_asymmetry(self.C, self._spectrum.length) <= SCALED_TOL

    def _require_symmetric(self, what: str) -> None:
        if not self.is_symmetric:
            asymmetry = scaled_asymmetry(self.C, self._spectrum.length)
            raise InvalidInputError(
                f"{what}: defined for a symmetric compliance only, and this one is not (scaled "
                f"asymmetry {asymmetry:.2e} > {SCALED_TOL:g}: a "
                "preload moment makes the tangent compliance non-symmetric)"
            )

    def _length(self, length: float | None) -> float:
        length = _check_length(self.length if length is None else length)
        if length is None:
            raise InvalidInputError("a characteristic length [m] is needed: pass length=...")
        return length

    def _block_eig(self, block: slice, what: str, need_full: bool):
        """Eigen-decomposition (c ascending, V) of a 3x3 compliance block, checked
        (:func:`block_spectrum`)."""
        c, V, rigid = (a[0] for a in block_spectrum(self.C[None], block, self._spectrum.length))
        if rigid.all() or (need_full and rigid.any()):
            directions = np.zeros((6, int(rigid.sum())))
            directions[block] = V[:, rigid]
            raise RigidDirectionsError(
                f"{what} does not exist: the compliance block has rank {3 - rigid.sum()} < 3, "
                f"infinitely stiff along {describe_directions(directions)}",
                directions,
            )
        return c, V

    # ------------------------------------------------------------------ whole matrix
    @property
    def K(self) -> np.ndarray:
        """(6, 6) stiffness C^-1 [N/m, N/rad, N m/m, N m/rad], from a square-root factor."""
        self._require_full_rank("K")
        return self._spectrum.K

    @property
    def _spectrum(self) -> Spectrum:
        if self.spectrum is None:  # built field by field: the rule on C itself
            return spectrum_from_compliance(self.C, 1.0 if self.length is None else self.length)
        return self.spectrum

    @property
    def scaled_condition_number(self) -> float:
        """cond(K_s) of the scaled stiffness over the rank
        (:mod:`closedloop.common.conditioning`)."""
        return self._spectrum.condition_number

    @property
    def ill_conditioned(self) -> bool:
        """True when :attr:`scaled_condition_number` exceeds ``ILL_CONDITIONED``."""
        return self._spectrum.ill_conditioned

    @property
    def determinant(self) -> float:
        """det K [N^6/rad^3], invariant under length unit, reference point and axes.

        det K = det(D)^2 det K_s, the product of the eigenvalues of the scaled K_s
        (:func:`inverse_pair_eigenvalues` of C_s and K_s): accurate to about
        eps sqrt(cond(K_s)) relative, where an LU determinant of K errs by eps cond(K_s) (at
        cond 3e18 it is off by a factor of two or has the wrong sign). A K that is not
        positive definite (an unstable preloaded equilibrium) has its LU determinant.

        Raises:
            RigidDirectionsError: C is rank deficient.
            SingularConfigurationError: det K is beyond the floating point range
                (:func:`finite_determinant`).
        """
        self._require_full_rank("det K")
        K = self.K
        d = twist_scaling(self._spectrum.length)
        dd = np.outer(d, d)
        lam = inverse_pair_eigenvalues(self.C * dd, K / dd)
        if lam is None:
            return lu_determinant(K)
        # mantissas and exponents apart: det K_s = det K L^6 may leave the float range
        # where det K does not
        mantissa, exponent = np.frexp(np.concatenate([lam, d, d]))
        product, total = np.prod(mantissa), int(np.sum(exponent))
        with np.errstate(over="ignore", under="ignore"):
            det = float(np.ldexp(product, total))
        return finite_determinant(det, (np.log2(abs(product)) + total) * np.log10(2.0))

    def _eigenvalues(self, t: np.ndarray, what: str) -> np.ndarray:
        """(6,) eigenvalues of T^-1 K T^-1 (t: (6,) diagonal of T^-1), ascending, each from
        whichever of T C T and T^-1 K T^-1 resolves it (:func:`inverse_pair_eigenvalues`)."""
        self._require_full_rank(what)
        self._require_symmetric(what)
        tt = np.outer(t, t)
        K = self.K * tt
        lam = inverse_pair_eigenvalues(self.C / tt, K)
        return readonly(np.linalg.eigvalsh(K) if lam is None else lam)

    def _condition(self, t: np.ndarray) -> float:
        """cond(T^-1 K T^-1): max ``|lambda|`` / min ``|lambda|`` of a symmetric C, the 2-norm
        condition number of a non-symmetric one (as
        :func:`~closedloop.analysis.batch_indices.batch_indices`)."""
        self._require_full_rank("the condition number of K")
        if not self.is_symmetric:
            return float(np.linalg.cond(self.K * np.outer(t, t)))
        lam = np.abs(self._eigenvalues(t, "the condition number of K"))
        return float(lam.max() / lam.min())

    def _homogenising(self, length: float | None) -> np.ndarray:
        """(6,) diagonal of T^-1 = diag(1, 1, 1, 1/L, 1/L, 1/L), L = ``length`` [m]."""
        return np.r_[np.ones(3), np.full(3, 1.0 / self._length(length))]

    @property
    def eigenvalues(self) -> np.ndarray:
        """(6,) eigenvalues of the SI matrix K, ascending (mixed units: module docstring),
        each from whichever of C and K resolves it (:func:`inverse_pair_eigenvalues`).

        Raises:
            RigidDirectionsError: C is rank deficient.
            InvalidInputError: C is not symmetric (a preload moment).
        """
        return self._eigenvalues(np.ones(6), "the eigenvalues of K")

    @property
    def compliance_eigenvalues(self) -> np.ndarray:
        """(6,) eigenvalues of the SI matrix C, ascending (mixed units); exist at any rank."""
        return readonly(np.linalg.eigvalsh(self.C))

    @property
    def condition_number(self) -> float:
        """cond(K) = cond(C) of the SI matrix, max abs(lambda) / min abs(lambda) (positive also for
        an indefinite K, at an unstable preloaded equilibrium; the 2-norm condition number
        of a non-symmetric K): depends on the length unit and the point."""
        return self._condition(np.ones(6))

    def homogenised_stiffness(self, length: float | None = None) -> np.ndarray:
        """(6, 6) K_h = T^-1 K T^-1 [N/m], T = diag(1, 1, 1, L, L, L), L = ``length`` [m]
        (default: the instance's ``length``)."""
        t = self._homogenising(length)
        return readonly(self.K * np.outer(t, t))

    def homogenised_eigenvalues(self, length: float | None = None) -> np.ndarray:
        """(6,) eigenvalues of K_h [N/m], ascending, each from whichever of K_h and
        C_h = T C T resolves it (as :attr:`eigenvalues`); at L equal to the length of the
        scaling they are those of K_s / L^2 (K_s: :mod:`closedloop.common.conditioning`)."""
        return self._eigenvalues(self._homogenising(length), "the homogenised eigenvalues")

    def homogenised_condition_number(self, length: float | None = None) -> float:
        """cond(K_h), dimensionless, as :attr:`condition_number`; depends on L and on the
        reference point (at the length of the scaling, :attr:`scaled_condition_number`)."""
        return self._condition(self._homogenising(length))

    # ------------------------------------------------------------------ blocks
    @property
    def translational_stiffness(self) -> np.ndarray:
        """(3, 3) [N/m], rotations free: K_tt - K_tr K_rr^-1 K_rt = C_tt^-1."""
        self._block_eig(T, "translational stiffness (rotations free)", True)
        return readonly(np.linalg.inv(self.C[T, T]))

    @property
    def translational_stiffness_blocked(self) -> np.ndarray:
        """(3, 3) [N/m], rotations blocked: K_tt."""
        return readonly(self.K[T, T])

    @property
    def rotational_stiffness(self) -> np.ndarray:
        """(3, 3) [N m/rad], translations free: K_rr - K_rt K_tt^-1 K_tr = C_rr^-1."""
        self._block_eig(R, "rotational stiffness (translations free)", True)
        return readonly(np.linalg.inv(self.C[R, R]))

    @property
    def rotational_stiffness_blocked(self) -> np.ndarray:
        """(3, 3) [N m/rad], translations blocked: K_rr."""
        return readonly(self.K[R, R])

    def _principal(self, block: slice, which: str) -> PrincipalStiffness:
        kind = "translational" if block == T else "rotational"
        self._require_symmetric(f"the {which} {kind} stiffness")
        c, V = self._block_eig(block, f"{which} {kind} stiffness", which == "max")
        i = -1 if which == "min" else 0
        return PrincipalStiffness(float(1.0 / c[i]), unit_direction(V[:, i]))

    @property
    def min_translational_stiffness(self) -> PrincipalStiffness:
        """Smallest eigenvalue of the translational stiffness (rotations free) [N/m]."""
        return self._principal(T, "min")

    @property
    def max_translational_stiffness(self) -> PrincipalStiffness:
        """Largest eigenvalue of the translational stiffness (rotations free) [N/m]."""
        return self._principal(T, "max")

    @property
    def min_rotational_stiffness(self) -> PrincipalStiffness:
        """Smallest eigenvalue of the rotational stiffness (translations free) [N m/rad]."""
        return self._principal(R, "min")

    @property
    def max_rotational_stiffness(self) -> PrincipalStiffness:
        """Largest eigenvalue of the rotational stiffness (translations free) [N m/rad]."""
        return self._principal(R, "max")

    # ------------------------------------------------------------------ eigenscrews
    @property
    def eigenscrews(self) -> tuple[Eigenscrew, ...]:
        """The six eigenscrews of K, by ascending eigenvalue (three negative pitches first).

        Computed from both K and C (:func:`closedloop.analysis.screws.eigenscrews`).

        Raises:
            RigidDirectionsError: C is rank deficient.
            InvalidInputError: C is not symmetric, or K not positive definite (a preloaded
                equilibrium): the decomposition does not exist.
        """
        what = "the eigenscrews of K"
        self._require_full_rank(what)
        self._require_symmetric(what)
        return eigenscrews(0.5 * (self.C + self.C.T), 0.5 * (self.K + self.K.T))

    # ------------------------------------------------------------------ export
    def to_dict(self) -> dict:
        """JSON-ready summary; an index that does not exist is None, its reason in ``missing``."""
        out: dict = {"rank": self.rank, "rigid_directions": self.rigid_directions.T}
        missing: dict = {}
        names = list(_EXPORTED) + (
            ["homogenised_eigenvalues", "homogenised_condition_number"]
            if self.length is not None
            else []
        )
        for name in names:
            try:
                value = getattr(self, name)
                out[name] = _jsonable(value() if callable(value) else value)
            except (RigidDirectionsError, SingularConfigurationError, InvalidInputError) as e:
                out[name], missing[name] = None, str(e)
        out["rigid_directions"] = _jsonable(out["rigid_directions"])
        out.update(missing=missing, order=list(TWIST_LABELS), units=INDEX_UNITS)
        return out


#: Indices exported by :meth:`StiffnessIndices.to_dict` (besides rank and rigid directions).
_EXPORTED = (
    "length", "C", "compliance_eigenvalues", "K", "determinant", "eigenvalues",
    "condition_number", "scaled_condition_number", "ill_conditioned", "translational_stiffness",
    "translational_stiffness_blocked",
    "rotational_stiffness", "rotational_stiffness_blocked", "min_translational_stiffness",
    "max_translational_stiffness", "min_rotational_stiffness", "max_rotational_stiffness",
    "eigenscrews",
)  # fmt: skip


#: Units of the exported indices.
INDEX_UNITS = {
    **UNITS,
    "determinant": "N^6/rad^3",
    "translational": "N/m",
    "rotational": "N m/rad",
    "eigenscrews": "eigenvalue N/rad, pitch m/rad, point m, spring N/m",
    "homogenised": "N/m",
}


def _jsonable(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, PrincipalStiffness):
        return {"value": value.value, "direction": value.direction.tolist()}
    if isinstance(value, tuple):
        return [{k: _jsonable(v) for k, v in vars(screw).items()} for screw in value]
    return float(value) if isinstance(value, np.floating) else value
