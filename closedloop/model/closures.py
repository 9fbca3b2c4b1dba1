"""Loop closures and the names they join.

A closure constrains the relative placement of two frames A and B on two bodies. It holds
a Pinocchio 4 anchor constraint (:class:`pinocchio.PointAnchorConstraintModel` for a 3D
point, :class:`pinocchio.FrameAnchorConstraintModel` otherwise: the joints and placements
of the two frames), a display name and its type (:data:`CLOSURE_TYPES`):

* ``3d``: the origins coincide (a ball joint; 3 rows [m]);
* ``6d``: the placements coincide (a weld; 6 rows [m, rad]);
* ``revolute``: the origins coincide and the z axes are parallel, pointing the same way
  (5 rows: 3 [m], 2 [rad]);
* ``prismatic``: the orientations are equal and B's origin is on A's z axis (5 rows:
  3 [rad], 2 [m]);
* ``cylindrical``: the z axes are parallel, pointing the same way, and B's origin is on
  A's z axis (4 rows: 2 [rad], 2 [m]);
* ``universal``: the origins coincide and A's z axis is perpendicular to B's (4 rows:
  3 [m], 1 [rad]).

The rows themselves are built in :mod:`closedloop.kinematics.constraints`. Frames and
joints are looked up by name with errors that list the valid ones.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from closedloop.exceptions import InvalidInputError, NameNotFoundError

AnchorConstraint = pin.PointAnchorConstraintModel | pin.FrameAnchorConstraintModel

#: Closure types of the closure-file convention and their Pinocchio constraint (the
#: carrier of the two frames' joints and placements).
CLOSURE_TYPES = {
    "3d": pin.PointAnchorConstraintModel,
    "6d": pin.FrameAnchorConstraintModel,
    "revolute": pin.FrameAnchorConstraintModel,
    "prismatic": pin.FrameAnchorConstraintModel,
    "cylindrical": pin.FrameAnchorConstraintModel,
    "universal": pin.FrameAnchorConstraintModel,
}

#: Per closure type, which of its rows are in metres (True) or dimensionless [rad] (False),
#: in the order of :func:`closedloop.kinematics.constraints.residual_rows`.
LINEAR_ROWS = {
    "3d": (True,) * 3,
    "6d": (True,) * 3 + (False,) * 3,
    "revolute": (True,) * 3 + (False,) * 2,
    "prismatic": (False,) * 3 + (True,) * 2,
    "cylindrical": (False,) * 2 + (True,) * 2,
    "universal": (True,) * 3 + (False,),
}


@dataclass(frozen=True)
class Closure:
    """One loop closure: a Pinocchio anchor constraint, a display name and its type.

    Attributes:
        constraint: the anchor constraint between frame A (side 1) and frame B (side 2).
        name: display name.
        kind: one of :data:`CLOSURE_TYPES`; empty: ``"3d"`` for a point anchor, ``"6d"``
            for a frame anchor.
    """

    constraint: AnchorConstraint
    name: str
    kind: str = ""

    def __post_init__(self):
        point = isinstance(self.constraint, pin.PointAnchorConstraintModel)
        if not self.kind:
            object.__setattr__(self, "kind", "3d" if point else "6d")
        if self.kind not in CLOSURE_TYPES:
            raise InvalidInputError(
                f"closure {self.name!r} of type {self.kind!r}; expected one of "
                f"{list(CLOSURE_TYPES)}"
            )
        if isinstance(self.constraint, AnchorConstraint) and point != (self.kind == "3d"):
            raise InvalidInputError(
                f"closure {self.name!r} of type {self.kind!r} holds a "
                f"{type(self.constraint).__name__}; expected a "
                f"{CLOSURE_TYPES[self.kind].__name__}"
            )

    @property
    def size(self) -> int:
        """Number of residual rows (3, 4, 5 or 6)."""
        return len(LINEAR_ROWS[self.kind])

    @property
    def linear_rows(self) -> tuple[bool, ...]:
        """Per row, True when it is in metres, False when dimensionless [rad]."""
        return LINEAR_ROWS[self.kind]

    def on(self, model: pin.Model, end1: tuple, end2: tuple) -> Closure:
        """The same closure on ``model`` with its ends at ``end1``, ``end2`` (joint index,
        placement in that joint's frame)."""
        return Closure(type(self.constraint)(model, *end1, *end2), self.name, self.kind)


def check_name(kind: str, name) -> None:
    """:class:`InvalidInputError` unless ``name`` (of a ``kind``: frame, joint) is a str."""
    if not isinstance(name, str):
        raise InvalidInputError(f"{kind} name must be a str, got {name!r} ({type(name).__name__})")


def frame_id(model: pin.Model, name: str) -> int:
    """Index of frame ``name``; raises :class:`NameNotFoundError` listing the frames
    (:class:`InvalidInputError` when ``name`` is not a str)."""
    check_name("frame", name)
    if not model.existFrame(name):
        raise NameNotFoundError("frame", name, [f.name for f in model.frames])
    try:
        return model.getFrameId(name)
    except ValueError:  # several frames of that name (a URDF link and joint, MJCF body and site)
        return _one_of_frames(model, name)


def _one_of_frames(model: pin.Model, name: str) -> int:
    """The first of the frames named ``name`` when they are one place (a link and the
    joint that carries it), else :class:`InvalidInputError`."""
    ids = [i for i, f in enumerate(model.frames) if f.name == name]
    first = model.frames[ids[0]]
    if all(
        model.frames[i].parentJoint == first.parentJoint
        and model.frames[i].placement.isApprox(first.placement, 1e-12)
        for i in ids[1:]
    ):
        return ids[0]
    kinds = ", ".join(str(model.frames[i].type).rsplit(".", 1)[-1] for i in ids)
    raise InvalidInputError(
        f"frame name {name!r} names {len(ids)} frames at different places ({kinds}); expected "
        "the name of one frame: rename one of them in the robot file"
    )


def joint_id(model: pin.Model, name: str) -> int:
    """Index of joint ``name``; raises :class:`NameNotFoundError` listing the joints
    (:class:`InvalidInputError` when ``name`` is not a str)."""
    check_name("joint", name)
    known = model.existJointName(name)
    if known and (j := model.getJointId(name)) != 0:  # joint 0 is the universe
        return j
    if known:
        hint = "joint 0, the world: it does not move"
    elif model.existFrame(name, pin.FrameType.FIXED_JOINT):
        hint = "a fixed joint: it does not move"
    elif composite := [n for n in model.names if n.startswith("Composite_")]:
        hint = (f"Pinocchio merges the joints of one MJCF body into a composite joint, "
                f"{composite}: nest a body for each joint")  # fmt: skip
    else:
        hint = ""
    raise NameNotFoundError("joint", name, list(model.names)[1:], hint)


def closure_between_frames(model: pin.Model, frame_a: str, frame_b: str, kind: str) -> Closure:
    """Closure of type ``kind`` between frames ``frame_a`` (A) and ``frame_b`` (B).

    Args:
        model: the kinematic tree.
        frame_a, frame_b: frame names (module docstring: what each type makes hold).
        kind: one of :data:`CLOSURE_TYPES`.
    """
    if kind not in CLOSURE_TYPES:
        raise InvalidInputError(f"closure type {kind!r}; expected one of {list(CLOSURE_TYPES)}")
    fa, fb = model.frames[frame_id(model, frame_a)], model.frames[frame_id(model, frame_b)]
    constraint = CLOSURE_TYPES[kind](
        model, fa.parentJoint, fa.placement, fb.parentJoint, fb.placement
    )
    return Closure(constraint, f"{frame_a}<->{frame_b}", kind)


#: Directions of the relative motion of frame B with respect to frame A, in A's axes at
#: A's origin: translations [m], then rotations [rad]; the order of ``closure_springs``.
DIRECTIONS = ("px", "py", "pz", "rx", "ry", "rz")

#: The single-dof joint of each direction (:data:`DIRECTIONS`), about or along A's axis.
_DIRECTION_JOINTS = (
    pin.JointModelPX, pin.JointModelPY, pin.JointModelPZ,
    pin.JointModelRX, pin.JointModelRY, pin.JointModelRZ,
)  # fmt: skip

#: Per closure type, the directions (indices in :data:`DIRECTIONS`) it leaves free; the
#: universal type, whose free rotation about B's z axis is not one of A's axes, takes no
#: closure spring.
FREE_DIRECTIONS = {
    "3d": (3, 4, 5),
    "6d": (),
    "revolute": (5,),
    "prismatic": (2,),
    "cylindrical": (2, 5),
}

#: Relative asymmetry max|K - K^T| / max|K| above which a 6x6 closure spring is refused.
SYMMETRY_RTOL = 1e-9

#: Suffix of the 6-dof joint of a full 6x6 closure spring (a bushing).
BUSHING = "bushing"


def closure_spring(closure: Closure, value) -> np.ndarray:
    """The validated spring of ``closure``: (6,) diagonal or (6, 6) matrix [N/m, N/rad,
    N m/rad] (module :func:`with_elastic_closures`); a 6x6 that is diagonal is returned as
    its diagonal.

    Raises:
        InvalidInputError: naming the closure, the value and what was expected.
    """
    what = f"closure {closure.name!r} of type {closure.kind!r}"
    if closure.kind not in FREE_DIRECTIONS:
        raise InvalidInputError(
            f"{what} given the spring {value!r}; expected a spring only at a closure of type "
            f"{', '.join(map(repr, FREE_DIRECTIONS))} (the free rotation of a universal "
            "closure is not about one of frame A's axes)"
        )
    try:
        K = np.array(value, dtype=float)
    except (TypeError, ValueError):
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
        if (K < 0).any():
            raise InvalidInputError(
                f"{what} given the spring {value!r}; expected values >= 0 (0 = free, .inf = rigid)"
            )
        free_inf = [DIRECTIONS[i] for i in FREE_DIRECTIONS[closure.kind] if np.isinf(K[i])]
        if free_inf:
            raise InvalidInputError(
                f"{what} given the spring {value!r}: .inf on {free_inf}, which the type "
                "leaves free; expected a finite value there (0 = free), or a closure type "
                "that constrains it"
            )
        return K
    if not np.isfinite(K).all():
        raise InvalidInputError(
            f"{what} given the 6x6 spring {value!r} with infinite entries; expected a "
            "finite 6x6 (a full bushing), or 6 values (.inf for a rigid direction)"
        )
    scale, skew = np.max(np.abs(K)), np.max(np.abs(K - K.T))
    if skew > SYMMETRY_RTOL * scale:
        raise InvalidInputError(
            f"{what} given the 6x6 spring {value!r}, not symmetric (max |K - K^T| = "
            f"{skew:.3g}); expected a symmetric positive semi-definite matrix"
        )
    K = 0.5 * (K + K.T)
    eig = np.linalg.eigvalsh(K)
    if eig[0] < -SYMMETRY_RTOL * scale:
        raise InvalidInputError(
            f"{what} given the 6x6 spring {value!r}, not positive semi-definite "
            f"(eigenvalues {eig.tolist()}); expected a symmetric positive semi-definite matrix"
        )
    try:
        np.linalg.cholesky(K)
    except np.linalg.LinAlgError:
        raise InvalidInputError(
            f"{what} given the 6x6 spring {value!r}, singular (eigenvalues {eig.tolist()}); "
            "expected a positive definite 6x6, or 6 values (0 on a free direction)"
        ) from None
    return K


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


def with_elastic_closures(
    model: pin.Model, closures: list[Closure], springs
) -> tuple[pin.Model, list[Closure], dict[str, float | np.ndarray]]:
    """The model with the closures given a spring made elastic.

    The spring of a closure is the stiffness of the relative motion of frame B with respect
    to frame A, in A's axes at A's origin (:data:`DIRECTIONS`). Given as 6 values, each
    direction is rigid (``inf`` on a direction the closure type constrains), elastic (a
    finite value on a constrained direction, or > 0 on a free one) or free (0 on a free
    direction: the default of :data:`FREE_DIRECTIONS`, or on a constrained one). At the
    cut, on A's body at A's origin, a chain of single-dof joints, prismatic x, y, z then
    revolute x, y, z along and about A's axes, stands for the elastic and free directions
    (none for a rigid one), named ``"<closure>_<direction>"`` (``"A<->B_rz"``); an elastic
    one has its value as joint spring, a free one none (passive). The chain's end is welded
    (``6d``) to frame B. Given as a finite positive definite 6x6, a 6-dof joint (a free
    flyer) ``"<closure>_bushing"`` at A carries it as a block spring (its tangent, linear
    then angular, is in A's axes). A closure with no elastic direction is unchanged.

    The joints are at 0 where A and B coincide: the closure met as if rigid, the springs
    at rest there. For small motions about that state the springs are exactly the given
    stiffness of B's motion in A's axes at A's origin: the chain's coordinates are a local
    parametrisation of that motion (exact to first order; the spring energy, and the
    tangent terms of a loaded equilibrium, are those of the chain's coordinates).

    Args:
        model: the kinematic tree (not modified).
        closures: its closures.
        springs: closure index (0-based) -> 6 values or a 6x6 matrix [N/m, N m/rad].

    Returns:
        (the model with the closures' joints appended, the closures on it, the springs of
        those joints {joint name: stiffness, or (6, 6) block}).

    Raises:
        InvalidInputError: an index out of range, a spring of the wrong length, a 6x6 not
            symmetric positive definite or not finite, ``inf`` on a free direction, a
            spring at a universal closure.
    """
    checked = check_closure_springs(closures, springs)
    elastic = {
        i: K
        for i, K in checked.items()
        if K.ndim == 2 or any(np.isfinite(k) and (k > 0 or d not in FREE_DIRECTIONS[
            closures[i].kind]) for d, k in enumerate(K))
    }  # fmt: skip
    if not elastic:
        return model, list(closures), {}
    out_model = pin.Model(model)
    ends, out = [], {}
    for i, c in enumerate(closures):
        j1, M1 = c.constraint.joint1_id, c.constraint.joint1_placement
        end2 = (c.constraint.joint2_id, c.constraint.joint2_placement)
        if i not in elastic:
            ends.append((c.name, c.kind, (j1, M1), end2))
            continue
        K = elastic[i]
        if K.ndim == 2:
            joints = [(BUSHING, pin.JointModelFreeFlyer(), K)]
        else:
            joints = [(d, J(), k) for d, J, k in zip(DIRECTIONS, _DIRECTION_JOINTS, K,
                                                      strict=True) if np.isfinite(k)]  # fmt: skip
        for suffix, joint, k in joints:
            name = f"{c.name}_{suffix}"
            j1 = out_model.addJoint(j1, joint, M1, name)
            out_model.addJointFrame(j1)
            M1 = pin.SE3.Identity()
            if np.ndim(k) == 2 or k > 0:
                out[name] = k if np.ndim(k) == 2 else float(k)
        ends.append((c.name, "6d", (j1, M1), end2))
    closures = [
        Closure(CLOSURE_TYPES[kind](out_model, *e1, *e2), name, kind) for name, kind, e1, e2 in ends
    ]
    return out_model, closures, out


def joint_names(what: str, names) -> tuple[str, ...]:
    """``names`` (an iterable of str, not a str) as a tuple; repeated names refused."""
    if isinstance(names, str) or not isinstance(names, Iterable):
        raise InvalidInputError(
            f"{what} joints must be a list of joint names, got {names!r} ({type(names).__name__})"
        )
    names = tuple(names)
    repeated = sorted({n for n in names if isinstance(n, str) and names.count(n) > 1})
    if repeated:
        raise InvalidInputError(f"{what} joints {repeated} are listed more than once")
    return names


def checked_closures(model: pin.Model, closures) -> tuple[Closure, ...]:
    """The closures as :class:`Closure` objects, each joining two bodies of ``model``."""
    if isinstance(closures, str) or not isinstance(closures, Iterable):
        raise InvalidInputError(
            f"closures must be a list of Closure or anchor constraints, got {closures!r}"
        )
    out = []
    for i, c in enumerate(closures):
        c = c if isinstance(c, Closure) else Closure(c, f"closure{i}")
        if not isinstance(c.constraint, AnchorConstraint):
            raise InvalidInputError(
                f"closure {i} is a {type(c.constraint).__name__}; expected a Closure, a "
                "pinocchio.PointAnchorConstraintModel or a pinocchio.FrameAnchorConstraintModel"
            )
        j1, j2 = c.constraint.joint1_id, c.constraint.joint2_id
        if not (0 <= j1 < model.njoints and 0 <= j2 < model.njoints):
            raise InvalidInputError(
                f"closure {c.name!r} joins joints {j1} and {j2}, but the model has joints "
                f"0..{model.njoints - 1}: it was built for another model"
            )
        if j1 == j2:
            raise InvalidInputError(
                f"closure {c.name!r} has both ends on the body of joint {model.names[j1]!r}: "
                "a closure must join two different bodies (it would hold nothing, or never "
                "close)"
            )
        out.append(c)
    return tuple(out)
