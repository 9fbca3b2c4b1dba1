"""Points of a CaHyMan sweep: a grid of inputs or a list of poses, and the path through them.

Inputs are SI: crank angles alpha_1..3 and arm angle alpha_4 in rad, stroke s_4 in m,
design values in the units of :class:`~cahyman_pin.params.CaHyManParams`. A grid is
computed along a path of unit steps (:func:`closedloop.analysis.map_engine.path_order`) so that each
point can start from its neighbour's configuration.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from cahyman_pin.params import DEFAULT_PARAMS, CaHyManParams
from closedloop.analysis.map_engine import path_order
from closedloop.common.arrays import readonly
from closedloop.exceptions import InvalidInputError

#: Pose inputs a grid axis can sweep ("alpha": alpha_1 = alpha_2 = alpha_3 together).
POSE_AXES = ("alpha", "alpha1", "alpha2", "alpha3", "alpha4", "s4")
#: Units of the inputs (design fields: the units of CaHyManParams).
INPUT_UNITS = {"alpha": "rad", "alpha4": "rad", "s4": "m"}


def param_unit(name: str) -> str:
    """SI unit of a CaHyManParams field (see :class:`CaHyManParams`)."""
    if name in ("K_T", "K_T4"):
        return "N m/rad"
    if name.startswith("K_"):
        return "N/m"
    if name.startswith("m_"):
        return "kg"
    return "m/s^2" if name == "gravity" else "m"


def _vector(values, name: str) -> np.ndarray:
    v = np.atleast_1d(np.asarray(values, dtype=float))
    if v.ndim != 1 or v.size == 0 or not np.all(np.isfinite(v)):
        raise InvalidInputError(f"{name} must be a non-empty 1-D array of finite values")
    return v


@dataclass(frozen=True)
class SweepPoints:
    """The points of a sweep, in storage order (arrays read-only, SI).

    Attributes:
        alpha: (n, 3) crank angles alpha_1..3 [rad].
        alpha4: (n,) arm angle [rad].
        s4: (n,) telescope stroke [m].
        design: CaHyManParams field -> (n,) value [SI] at each point.
        params: parameters shared by all points (before the design values).
        shape: grid shape (product = n), or (n,) for a list.
        axes: grid axes as (name, (size,) values [SI]) in grid order; () for a list.
        order: (n,) indices of the points in execution order (the sweep path).
    """

    alpha: np.ndarray
    alpha4: np.ndarray
    s4: np.ndarray
    design: dict
    params: CaHyManParams
    shape: tuple
    axes: tuple
    order: np.ndarray

    def __len__(self) -> int:
        return len(self.alpha4)

    def params_at(self, i: int) -> CaHyManParams:
        """Parameters of point i."""
        return self.params.replace(**{k: float(v[i]) for k, v in self.design.items()})


def _check_params(params) -> CaHyManParams:
    if not isinstance(params, CaHyManParams):
        raise InvalidInputError(f"params must be a CaHyManParams, got {type(params).__name__}")
    return params


def grid(
    axes: Mapping,
    *,
    alpha=None,
    alpha4: float | None = None,
    s4: float | None = None,
    params: CaHyManParams = DEFAULT_PARAMS,
) -> SweepPoints:
    """All combinations of the values of ``axes`` (a Cartesian grid).

    Args:
        axes: name -> 1-D values [SI], in grid order. Names: ``alpha`` (alpha_1 = alpha_2 =
            alpha_3 [rad]), ``alpha1``, ``alpha2``, ``alpha3``, ``alpha4`` [rad], ``s4`` [m],
            or any field of CaHyManParams.
        alpha: (3,) crank angles [rad] where not swept.
        alpha4: arm angle [rad] where not swept.
        s4: stroke [m] where not swept.
        params: parameters where not swept.

    Raises:
        InvalidInputError: unknown or conflicting axis names, empty or non-finite values,
            or a pose input neither swept nor given.
    """
    params = _check_params(params)
    names = list(axes)
    fields = CaHyManParams.field_names()
    unknown = [a for a in names if a not in POSE_AXES and a not in fields]
    if unknown or not names:
        raise InvalidInputError(
            f"grid axes {unknown or names}; expected some of {list(POSE_AXES)} or CaHyManParams "
            f"fields {list(fields)}"
        )
    if "alpha" in names and any(a in names for a in ("alpha1", "alpha2", "alpha3")):
        raise InvalidInputError("axis 'alpha' sets alpha1 = alpha2 = alpha3: do not sweep both")
    values = [_vector(axes[a], f"axis {a!r}") for a in names]
    shape = tuple(v.size for v in values)
    mesh = dict(zip(names, (m.ravel() for m in np.meshgrid(*values, indexing="ij")), strict=True))
    n = int(np.prod(shape))
    swept_alpha = "alpha" in names or any(f"alpha{k}" in names for k in (1, 2, 3))
    if alpha is None and not ("alpha" in names or all(f"alpha{k}" in names for k in (1, 2, 3))):
        raise InvalidInputError("give alpha (3 crank angles [rad]) or sweep it")
    base = np.zeros(3) if alpha is None else np.asarray(alpha, dtype=float).reshape(-1)
    if base.shape != (3,) or not np.all(np.isfinite(base)):
        raise InvalidInputError(f"alpha must be 3 finite angles [rad], got {base.tolist()}")
    A = np.tile(base, (n, 1))
    if swept_alpha:
        for k in range(3):
            for a in ("alpha", f"alpha{k + 1}"):
                if a in mesh:
                    A[:, k] = mesh[a]
    fixed = {}
    for a, value in (("alpha4", alpha4), ("s4", s4)):
        if a in mesh:
            fixed[a] = mesh[a]
        elif value is None:
            raise InvalidInputError(f"give {a} [{INPUT_UNITS[a]}] or sweep it")
        else:
            v = _vector(value, a)
            if v.size != 1:
                raise InvalidInputError(f"{a} must be one value [{INPUT_UNITS[a]}] or a grid axis")
            fixed[a] = np.full(n, v[0])
    design_axes = [a for a in names if a in fields]
    return SweepPoints(
        alpha=readonly(A),
        alpha4=readonly(fixed["alpha4"]),
        s4=readonly(fixed["s4"]),
        design={a: readonly(mesh[a]) for a in design_axes},
        params=params,
        shape=shape,
        axes=tuple((a, readonly(v)) for a, v in zip(names, values, strict=True)),
        order=path_order(shape, [names.index(a) for a in design_axes]),
    )


def pose_list(
    alpha, alpha4, s4, *, design: Mapping | None = None, params: CaHyManParams = DEFAULT_PARAMS
) -> SweepPoints:
    """An explicit list of n points, computed in the given order (a path).

    Args:
        alpha: (n, 3) crank angles [rad]; alpha4: (n,) arm angles [rad]; s4: (n,) strokes
            [m] (alpha4 and s4 may be scalars).
        design: CaHyManParams field -> (n,) values [SI] (optional).
        params: parameters of every point (before the design values).
    """
    params = _check_params(params)
    A = np.atleast_2d(np.asarray(alpha, dtype=float))
    if A.ndim != 2 or A.shape[1] != 3 or A.shape[0] == 0:
        raise InvalidInputError(f"alpha must have shape (n, 3) [rad], got {np.shape(alpha)}")
    n = A.shape[0]
    design = dict(design or {})
    unknown = sorted(set(design) - set(CaHyManParams.field_names()))
    if unknown:
        raise InvalidInputError(
            f"unknown design field(s) {unknown}; expected CaHyManParams fields "
            f"{list(CaHyManParams.field_names())}"
        )
    columns = {"alpha4": alpha4, "s4": s4, **design}
    try:
        columns = {k: np.broadcast_to(np.asarray(v, dtype=float), (n,)) for k, v in columns.items()}
    except ValueError as err:
        raise InvalidInputError(f"every input must have {n} values (one per point)") from err
    return SweepPoints(
        alpha=readonly(A),
        alpha4=readonly(columns.pop("alpha4")),
        s4=readonly(columns.pop("s4")),
        design={k: readonly(v) for k, v in columns.items()},
        params=params,
        shape=(n,),
        axes=(),
        order=path_order((n,), []),
    )


__all__ = [
    "INPUT_UNITS",
    "POSE_AXES",
    "SweepPoints",
    "grid",
    "param_unit",
    "pose_list",
]
