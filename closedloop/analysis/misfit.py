"""Diagnosis of an identification whose model does not fit its data
(:class:`closedloop.exceptions.ModelMisfitWarning`): which measurements misfit most, and
which ``actuated`` measurements were assembled on another assembly mode than the robot.

**Worst measurements.** Under a fit, the sum of squares of a measurement's weighted
residuals is a chi-square variable of its m measured components (fewer degrees of
freedom, by the parameters' share: the test is loose by that much). A measurement whose
sum exceeds the quantile of significance ``FIT_SIGNIFICANCE / n`` (Bonferroni over the n
measurements: a data set that fits names none, but once in a million) misfits; they are
named worst first (:func:`worst_measurements`).

**Another assembly mode.** The ``actuated`` values of a measurement are assembled as the
command line assembles them: driven from the model's reference configuration (or the
``q0`` of the identification; :func:`closedloop.kinematics.driving.assemble_connected`).
A robot driven otherwise may be on another assembly mode at the same values, and its
twists are then those of another configuration: a misfit the residuals alone do not
explain. Two checks
(:func:`other_modes`), each comparing two closed configurations of the same actuated
values, assembled from two starts (equal to within :data:`SAME_BRANCH` on one branch):

* a measurement that also states its configuration ``q`` (the configuration the robot
  was in): its actuated values assembled from that q, on q's branch, against the
  command line's assembly;
* the other ``actuated`` measurements: each one's assembly against its values driven from
  its neighbour's assembled configuration, the neighbours the edges of the shortest tree
  joining the measurements' actuated values (scaled as
  :func:`closedloop.kinematics.driving.input_scale`; in one input, the next value up or
  down). The tree cut where two neighbours differ leaves groups of one mode each; a group
  joins the mode of a larger one whose first measurement agrees with its own (driven from
  one to the other); the measurements outside the mode of the most measurements are named
  (a tie: the mode of the first measurement is kept).
"""

from __future__ import annotations

import numpy as np
import scipy.special

from closedloop.exceptions import AssemblyError, InvalidInputError, SingularConfigurationError
from closedloop.kinematics.assembly_modes import scaled_difference
from closedloop.kinematics.driving import (
    assemble_connected,
    assemble_within_limits,
    input_scale,
)
from closedloop.model.closed_loop import ClosedLoopModel

#: Misfitting measurements named in a warning (the others are counted).
WORST_SHOWN = 3
#: Largest scaled difference (rad, or lengths per the model's length L, any velocity
#: coordinate) between two closed configurations of the same actuated values on one
#: branch. Each closes to ASSEMBLY_TOL (1e-12); off a singular configuration (a singular
#: value of the passive Jacobian above 1e-6 of its largest) they then agree to 1e-6;
#: two assembly modes differ by the order of 1 rad, except near the singular
#: configurations where they meet (and are one).
SAME_BRANCH = 1e-6
#: Failures of an assembly of a check: no evidence, the measurement is not named.
_NO_EVIDENCE = (AssemblyError, InvalidInputError, SingularConfigurationError)


def measurement_rms(r: np.ndarray) -> np.ndarray:
    """(n,) weighted residual RMS of each measurement, over its 6 components (those not
    measured are 0), from the weighted residuals r (n, 6) [-]."""
    return np.sqrt(np.mean(np.asarray(r) ** 2, axis=1))


def worst_measurements(r: np.ndarray, sd: np.ndarray, significance: float) -> tuple[int, ...]:
    """Indices of the measurements that misfit (module docstring), worst first.

    Args:
        r: (n, 6) weighted residuals (C w - d) / sd [-].
        sd: (n, 6) standard deviations of the twists (inf: not measured).
        significance: the fit's test significance, shared among the n measurements.
    """
    r = np.asarray(r)
    measured = np.isfinite(sd).sum(axis=1)
    limit = scipy.special.chdtri(measured, significance / len(r))
    sums = np.sum(r**2, axis=1)
    bad = np.flatnonzero(sums > limit)
    return tuple(int(i) for i in bad[np.argsort(-sums[bad], kind="stable")])


def _distance(clm: ClosedLoopModel, q1: np.ndarray, q2: np.ndarray) -> float:
    """Largest scaled difference of two configurations (rad, lengths per L), angles taken
    modulo 2 pi (:func:`closedloop.kinematics.assembly_modes.scaled_difference`)."""
    return float(np.max(np.abs(scaled_difference(clm, q1, q2))))


def _stated_branch(clm, m, q, check_limits: bool) -> float | None:
    """Scaled distance of q (nq,) to m's actuated values assembled from m's stated q
    (None: no q stated, or that assembly fails)."""
    if m.q is None:
        return None
    try:
        on_q = assemble_within_limits(clm, m.actuated, m.q, jacobian=False,
                                      check_limits=check_limits).q  # fmt: skip
    except _NO_EVIDENCE:
        return None
    return _distance(clm, q, on_q)


def _tree(points: np.ndarray) -> list[tuple[int, int]]:
    """Edges (i, j) of the shortest tree joining the points (k, d) (Prim's)."""
    k = len(points)
    inside, edges = np.zeros(k, bool), []
    inside[0] = True
    best = np.linalg.norm(points - points[0], axis=1)
    parent = np.zeros(k, int)
    for _ in range(k - 1):
        j = int(np.argmin(np.where(inside, np.inf, best)))
        edges.append((int(parent[j]), j))
        inside[j] = True
        d = np.linalg.norm(points - points[j], axis=1)
        closer = d < best
        best[closer], parent[closer] = d[closer], j
    return edges


def other_modes(
    clm: ClosedLoopModel, measurements, configs, *, check_limits: bool = True
) -> dict[int, str]:
    """index -> "stated q" or "neighbours": the ``actuated`` measurements assembled on
    another assembly mode than their stated q or their neighbours (module docstring).

    Args:
        clm: the model.
        measurements: the :class:`~closedloop.analysis.measurements.Measurement` list.
        configs: (nq,) configuration each measurement was computed at (their assembly).
        check_limits: as for the assembly of the fit.
    """
    out = {}
    for i, (m, q) in enumerate(zip(measurements, configs, strict=True)):
        if m.actuated is not None:
            far = _stated_branch(clm, m, q, check_limits)
            if far is not None and far > SAME_BRANCH:
                out[i] = "stated q"
    driven = [i for i, m in enumerate(measurements) if m.actuated is not None]
    if len(driven) < 2:
        return out
    points = np.array([measurements[i].actuated for i in driven]) / input_scale(clm)
    link = list(range(len(driven)))  # union-find over the tree's edges of one mode

    def root(a):
        while link[a] != a:
            link[a] = a = link[link[a]]
        return a

    def same(a, b) -> bool:  # a's values driven from b's configuration: a's?
        i, j = driven[a], driven[b]
        try:
            from_j = assemble_connected(clm, measurements[i].actuated, configs[j],
                                        jacobian=False, check_limits=check_limits).q  # fmt: skip
        except _NO_EVIDENCE:
            return True
        return _distance(clm, configs[i], from_j) <= SAME_BRANCH

    for a, b in _tree(points):
        if same(a, b):
            link[root(a)] = root(b)
    members: dict = {}  # the groups the tree cut, each one mode
    for a in range(len(driven)):
        members.setdefault(root(a), []).append(a)
    modes: list = []  # (first member, its members) of each mode, the largest group first
    for group in sorted(members.values(), key=lambda g: (-len(g), g[0])):
        mode = next((m for m in modes if same(group[0], m[0])), None)
        if mode is None:
            modes.append((group[0], list(group)))
        else:
            mode[1].extend(group)
    kept = set(max(modes, key=lambda m: (len(m[1]), -m[0]))[1])
    for a in range(len(driven)):
        if a not in kept:
            out.setdefault(driven[a], "neighbours")
    return dict(sorted(out.items()))


def _values(m) -> str:
    kind, values = ("actuated", m.actuated) if m.actuated is not None else ("q", m.q)
    return f"{kind} [{', '.join(f'{v:.6g}' for v in values)}]"


def describe(measurements, rms: np.ndarray, worst, other: dict[int, str]) -> str:
    """The diagnosis of a misfit in a sentence: the worst measurements (index, actuated or
    q values, RMS) and those on another assembly mode; "" when there is none."""
    parts = []
    if worst:
        shown = "; ".join(f"{i} ({_values(measurements[i])}, RMS {rms[i]:.3g})"
                          for i in worst[:WORST_SHOWN])  # fmt: skip
        more = f" and {len(worst) - WORST_SHOWN} more" if len(worst) > WORST_SHOWN else ""
        parts.append(f"the measurements that misfit most: {shown}{more}")
    for why in ("stated q", "neighbours"):
        named = [i for i, w in other.items() if w == why]
        if named:
            shown = ", ".join(f"{i} ({_values(measurements[i])})" for i in named)
            parts.append(
                f"measurement(s) {shown} assembled on another assembly mode than their {why} "
                "(to fit them where the robot was, give their q without actuated values)"
            )
    return "; ".join(parts)
