"""A model without visual geometry drawn as its skeleton: a sphere at each joint, a rod from
each joint's origin to the origins of the joints and frames its body carries.

The skeleton is a Pinocchio ``GeometryModel`` of coal primitives (spheres and cylinders),
each object fixed to its parent joint, so the viewer draws and moves it as any visual
model: the nominal and the deflected robot, the colours by displacement, the animation
(:mod:`closedloop.viewer.mesh`). A rod of the universe runs from the world origin to a
first joint (the fixed base); a point that coincides with the joint's origin gets no rod.
"""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin

from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.viewer.scene import model_size

#: Radius of a joint's sphere and of a rod, per model size L (:func:`model_size` at the
#: model's reference configuration).
JOINT_FRACTION, ROD_FRACTION = 0.02, 0.008
#: Colours (RGBA, 0..1) of the joints' spheres and of the rods.
JOINT_RGBA, ROD_RGBA = (0.85, 0.55, 0.2, 1.0), (0.45, 0.5, 0.6, 1.0)
#: Distance below which a point counts as the joint's origin or as a point already joined,
#: per model size L (rounding of the placements' products).
SAME_POINT = 1e-9
#: Frames that end a rod: the frames a body carries (its links, fixed links, operational
#: frames such as sites, loaded frames and closure frames), not the joints' own.
ROD_FRAMES = (pin.FrameType.BODY, pin.FrameType.FIXED_JOINT, pin.FrameType.OP_FRAME,
              pin.FrameType.SENSOR)  # fmt: skip
_Z = np.array([0.0, 0.0, 1.0])


def _rod_placement(tip: np.ndarray) -> pin.SE3:
    """Placement of a coal cylinder (axis z, centred on its origin) from 0 to ``tip`` (3,)."""
    rotation = pin.Quaternion.FromTwoVectors(_Z, tip / np.linalg.norm(tip)).matrix()
    return pin.SE3(rotation, 0.5 * tip)


def _add(skeleton: pin.GeometryModel, name: str, joint: int, placement: pin.SE3, shape,
         rgba) -> None:  # fmt: skip
    g = pin.GeometryObject(name, joint, placement, shape)
    g.meshColor = np.array(rgba, dtype=float)
    skeleton.addGeometryObject(g)


def _body_points(model: pin.Model) -> list[list[tuple[str, np.ndarray]]]:
    """Per joint (the universe too): (name, (3,) position [m] in the joint's frame) of the
    origins of its child joints and of its :data:`ROD_FRAMES` frames."""
    points: list[list] = [[] for _ in range(model.njoints)]
    for j in range(1, model.njoints):
        points[model.parents[j]].append((model.names[j], model.jointPlacements[j].translation))
    for f in model.frames:
        if f.type in ROD_FRAMES:
            points[f.parentJoint].append((f.name, f.placement.translation))
    return points


def skeleton_model(clm: ClosedLoopModel) -> pin.GeometryModel:
    """The skeleton of ``clm`` (module docstring), sized by its model size L at its
    reference configuration: spheres of radius :data:`JOINT_FRACTION` L named
    ``joint <name>``, rods of radius :data:`ROD_FRACTION` L named ``rod <joint> to
    <joint or frame>``."""
    model = clm.model
    size = model_size(clm, clm.reference_configuration())
    skeleton = pin.GeometryModel()
    for j in range(1, model.njoints):
        sphere = coal.Sphere(JOINT_FRACTION * size)
        _add(skeleton, f"joint {model.names[j]}", j, pin.SE3.Identity(), sphere, JOINT_RGBA)
    for j, points in enumerate(_body_points(model)):
        joined: list[np.ndarray] = [np.zeros(3)]
        for name, tip in points:
            if min(np.linalg.norm(tip - p) for p in joined) <= SAME_POINT * size:
                continue
            joined.append(tip)
            rod = coal.Cylinder(ROD_FRACTION * size, float(np.linalg.norm(tip)))
            _add(skeleton, f"rod {model.names[j]} to {name}", j, _rod_placement(tip), rod, ROD_RGBA)
    return skeleton
