"""Statistics of a weighted least-squares fit (:mod:`closedloop.analysis.identification`)
from its weighted residuals r (n, 6) and sensitivities S (6 n, p) at the solution: the
rank of S and the parameters it does not see
(:func:`~closedloop.analysis.fit_statistics.null_directions`), the covariance of the
parameters (:func:`~closedloop.analysis.fit_statistics.covariance`), and the largest
residual RMS that the chi-square test of the fit accepts
(:func:`~closedloop.analysis.fit_statistics.chi_square_rms_limit`).
"""

from __future__ import annotations

import numpy as np
import scipy.special

from closedloop.common.conditioning import rule_rank

#: Relative share of a null vector of S above which a parameter takes part in it.
NULL_SHARE = 0.1
#: A column of S below this share of the largest is rounding (the parameter is not seen):
#: the rank rule's RANK_RTOL^2, its threshold on eigenvalue ratios. A column above
#: it, however small, stays in the rank test: a stiff spring in series with a soft one is
#: confounded with it, not "not seen" while the soft one is "identified".
DEAD_RTOL = 1e-14
#: Significance of the chi-square test of the fit (:mod:`closedloop.analysis.identification`):
#: a data set that the model fits, with Gaussian errors of the stated sd, is flagged once
#: in a million fits.
#: This small a value flags what the sd cannot explain (an RMS above 1.5 from 50
#: components, above 1.11 from 1000), not a few outliers or sd known to within 10 %.
FIT_SIGNIFICANCE = 1e-6


def chi_square_rms_limit(r: np.ndarray, S: np.ndarray, rank: int) -> float | None:
    """Largest weighted residual RMS of r (n, 6) that the chi-square test at
    :data:`FIT_SIGNIFICANCE` accepts, S (6 n, p) of rank ``rank``; None when no degree of
    freedom is left.

    The components that carry no noise are not counted: those whose sensitivities vanish
    and whose residual is exactly zero (a planar mechanism's out-of-plane twist, zero in
    the model whatever the springs and measured as 0): their residual is 0 for any fit,
    and counting them would loosen the test. The limit is then on the RMS over all n 6
    components, as ``Fit.residual_rms``.
    """
    flat = r.reshape(-1)
    noisy = int(np.count_nonzero((flat != 0.0) | np.any(S != 0.0, axis=1)))
    dof = noisy - rank
    if dof <= 0:
        return None
    return float(np.sqrt(scipy.special.chdtri(dof, FIT_SIGNIFICANCE) / flat.size))


def smallest_seen(S: np.ndarray) -> float:
    """Smallest singular value of S (6 n, p) among its rank(S) largest, the rank by the
    rule on unit-norm columns (:func:`null_directions`); 0 when S sees nothing."""
    rank = null_directions(S, tuple(map(str, range(S.shape[1]))))[2]
    return float(np.linalg.svd(S, compute_uv=False)[rank - 1]) if rank else 0.0


def covariance(S: np.ndarray) -> np.ndarray:
    """(p, p) covariance of theta, (S^T S)^+ by the rank rule on S with unit-norm columns
    (an SVD: no squared condition). Its rows of the parameters outside every null
    direction are their covariance; the other rows (vanishing columns: zero) are not used.
    """
    norms = np.linalg.norm(S, axis=0)
    live = norms > 0.0
    cov = np.zeros((S.shape[1], S.shape[1]))
    if live.any():
        _, s, Vt = np.linalg.svd(S[:, live] / norms[live], full_matrices=False)
        root = Vt[: rule_rank(s)].T / s[: rule_rank(s)]
        cov[np.ix_(live, live)] = (root @ root.T) / np.outer(norms[live], norms[live])
    return cov


def null_directions(S: np.ndarray, names: tuple[str, ...]) -> tuple[list[str], list[tuple], int]:
    """(names, confounded, rank): the names whose column of S vanishes or that take part
    in a null direction of S (columns scaled to unit norm; the rank rule), the names of
    each null direction, and the rank of S by that rule."""
    norms = np.linalg.norm(S, axis=0)
    dead = norms <= DEAD_RTOL * max(norms.max(initial=0.0), 1e-300)
    out = {names[i] for i in np.flatnonzero(dead)}
    live = np.flatnonzero(~dead)
    confounded, rank = [], 0
    if live.size:
        _, s, Vt = np.linalg.svd(S[:, live] / norms[live], full_matrices=True)
        rank = rule_rank(s)
        for v in Vt[rank:]:
            part = tuple(sorted((names[live[i]] for i in np.flatnonzero(np.abs(v) > NULL_SHARE)),
                                key=names.index))  # fmt: skip
            confounded.append(part)
            out |= set(part)
    return sorted(out, key=names.index), confounded, rank
