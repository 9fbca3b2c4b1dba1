"""Elastostatic identification: joint spring stiffnesses fitted to measured deflections.

Each measurement is a configuration (full q, or the actuated values to assemble), a
wrench w (6,) applied at a frame (fx, fy, fz [N], nx, ny, nz [N m], world axes, at the
frame origin) and the measured twist of that frame d (6,) (dx, dy, dz [m], rx, ry, rz
[rad]) with its standard deviation sd (6,) (same units; ``inf`` for a component not
measured, e.g. the rotations when a laser tracker gives positions only: its twist may
then be NaN, and it weighs nothing). The model predicts d = C(k) w
(:func:`closedloop.elastostatics.compliance.compliance`); the fitted parameters are spring values
k_g, one per group of joints tied to one value, found by weighted nonlinear least squares::

    min_theta  sum_m |(C_m(k) w_m - d_m) / sd_m|^2,   k_g = exp(theta_g)

(``scipy.optimize.least_squares``, in log space: k stays positive and the problem is
scale-free). A joint with a number (or one value per coordinate) is fitted as one
stiffness k [N m/rad or N/m] on every velocity coordinate of the joint. A joint with a
block spring (an SPD matrix K_0, e.g. a beam's ``<link>_beam``, :mod:`closedloop.model.beams`)
is fitted as a dimensionless factor k of its start block, K = k K_0 (start 1): for a beam
of given E and G this is E / E_0 = G / G_0 at a fixed Poisson ratio (the tip stiffness is
linear in E and G together); a section's dimensions are not fitted. A group ties joints of
one kind (numbers, or blocks) to one value.

The derivatives are analytic: at a fixed configuration the compliance depends on the
springs only through the joint stiffness K_q, and dC = -G^T dK_q G with G (nv, 6) the
joint deflection per wrench (``ComplianceResult.G``), so that

    dC/dk_g = -sum_{j in g} G_j^T U_j G_j,   G_j = rows of G of joint j,

U_j the identity (a number) or K_0 (a block), and d(C w)/d theta_g = k_g dC/dk_g w.

Standard errors come from the covariance (S^T S)^+ of theta at the solution (S the
sensitivity matrix of the weighted residuals: the sd are taken as known), by the delta
method se(k) = k se(theta). A parameter the data cannot identify (its column of S is
rounding, below ``fit_statistics.DEAD_RTOL`` of the largest, or it takes part in a null
direction of S with unit-norm columns, by the rank rule of
:mod:`closedloop.common.conditioning`, at the solution), or whose log has a standard
error above ``LOG_SE_MAX`` (the data do not bound it), is named in ``unidentifiable``,
its estimate and standard error are None, never an arbitrary value (the fit moves it
only along what the data see: two springs in series keep the sum of their compliances; a
small weight on the offsets from the start keeps the unseen directions there);
``confounded`` names the parameters of each null direction. The errors of the identified
parameters, outside every null direction, are exact. Before the fit, one common log
offset brings the start to the scale of the data (the log offset that best fits the
measured twists with every spring scaled alike).

The standard errors assume that the model fits the data: the weighted residuals are then
draws of a unit normal, and their sum of squares a chi-square variable of n_c - rank(S)
degrees of freedom (n_c the measured components). A fit whose sum of squares exceeds the
quantile of significance :data:`FIT_SIGNIFICANCE` of that distribution (a residual RMS far
above what the stated sd allow: measurements taken on another assembly mode than the
model's, another frame, a unit slip, sd stated too small) is flagged (``Fit.consistent``
False, :class:`ModelMisfitWarning`): its estimates are the best compromise of a model that
does not describe the data, and its standard errors do not hold. The warning and the fit
then name the measurements that misfit most and those whose actuated values were assembled
on another assembly mode than the robot was in (:mod:`closedloop.analysis.misfit`).
"""

from __future__ import annotations

import numbers
import warnings
from collections.abc import Mapping, Sequence

import numpy as np
import scipy.optimize
import scipy.special

from closedloop.analysis.fit_result import Fit
from closedloop.analysis.fit_statistics import (
    FIT_SIGNIFICANCE,
    chi_square_rms_limit,
    covariance,
    null_directions,
    smallest_seen,
)
from closedloop.analysis.measurements import Measurement
from closedloop.analysis.misfit import (
    describe,
    measurement_rms,
    other_modes,
    worst_measurements,
)
from closedloop.common.arrays import readonly
from closedloop.elastostatics.query import ComplianceQuery
from closedloop.exceptions import (
    InvalidInputError,
    MechanismError,
    ModelMisfitWarning,
    OpenLoopError,
    OutsideLimitsError,
    SingularConfigurationError,
)
from closedloop.kinematics.configuration import require_within_limits
from closedloop.kinematics.driving import assemble_connected
from closedloop.model.closed_loop import ClosedLoopModel

#: Largest standard error of log k (the 1-sigma interval of k spans a factor e^2) of an
#: identified parameter: beyond it the data do not bound k (e.g. twists that a rigid spring
#: explains best: the optimiser stops at an arbitrary large k, its error 1e3-1e5 times k).
LOG_SE_MAX = 1.0
#: Most steps of the common log offset that brings a start to the scale of the data.
MAX_OFFSET_STEPS = 5
#: Scale of the log-stiffness unknowns [-]: the first step changes k by at most e^1.
LOG_STEP = 0.01
#: Weighted residual returned for springs that leave a mechanism: a step there is rejected.
REJECTED = 1e100
#: Weight of the offsets from the start, relative to the least seen direction (see _solve).
PRIOR = 1e-9
#: Largest weighted residual, weighted twist d / sd or weighted sensitivity at the start:
#: their sums of squares stay finite (1e200 a term); beyond, a twist, a wrench or an sd is
#: out of scale (a unit slip), not data.
LARGEST_WEIGHTED = 1e100
#: Longest text of a bad argument shown in an error message; a longer one is cut.
SHOWN_REPR = 80


def _groups(clm: ClosedLoopModel, fit) -> list[tuple[str, ...]]:
    if isinstance(fit, str):
        raise InvalidInputError(f"fit must be a list of joint names or groups, got {fit!r}")
    groups = []
    for item in fit:
        group = (item,) if isinstance(item, str) else tuple(item)
        if not group or not all(isinstance(n, str) for n in group):
            raise InvalidInputError(f"a fitted parameter is a joint name or a group, got {item!r}")
        for name in group:
            clm.joint_id(name)  # NameNotFoundError listing the joints
        if len({n in clm.spring_blocks for n in group}) > 1:
            raise InvalidInputError(
                f"group {group} mixes block springs and numbers; expected one kind"
            )
        units = {
            n: ("N/m" if clm.linear_coordinates[clm.joint_v_slice(n)].all() else "N m/rad")
            for n in group
            if n not in clm.spring_blocks
        }
        if len(set(units.values())) > 1:
            raise InvalidInputError(
                f"group {group} ties springs of different units ({units}); a value in N/m "
                "and one in N m/rad are not one number: fit them apart"
            )
        groups.append(group)
    seen = [n for g in groups for n in g]
    if len(set(seen)) != len(seen):
        raise InvalidInputError(f"a joint appears in two fitted parameters: {seen}")
    return groups


def _unit(clm: ClosedLoopModel, group: tuple[str, ...]) -> str:
    """Unit of a fitted value: "1" (a factor of block springs), "N/m" (joints whose
    coordinates all translate), "N m/rad" (all rotate), or both (a joint with both kinds
    of coordinates, one stiffness on each)."""
    if group[0] in clm.spring_blocks:
        return "1"
    linear = clm.linear_coordinates[clm.joint_v_slice(group[0])]
    if linear.all():
        return "N/m"
    return "N m/rad" if not linear.any() else "N/m on translations, N m/rad on rotations"


def _shown(value) -> str:
    """``repr(value)`` for an error message, cut after :data:`SHOWN_REPR` characters (an
    array of many measurements would fill kilobytes)."""
    text = repr(value)
    if len(text) <= SHOWN_REPR:
        return text
    shape = getattr(value, "shape", None)
    what = f"{type(value).__name__} of shape {shape}" if shape is not None else type(value).__name__
    return f"{text[:SHOWN_REPR]}... ({what}, {len(text)} characters)"


def _start(clm: ClosedLoopModel, names, groups, start) -> np.ndarray:
    """(p,) log start values: ``start``, else the model's (1 for a block factor)."""
    start = dict(start or {})
    unknown = sorted(set(start) - set(names))
    if unknown:
        raise InvalidInputError(f"start values for {unknown}, not fitted; expected {names}")
    theta0 = np.empty(len(groups))
    for i, (name, group) in enumerate(zip(names, groups, strict=True)):
        value = start.get(name)
        if value is None and group[0] in clm.spring_blocks:
            value = 1.0
        elif value is None:
            k = clm.stiffness[clm.joint_v_slice(group[0])]
            value = float(k[0]) if k.size else 0.0
        if not (isinstance(value, numbers.Real) and np.isfinite(value) and value > 0):
            unit = _unit(clm, group)
            raise InvalidInputError(
                f"parameter {name!r} needs a finite start value > 0 "
                f"[{'a factor of its block' if unit == '1' else unit}], got {_shown(value)}"
            )
        theta0[i] = np.log(value)
    return theta0


def _configurations(clm: ClosedLoopModel, measurements, check_limits: bool,
                    q0=None) -> list[np.ndarray]:  # fmt: skip
    """The configuration of each measurement (its index named in an error): its actuated
    values driven from q0 (default: the reference configuration), else its q (within the
    limits, with ``check_limits``)."""
    if isinstance(measurements, Measurement | str) or not isinstance(measurements, Sequence):
        raise InvalidInputError(
            f"measurements must be a list of Measurement, got {_shown(measurements)}"
        )
    if not measurements or not all(isinstance(m, Measurement) for m in measurements):
        raise InvalidInputError("measurements must be a non-empty list of Measurement")
    out = []
    start = clm.reference_configuration() if q0 is None else clm.check_configuration(q0)
    for i, m in enumerate(measurements):
        try:  # actuated values: their count and values checked by the assembly
            q = None if m.q is None else clm.check_configuration(m.q)
            if m.actuated is not None:
                q = assemble_connected(clm, m.actuated, start, jacobian=False,
                                       check_limits=check_limits).q  # fmt: skip
            elif check_limits:
                require_within_limits(clm, q)
            out.append(q)
        except OutsideLimitsError as e:
            raise OutsideLimitsError(f"measurement {i}: {e}", e.joints) from None
        except InvalidInputError as e:
            raise InvalidInputError(f"measurement {i}: {e}") from None
    return out


def identify(
    clm: ClosedLoopModel,
    measurements: Sequence[Measurement],
    frame: str,
    fit: Sequence[str | Sequence[str]],
    *,
    start: Mapping[str, float] | None = None,
    check_limits: bool = True,
    q0: np.ndarray | None = None,
) -> Fit:
    """Fit spring values to measured deflections (see the module docstring).

    Args:
        clm: the model; its springs are the start values (and the values of the springs
            not fitted).
        measurements: the data (:class:`Measurement`).
        frame: the loaded and measured frame.
        fit: joint names, or groups of names tied to one value (a stiffness applied to
            every velocity coordinate of its joints, or a factor of their blocks).
        start: parameter name ("a+b" for a group) -> start value [N m/rad, N/m, or a
            block's factor], overriding the model's.
        check_limits: refuse a measurement outside the joints' position limits (a q, or
            actuated values); False: take them as they are (``--no-limits``).
        q0: (nq,) the configuration the ``actuated`` measurements are driven from, on its
            assembly mode (default: the model's reference configuration, as
            :func:`closedloop.kinematics.assembly.assemble`).

    Warns:
        ModelMisfitWarning: the model does not fit the data (``Fit.consistent`` False:
            the chi-square test of the module docstring); the message gives the residual
            RMS and the largest the sd allow, the measurements that misfit most and those
            assembled on another assembly mode (``Fit.worst``, ``Fit.other_mode``).

    Raises:
        InvalidInputError: no parameter, a parameter without a start value > 0, a start
            value of a parameter not fitted, a group mixing blocks and numbers, a bad
            measurement (its index named), fewer measured components than parameters, a
            measurement whose weighted deflection overflows (a twist, a wrench or an sd
            out of scale, its index and the culprit named).
        NameNotFoundError: unknown joint or frame.
        OpenLoopError: a measurement's q does not close the loops (its index named).
        OutsideLimitsError: ``check_limits`` and a measurement's q outside the joints'
            limits (its index named; actuated values outside: InvalidInputError).
        MechanismError, SingularConfigurationError: no compliance at a measurement's
            configuration with the start springs (its index named).
    """
    groups = _groups(clm, fit)
    if not groups:
        raise InvalidInputError("nothing to fit: give at least one joint name")
    names = tuple("+".join(g) for g in groups)
    configs = _configurations(clm, measurements, check_limits, q0)
    clm.frame_id(frame)  # NameNotFoundError listing the frames
    n_measured = sum(int(np.isfinite(m.sd).sum()) for m in measurements)
    if n_measured < len(groups):
        raise InvalidInputError(f"{n_measured} measured components for {len(groups)} parameters")
    theta0 = _start(clm, names, groups, start)
    w = np.array([m.wrench for m in measurements])
    d = np.array([m.twist for m in measurements])
    sd = np.array([m.sd for m in measurements])  # inf: not measured, weight 0
    springs, locked = clm.springs, [n for n in clm.locked if n not in set().union(*groups)]
    coords = np.arange(clm.model.nv)
    parts = [[(coords[clm.joint_v_slice(n)], clm.spring_blocks.get(n)) for n in g] for g in groups]

    def evaluate(theta):
        k = np.exp(theta)
        values = {
            n: (k[c] if u is None else k[c] * u)
            for c, g in enumerate(groups)
            for n, (_, u) in zip(g, parts[c], strict=True)
        }
        model = clm.with_springs({**springs, **values}, locked)
        query = ComplianceQuery(model, frame, check_limits=False)  # the limits checked above
        pred, sens = np.empty((len(configs), 6)), np.empty((len(configs), 6, len(groups)))
        for m, q in enumerate(configs):
            try:
                res = query(q)
            except OpenLoopError as e:
                raise OpenLoopError(f"measurement {m}: {e}", e.residual, e.tolerance) from None
            except (MechanismError, SingularConfigurationError) as e:
                raise type(e)(f"measurement {m}: {e}") from None
            pred[m] = res.C @ w[m]
            for c in range(len(groups)):
                dC = sum(compliance_derivative(res, r, u) for r, u in parts[c])
                sens[m, :, c] = k[c] * (dC @ w[m])
        return (pred - d) / sd, sens.reshape(-1, len(groups)) / sd.reshape(-1, 1)

    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is named below
        _check_scale(*evaluate(theta0), d, w, sd)
    theta, success = _solve(evaluate, _common_offset(evaluate, theta0, d / sd))
    r, S = evaluate(theta)
    unidentifiable, confounded, rank = null_directions(S, names)
    free = [i for i, n in enumerate(names) if n not in unidentifiable]
    cov = covariance(S)[np.ix_(free, free)]
    se = np.sqrt(np.diag(cov))
    vague = se > LOG_SE_MAX  # the data do not bound it: the fit stopped anywhere
    if vague.any():
        unidentifiable = sorted({*unidentifiable, *(names[free[j]] for j in np.flatnonzero(vague))},
                                key=names.index)  # fmt: skip
        keep = np.flatnonzero(~vague)
        free, cov, se = [free[j] for j in keep], cov[np.ix_(keep, keep)], se[keep]
    k = np.exp(theta)
    estimates, ses = dict.fromkeys(names), dict.fromkeys(names)
    for j, i in enumerate(free):
        estimates[names[i]], ses[names[i]] = float(k[i]), float(k[i] * se[j])
    rms = float(np.sqrt(np.mean(r**2)))
    rms_limit = chi_square_rms_limit(r, S, rank)
    consistent = rms_limit is None or rms <= rms_limit
    worst, other = (), {}
    if not consistent:
        worst = worst_measurements(r, sd, FIT_SIGNIFICANCE)
        other = other_modes(clm, measurements, configs, check_limits=check_limits)
        diagnosis = describe(measurements, measurement_rms(r), worst, other)
        warnings.warn(
            f"the model does not fit the data: weighted residual RMS {rms:.3g}, where "
            f"errors of the stated sd give at most {rms_limit:.3g} (chi-square test at "
            f"significance {FIT_SIGNIFICANCE:g}); the standard errors assume a fit and do "
            "not hold (check the configurations' assembly mode, the frame, the units, the sd)"
            + (f"; {diagnosis}" if diagnosis else ""),
            ModelMisfitWarning,
            stacklevel=2,
        )
    return Fit(
        names=names,
        estimates=estimates,
        std_errors=ses,
        correlations=readonly(cov / np.outer(se, se)),
        identified=tuple(names[i] for i in free),
        unidentifiable=tuple(unidentifiable),
        confounded=tuple(confounded),
        residuals=readonly(r),
        residual_rms=rms,
        rms_limit=rms_limit,
        consistent=consistent,
        measurement_rms=readonly(measurement_rms(r)),
        worst=worst,
        other_mode=other,
        units={name: _unit(clm, g) for name, g in zip(names, groups, strict=True)},
        n_measurements=len(configs),
        success=success,
    )


def _check_scale(r, S, d, w, sd) -> None:
    """Refuse a measurement whose weighted values at the start overflow or exceed
    :data:`LARGEST_WEIGHTED`: the residual r, the measured twist d / sd, the predicted one
    C w / sd = r + d / sd or the sensitivities S (r, d, w, sd (n, 6); S (6 n, p)).

    The culprit named is the measured twist when d / sd is out of scale and C w / sd (and
    its sensitivities) is not, the wrench (or a start spring) in the opposite case, and the
    sd when both are.

    Raises:
        InvalidInputError: naming the first such measurement, its largest weighted value,
            wrench, twist and sd, and the culprit.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        data = d / sd
        measured = np.abs(data)
        predicted = np.abs(np.concatenate([r + data, S.reshape(len(r), -1)], axis=1))
        rows = np.concatenate([np.abs(r), measured, predicted], axis=1)
    largest = np.where(np.isnan(rows), np.inf, rows).max(axis=1)
    bad = np.flatnonzero(~(largest <= LARGEST_WEIGHTED))
    if bad.size:
        m = int(bad[0])
        twist_bad, predicted_bad = (
            not np.all(a[m] <= LARGEST_WEIGHTED) for a in (measured, predicted)
        )  # NaN (inf - inf) counts as out of scale
        if twist_bad and not predicted_bad:
            culprit = "the measured twist out of scale for its sd"
        elif predicted_bad and not twist_bad:
            culprit = "the wrench (or a start spring) out of scale for the sd: C w / sd is"
        else:
            culprit = "an sd out of scale for the twist and the wrench"
        value = "overflows" if not np.isfinite(largest[m]) else f"reaches {largest[m]:.3g}"
        wrench, twist, sds = (", ".join(f"{x:.6g}" for x in v) for v in (w[m], d[m], sd[m]))
        raise InvalidInputError(
            f"measurement {m}: its weighted deflection (C w - d) / sd {value} (wrench "
            f"[{wrench}], twist [{twist}], sd [{sds}]); expected at most "
            f"{LARGEST_WEIGHTED:g}: {culprit} (SI units)"
        )


def compliance_derivative(result, coordinates, block=None) -> np.ndarray:
    """(6, 6) derivative dC/dk of a compliance with respect to one spring value k of the
    velocity coordinates ``coordinates`` (indices into v) [per N m/rad or N/m; per unit
    factor for a block].

    ``-G_c^T U G_c`` with G_c the rows ``coordinates`` of ``result.G`` and U the identity
    (a stiffness k on every coordinate) or ``block`` (the (n_c, n_c) K_0 of a factor k,
    K = k K_0): exact at a fixed configuration, for coordinates that carry a spring.
    """
    G = result.G[np.asarray(coordinates, dtype=int)]
    return -(G.T @ G) if block is None else -(G.T @ block @ G)


def _solve(evaluate, theta0: np.ndarray) -> tuple[np.ndarray, bool]:
    """(theta, success): theta0 fitted by Levenberg-Marquardt (``evaluate(theta)`` ->
    (residuals, sensitivities), computed once per theta).

    The unknowns are the offsets u from theta0, scaled by ``LOG_STEP``: the first trust
    region allows a change of about ``100 * LOG_STEP`` in log k (MINPACK's initial step
    bound is 100 times the scaled size of the start, here zero), and a step to springs
    that leave a mechanism, or that spread beyond what the general path resolves
    (:data:`closedloop.elastostatics.springs.SPREAD_RESOLVED`), is rejected as a
    step that raises the cost. The residuals carry ``PRIOR`` times u times the smallest
    singular value of S at theta0 of the directions the data see (as many as the rank of
    S with unit-norm columns, by the rank rule): the directions the data do not see stay
    at the start (no drift that would make one of two series springs vanish beside the
    other: the steps are the shortest in log k), and the others move by ~PRIOR^2, below
    1e-16 relative, whatever the spread of the sensitivities. (A prior on the largest
    singular value held a spring seen 1e10 times less than another, yet seen, at its
    start; one on each column's norm made the shortest steps those of unit-norm columns,
    a stiff spring in series then drifting to infinity.)
    """
    r0, S0 = evaluate(theta0)
    weight = PRIOR * smallest_seen(S0)
    rejected = (np.full(r0.size, REJECTED), np.zeros_like(S0))
    last = {}

    def cached(u):
        key = u.tobytes()
        if key not in last:
            last.clear()
            try:
                last[key] = evaluate(theta0 + u)
            except (MechanismError, SingularConfigurationError):
                last[key] = rejected
        return last[key]

    out = scipy.optimize.least_squares(
        lambda u: np.concatenate((cached(u)[0].ravel(), weight * u)),
        np.zeros(theta0.size),
        jac=lambda u: np.vstack((cached(u)[1], weight * np.eye(u.size))),
        method="lm",
        x_scale=np.full(theta0.size, LOG_STEP),
        xtol=1e-15,
        ftol=1e-15,
        gtol=1e-15,
    )
    return theta0 + out.x, bool(out.success)


def _common_offset(evaluate, theta0: np.ndarray, data: np.ndarray) -> np.ndarray:
    """theta0 shifted by one common log offset t that fits the scale of the data: the
    predictions are about exp(-t) times those at theta0 (exactly when the fitted springs
    carry all the compliance), so exp(-t) = <p, d> / <p, p> (weighted), repeated while it
    lowers the cost. A start far off (1e6 times) then begins at the data's scale."""
    theta, r = theta0, evaluate(theta0)[0]
    for _ in range(MAX_OFFSET_STEPS):
        p = r + data
        a = float(np.sum(p * data) / max(np.sum(p * p), 1e-300))
        if not (np.isfinite(a) and a > 0.0) or abs(np.log(a)) < 1e-12:
            break
        try:
            trial = evaluate(theta - np.log(a))[0]
        except (MechanismError, SingularConfigurationError):
            break
        if not np.sum(trial**2) < np.sum(r**2):
            break
        theta, r = theta - np.log(a), trial
    return theta
