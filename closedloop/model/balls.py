"""Ball joints in URDF files: ``balls: [joint, ...]`` in the closure file.

URDF has no spherical joint type. A joint named under ``balls`` (declared with any type
in the URDF, e.g. ``revolute`` or ``fixed`` as a placeholder, at the ball's centre) is
read as a ``floating`` joint whose three translations are locked: a ball joint, the three
rotations free (a Pinocchio free flyer: its angular velocity is in the joint's own axes,
the rotation is a quaternion, no gimbal lock). A spring given to that joint in
``springs`` acts on the three rotations: one value for all, or three.
"""

from __future__ import annotations

import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from closedloop.common.input_files import read_xml
from closedloop.exceptions import ModelFileError, did_you_mean


def urdf_with_balls(path: Path, balls: Sequence[str]) -> Path:
    """A temporary copy of URDF ``path`` with the ``balls`` joints turned floating.

    Raises:
        ModelFileError: a name that is not a joint of the file.
    """
    tree = ET.ElementTree(read_xml(path, f"robot file {str(path)!r}"))
    # the joints of the robot, not the <joint> references of its <transmission>s
    joints = {j.get("name"): j for j in tree.getroot().findall("joint")}
    for name in balls:
        if name not in joints:
            names = sorted(n for n in joints if n)
            raise ModelFileError(
                f"balls: {name!r} is not a joint of {str(path)!r}{did_you_mean(name, names)}; "
                f"expected one of {names[:12]}"
            )
        joint = joints[name]
        joint.set("type", "floating")
        for child in [c for c in joint if c.tag in ("axis", "limit", "dynamics", "mimic")]:
            joint.remove(child)
    handle = tempfile.NamedTemporaryFile(
        "wb", suffix=".urdf", dir=path.parent, prefix=f".{path.stem}-balls-", delete=False
    )  # beside the original, so that relative mesh paths still resolve
    with handle:
        tree.write(handle)
    return Path(handle.name)


def ball_springs(
    springs: dict, balls: Sequence[str], *, locked: Sequence[str] = (), keyword=(), file=None
) -> dict:
    """``springs`` with each ball's translations locked and its spring on the rotations
    (a locked ball is left to its lock).

    Args:
        springs: joint -> stiffness, the files' merged with the keyword's.
        balls: the ball joints.
        locked: joints locked whole.
        keyword: the names whose spring the caller gave (``load_model(springs=)``), for the
            message; the others are the closure file's (``file``).

    Raises:
        ModelFileError: a ball spring that is not one value or three.
    """
    out = dict(springs)
    for name in balls:
        if name in locked:
            continue
        k = out.get(name, 0.0)
        rot = list(k) if isinstance(k, list | tuple | np.ndarray) else [k] * 3
        if len(rot) != 3:
            where = "load_model springs=" if name in keyword else f"closure file {str(file)!r}"
            raise ModelFileError(
                f"{where}: ball joint {name!r} takes one stiffness or three (its rotations "
                f"[N m/rad]), got {len(rot)}"
            )
        out[name] = [float("inf")] * 3 + [float(v) for v in rot]
    return out
