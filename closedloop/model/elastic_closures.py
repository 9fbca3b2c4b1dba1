"""Elastic loop closures: a stiffness at a cut, carried by joints added there.

The spring of a closure is the stiffness of the relative motion of frame B with respect
to frame A, in A's axes at A's origin (:data:`DIRECTIONS`: translations [N/m], then
rotations [N m/rad]). Given as 6 values, each direction is rigid (``inf`` on a direction
the closure type constrains), elastic (a finite value on a constrained direction, or > 0
on a free one) or free (0 on a free direction: the default of :data:`FREE_DIRECTIONS`,
or on a constrained one). Given as a 6x6, every direction is elastic.

The joints that carry it are laid out so that, for small motions about any configuration
where the pair holds as its type says, their deflection is exactly B's motion relative to
A in A's axes at A's origin, whatever the pair's relative placement there (no gimbal
lock):

* 6 values: a chain of single-coordinate joints on A's body at A's origin, one per
  elastic or free direction (none for a rigid one), in the order px, py, rx, ry, pz, rz
  (:data:`CHAIN_ORDER`), named ``"<closure>_<direction>"``, its end welded (``6d``) to B.
  Where a pair of type ``6d``, ``revolute``, ``prismatic`` or ``cylindrical`` holds,
  px, py, rx and ry are 0: every joint's axis is A's and passes through A's origin, and
  pz and rz, the only ones away from 0, are along and about A's z axis.
* 6 values whose three rotations are free (0; a ``3d`` pair's default): no rotation
  joint; the chain's end is closed to B's origin by a point (``3d``).
* 6 values whose three rotations have springs (> 0) on a ``3d`` pair, whose relative
  orientation is free: a ball joint (``"<closure>_ball"``, spherical: no gimbal lock) on
  B's body at B's origin, then the translations' joints, the end welded to A. The ball's
  rotation is A's orientation relative to B, its deflection A's rotation in A's axes:
  minus B's relative to A, the same energy.
* a 6x6: one 6-coordinate joint (a free flyer) ``"<closure>_bushing"`` carrying the
  matrix as its block spring, on A's body at A's origin welded to B for a ``6d`` pair
  (A and B coincide at rest), else on B's body at B's origin welded to A (its tangent,
  linear then angular, is A's motion relative to B in A's axes at A's origin). A
  singular 6x6 (positive semi-definite) is followed by one passive screw joint per free
  direction, ``"<closure>_free1"``, ....
* a ``universal`` pair (6 values only): its directions are those of its own frame U at
  A's origin, whose axes turn with the pair's free rotations: x along B's z axis, y along
  z_A x z_B (the cross axis), z along A's z axis (U is A where B's z is along A's x). The
  chain turns about A's z first (rz, turning U with it), then px, py, pz, ry, rx along and
  about U's axes (:data:`UNIVERSAL_ORDER`), its end welded to B turned z onto x.

Three non-rigid rotations of which some are free and some sprung are refused (a chain of
three rotations has a gimbal lock), as are a universal pair's free cross rotation (a ball:
a ``3d`` pair) and a 6x6 on a universal pair.

The joints are named after their closure, whose name is the model's only
(:func:`closedloop.model.closures.distinct_names`: two closures of one pair of frames,
``A<->B`` and ``A<->B#2``, are two springs in parallel, of the summed stiffness); the
closure keeps their names (``Closure.cut``) and is not made elastic again (a second
spring there would be in series with the first). The joints are springs like any other
(an elastic one has its value as joint spring, a free one none: passive). Their rest
state is the pair met as its type says, the springs at rest at the configuration
analysed. The model's reference configurations (an MJCF ``qpos0``, an SDF rest, a URDF's
drawing) are extended with the joints' values there (:func:`chain_values`), so that an
assembly started from them closes an elastic closure as the file draws it. The energy of
a loaded equilibrium is that of the joints' coordinates (exact to first order about the
rest, as above).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import real_array, symmetrized
from closedloop.exceptions import InvalidInputError
from closedloop.model.closures import CLOSURE_TYPES, Closure, distinct_names

#: Directions of the relative motion of frame B with respect to frame A, in A's axes at
#: A's origin: translations [m], then rotations [rad]; the order of ``closure_springs``.
DIRECTIONS = ("px", "py", "pz", "rx", "ry", "rz")

#: Order of the chain's joints (indices in :data:`DIRECTIONS`): across A's z axis first,
#: then along and about it (module docstring).
CHAIN_ORDER = (0, 1, 3, 4, 2, 5)

#: The single-dof joint of each direction (:data:`DIRECTIONS`), about or along A's axis.
_DIRECTION_JOINTS = (
    pin.JointModelPX, pin.JointModelPY, pin.JointModelPZ,
    pin.JointModelRX, pin.JointModelRY, pin.JointModelRZ,
)  # fmt: skip

#: Per closure type, the directions (indices in :data:`DIRECTIONS`) it leaves free (a
#: universal pair's in its own frame U: the rotations about B's z axis and A's z axis).
FREE_DIRECTIONS = {
    "3d": (3, 4, 5),
    "6d": (),
    "revolute": (5,),
    "prismatic": (2,),
    "cylindrical": (2, 5),
    "universal": (3, 5),
}

#: A universal pair's chain: about A's z first (turning U about it), then U's axes.
UNIVERSAL_ORDER = (5, 0, 1, 2, 4, 3)
#: B's orientation relative to the end of a universal pair's chain: z onto x.
_Z_ONTO_X = pin.SE3(pin.rpy.rpyToMatrix(0.0, math.pi / 2, 0.0), np.zeros(3))

#: Relative asymmetry max|K - K^T| / max|K| above which a 6x6 closure spring is refused.
SYMMETRY_RTOL = 1e-9
#: Eigenvalues of a 6x6 closure spring (unit-balanced: its translations scaled by the
#: spring's own length, the square root of its mean rotational over its mean translational
#: diagonal stiffness) below this times its largest are its free directions: its entries
#: are known to about its symmetry's precision (:data:`SYMMETRY_RTOL`), which moves its
#: eigenvalues by as much.
NULL_RTOL = 1e-9
#: Eigenvalues below this times the largest are the rounding of a zero (a symmetric
#: eigensolver's error on a 6x6 is a few eps times its largest, 2.2e-16 each; a margin of
#: about 100): free directions. Between it and :data:`NULL_RTOL` a spring is refused, being
#: neither clearly free nor resolved (1e11 against 20 N m/rad is 2e-10).
EIGEN_ROUNDING = 1e-13

#: Suffix of the 6-dof joint of a full 6x6 closure spring (a bushing).
BUSHING = "bushing"

#: Suffix of the ball joint of a ``3d`` pair's rotation springs.
BALL = "ball"


def closure_spring(closure: Closure, value) -> np.ndarray:
    """The validated spring of ``closure``: (6,) diagonal or (6, 6) matrix [N/m, N/rad,
    N m/rad] (module docstring); a 6x6 that is diagonal is returned as its diagonal.

    Raises:
        InvalidInputError: naming the closure, the value and what was expected.
    """
    what = f"closure {closure.name!r} of type {closure.kind!r}"
    try:
        K = real_array(value, f"the spring of {what}")
    except InvalidInputError:  # not numbers: the message below says what is expected
        K = np.empty(0)
    if K.shape not in ((6,), (6, 6)) or np.isnan(K).any():
        raise InvalidInputError(
            f"{what} given the spring {value!r}; expected 6 numbers (dx dy dz rx ry rz in "
            "frame A's axes [N/m, N m/rad], .inf = rigid) or a 6x6 symmetric positive "
            "semi-definite matrix"
        )
    if K.ndim == 2 and not np.any(K - np.diag(np.diag(K))):
        K = np.diag(K).copy()
    if K.ndim == 1:
        _check_diagonal(what, value, K, closure.kind)
        return K
    if closure.kind == "universal":
        raise InvalidInputError(
            f"{what} given the 6x6 spring {value!r}; expected 6 values (in the pair's frame "
            "U, whose axes turn with the pair's free rotations: a coupled matrix there has "
            "no fixed meaning)"
        )
    if not np.isfinite(K).all():
        raise InvalidInputError(
            f"{what} given the 6x6 spring {value!r} with infinite entries; expected a "
            "finite 6x6 (a full bushing), or 6 values (.inf for a rigid direction)"
        )
    K = symmetrized(
        K, SYMMETRY_RTOL, f"{what} given the 6x6 spring {value!r}",
        "a symmetric positive semi-definite matrix",
    )  # fmt: skip
    d = _balance(K)
    lam = np.linalg.eigvalsh(K * np.outer(d, d))  # unit-balanced
    if lam[0] < -SYMMETRY_RTOL * lam[-1]:
        raise InvalidInputError(
            f"{what} given the 6x6 spring {value!r}, not positive semi-definite "
            f"(eigenvalues {np.linalg.eigvalsh(K).tolist()}); expected a symmetric positive "
            "semi-definite matrix"
        )
    soft = lam[(lam > EIGEN_ROUNDING * lam[-1]) & (lam <= NULL_RTOL * lam[-1])] / lam[-1]
    if soft.size:  # neither a free direction (rounding of zero) nor a spring it resolves
        raise InvalidInputError(
            f"{what} given the 6x6 spring {value!r}, whose stiffness along {soft.size} "
            f"direction(s) is {soft.tolist()} of its stiffest (unit-balanced): below "
            f"{NULL_RTOL:g}, where a 6x6 cannot tell a spring from a free direction; "
            "expected 0 there (free), a spring above that share, or 6 values in the "
            "pair's axes"
        )
    return K


def _balance(K: np.ndarray) -> np.ndarray:
    """(6,) d = (L, L, L, 1, 1, 1) with the spring's own length L [m], the square root of
    its mean rotational over its mean translational diagonal stiffness (1 m if either is
    0): D K D, D = diag(d), weighs translations and rotations alike."""
    t, r = np.mean(np.diag(K)[:3]), np.mean(np.diag(K)[3:])
    L = math.sqrt(r / t) if t > 0 and r > 0 else 1.0
    return np.array([L, L, L, 1.0, 1.0, 1.0])


def _check_diagonal(what: str, value, K: np.ndarray, kind: str) -> None:
    """6 values: >= 0, finite on the type's free directions, three non-rigid rotations
    all free or all sprung."""
    if (K < 0).any():
        raise InvalidInputError(
            f"{what} given the spring {value!r}; expected values >= 0 (0 = free, .inf = rigid)"
        )
    free_inf = [DIRECTIONS[i] for i in FREE_DIRECTIONS[kind] if np.isinf(K[i])]
    if free_inf:
        raise InvalidInputError(
            f"{what} given the spring {value!r}: .inf on {free_inf}, which the type "
            "leaves free; expected a finite value there (0 = free), or a closure type "
            "that constrains it"
        )
    rotations = K[3:]
    if kind == "universal" and K[4] == 0:
        raise InvalidInputError(
            f"{what} given the spring {value!r}: 0 (free) on ry, the rotation about the "
            "pair's cross axis, which makes it a ball joint; expected .inf (rigid) or a "
            "stiffness > 0 there, or a '3d' pair"
        )
    if (
        kind != "universal"
        and np.isfinite(rotations).all()
        and (rotations == 0).any()
        and (rotations > 0).any()
    ):
        raise InvalidInputError(
            f"{what} given the spring {value!r}: the rotations rx ry rz are partly free (0) "
            "and partly sprung; expected all three free, all three sprung (a ball joint "
            "with springs), or one of them rigid (.inf, on a type that constrains it): "
            "three rotations in a chain would lock at 90 degrees"
        )


def check_closure_springs(closures: list[Closure], springs) -> dict[int, np.ndarray]:
    """``springs`` (closure index -> spring) validated against ``closures``
    (:func:`closure_spring`); :class:`InvalidInputError` for an index out of range."""
    if not isinstance(springs, Mapping):
        raise InvalidInputError(
            f"closure_springs must be a mapping closure index -> spring, got {springs!r}"
        )
    out = {}
    for i, value in springs.items():
        if (
            isinstance(i, bool)
            or not isinstance(i, int | np.integer)
            or not (0 <= i < len(closures))
        ):
            raise InvalidInputError(
                f"closure_springs index {i!r}; expected the 0-based index of a pair of "
                f"closed_loop, 0..{len(closures) - 1}"
            )
        out[int(i)] = closure_spring(closures[i], value)
    return out


class _Joint(NamedTuple):
    """One joint at a cut: its name's suffix, Pinocchio joint model, spring (None:
    passive) and placement relative to the previous joint's frame."""

    suffix: str
    model: object
    spring: object = None
    placement: pin.SE3 = pin.SE3.Identity()


class _Cut(NamedTuple):
    """The joints of one elastic closure: hung from ``start`` (joint, placement: frame A's,
    or B's when ``from_b``), their end closed to ``end`` (the other frame) by a closure of
    type ``end_kind``."""

    start: tuple
    end: tuple
    joints: tuple  # the _Joint of the chain, in order
    end_kind: str
    kind: str  # the closure's type
    from_b: bool = False
    tip: pin.SE3 = pin.SE3.Identity()  # the closed frame relative to the chain's end


def _layout(closure: Closure, K: np.ndarray) -> _Cut:
    """Where and which joints carry the spring ``K`` of ``closure`` (module docstring)."""
    c = closure.constraint
    a, b = (c.joint1_id, c.joint1_placement), (c.joint2_id, c.joint2_placement)
    if K.ndim == 2:
        joints, tip = _bushing(K)
        from_b = closure.kind != "6d"
        return _Cut(*((b, a) if from_b else (a, b)), joints, "6d", closure.kind, from_b, tip)
    if closure.kind == "universal":
        chain = tuple(
            _Joint(DIRECTIONS[d], _DIRECTION_JOINTS[d](), K[d] if K[d] > 0 else None)
            for d in UNIVERSAL_ORDER
            if math.isfinite(K[d])
        )
        return _Cut(a, b, chain, "6d", "universal", tip=_Z_ONTO_X)
    rotations = K[3:]
    free = not rotations.any()  # three free rotations: closed by a point
    ball = closure.kind == "3d" and not free  # three sprung rotations of a '3d' pair
    chain = tuple(
        _Joint(DIRECTIONS[d], _DIRECTION_JOINTS[d](), K[d] if K[d] > 0 else None)
        for d in CHAIN_ORDER
        if math.isfinite(K[d]) and not (d >= 3 and (free or ball))
    )
    if ball:
        joints = (_Joint(BALL, pin.JointModelSpherical(), rotations), *chain)
        return _Cut(b, a, joints, "6d", closure.kind, from_b=True)
    return _Cut(a, b, chain, "3d" if free else "6d", closure.kind)


#: Components of a free direction (unit-balanced, unit norm) below this are rounding.
ROUNDING = 1e-12


def _bushing(K: np.ndarray) -> tuple[tuple, pin.SE3]:
    """The joints of a 6x6 spring K (PSD) and the closed frame relative to their end.

    A free flyer carries K + c n n^T, its free directions n (K n = 0) given the stiffness
    c (K's largest eigenvalue, unit-balanced), followed by one passive screw joint per
    free direction (a helical joint, or a prismatic one for a translation) along it at
    rest: the series of the two is exactly K, whatever c > 0 (the free flyer's spring on
    the screws' directions is annulled by their freedom:
    K + c n n^T - (K + c n n^T) n (n^T (K + c n n^T) n)^-1 n^T (K + c n n^T) = K).
    """
    d = _balance(K)
    lam, V = np.linalg.eigh(K * np.outer(d, d))
    free = V[:, lam <= NULL_RTOL * lam[-1]]
    free[np.abs(free) < ROUNDING] = 0.0
    block = K + lam[-1] * (free @ free.T) / np.outer(d, d)
    joints, point = [_Joint(BUSHING, pin.JointModelFreeFlyer(), block)], np.zeros(3)
    for i, n in enumerate((free * d[:, None]).T):  # SI twists (v [m], w [rad])
        v, w = n[:3], n[3:]
        if not w.any():
            joint, at = pin.JointModelPrismaticUnaligned(v / np.linalg.norm(v)), np.zeros(3)
        else:  # a screw along w through the point at: v = h w + at x w
            u, v = w / np.linalg.norm(w), v / np.linalg.norm(w)
            joint, at = pin.JointModelHelicalUnaligned(u, float(u @ v)), np.cross(u, v)
        joints.append(_Joint(f"free{i + 1}", joint, None, pin.SE3(np.eye(3), at - point)))
        point = at
    return tuple(joints), pin.SE3(np.eye(3), -point)


def with_elastic_closures(
    model: pin.Model, closures: list[Closure], springs
) -> tuple[pin.Model, list[Closure], dict[str, float | np.ndarray]]:
    """The model with the closures given a spring made elastic (module docstring).

    Args:
        model: the kinematic tree (not modified).
        closures: its closures.
        springs: closure index (0-based) -> 6 values or a 6x6 matrix [N/m, N m/rad].

    Returns:
        (the model with the closures' joints appended and its reference configurations
        extended with their values there (:func:`chain_values`), the closures on it, the
        springs of those joints {joint name: stiffness, (3,) rotations of a ball, or a
        (6, 6) block}).

    Raises:
        InvalidInputError: an index out of range, a spring of the wrong length, a 6x6 not
            symmetric positive semi-definite or not finite, ``inf`` on a free direction,
            rotations partly free and partly sprung, a spring at a universal closure, a
            spring at a closure elastic already, a joint to add whose name the model has.
    """
    closures = distinct_names(closures)
    checked = check_closure_springs(closures, springs)
    again = [closures[i] for i in checked if closures[i].cut]
    if again:
        raise InvalidInputError(
            f"closure {again[0].name!r} is elastic already (its spring on the joints "
            f"{list(again[0].cut)}); expected each closure's spring once (two springs on one "
            "pair act in parallel as two closures of the pair, each with its spring)"
        )
    cuts = {}
    for i, K in checked.items():
        free = FREE_DIRECTIONS[closures[i].kind]
        if K.ndim == 2 or any(np.isfinite(k) and (k > 0 or d not in free) for d, k in enumerate(K)):
            cuts[i] = _layout(closures[i], K)
    if not cuts:
        return model, list(closures), {}
    out_model = pin.Model(model)
    out_closures, out = [], {}
    for i, c in enumerate(closures):
        if i not in cuts:
            out_closures.append(c.on(out_model, *_ends(c)))
            continue
        j, M = cuts[i].start
        names = [f"{c.name}_{joint.suffix}" for joint in cuts[i].joints]
        for joint, name in zip(cuts[i].joints, names, strict=True):
            if out_model.existJointName(name):
                raise InvalidInputError(
                    f"the spring of closure {c.name!r} needs a joint {name!r}, a name the "
                    "model has already; expected joint names that are not <closure>_<suffix> "
                    "of an elastic closure (rename the joint)"
                )
            k = joint.spring
            j = out_model.addJoint(j, joint.model, M * joint.placement, name)
            out_model.addJointFrame(j)
            M = pin.SE3.Identity()
            if k is not None:
                out[name] = k if np.ndim(k) == 2 or np.size(k) > 1 else float(k)
        M, kind = cuts[i].tip, cuts[i].end_kind
        constraint = CLOSURE_TYPES[kind](out_model, j, M, *cuts[i].end)
        out_closures.append(Closure(constraint, c.name, kind, tuple(names)))
    for entry in model.referenceConfigurations:
        q = entry.data()
        out_model.referenceConfigurations[entry.key()] = np.concatenate(
            [q, *chain_values(model, q, cuts.values())]
        )
    return out_model, out_closures, out


def _ends(c: Closure) -> tuple[tuple, tuple]:
    k = c.constraint
    return (k.joint1_id, k.joint1_placement), (k.joint2_id, k.joint2_placement)


def chain_values(model: pin.Model, q: np.ndarray, cuts) -> list[np.ndarray]:
    """The configuration values of each cut's joints (in order) at the configuration
    ``q`` (nq,) of the tree ``model`` without them: those of the pair met as its type says
    there, the springs at rest (B's placement relative to A reduced to what the pair leaves
    free)."""
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    out = []
    for cut in cuts:
        (j1, M1), (j2, M2) = cut.start, cut.end
        M = (data.oMi[j1] * M1).actInv(data.oMi[j2] * M2)
        P = _free_part(cut.kind, M.inverse() if cut.from_b else M)  # B relative to A
        # the chain's end relative to its start
        M = (P.inverse() if cut.from_b else P) * cut.tip.inverse()
        R, t = M.rotation, M.translation
        values = []
        for suffix, *_ in cut.joints:
            if suffix == BUSHING:  # the screws after it at 0: it takes the whole placement
                values.append(pin.SE3ToXYZQUAT(M * cut.tip))
            elif suffix in (BALL, "rz"):  # the rest of the chain in the joint's moving axes
                turn = math.atan2(R[1, 0], R[0, 0])
                values.append(pin.Quaternion(R).coeffs() if suffix == BALL else [turn])
                Rj = R if suffix == BALL else pin.rpy.rpyToMatrix(0.0, 0.0, turn)
                R, t = Rj.T @ R, Rj.T @ t
            elif suffix == "rx" and cut.kind == "universal":  # the turn about B's z
                values.append([math.atan2(R[2, 1], R[1, 1])])
            elif suffix in DIRECTIONS[:3]:
                values.append([t["xyz".index(suffix[1])]])
            else:  # a rotation a type constrains, a bushing's screw: 0 where the pair holds
                values.append([0.0])
        out.append(np.concatenate(values) if values else np.empty(0))
    return out


def _free_part(kind: str, M: pin.SE3) -> pin.SE3:
    """B's placement ``M`` relative to A reduced to what a pair of type ``kind`` leaves
    free: the turn about and the slide along A's z axis, a ball's rotation, nothing for a
    weld (the constrained directions at 0, as the assembly makes them)."""
    turn = math.atan2(M.rotation[1, 0], M.rotation[0, 0])
    slide = np.array([0.0, 0.0, M.translation[2]])
    if kind == "universal":  # B's z turned onto U's x about A's z, then B about it
        z = M.rotation[:, 2]
        U = pin.rpy.rpyToMatrix(0.0, 0.0, math.atan2(z[1], z[0]))
        Rb = U.T @ M.rotation @ _Z_ONTO_X.rotation.T
        spin = pin.rpy.rpyToMatrix(math.atan2(Rb[2, 1], Rb[1, 1]), 0.0, 0.0)
        return pin.SE3(U @ spin @ _Z_ONTO_X.rotation, np.zeros(3))
    return {
        "6d": pin.SE3.Identity(),
        "3d": pin.SE3(M.rotation, np.zeros(3)),
        "revolute": pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, turn), np.zeros(3)),
        "prismatic": pin.SE3(np.eye(3), slide),
        "cylindrical": pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, turn), slide),
    }[kind]
