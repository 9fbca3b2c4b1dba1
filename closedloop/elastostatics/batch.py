"""Compliances of many configurations of one model at once.

:func:`~closedloop.compliance` answers one configuration; a map or a sweep asks thousands, and most
of a single query's time is the fixed cost of its small numpy and LAPACK calls. Here the
kinematics are evaluated configuration by configuration (Pinocchio), and the fast paths
of :mod:`closedloop.elastostatics.springs` (serial, partitioned) run once on the whole stack:

    A = [-J_p, J_s] scaled,  A = Q R (stacked QR),  X = -J_p^+ J_s = R11^-1 R12,
    dq = T y (T = [I; X] scaled),  B = J T W,  C = B B^T,  G = T W B^T,

the same formulas as :func:`closedloop.elastostatics.compliance.compliance`, with the same
decisions: a configuration is answered here only when each test of the single query passes with a
margin (:data:`MARGIN`): the closure residual within its tolerance and resolved to it
(:func:`closedloop.kinematics.configuration.residual_rounding`), J_p well conditioned (the exact
1-norm condition, which bounds the estimate of the single query), the closure equations
solved, no singular value of the rank rule near its threshold, C, G and K finite. Every other
configuration (near a singular pose, the null-space path, open loops, a mechanism) goes
through :func:`~closedloop.compliance` itself, so that the answer, or the error, is that of
the single query. Results agree with the single query to rounding (the stacked LAPACK calls differ
from the single ones only in their order of operations).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import ReadOnlyArrays, frozen, real_array, upper_triangular_inverses
from closedloop.common.conditioning import RANK_RTOL, check_length
from closedloop.elastostatics.partition import PARTITION_RCOND, PARTITION_RTOL, model_scaling
from closedloop.elastostatics.query import ComplianceQuery
from closedloop.exceptions import ClosedLoopError, InvalidInputError, OutsideLimitsError
from closedloop.kinematics.configuration import (
    CLOSURE_TOL,
    require_within_limits,
    residual_rounding,
)
from closedloop.kinematics.constraints import jacobian_rows, reference_frame, residual_rows
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.model.closures import check_name

#: Errors of a configuration's query: the project's typed errors and LAPACK's (anything
#: else, a programming error, propagates).
QUERY_ERRORS = (ClosedLoopError, np.linalg.LinAlgError)
#: Factor by which each test of the single query must pass for a configuration to be
#: answered by the stacked computation (the two compute the tested quantities with
#: different rounding; with this margin a configuration answered here is one the single
#: query answers by the same path).
MARGIN = 2.0
#: Configurations computed together at most: the stacked arrays (closure and frame
#: Jacobians, QR factors, P, B, G) take a few tens of kB per CaHyMan configuration, so a
#: stack stays within tens of MB.
STACK = 1024
#: Largest entry of K [SI] the stacked computation answers (the single query's overflow
#: check, with room): beyond it the configuration goes through :func:`~closedloop.compliance`.
K_MAX = 1e290
#: Factor above the rank rule's threshold (RANK_RTOL spread)^2 on the eigenvalue ratio
#: lambda_min / lambda_max of the formed C_s = B_s B_s^T by which a configuration is full
#: rank without the SVD of its factor. Forming C_s and its eigenvalues err by about
#: s eps lambda_max (s springs), below 1e-12 lambda_max up to s ~ 1e3, while the ratio
#: tested is at least 1e4 RANK_RTOL^2 = 1e-10: the SVD of the single query then finds
#: beta_6 / beta_1 about 100 times above its threshold.
GRAM_MARGIN = 1e4
#: Largest condition number taken from the eigenvalues of the formed C_s: their ratio errs
#: by about s eps cond (relative; at most 1.6e-12 measured on 2000 random UR5 poses),
#: while the singular values of the factor, as the single query's, err by about
#: eps sqrt(cond). Above it the condition number is (beta_1 / beta_6)^2 from the factor's
#: SVD (an eighth of a UR5 map's random poses; the SVD costs about twice the eigenvalues).
COND_GRAM = 1e4


@dataclass(frozen=True)
class BatchCompliance(ReadOnlyArrays):
    """Compliances of n configurations (arrays read-only).

    Attributes:
        C: (n, 6, 6) compliance [SI] of the frame, twist (dx, dy, dz [m], rx, ry, rz [rad])
            per wrench (fx, fy, fz [N], nx, ny, nz [N m]), at the frame origin, in
            ``axes``.
        G: (n, nv, 6) wrench to joint deflection dq (tangent of q) [rad or m per N, N m].
        rank: (n,) rank of C (the rule of :mod:`closedloop.common.conditioning`).
        condition_number: (n,) cond(K_s) of the scaled stiffness over the rank, as
            :attr:`closedloop.elastostatics.compliance.ComplianceResult.condition_number` (from the
            square-root factor: it resolves near-singular poses that the formed C does not;
            equal to the single query's to ~2e-12 relative up to :data:`COND_GRAM`, from
            the formed C_s, and to ~eps sqrt(cond) above it).
        stacked: (n,) True where the stacked fast path answered, False where the single
            query did.
        frame, axes: the loaded frame and the axes (``"world"`` or ``"local"``).
        length: characteristic length L [m] of the unit-free rules.
    """

    C: np.ndarray
    G: np.ndarray
    rank: np.ndarray
    condition_number: np.ndarray
    stacked: np.ndarray
    frame: str
    axes: str
    length: float


def compliances(
    clm: ClosedLoopModel,
    Q,
    frame: str,
    axes: str = "world",
    *,
    length: float | None = None,
    check_limits: bool = True,
) -> BatchCompliance:
    """Compliance of ``frame`` at each of n assembled configurations (module docstring).

    Args:
        clm: the model.
        Q: (n, nq) configurations, each closing the loops (:func:`closedloop.assemble`).
        frame: name of the loaded frame; the reference point is its origin.
        axes: ``"world"`` (world-aligned axes, default) or ``"local"``.
        length: characteristic length [m] of the unit-free rules (default: the model's).
        check_limits: refuse configurations outside the joints' position limits (as the
            single query; False takes them as they are).

    Returns:
        The :class:`BatchCompliance`; each configuration's C, G and rank equal those of
        ``compliance(clm, Q[i], frame, axes, length=length)`` to rounding.

    Raises:
        InvalidInputError: Q is not (n, nq) finite real numbers; bad axes or length.
        NameNotFoundError: unknown frame.
        OutsideLimitsError: ``check_limits`` and a configuration outside the limits (a
            note names its index).
        ClosedLoopError: the error of :func:`closedloop.compliance` at the first
            configuration that has one (open loops, a mechanism, an overflow), with a note
            naming the configuration's index (an error of the frame, axes or length
            concerns no configuration: it has no such note).
    """
    Q = _check_configurations(clm, Q)
    _check_query(clm, frame, axes, length)  # before any configuration
    for i, q in enumerate(Q if check_limits else ()):
        try:
            require_within_limits(clm, q)
        except OutsideLimitsError as e:
            e.add_note(f"at configuration {i} of Q")
            raise
    C, G, rank, cond, stacked, errors, L = answered(
        clm, Q, frame, axes, length, QUERY_ERRORS, first_error=True, check_limits=False
    )
    for i, e in errors.items():  # the single query's error, with the configuration
        e.add_note(f"at configuration {i} of Q")
        raise e
    arrays = (frozen(a) for a in (C, G, rank, cond, stacked))
    return BatchCompliance(*arrays, frame, axes, L)


def answered(
    clm,
    Q,
    frame,
    axes,
    length,
    catch,
    *,
    first_error: bool = False,
    closure=None,
    check_limits: bool = True,
):
    """Every configuration of Q (n, nq) answered: by :func:`stacked_compliances`, and the
    others by :func:`closedloop.elastostatics.compliance.compliance`.

    Args:
        length: characteristic length [m], or None (the model's).
        catch: exception types recorded per configuration (others propagate). One of
            them from the stacked path (a bad frame, axes or length) leaves every
            configuration to the single query, which raises it again (with no
            configuration, it propagates).
        first_error: stop at the first recorded error.
        closure: as :func:`stacked_compliances`.
        check_limits: as for :func:`closedloop.elastostatics.compliance.compliance` (the stacked
            path does not check them).

    Returns:
        C (n, 6, 6), G (n, nv, 6), rank (n,), the scaled condition number cond(K_s) (n,)
        (NaN, -1 and NaN where an error was recorded), stacked (n,) bool, the errors by
        configuration index, and the length L [m] (NaN when invalid; a valid one is kept
        when the stacked path fails after it, e.g. on a LAPACK error).
    """
    L = np.nan
    try:
        L = clm.length if length is None else check_length(length)
        C, G, rank, cond = stacked_compliances(clm, Q, frame, axes, L, closure)
    except catch:
        if not len(Q):  # no single query to raise it again
            raise
        n = len(Q)
        C, G, rank, cond = (
            np.full((n, 6, 6), np.nan),
            np.full((n, clm.model.nv, 6), np.nan),
            np.full(n, -1),
            np.full(n, np.nan),
        )
    stacked, errors, query = rank >= 0, {}, None
    for i in np.flatnonzero(~stacked):
        try:
            if query is None:  # made (its arguments checked) once, or raising at each
                query = ComplianceQuery(clm, frame, axes, length=length, check_limits=check_limits)
            r = query(Q[i])
        except catch as e:
            errors[int(i)] = e
            if first_error:
                break
            continue
        C[i], G[i], rank[i], cond[i] = r.C, r.G, r.rank, r.condition_number
    return C, G, rank, cond, stacked, errors, L


def _check_query(clm: ClosedLoopModel, frame: str, axes: str, length: float | None) -> None:
    """The arguments shared by every configuration's query, checked as the single query
    checks them.

    Raises:
        InvalidInputError: a frame that is not a str, bad axes or length.
        NameNotFoundError: unknown frame.
    """
    check_name("frame", frame)
    clm.frame_id(frame)
    reference_frame(axes)
    if length is not None:
        check_length(length)


def _check_configurations(clm: ClosedLoopModel, Q) -> np.ndarray:
    Q = real_array(Q, "Q")
    nq = clm.model.nq
    if Q.ndim != 2 or Q.shape[1] != nq:
        raise InvalidInputError(f"Q has shape {Q.shape}; expected (n, nq={nq})")
    bad = np.flatnonzero(~np.isfinite(Q).all(axis=1))
    if bad.size:
        raise InvalidInputError(f"configuration {bad[0]} of Q has non-finite values")
    if nq != clm.model.nv:  # quaternions or unit complex numbers: as a single q
        for i, q in enumerate(Q):
            try:
                Q[i] = clm.check_configuration(q)
            except InvalidInputError as e:
                raise InvalidInputError(f"configuration {i} of Q: {e}") from None
    return Q


def stacked_compliances(
    clm: ClosedLoopModel, Q: np.ndarray, frame: str, axes: str, L: float, closure=None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The stacked fast path on checked configurations Q (n, nq) at length L [m],
    :data:`STACK` configurations at a time.

    Args:
        closure: the closure residuals (n, m) and Jacobians (n, m, nv) at Q when the
            caller has them (:attr:`closedloop.kinematics.assembly.Assembly.closure`), or None:
            evaluated here.

    Returns:
        C: (n, 6, 6) [SI] and G: (n, nv, 6), NaN where the path did not answer;
        rank: (n,) rank of C, -1 where the path did not answer (module docstring:
        everything else is left to :func:`closedloop.elastostatics.compliance.compliance`);
        cond: (n,) cond(K_s) over the rank, NaN where the path did not answer.
    """
    starts = range(0, len(Q), STACK) if len(Q) else [0]  # no configuration: empty arrays
    parts = [
        _stack(clm, Q[i : i + STACK], frame, axes, L,
               None if closure is None else (closure[0][i : i + STACK], closure[1][i : i + STACK]))
        for i in starts
    ]  # fmt: skip
    C, G, rank, cond = (np.concatenate(a) for a in zip(*parts, strict=True))
    return C, G, rank, cond


def _stack(clm: ClosedLoopModel, Q: np.ndarray, frame: str, axes: str, L: float, closure):
    """:func:`stacked_compliances` of one stack."""
    check_name("frame", frame)
    reference = reference_frame(axes)
    fid, model = clm.frame_id(frame), clm.model
    n, nv, m = len(Q), model.nv, clm.n_constraints
    C, G = np.full((n, 6, 6), np.nan), np.full((n, nv, 6), np.nan)
    sc = model_scaling(clm, L)
    p, s = sc.passive.size, sc.sprung.size
    if not n or not nv or not s or sc.loop_blocks is not None or (m < p if p else m):
        return C, G, np.full(n, -1), np.full(n, np.nan)  # no fast path (partition.partition)
    r, Jc, J = _kinematics(clm, Q, fid, reference, closure)
    ok = MARGIN * np.max(abs(r) * sc.row_scale[:, 0], axis=1, initial=0.0) <= CLOSURE_TOL
    if m:  # the residual resolved to its tolerance (Configuration.require_closed)
        ok &= MARGIN * residual_rounding(clm, Q, L) <= CLOSURE_TOL
    X, norm2 = None, np.zeros(n)
    if p:  # the fast paths have no spring-free motion: the springs' coordinates move
        X, ok_p = _passive_motions(Jc, sc)
        ok &= ok_p
        norm2 = np.einsum("kij,kij->k", X, X)
    with np.errstate(over="ignore", invalid="ignore"):  # overflows: not finite, left
        if sc.P_diagonal is not None:  # every coordinate with a diagonal spring
            B = J * sc.P_diagonal
            Gk = np.swapaxes(B, 1, 2) * sc.P_diagonal[:, None]
        else:
            P = np.broadcast_to(sc.P0, (n, *sc.P0.shape)).copy()
            if X is not None:
                P[:, sc.passive] = X * sc.passive_coef if sc.W is None else (X @ sc.W) * sc.s_p
            B = J @ P
            Gk = P @ np.swapaxes(B, 1, 2)
        Ck = B @ np.swapaxes(B, 1, 2)
        rank, cond = _ranks(B * sc.d[:, None], Ck * sc.dd, sc, np.sqrt(1.0 + norm2))
    ok &= rank >= 0
    ok &= np.isfinite(Ck).all(axis=(1, 2)) & np.isfinite(Gk).all(axis=(1, 2))
    C[ok], G[ok] = Ck[ok], Gk[ok]
    return C, G, np.where(ok, rank, -1), np.where(ok, cond, np.nan)


def _ranks(B_s: np.ndarray, C_s: np.ndarray, sc, cond_T: np.ndarray):
    """(n,) rank of each C = D^-1 B_s B_s^T D^-1 from its scaled factor B_s (n, 6, s) by the
    rule of :func:`closedloop.common.conditioning.spectrum_from_factor`, or -1 where a singular
    value lies within :data:`MARGIN` of a threshold of the rule (or K would overflow); and
    (n,) the condition number cond(K_s) over the rank, as that function's.

    The rule reads the kinematic factor on an orthonormal basis of the admissible motions
    (:func:`closedloop.elastostatics.partition.kinematic_factor`); the factors here are on
    T = [I; X], whose condition numbers, at most ``cond_T`` (n,) (sqrt(1 + ``|X|_F^2``), 1 for a
    serial robot), widen the thresholds: a decision taken here is the rule's.

    Most configurations are clearly full rank: the eigenvalues of C_s = B_s B_s^T (n, 6, 6)
    (formed, a third of the cost of the SVDs) tell them within :data:`GRAM_MARGIN`; the
    others are decided on the singular values of their factors. The condition number is
    the eigenvalues' ratio up to :data:`COND_GRAM`, beyond it the factor's (as the single
    query's: the formed C_s would err by eps cond, 2.6e-7 relative at cond 1.7e9).
    """
    finite = np.isfinite(C_s).all(axis=(1, 2)) & np.isfinite(B_s).all(axis=(1, 2))
    mu = np.linalg.eigvalsh(np.where(finite[:, None, None], C_s, 0.0))  # ascending
    with np.errstate(over="ignore", invalid="ignore"):
        threshold = GRAM_MARGIN * (RANK_RTOL * sc.spread * cond_T) ** 2  # (n,); inf: not full
        full = (
            finite & (mu[:, 0] > threshold * mu[:, 5]) & (MARGIN * sc.dd.max() / K_MAX < mu[:, 0])
        )
    rank = np.where(full, 6, -1)
    with np.errstate(divide="ignore", invalid="ignore"):  # within GRAM_MARGIN: positive
        cond = np.where(full, mu[:, 5] / mu[:, 0], np.nan)
    ill = np.flatnonzero(full & (cond > COND_GRAM))  # full rank: B_s has 6 singular values
    if ill.size:
        beta = np.linalg.svd(B_s[ill], compute_uv=False)
        cond[ill] = (beta[:, 0] / beta[:, 5]) ** 2
    rest = np.flatnonzero(~full)
    if rest.size:
        rank[rest], cond[rest] = _factor_ranks(B_s[rest], sc, cond_T[rest])
    return rank, cond


def _factor_ranks(B_s: np.ndarray, sc, cond_T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_ranks` from the singular values of the factors B_s (n, 6, s)."""
    B_s = np.where(np.isfinite(B_s).all(axis=(1, 2))[:, None, None], B_s, 0.0)  # 0: not decided
    beta = np.linalg.svd(B_s, compute_uv=False)  # (n, min(6, s))
    rank = np.full(len(B_s), -1)
    if beta.shape[1] == 6:  # full rank by the factor's singular values
        # B_s = 0 gives NaN (not decided), huge ones inf (decided by the comparisons)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            low = beta[:, 5] / (RANK_RTOL * sc.spread * cond_T * beta[:, 0])
            full = (low > MARGIN) & (sc.dd.max() / K_MAX < beta[:, 5] ** 2)  # K <= dd / beta_6^2
        rank[full] = 6
        deficient = low < 1.0 / MARGIN
    else:
        deficient = np.ones(len(B_s), dtype=bool)
    if deficient.any():  # the rank of the kinematic factor J T V = B_s diag(sigma)
        s_k = np.linalg.svd(B_s[deficient] * sc.sigma, compute_uv=False)
        ratio = s_k / np.where(s_k[:, :1] > 0.0, RANK_RTOL * s_k[:, :1], np.nan)
        band = MARGIN * cond_T[deficient, None]  # J T V: within cond(T) of the rule's factor
        clear = ((ratio > band) | (ratio < 1.0 / band)).all(axis=1)
        r = np.where(clear, np.count_nonzero(ratio > band, axis=1), -1)
        if beta.shape[1] == 6:  # full rank from the kinematic factor: K must not overflow
            with np.errstate(over="ignore"):
                r[(r == 6) & ~(sc.dd.max() / K_MAX < beta[deficient, 5] ** 2)] = -1
        rank[deficient] = r
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # (beta_1 / beta_r)^2
        last = beta[np.arange(len(B_s)), np.clip(rank - 1, 0, None)]
        cond = np.where(rank > 0, (beta[:, 0] / last) ** 2, 1.0)
    return rank, np.where(rank >= 0, cond, np.nan)


def _kinematics(clm: ClosedLoopModel, Q: np.ndarray, fid: int, reference, closure=None):
    """Closure residuals (n, m), closure Jacobians (n, m, nv) and frame Jacobians
    (n, 6, nv) of the configurations Q (n, nq), on a workspace of the model's pool; the
    closure ones are ``closure`` when given (only the frame Jacobians are computed)."""
    model = clm.model
    n, nv, m = len(Q), model.nv, clm.n_constraints
    J = np.empty((n, 6, nv))
    data, datas = workspace = clm.acquire_workspace()
    try:
        if closure is not None:
            for k in range(n):
                J[k] = pin.computeFrameJacobian(model, data, Q[k], fid, reference).reshape(6, nv)
            return *closure, J
        r, Jc = np.empty((n, m)), np.empty((n, m, nv))
        for k in range(n):
            pin.computeJointJacobians(model, data, Q[k])
            if m:
                r[k] = residual_rows(clm, data, datas)
                Jc[k] = jacobian_rows(clm, data, datas, calc=False)
            J[k] = pin.getFrameJacobian(model, data, fid, reference).reshape(6, nv)
    finally:
        clm.release_workspace(workspace)
    return r, Jc, J


@functools.cache
def _upper(rows: int, columns: int) -> np.ndarray:
    """(rows, columns) bool mask of the upper triangle (diagonal included)."""
    return frozen(np.triu(np.ones((rows, columns), dtype=bool)))


def _passive_motions(Jc: np.ndarray, sc) -> tuple[np.ndarray, np.ndarray]:
    """X (n, p, s) = -J_p^+ J_s of each closure Jacobian of Jc (n, m, nv), and where it
    holds with the margin: J_p well conditioned, J_s + J_p X = 0 (the tests of
    :func:`closedloop.elastostatics.partition.passive_motion`)."""
    p = sc.passive.size
    A = np.take(Jc, sc.order, axis=2)
    A *= sc.scale_order
    scale = PARTITION_RTOL * np.max(abs(A[:, :, p:]), axis=(1, 2))
    # -J_p = Q1 R11, R12, R22 from the Householder form (mode "r" would copy the whole
    # triangle out of it): R (n, m, p + s) is the upper trapezoid of h^T
    Rt = np.swapaxes(np.linalg.qr(A, mode="raw")[0], 1, 2)
    R11 = np.where(_upper(p, p), Rt[:, :p, :p], 0.0)
    R12 = Rt[:, :p, p:]  # above the diagonal: all of it
    R22 = np.where(_upper(Rt.shape[1] - p, Rt.shape[2] - p), Rt[:, p:, p:], 0.0)
    singular = (np.diagonal(R11, axis1=1, axis2=2) == 0.0).any(axis=1)
    R11 = np.where(singular[:, None, None], np.eye(p), R11)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        R_inv = upper_triangular_inverses(R11)
        norm = abs(R11).sum(axis=1).max(axis=1) * abs(R_inv).sum(axis=1).max(axis=1)
        X = R_inv @ R12
    ok = ~singular & (MARGIN * norm * PARTITION_RCOND < 1.0)  # exact 1-norm condition
    ok &= MARGIN * MARGIN * np.einsum("kij,kij->k", R22, R22) <= scale * scale
    ok &= np.isfinite(X).all(axis=(1, 2))
    return X, ok
