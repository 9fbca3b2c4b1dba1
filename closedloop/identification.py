"""Elastostatic identification: joint spring stiffnesses fitted to measured deflections.

Each measurement is a configuration (full q, or the actuated values to assemble), a
wrench w (6,) applied at a frame (fx, fy, fz [N], nx, ny, nz [N m], world axes, at the
frame origin) and the measured twist of that frame d (6,) (dx, dy, dz [m], rx, ry, rz
[rad]) with its standard deviation sd (6,) (same units). The model predicts d = C(k) w
(:func:`closedloop.compliance.compliance`); the fitted parameters are spring stiffnesses
k_g, one per group of joints tied to one value, found by weighted nonlinear least squares

    min_theta  sum_m |(C_m(k) w_m - d_m) / sd_m|^2,   k_g = exp(theta_g)

(``scipy.optimize.least_squares``, in log space: k stays positive and the problem is
scale-free). The derivatives are analytic: at a fixed configuration the compliance
depends on a spring coordinate i only through K_r, and

    dC/dk_i = -g_i g_i^T,   g_i = (row i of G)^T,

with G (nv, 6) the joint deflection per wrench (``ComplianceResult.G``), so that
d(C w)/d theta_g = -k_g sum_{i in g} (g_i . w) g_i.

Standard errors come from the covariance (S^T S)^-1 of theta at the solution (S the
sensitivity matrix of the weighted residuals: the sd are taken as known), by the delta
method se(k) = k se(theta). A parameter the data cannot identify (its column of S, or a
combination of columns, below the rank rule of :mod:`closedloop.conditioning`) is named
in ``unidentifiable`` and kept at its starting value, never given an arbitrary one.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.optimize
import yaml

from .arrays import check_wrench, readonly
from .assembly import assemble
from .compliance import compliance
from .conditioning import RANK_RTOL, rule_rank
from .exceptions import InvalidInputError, ModelFileError
from .model import ClosedLoopModel

#: Relative share of a null vector of S above which a parameter takes part in it.
NULL_SHARE = 0.1


@dataclass(frozen=True)
class Measurement:
    """One measured deflection (arrays read-only, SI).

    Attributes:
        q: (nq,) configuration, or None when ``actuated`` is given.
        actuated: (n_act,) actuated joint values [rad, m] to assemble, or None.
        wrench: (6,) applied wrench (fx, fy, fz [N], nx, ny, nz [N m]), world axes.
        twist: (6,) measured twist (dx, dy, dz [m], rx, ry, rz [rad]), world axes.
        sd: (6,) standard deviation of the twist, > 0 (same units).
    """

    q: np.ndarray | None
    actuated: np.ndarray | None
    wrench: np.ndarray
    twist: np.ndarray
    sd: np.ndarray

    @classmethod
    def of(cls, *, wrench, twist, sd, q=None, actuated=None) -> Measurement:
        """A validated measurement (see the attributes).

        Raises:
            InvalidInputError: wrong shapes, NaN, sd <= 0, neither or both of q/actuated.
        """
        if (q is None) == (actuated is None):
            raise InvalidInputError("a measurement needs exactly one of q and actuated")
        twist_ = np.asarray(twist, dtype=float).reshape(-1)
        if twist_.shape != (6,) or not np.all(np.isfinite(twist_)):
            raise InvalidInputError(
                f"measured twist must be 6 finite values (dx dy dz [m], rx ry rz [rad]), "
                f"got {np.asarray(twist).tolist()}"
            )
        sd_ = np.broadcast_to(np.asarray(sd, dtype=float), (6,)) if np.ndim(sd) == 0 else sd
        sd_ = np.asarray(sd_, dtype=float).reshape(-1)
        if sd_.shape != (6,) or not np.all(np.isfinite(sd_)) or np.any(sd_ <= 0.0):
            raise InvalidInputError(
                f"sd must be one or 6 finite values > 0 (units of the twist), got "
                f"{np.asarray(sd).tolist()}"
            )
        vector = None if q is None else readonly(np.asarray(q, dtype=float).reshape(-1))
        act = None if actuated is None else readonly(np.asarray(actuated, float).reshape(-1))
        return cls(vector, act, readonly(check_wrench(wrench)), readonly(twist_), readonly(sd_))


def read_measurements(path: str | Path) -> tuple[str, list[Measurement]]:
    """(frame, measurements) from a YAML file (module docstring; keys ``frame`` and
    ``measurements``, each with ``q`` or ``actuated``, ``wrench``, ``twist``, ``sd``).

    Raises:
        ModelFileError: missing or unreadable file, wrong structure.
        InvalidInputError: a bad measurement (its index is named).
    """
    try:
        doc = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as e:
        raise ModelFileError(f"cannot read measurement file {str(path)!r}: {e}") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("frame"), str):
        raise ModelFileError(f"{str(path)!r}: expected a mapping with 'frame' and 'measurements'")
    items = doc.get("measurements")
    if not isinstance(items, list) or not items:
        raise ModelFileError(f"{str(path)!r}: 'measurements' must be a non-empty list")
    out = []
    for i, item in enumerate(items):
        keys = {"q", "actuated", "wrench", "twist", "sd"}
        if not isinstance(item, dict) or not set(item) <= keys:
            raise ModelFileError(f"{str(path)!r}: measurement {i} must be a mapping of {keys}")
        try:
            out.append(Measurement.of(**{k: _number(v) for k, v in item.items()}))
        except (InvalidInputError, TypeError, ValueError) as e:
            raise InvalidInputError(f"measurement {i} of {str(path)!r}: {e}") from None
    return doc["frame"], out


def _number(value):
    """YAML 1.1 reads 1e-6 as a string: numbers, and lists of them, as floats."""
    if isinstance(value, list):
        return [_number(v) for v in value]
    return float(value) if isinstance(value, str) else value


@dataclass(frozen=True)
class Fit:
    """Result of :func:`identify` (SI: N m/rad or N/m per parameter).

    Attributes:
        names: parameter names (a group "a+b" for joints tied to one value).
        estimates: name -> fitted stiffness, or None when unidentifiable.
        std_errors: name -> standard error, or None when unidentifiable.
        correlations: (p, p) correlation matrix of the identified log-stiffnesses, in the
            order of ``names`` (NaN rows for unidentifiable ones are not kept: rows and
            columns follow ``identified``).
        identified: names of the identified parameters, in order.
        unidentifiable: names the data cannot identify (kept at their start values).
        residuals: (n, 6) weighted residuals (C w - d) / sd at the solution.
        residual_rms: RMS of the weighted residuals (about 1 for consistent data).
        n_measurements: number of measurements.
        success: whether the optimiser reports convergence.
    """

    names: tuple[str, ...]
    estimates: dict
    std_errors: dict
    correlations: np.ndarray
    identified: tuple[str, ...]
    unidentifiable: tuple[str, ...]
    residuals: np.ndarray
    residual_rms: float
    n_measurements: int
    success: bool

    def to_dict(self) -> dict:
        """JSON-ready summary."""
        return {
            "estimates": self.estimates,
            "std_errors": self.std_errors,
            "identified": list(self.identified),
            "unidentifiable": list(self.unidentifiable),
            "correlations": self.correlations.tolist(),
            "residual_rms": self.residual_rms,
            "residuals": self.residuals.tolist(),
            "n_measurements": self.n_measurements,
            "success": self.success,
        }


def _spring_spec(clm: ClosedLoopModel) -> tuple[dict, list[str]]:
    """(springs, locked) that rebuild ``clm.stiffness`` through ``with_springs``."""
    springs, locked = {}, []
    for j in range(1, clm.model.njoints):
        jm = clm.model.joints[j]
        k = clm.stiffness[jm.idx_v : jm.idx_v + jm.nv]
        name = clm.model.names[j]
        if k.size and np.all(np.isinf(k)):
            locked.append(name)
        elif np.any(k > 0.0):
            springs[name] = k.tolist()
    return springs, locked


def _groups(clm: ClosedLoopModel, fit) -> list[tuple[str, ...]]:
    groups = []
    for item in fit:
        group = (item,) if isinstance(item, str) else tuple(item)
        if not group or not all(isinstance(n, str) for n in group):
            raise InvalidInputError(f"a fitted parameter is a joint name or a group, got {item!r}")
        for name in group:
            clm.joint_id(name)  # NameNotFoundError listing the joints
        groups.append(group)
    seen = [n for g in groups for n in g]
    if len(set(seen)) != len(seen):
        raise InvalidInputError(f"a joint appears in two fitted parameters: {seen}")
    return groups


def identify(
    clm: ClosedLoopModel,
    measurements: Sequence[Measurement],
    frame: str,
    fit: Sequence[str | Sequence[str]],
    *,
    start: Mapping[str, float] | None = None,
) -> Fit:
    """Fit spring stiffnesses to measured deflections (see the module docstring).

    Args:
        clm: the model; its springs are the start values (and the values of the springs
            not fitted).
        measurements: the data (:class:`Measurement`).
        frame: the loaded and measured frame.
        fit: joint names, or groups of names tied to one value (one spring value per
            group, applied to every velocity coordinate of its joints).
        start: group name ("a+b" for a group) -> start value [N m/rad or N/m], overriding
            the model's.

    Raises:
        InvalidInputError: no parameter, an unknown one, a parameter without a start
            value > 0, fewer measured components than parameters.
        NameNotFoundError: unknown joint or frame.
    """
    groups = _groups(clm, fit)
    if not groups:
        raise InvalidInputError("nothing to fit: give at least one joint name")
    names = tuple("+".join(g) for g in groups)
    if not measurements or not all(isinstance(m, Measurement) for m in measurements):
        raise InvalidInputError("measurements must be a non-empty list of Measurement")
    if 6 * len(measurements) < len(groups):
        raise InvalidInputError(
            f"{6 * len(measurements)} measured components for {len(groups)} parameters"
        )
    springs, locked = _spring_spec(clm)
    theta0 = np.empty(len(groups))
    for i, (name, group) in enumerate(zip(names, groups, strict=True)):
        value = (start or {}).get(name)
        if value is None:
            k = clm.stiffness[clm.joint_v_slice(group[0])]
            value = float(k[0]) if k.size else 0.0
        if not (np.isfinite(value) and value > 0.0):
            raise InvalidInputError(
                f"parameter {name!r} needs a start value > 0 [N m/rad or N/m], got {value}"
            )
        theta0[i] = np.log(value)
    configs = [m.q if m.q is not None else assemble(clm, m.actuated).q for m in measurements]
    w = np.array([m.wrench for m in measurements])
    d = np.array([m.twist for m in measurements])
    sd = np.array([m.sd for m in measurements])

    coords = [
        np.concatenate([np.arange(clm.model.nv)[clm.joint_v_slice(n)] for n in g]) for g in groups
    ]

    def evaluate(theta):
        values = {n: float(np.exp(t)) for g, t in zip(groups, theta, strict=True) for n in g}
        model = clm.with_springs({**springs, **values}, [n for n in locked if n not in values])
        pred, sens = np.empty((len(configs), 6)), np.empty((len(configs), 6, len(groups)))
        for m, q in enumerate(configs):
            res = compliance(model, q, frame)
            pred[m] = res.C @ w[m]
            for c, rows in enumerate(coords):
                sens[m, :, c] = np.exp(theta[c]) * (compliance_derivative(res, rows) @ w[m])
        return (pred - d) / sd, sens / sd[:, :, None]

    _, S0 = evaluate(theta0)
    unidentifiable = _unidentifiable(S0.reshape(-1, len(groups)), names)
    free = [i for i, n in enumerate(names) if n not in unidentifiable]
    theta = theta0.copy()
    success = True
    if free:
        out = scipy.optimize.least_squares(
            lambda t: evaluate(_put(theta0, free, t))[0].ravel(),
            theta0[free],
            jac=lambda t: evaluate(_put(theta0, free, t))[1].reshape(-1, len(groups))[:, free],
            method="lm" if 6 * len(configs) >= len(free) else "trf",
            xtol=1e-15,
            ftol=1e-15,
            gtol=1e-15,
        )
        theta, success = _put(theta0, free, out.x), bool(out.success)
    r, S = evaluate(theta)
    Sf = S.reshape(-1, len(groups))[:, free]
    cov = np.linalg.inv(Sf.T @ Sf) if free else np.zeros((0, 0))
    se = np.sqrt(np.diag(cov))
    corr = cov / np.outer(se, se) if free else cov
    k = np.exp(theta)
    estimates = {n: (float(k[i]) if i in free else None) for i, n in enumerate(names)}
    ses = dict.fromkeys(names)
    for j, i in enumerate(free):
        ses[names[i]] = float(k[i] * se[j])
    return Fit(
        names=names,
        estimates=estimates,
        std_errors=ses,
        correlations=readonly(corr),
        identified=tuple(names[i] for i in free),
        unidentifiable=tuple(unidentifiable),
        residuals=readonly(r),
        residual_rms=float(np.sqrt(np.mean(r**2))),
        n_measurements=len(configs),
        success=success,
    )


def compliance_derivative(result, coordinates) -> np.ndarray:
    """(6, 6) derivative dC/dk of a compliance with respect to one spring value k shared
    by the velocity coordinates ``coordinates`` (indices into v) [per N m/rad or N/m].

    ``-sum_i g_i g_i^T`` with g_i the row i of ``result.G``: exact at a fixed
    configuration, for coordinates that carry a spring (0 < k < inf).
    """
    G = result.G[np.asarray(coordinates, dtype=int)]
    return -(G.T @ G)


def _put(base: np.ndarray, idx: list[int], values: np.ndarray) -> np.ndarray:
    out = base.copy()
    out[idx] = values
    return out


def _unidentifiable(S: np.ndarray, names: tuple[str, ...]) -> list[str]:
    """Names that take part in a null direction of S (columns scaled to unit norm; the
    rank rule), or whose column vanishes."""
    norms = np.linalg.norm(S, axis=0)
    dead = norms <= RANK_RTOL * max(norms.max(initial=0.0), 1e-300)
    out = {names[i] for i in np.flatnonzero(dead)}
    live = np.flatnonzero(~dead)
    if live.size:
        _, s, Vt = np.linalg.svd(S[:, live] / norms[live], full_matrices=True)
        r = rule_rank(s)
        for v in Vt[r:]:
            out |= {names[live[i]] for i in np.flatnonzero(np.abs(v) > NULL_SHARE)}
    return sorted(out, key=names.index)
