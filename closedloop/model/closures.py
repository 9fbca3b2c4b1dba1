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

A closure may be made elastic (:mod:`closedloop.model.elastic_closures`). The closures of a
model have a name each: a second closure of the same name (the same pair of frames listed
twice) is named ``<name>#2`` (:func:`distinct_names`).

The rows themselves are built in :mod:`closedloop.kinematics.constraints`. Frames and
joints are looked up by name with errors that list the valid ones.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, replace

import pinocchio as pin

from closedloop.exceptions import InvalidInputError, NameNotFoundError, did_you_mean

#: Pinocchio's constraint of a closure: a point (``3d``) or a frame (the other types).
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
        name: display name (one a closure of a model: :func:`checked_closures`).
        kind: one of :data:`CLOSURE_TYPES`; empty: ``"3d"`` for a point anchor, ``"6d"``
            for a frame anchor.
        cut: the names of the joints that carry the spring of an elastic closure, the
            constraint closing their chain (:mod:`closedloop.model.elastic_closures`);
            empty for a rigid closure.
    """

    constraint: AnchorConstraint
    name: str
    kind: str = ""
    cut: tuple[str, ...] = ()

    def __post_init__(self):
        point = isinstance(self.constraint, pin.PointAnchorConstraintModel)
        if not self.kind:
            object.__setattr__(self, "kind", "3d" if point else "6d")
        if self.kind not in CLOSURE_TYPES:
            raise InvalidInputError(f"closure {self.name!r} of {unknown_type(self.kind)}")
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
        constraint = type(self.constraint)(model, *end1, *end2)
        return Closure(constraint, self.name, self.kind, self.cut)


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


def unknown_type(kind) -> str:
    """The message's words for a closure type that is not one of :data:`CLOSURE_TYPES`:
    ``"type '3D' (did you mean '3d'?); expected one of [...]"``."""
    expected = list(CLOSURE_TYPES)
    return f"type {kind!r}{did_you_mean(kind, expected)}; expected one of {expected}"


def closure_between_frames(model: pin.Model, frame_a: str, frame_b: str, kind: str) -> Closure:
    """Closure of type ``kind`` between frames ``frame_a`` (A) and ``frame_b`` (B).

    Args:
        model: the kinematic tree.
        frame_a, frame_b: frame names (module docstring: what each type makes hold).
        kind: one of :data:`CLOSURE_TYPES`.
    """
    if kind not in CLOSURE_TYPES:
        raise InvalidInputError(f"closure {unknown_type(kind)}")
    fa, fb = model.frames[frame_id(model, frame_a)], model.frames[frame_id(model, frame_b)]
    constraint = CLOSURE_TYPES[kind](
        model, fa.parentJoint, fa.placement, fb.parentJoint, fb.placement
    )
    return Closure(constraint, f"{frame_a}<->{frame_b}", kind)


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


def distinct_names(closures: Iterable[Closure]) -> list[Closure]:
    """``closures`` with a name each: the second of a name (two closures of one pair of
    frames, ``A<->B``) renamed ``<name>#2``, the third ``<name>#3``, ... (the joints at an
    elastic closure's cut are named after it)."""
    closures = list(closures)
    taken, out = {c.name for c in closures}, []
    for c in closures:
        if any(c.name == d.name for d in out):
            n = 2
            while f"{c.name}#{n}" in taken:
                n += 1
            c = replace(c, name=f"{c.name}#{n}")
            taken.add(c.name)
        out.append(c)
    return out


def checked_closures(model: pin.Model, closures) -> tuple[Closure, ...]:
    """The closures as :class:`Closure` objects, each joining two bodies of ``model``, one
    name a closure (:func:`distinct_names`)."""
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
    return tuple(distinct_names(out))
