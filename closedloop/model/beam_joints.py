"""The beams of a model, recognised by its structure: the virtual joints that
:func:`closedloop.model.beams.apply_beams` inserts (free flyers that carry no BODY frame,
named after their link). Apart from the beam theory, so that a command that only lists a
model's joints (``closedloop info``) does not import it.
"""

from __future__ import annotations

from dataclasses import dataclass

import pinocchio as pin


@dataclass(frozen=True)
class InsertedBeam:
    """A beam of a model built by :func:`closedloop.model.beams.apply_beams`: its virtual joint
    ``joint`` (index) named ``name``, the link's frame ``link_frame`` (index, the beam's clamped
    start), and ``rest`` the virtual joint's placement at rest in the link frame (its
    translation, (3,) [m], is the undeflected beam from start to tip)."""

    name: str
    link_frame: int
    joint: int
    rest: pin.SE3


def virtual_frames(model: pin.Model) -> set[int]:
    """The JOINT frames that may be beams' virtual joints, whatever their names: those of free
    flyers from which no BODY frame hangs. Every joint a robot file's parser builds carries the
    BODY frame of its child link; :func:`closedloop.model.beams.apply_beams` gives its virtual
    joints none (the frames they carry keep their parent frames)."""
    bodies = {f.parentFrame for f in model.frames if f.type == pin.BODY}
    return {
        i for i, f in enumerate(model.frames)
        if f.type == pin.JOINT and i not in bodies
        and model.joints[f.parentJoint].shortname() == "JointModelFreeFlyer"
    }  # fmt: skip


def beam_link(model: pin.Model, frame: int, virtual: set[int]) -> str | None:
    """The link of the beam whose virtual joint has the JOINT frame ``frame`` (index): the BODY
    frame reached through its parent frames, all ``virtual`` (:func:`virtual_frames`) and named
    ``<link>_beam`` or ``<link>_beam_*``; None if there is none."""
    chain = []
    while frame in virtual:
        chain.append(model.frames[frame].name)
        frame = model.frames[frame].parentFrame
    link = model.frames[frame]
    if not chain or link.type != pin.BODY:
        return None
    ok = all(n == f"{link.name}_beam" or n.startswith(f"{link.name}_beam_") for n in chain)
    return link.name if ok else None


def inserted_beams(model: pin.Model) -> list[InsertedBeam]:
    """The beams (their elements) of ``model``, as :func:`closedloop.model.beams.apply_beams`
    builds them: the JOINT frames of its virtual joints (free flyers that carry no BODY frame),
    each on the joint's parent joint, whose parent frame (``link_frame``, the beam's or
    element's start) is the link's body frame or the frame of another virtual joint of the link,
    all named ``<link>_beam`` or ``<link>_beam_*``. An ordinary joint so named is no beam."""
    out, virtual = [], virtual_frames(model)
    for i in sorted(virtual):
        f = model.frames[i]
        start = model.frames[f.parentFrame]
        j = f.parentJoint
        if start.parentJoint == model.parents[j] and beam_link(model, i, virtual) is not None:
            rest = start.placement.actInv(model.jointPlacements[j])
            out.append(InsertedBeam(f.name, f.parentFrame, j, rest))
    return out
