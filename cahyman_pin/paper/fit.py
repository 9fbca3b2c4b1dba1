"""Least-squares fits of CaHyMan's stiffnesses, or of its assumed dimensions, to the tables.

Both fits minimise the weighted sum of squares chi^2 = sum_q ((m_q - p_q) / sd_q)^2 over
the 48 compared quantities of :mod:`cahyman_pin.paper.cells` (m_q: consistent model, in
the paper's coordinates; p_q: published; sd_q: rounding and relative error), with
``scipy.optimize.least_squares`` in log space (every value stays positive) within bounds:

* stiffnesses: K_T, K_b = K_d (tied), K_T4, K_s, K_4 between 1/:data:`STIFFNESS_RANGE`
  and :data:`STIFFNESS_RANGE` times their reference values. The compliance is linear in
  the spring compliances 1/K, so on the linear quantities (all but the tilt) the problem
  is a non-negative least squares in the compliances, convex: :func:`linear_optimum`
  solves it globally, and the fit starts from that solution as well as from the
  reference values;
* dimensions: the lengths flagged assumed in :data:`cahyman_pin.params.SOURCES`, between
  1/:data:`DIMENSION_RANGE` and :data:`DIMENSION_RANGE` times their reference values,
  springs at their reference values.

Fits are cached per parameter set and published values (in memory).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.optimize

from cahyman_pin.paper.cells import (
    RELATIVE_ERROR,
    model_values,
    published_values,
    quantities,
    standard_deviations,
)
from cahyman_pin.params import SOURCES, CaHyManParams
from closedloop.common.conditioning import rule_rank
from closedloop.exceptions import ClosedLoopError

#: Fitted stiffness groups (name -> the parameters tied to one value).
STIFFNESS_GROUPS = {
    "K_T": ("K_T",),
    "K_b = K_d": ("K_b", "K_d"),
    "K_T4": ("K_T4",),
    "K_s": ("K_s",),
    "K_4": ("K_4",),
}
#: The assumed dimensions (SOURCES says the paper gives none).
DIMENSIONS = tuple(n for n in CaHyManParams.field_names() if SOURCES[n].endswith("no dimensions"))
#: Bounds of the stiffness fit: reference / range .. reference * range.
STIFFNESS_RANGE = 1e6
#: Bounds of the dimension fit: reference / range .. reference * range.
DIMENSION_RANGE = 2.0
#: Relative tolerance of the fits on the cost, the step and the gradient (the cells are
#: printed to 2 or 3 digits).
FIT_TOL = 1e-8
#: Evaluation limit of each trust-region search of the dimension fit. Its cost has a flat
#: valley (a and h act almost alike) that runs towards the bounds, where scipy's trf and
#: dogbox crawl: measured, 200, 1000 and 2000 evaluations lower chi^2 from 4492 (60) to
#: 4462, 4449 and 4447 without converging. An active-set polish of the result converges
#: instead (measured: 1.1 s in all at the report's parameters, to a local optimum).
DIMENSION_EVALUATIONS = 60
#: Singular values of the weighted sensitivity below this share of the largest: not
#: identified (the rank rule of closedloop.common.conditioning, on a well-scaled matrix).
IDENTIFIABLE_RTOL = 1e-6
#: Distance in log space from a bound below which the active set puts a value on it.
SNAP = 1e-3
#: Rounds of the active set (measured: 2 suffice at the report's parameters).
POLISH_ROUNDS = 4
#: Inward step in log space of the optimality check at a bound.
KKT_STEP = 1e-4
#: Weighted residual of every quantity where the machine cannot be assembled (a cost far
#: above any assembled one, so that the trust region refuses the step).
UNASSEMBLED = 1e4
#: Distance from a bound, as a share of the log-space range, below which a fitted value is
#: on that bound (the fits stop at 1e-8 of the step: a value that close has met it).
AT_BOUND = 1e-6
#: Relative share of a null vector above which a parameter takes part in it.
NULL_SHARE = 0.1


@dataclass(frozen=True)
class FitResult:
    """One fit (values SI).

    Attributes:
        names: fitted names (stiffness groups or dimensions).
        reference: name -> value before the fit [N/m, N m/rad or m].
        estimates: name -> fitted value.
        at_bound: name -> "lower", "upper" or "" (a value on its bound is not determined
            by the data beyond "at least / at most").
        params: the fitted parameter set.
        values: (48,) model values at the fit [mm or deg], in :func:`quantities` order.
        residuals: (48,) values minus published [mm or deg].
        chi2: weighted sum of squares at the fit.
        chi2_reference: weighted sum of squares at the reference values.
        rank: rank of the weighted sensitivity (log space) of the free parameters.
        unidentifiable: names in the null space of that sensitivity, or acting on no
            quantity.
        converged: False when the fit stopped at its evaluation limit (a flat valley);
            for the dimension fit, True only at a local optimum (its active-set polish
            converged).
    """

    names: tuple[str, ...]
    reference: dict[str, float]
    estimates: dict[str, float]
    at_bound: dict[str, str]
    params: CaHyManParams
    values: np.ndarray
    residuals: np.ndarray
    chi2: float
    chi2_reference: float
    rank: int
    unidentifiable: tuple[str, ...]
    converged: bool


def _apply(params: CaHyManParams, groups: dict[str, tuple[str, ...]], x) -> CaHyManParams:
    return params.replace(
        **{p: float(v) for g, v in zip(groups.values(), x, strict=True) for p in g}
    )


def _weighted(params, groups, published, sd):
    def f(theta):
        try:
            return (model_values(_apply(params, groups, np.exp(theta))) - published) / sd
        except ClosedLoopError:  # the plate cannot be assembled: a step to refuse
            return np.full(len(published), UNASSEMBLED)

    return f


def _linear_basis(params: CaHyManParams, groups) -> tuple[np.ndarray, np.ndarray]:
    """(B (48, n), c (n,)): model values = B c, c the group compliances 1/K [SI]. Exact
    for a linear function: the column is the change when the compliance doubles."""
    k = np.array([getattr(params, g[0]) for g in groups.values()])
    base = model_values(params)
    cols = []
    for i in range(len(k)):
        x = k.copy()
        x[i] /= 2.0
        cols.append((model_values(_apply(params, groups, x)) - base) * k[i])
    return np.column_stack(cols), 1.0 / k


def linear_optimum(
    params: CaHyManParams, relative_error: float = RELATIVE_ERROR
) -> tuple[dict[str, float], float, float]:
    """Global least-squares optimum over the linear quantities of the stiffness groups.

    Args:
        relative_error: of the weights (:func:`~cahyman_pin.paper.cells.standard_deviations`;
            0: the rounding alone, millimetres and degrees taken as alike).

    Returns:
        (name -> stiffness [SI], inf where the compliance is 0: rigid), its chi^2 over the
        linear quantities, and the chi^2 there of a rigid machine (every value 0).
    """
    k, chi2, chi2_rigid, _ = _nnls(params, relative_error)
    return k, chi2, chi2_rigid


def linear_optimum_values(params: CaHyManParams, relative_error: float = RELATIVE_ERROR):
    """(48,) the quantities at :func:`linear_optimum` [mm or deg], NaN at the tilts."""
    return _nnls(params, relative_error)[3]


@lru_cache(maxsize=8)
def _nnls(params: CaHyManParams, relative_error: float):
    qs = quantities(params)
    lin = np.array([q.linear for q in qs])
    sd = standard_deviations(params, relative_error)[lin]
    p = published_values(params)[lin]
    B, c0 = _linear_basis(params, STIFFNESS_GROUPS)
    # columns scaled by the reference compliances: a well-conditioned NNLS
    c, norm = scipy.optimize.nnls(B[lin] * c0 / sd[:, None], p / sd)
    k = {n: (1.0 / (ci * c0i) if ci > 0 else np.inf) for n, ci, c0i in
         zip(STIFFNESS_GROUPS, c, c0, strict=True)}  # fmt: skip
    values = np.full(len(qs), np.nan)
    values[lin] = B[lin] @ (c * c0)
    return k, float(norm**2), float(np.sum((p / sd) ** 2)), values


def _inactive(f, x: np.ndarray) -> np.ndarray:
    """(n,) True for a parameter that changes no quantity (central differences in log
    space, step 1e-3, against 1e-9 of the largest column)."""
    cols = []
    for i in range(len(x)):
        e = np.zeros(len(x))
        e[i] = 1e-3
        cols.append(np.linalg.norm(f(x + e) - f(x - e)))
    cols = np.array(cols)
    return cols <= 1e-9 * cols.max()


def _jacobian(f, x: np.ndarray, step: float = 1e-6) -> np.ndarray:
    """(m, n) central differences of f in log space (step 1e-6: truncation ~1e-12)."""
    cols = []
    for i in range(len(x)):
        e = np.zeros(len(x))
        e[i] = step
        cols.append((f(x + e) - f(x - e)) / (2 * step))
    return np.column_stack(cols)


def _polish(f, x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, bool]:
    """Active set after a capped trust-region search: values within :data:`SNAP` of a
    bound are put on it, the others fitted to convergence (a free value that reaches a
    bound is put on it in the next round); up to :data:`POLISH_ROUNDS` rounds. Converged
    when the free fit converges away from the bounds and every value on a bound
    satisfies the optimality condition there (chi^2 rises when it moves inwards,
    one-sided differences of :data:`KKT_STEP`); otherwise a capped search over all
    values starts the next round. A local optimum: the valley may hold others.

    Returns:
        (x, converged).
    """
    for _ in range(POLISH_ROUNDS):
        x = np.where(x - lo < SNAP, lo, np.where(hi - x < SNAP, hi, x))
        free = (x > lo) & (x < hi)
        ok = True
        if free.any():

            def g(y, x=x, free=free):
                z = x.copy()
                z[free] = y
                return f(z)

            r = scipy.optimize.least_squares(
                g, x[free], bounds=(lo[free], hi[free]), x_scale="jac", xtol=FIT_TOL,
                ftol=FIT_TOL, gtol=FIT_TOL, max_nfev=DIMENSION_EVALUATIONS,
            )  # fmt: skip
            x = x.copy()
            x[free] = r.x
            ok = r.status > 0
            if np.any(free & ((x - lo < SNAP) | (hi - x < SNAP))):
                continue  # a free value reached a bound: the next round puts it there
        chi2 = np.sum(f(x) ** 2)
        inward = []
        for i in np.flatnonzero(~free):
            y = x.copy()
            y[i] += KKT_STEP if x[i] == lo[i] else -KKT_STEP
            inward.append(np.sum(f(y) ** 2) >= chi2)
        if ok and all(inward):
            return x, True
        x = scipy.optimize.least_squares(
            f, x, bounds=(lo, hi), x_scale="jac", xtol=FIT_TOL, ftol=FIT_TOL, gtol=FIT_TOL,
            max_nfev=DIMENSION_EVALUATIONS,
        ).x  # fmt: skip
    return x, False


def _fit(
    params: CaHyManParams, groups, ratio: float, starts, max_nfev=None, polish=False
) -> FitResult:
    published, sd = published_values(params), standard_deviations(params)
    names = list(groups)
    ref = np.array([getattr(params, g[0]) for g in groups.values()])
    f_all = _weighted(params, groups, published, sd)
    inactive = _inactive(f_all, np.log(ref))
    act = [n for n, i in zip(names, inactive, strict=True) if not i]
    if not act:  # no value changes any quantity (e.g. a machine far stiffer than the
        # tables, every cell ~0 in their units): nothing to fit, every value unidentifiable
        kept = dict(zip(names, map(float, ref), strict=True))
        values = model_values(params)
        chi2 = float(np.sum(f_all(np.log(ref)) ** 2))
        return FitResult(tuple(names), kept, dict(kept), dict.fromkeys(names, ""), params,
                         values, values - published, chi2, chi2, 0, tuple(names), True)  # fmt: skip
    sub = {n: groups[n] for n in act}
    ref_act = ref[~inactive]
    lo, hi = np.log(ref_act / ratio), np.log(ref_act * ratio)
    f = _weighted(params, sub, published, sd)
    best = None
    for start in starts:
        x0 = np.clip(np.log(np.asarray(start)[~inactive]), lo + 1e-9, hi - 1e-9)
        r = scipy.optimize.least_squares(f, x0, bounds=(lo, hi), x_scale="jac", xtol=FIT_TOL,
                                         ftol=FIT_TOL, gtol=FIT_TOL, max_nfev=max_nfev)  # fmt: skip
        if best is None or r.cost < best.cost:
            best = r
    x_best, jac, converged = best.x, best.jac, best.status > 0
    if polish:
        x_best, converged = _polish(f, best.x, lo, hi)
        jac = _jacobian(f, x_best)
    fitted = _apply(params, sub, np.exp(x_best))
    values = model_values(fitted)
    span = hi - lo
    bound = dict.fromkeys(names, "")
    bound.update({n: ("lower" if x - a < AT_BOUND * s else "upper" if b - x < AT_BOUND * s else "")
                  for n, x, a, b, s in zip(act, x_best, lo, hi, span, strict=True)})  # fmt: skip
    free = [i for i, n in enumerate(act) if not bound[n]]
    rank, unident = 0, [n for n, i in zip(names, inactive, strict=True) if i]
    if free:
        _, s, Vt = np.linalg.svd(jac[:, free], full_matrices=False)
        rank = rule_rank(s, IDENTIFIABLE_RTOL)
        null = Vt[rank:]
        unident += [
            act[free[i]] for i in range(len(free)) if np.any(np.abs(null[:, i]) > NULL_SHARE)
        ]
    est = {n: float(getattr(fitted, groups[n][0])) for n in names}
    return FitResult(
        tuple(names), dict(zip(names, map(float, ref), strict=True)), est, bound, fitted, values,
        values - published, float(np.sum(f(x_best) ** 2)),
        float(np.sum(f_all(np.log(ref)) ** 2)), rank, tuple(unident), converged,
    )  # fmt: skip


@lru_cache(maxsize=4)
def _stiffness_fit(params: CaHyManParams, published: tuple[float, ...]) -> FitResult:
    k_lin, _, _ = linear_optimum(params)
    ref = np.array([getattr(params, g[0]) for g in STIFFNESS_GROUPS.values()])
    nnls = np.array([min(k, STIFFNESS_RANGE * r) for k, r in zip(k_lin.values(), ref, strict=True)])
    return _fit(params, STIFFNESS_GROUPS, STIFFNESS_RANGE, (ref, nnls))


@lru_cache(maxsize=4)
def _dimension_fit(params: CaHyManParams, published: tuple[float, ...]) -> FitResult:
    groups = {n: (n,) for n in DIMENSIONS}
    ref = np.array([getattr(params, n) for n in DIMENSIONS])
    return _fit(params, groups, DIMENSION_RANGE, (ref,), DIMENSION_EVALUATIONS, polish=True)


def stiffness_fit(params: CaHyManParams) -> FitResult:
    """The best stiffness values (:data:`STIFFNESS_GROUPS`), dimensions at ``params``."""
    return _stiffness_fit(params, tuple(published_values(params)))


def dimension_fit(params: CaHyManParams) -> FitResult:
    """The best assumed dimensions (:data:`DIMENSIONS`), springs at ``params``."""
    return _dimension_fit(params, tuple(published_values(params)))


#: Relative change of each assumed dimension in the sensitivity study.
SENSITIVITY_STEP = 0.2
#: Change of a cell [mm or deg] below which a dimension is said to change no cell (the
#: closed form's rounding is about 1e-15 of the cells).
IDLE_CHANGE = 1e-12


def dimension_sensitivity(params: CaHyManParams) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Change of every quantity when one assumed dimension changes by -+20 %.

    Returns:
        ``{dimension: (change at -20 % (48,), change at +20 % (48,))}`` [mm or deg], in
        :func:`~cahyman_pin.paper.cells.quantities` order; NaN where the machine cannot be
        assembled.
    """
    base = model_values(params)
    out = {}
    for name in DIMENSIONS:
        pair = []
        for factor in (1.0 - SENSITIVITY_STEP, 1.0 + SENSITIVITY_STEP):
            try:
                v = model_values(params.replace(**{name: factor * getattr(params, name)}))
            except ClosedLoopError:
                v = np.full(len(base), np.nan)
            pair.append(v - base)
        out[name] = (pair[0], pair[1])
    return out
