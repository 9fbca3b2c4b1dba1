"""The assembly modes of a mechanism at given actuated values: the distinct closed
configurations found from a set of starts.

A mechanism with loops may close in several ways at the same actuated values: the
four-bar's coupler and rocker meet above or below the line from the crank tip to the
rocker's pivot (elbow up, elbow down). :func:`closedloop.kinematics.assembly.assemble`
returns one, the mode continuous from its start (by default the model's reference
configuration); :func:`assembly_modes` lists the modes that a set of starts finds:

* the default assembly (:func:`~closedloop.kinematics.assembly.assemble` from the
  reference configuration, driven to the actuated values), the mode the library and the
  command line use;
* each configuration of ``starts``, driven there in the same way;
* ``samples`` random starts (a generator seeded with ``seed``): each passive coordinate
  drawn uniformly within its joint's position limits (a revolute or prismatic joint with
  both limits finite), else within pi rad or L (the model's characteristic length) of the
  reference configuration; actuated values at their targets, sprung and locked joints at
  their reference values; each closed in one solve.

The list holds what these starts found, not necessarily every mode: a mode whose basin
of attraction none of them reaches is missed (more ``samples`` or a ``starts`` near it
find it). Two closed configurations are one mode when their passive coordinates differ by
at most :data:`MODE_TOL` (:func:`scaled_difference`: angles modulo 2 pi, lengths per L)
along the directions the closures see (the passive Jacobian's row space at the mode
found first: an idle motion, a rod spinning about its own axis between two balls, does
not make another mode).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import check_count, check_positive
from closedloop.common.conditioning import rule_rank, svd
from closedloop.exceptions import AssemblyError, InvalidInputError, SingularConfigurationError
from closedloop.kinematics.assembly import (
    Assembly,
    assemble,
    check_actuated,
    close_at,
    close_loops,
    coordinate_scale,
    free_coordinates,
    scaled_passive_jacobian,
)
from closedloop.kinematics.limits import UNBOUNDED_LIMIT, joints_outside_limits
from closedloop.model.closed_loop import ClosedLoopModel

#: Largest scaled difference of the passive coordinates (rad, lengths per L) between two
#: closed configurations of one mode. Each closes to the assembly tolerance (1e-12 L); at a
#: regular configuration their difference is that over the smallest scaled singular value
#: of the passive Jacobian, which the assembly keeps above 1e-4 of the largest (else it
#: iterates on, :data:`closedloop.kinematics.assembly.POLISH_FACTOR`): at most about
#: 1e-8, a hundredth of this. Two modes differ by the order of 1 rad, except near the
#: singular configurations where they meet (and are one).
MODE_TOL = 1e-6
#: Random starts of :func:`assembly_modes` by default.
SAMPLES = 32
#: Failures of a start's assembly: it finds no mode.
_NO_MODE = (AssemblyError, SingularConfigurationError)


def passive_joints(clm: ClosedLoopModel) -> tuple[str, ...]:
    """Names of the joints whose coordinates the assembly moves (passive: no spring, not
    actuated, not locked), in the model's order (once per model)."""

    def build():
        free = set(free_coordinates(clm).tolist())
        model = clm.model
        return tuple(
            model.names[j]
            for j in range(1, model.njoints)
            if free.intersection(range(model.joints[j].idx_v,
                                       model.joints[j].idx_v + model.joints[j].nv))
        )  # fmt: skip

    return clm.memo("passive_joints", build)


def passive_values(clm: ClosedLoopModel, q: np.ndarray) -> dict[str, float | list[float]]:
    """The passive joints' values in q (nq,) [rad, m], which tell its assembly mode:
    joint name -> its value (one coordinate) or the list of its nq values (a free flyer's
    x y z qx qy qz qw)."""
    model, out = clm.model, {}
    for name in passive_joints(clm):
        jm = model.joints[model.getJointId(name)]
        values = [float(v) for v in q[jm.idx_q : jm.idx_q + jm.nq]]
        out[name] = values[0] if jm.nq == 1 else values
    return out


def scaled_difference(clm: ClosedLoopModel, q1: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """(nv,) q2 - q1 (:func:`pinocchio.difference`, tangent of q1) unit-free: angles
    modulo 2 pi in [-pi, pi) (a revolute joint wound once more is where it was), lengths
    per the model's length L."""
    d = pin.difference(clm.model, q1, q2)
    d = np.where(clm.linear_coordinates, d, np.remainder(d + np.pi, 2 * np.pi) - np.pi)
    return d / coordinate_scale(clm)


def assembly_modes(
    clm: ClosedLoopModel,
    actuated: np.ndarray | None = None,
    *,
    starts: Sequence[np.ndarray] | np.ndarray | None = None,
    samples: int = SAMPLES,
    seed: int = 0,
    tol: float = MODE_TOL,
    check_limits: bool = True,
) -> list[Assembly]:
    """The distinct assembly modes found at the actuated values (module docstring).

    Found, not all: the modes that the default assembly, ``starts`` and ``samples``
    random starts reach; another may exist that none of them does.

    Args:
        clm: the model.
        actuated: (n_act,) actuated values [rad, m] in the order of ``clm.actuated``
            (default: those of the reference configuration).
        starts: (k, nq) further start configurations, each driven to the actuated values
            as :func:`~closedloop.kinematics.assembly.assemble` drives its ``q0``.
        samples: number of random starts (an integer >= 0).
        seed: seed of the random starts' generator (an integer >= 0): the same seed, the
            same starts.
        tol: :data:`MODE_TOL`, > 0 [rad, lengths per L].
        check_limits: leave out the modes with joints outside their position limits (the
            rule of :func:`closedloop.kinematics.limits.joints_outside_limits`: a passive
            revolute joint wound by whole turns counts as inside).

    Returns:
        One :class:`~closedloop.kinematics.assembly.Assembly` per mode, each with its
        closure residuals and Jacobian (:attr:`Assembly.closure`), the configuration
        first found of the mode (from a random start, the angles of its passive revolute
        joints within pi of the reference configuration's); sorted by the largest scaled difference
        (:func:`scaled_difference`) of their passive coordinates from the default
        assembly's, which comes first (when it closes; else from the reference
        configuration). Empty when no start closes the loops.

    Raises:
        InvalidInputError: bad ``actuated``, ``starts`` (the index named), ``samples``,
            ``seed`` or ``tol``.
    """
    check_count("samples", samples, 0)
    check_count("seed", seed, 0)
    check_positive("tol", tol, "rad, lengths per L")
    reference = clm.reference_configuration()
    target = clm.actuated_values(reference) if actuated is None else check_actuated(clm, actuated)
    firsts = []
    for k, q0 in enumerate([] if starts is None else starts):
        try:
            firsts.append(clm.check_configuration(q0))
        except InvalidInputError as e:
            raise InvalidInputError(f"starts[{k}]: {e}") from None
    free = free_coordinates(clm)
    found: list[tuple[Assembly, np.ndarray]] = []  # each mode and its seen directions
    anchor = reference
    for i, start in enumerate(_starts(clm, reference, target, firsts, samples, seed)):
        try:
            a = (assemble(clm, target, start, jacobian=True) if i <= len(firsts)
                 else _unwound(clm, close_at(clm, start, target).q, reference))  # fmt: skip
        except _NO_MODE:
            continue
        if i == 0:
            anchor = a.q
        if check_limits and joints_outside_limits(clm, a.q):
            continue
        if not any(_same(clm, mode, seen, a.q, free, tol) for mode, seen in found):
            found.append((a, _seen_directions(clm, a, free)))
    modes = [a for a, _ in found]
    distance = [float(np.max(np.abs(scaled_difference(clm, anchor, a.q)[free]), initial=0.0))
                for a in modes]  # fmt: skip
    return [modes[k] for k in sorted(range(len(modes)), key=distance.__getitem__)]


def _starts(clm, reference, target, firsts, samples: int, seed: int):
    """The starts of :func:`assembly_modes` in order: the reference, ``firsts``, then
    ``samples`` random ones (module docstring), made one at a time."""
    yield reference
    yield from firsts
    rng = np.random.default_rng(seed)
    model, free = clm.model, np.zeros(clm.model.nv, bool)
    free[free_coordinates(clm)] = True
    lower, upper = model.lowerPositionLimit, model.upperPositionLimit
    for _ in range(samples):
        q, v = reference.copy(), np.zeros(model.nv)
        for j in range(1, model.njoints):
            jm = model.joints[j]
            part = slice(jm.idx_v, jm.idx_v + jm.nv)
            if not free[part].any():
                continue
            lo, hi = float(lower[jm.idx_q]), float(upper[jm.idx_q])
            if jm.nq == 1 and lo < hi and max(abs(lo), abs(hi)) < UNBOUNDED_LIMIT:
                q[jm.idx_q] = rng.uniform(lo, hi)
            else:
                span = np.where(clm.linear_coordinates[part], clm.length, np.pi)
                v[part] = rng.uniform(-span, span)
        q = pin.integrate(model, q, v)
        clm.set_actuated(q, target)
        yield q


def _unwound(clm: ClosedLoopModel, q: np.ndarray, reference: np.ndarray) -> Assembly:
    """The assembly of q (nq,), closed, with the angles of its passive revolute joints
    taken within pi of the reference's (a whole turn moves nothing), its closure residuals
    and Jacobian computed there (:func:`closedloop.kinematics.assembly.close_loops`)."""
    model, q = clm.model, q.copy()
    for name in passive_joints(clm):
        jm = model.joints[model.getJointId(name)]
        if jm.nq == 1 and jm.shortname().startswith("JointModelR"):
            i = jm.idx_q
            q[i] = reference[i] + np.remainder(q[i] - reference[i] + np.pi, 2 * np.pi) - np.pi
    return close_loops(clm, q, jacobian=True)


def _seen_directions(clm: ClosedLoopModel, a: Assembly, free: np.ndarray) -> np.ndarray:
    """(r, p) orthonormal rows: the directions of the scaled passive coordinates that the
    closures see at a's configuration (the row space of the scaled passive Jacobian,
    :func:`closedloop.kinematics.assembly.scaled_passive_jacobian`, rank by
    :func:`closedloop.common.conditioning.rule_rank`)."""
    A = scaled_passive_jacobian(clm, a.closure[1], free)
    if not A.size:  # no closure row (or no passive coordinate): nothing seen
        return np.zeros((0, len(free)))
    _, s, Vt = svd(A)
    return Vt[: rule_rank(s)]


def _same(clm, mode: Assembly, seen: np.ndarray, q: np.ndarray, free, tol: float) -> bool:
    """Whether q is on ``mode``: their scaled passive difference, in the directions
    ``seen`` at the mode, within ``tol``."""
    d = scaled_difference(clm, mode.q, q)[free]
    return float(np.max(np.abs(seen.T @ (seen @ d)), initial=0.0)) <= tol
