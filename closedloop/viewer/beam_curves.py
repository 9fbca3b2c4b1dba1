"""Flexible links (the beams of :mod:`closedloop.model.beams`) as the viewer draws them.

The link's mesh stays rigid with the beam's clamped start and its ``end`` rides on the
tip, and between them the beam's axis is the cubic Hermite curve of :func:`beam_curves`
from the start (the link frame origin, tangent along the undeflected beam) to the tip (the
virtual joint's origin, tangent along the undeflected beam turned by the tip's rotation),
both tangents of the beam's length L. To first order in the tip's deflection this is the
Euler-Bernoulli deflection line of a clamped beam loaded at its tip (a cubic: it has the
tip's displacement and slope), e.g. 5 F L^3 / (48 E I) at mid-length under a tip force F;
an unloaded beam is the straight segment from start to tip.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import readonly
from closedloop.model.beam_joints import inserted_beams
from closedloop.viewer.motion import frame_pose

#: Points of each drawn beam curve, start and tip included (evenly spaced parameter).
BEAM_POINTS = 13


@dataclass(frozen=True)
class BeamCurve:
    """A flexible link's axis as drawn: ``name`` its virtual joint, ``points`` (n, 3) [m],
    world frame, from the clamped start to the tip (the curve of :func:`beam_curves`)."""

    name: str
    points: np.ndarray


def beam_curves(model: pin.Model, poses: np.ndarray, n: int = BEAM_POINTS) -> tuple:
    """The beams of ``model`` with its joints at ``poses`` (njoints, 4, 4) (world
    placements, as drawn) as :class:`BeamCurve` of n points: the cubic Hermite curve
    p(u) = h00 p0 + h10 d0 + h01 p1 + h11 d1, u in [0, 1] (module docstring), with p0, p1
    the start and tip [m] and d0, d1 the tangents [m] (world frame)."""
    u = np.linspace(0.0, 1.0, n)[:, None]
    h00, h10, h01, h11 = (
        2 * u**3 - 3 * u**2 + 1,
        u**3 - 2 * u**2 + u,
        3 * u**2 - 2 * u**3,
        u**3 - u**2,
    )
    out = []
    for b in inserted_beams(model):
        start, tip = frame_pose(model, poses, b.link_frame), poses[b.joint]
        d0 = start[:3, :3] @ b.rest.translation
        d1 = tip[:3, :3] @ (b.rest.rotation.T @ b.rest.translation)
        p = h00 * start[:3, 3] + h10 * d0 + h01 * tip[:3, 3] + h11 * d1
        out.append(BeamCurve(b.name, readonly(p)))
    return tuple(out)
