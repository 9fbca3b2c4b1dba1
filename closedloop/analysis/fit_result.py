"""The result of an identification (:func:`closedloop.analysis.identification.identify`):
estimates, their errors and correlations, the residuals and the test of the fit."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Fit:
    """Result of :func:`closedloop.analysis.identification.identify` (SI: N m/rad or N/m
    per stiffness, 1 per block factor).

    Attributes:
        names: parameter names (a group "a+b" for joints tied to one value).
        estimates: name -> fitted value, or None when unidentifiable.
        std_errors: name -> standard error, or None when unidentifiable.
        correlations: (n_id, n_id) correlation matrix of the identified log-values
            (n_id = len(identified)), rows and columns in the order of ``identified``.
        identified: names of the identified parameters, in order.
        unidentifiable: names the data cannot identify (estimate and error None).
        confounded: the names taking part in each null direction of the sensitivities.
        residuals: (n, 6) weighted residuals (C w - d) / sd at the solution (per
            measurement, components dx dy dz rx ry rz).
        residual_rms: RMS of the weighted residuals (about 1 for consistent data).
        rms_limit: largest residual RMS that the chi-square test at
            :data:`closedloop.analysis.fit_statistics.FIT_SIGNIFICANCE` accepts for these
            data, or None when no component is left to test it (as many informative
            components as the rank of S).
        consistent: False when ``residual_rms`` exceeds ``rms_limit`` (the model does not
            fit the data: the standard errors do not hold;
            :class:`~closedloop.exceptions.ModelMisfitWarning`).
        measurement_rms: (n,) weighted residual RMS of each measurement [-].
        worst: indices of the measurements that misfit, worst first (empty when the fit
            is consistent; :func:`closedloop.analysis.misfit.worst_measurements`).
        other_mode: index -> "stated q" or "neighbours": the ``actuated`` measurements
            assembled on another assembly mode than their stated q or their neighbours
            (empty when the fit is consistent; :func:`closedloop.analysis.misfit.other_modes`).
        units: name -> unit of its estimate and error ("N m/rad", "N/m", or "1" for a
            block's factor).
        n_measurements: number of measurements.
        success: whether the optimiser reports convergence.
    """

    names: tuple[str, ...]
    estimates: dict
    std_errors: dict
    correlations: np.ndarray
    identified: tuple[str, ...]
    unidentifiable: tuple[str, ...]
    confounded: tuple[tuple[str, ...], ...]
    residuals: np.ndarray
    residual_rms: float
    rms_limit: float | None
    consistent: bool
    measurement_rms: np.ndarray
    worst: tuple[int, ...]
    other_mode: dict
    units: dict
    n_measurements: int
    success: bool

    def to_dict(self) -> dict:
        """JSON-ready summary."""
        return {
            "estimates": self.estimates,
            "std_errors": self.std_errors,
            "identified": list(self.identified),
            "unidentifiable": list(self.unidentifiable),
            "confounded": [list(c) for c in self.confounded],
            "correlations": self.correlations.tolist(),
            "residual_rms": self.residual_rms,
            "rms_limit": self.rms_limit,
            "consistent": self.consistent,
            "measurement_rms": self.measurement_rms.tolist(),
            "worst": list(self.worst),
            "other_mode": {str(i): why for i, why in self.other_mode.items()},
            "units": self.units,
            "residuals": self.residuals.tolist(),
            "n_measurements": self.n_measurements,
            "success": self.success,
        }
