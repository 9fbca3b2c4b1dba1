"""Loop closures and the names they join: a closure is a Pinocchio 4 anchor constraint
(:class:`pinocchio.PointAnchorConstraintModel` for a 3D point,
:class:`pinocchio.FrameAnchorConstraintModel` for a 6D weld) with a display name; frames and
joints are looked up by name with errors that list the valid ones.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import pinocchio as pin

from closedloop.exceptions import InvalidInputError, NameNotFoundError

AnchorConstraint = pin.PointAnchorConstraintModel | pin.FrameAnchorConstraintModel

#: Closure types of the closure-file convention and their Pinocchio constraint.
CLOSURE_TYPES = {"3d": pin.PointAnchorConstraintModel, "6d": pin.FrameAnchorConstraintModel}


@dataclass(frozen=True)
class Closure:
    """One loop closure: a Pinocchio anchor constraint and a display name."""

    constraint: AnchorConstraint
    name: str

    @property
    def kind(self) -> str:
        """``"3d"`` (point) or ``"6d"`` (frame weld)."""
        return "3d" if isinstance(self.constraint, pin.PointAnchorConstraintModel) else "6d"

    @property
    def size(self) -> int:
        """Number of residual rows (3 or 6)."""
        return self.constraint.residualSize()


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
    """Closure that makes frames ``frame_a`` and ``frame_b`` coincide.

    Args:
        model: the kinematic tree.
        frame_a, frame_b: frame names; for ``"3d"`` their origins coincide, for ``"6d"``
            their whole placements do.
        kind: ``"3d"`` or ``"6d"``.
    """
    if kind not in CLOSURE_TYPES:
        raise InvalidInputError(f"closure type {kind!r}; expected one of {sorted(CLOSURE_TYPES)}")
    fa, fb = model.frames[frame_id(model, frame_a)], model.frames[frame_id(model, frame_b)]
    constraint = CLOSURE_TYPES[kind](
        model, fa.parentJoint, fa.placement, fb.parentJoint, fb.placement
    )
    return Closure(constraint, f"{frame_a}<->{frame_b}")


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
