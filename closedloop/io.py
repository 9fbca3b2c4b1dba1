"""Loading models: URDF + closure file, MJCF with equality constraints, example robots.

Closure file (YAML), after the "Extended URDF" convention, extended with springs::

    closed_loop: [[frameA, frameB], ...]   # frame pairs made to coincide
    type: ['3d' | '6d', ...]               # point or weld, one per pair
    name_mot: [joint, ...]                 # actuated joints
    springs: {joint: stiffness, ...}       # optional [N m/rad or N/m]; list per coordinate
    locked: [joint, ...]                   # optional rigid joints
"""

from __future__ import annotations

import importlib.metadata
from dataclasses import dataclass, field
from pathlib import Path

import pinocchio as pin
import yaml

from .exceptions import ModelFileError
from .model import ClosedLoopModel, closure_between_frames


@dataclass(frozen=True)
class ClosureSpec:
    """Contents of a closure file (see the module docstring)."""

    pairs: tuple[tuple[str, str], ...] = ()
    types: tuple[str, ...] = ()
    actuated: tuple[str, ...] = ()
    springs: dict = field(default_factory=dict)
    locked: tuple[str, ...] = ()


def _existing(path: str | Path, what: str) -> Path:
    path = Path(path)
    if not path.is_file():
        raise ModelFileError(f"{what} {str(path)!r} does not exist or is not a file")
    return path


def read_closure_file(path: str | Path) -> ClosureSpec:
    """Parse and validate a closure file; raises :class:`ModelFileError` naming the fault."""
    path = _existing(path, "closure file")
    try:
        doc = yaml.safe_load(path.read_text())
    except yaml.YAMLError as e:
        raise ModelFileError(f"closure file {str(path)!r} is not valid YAML: {e}") from None
    if not isinstance(doc, dict):
        raise ModelFileError(f"closure file {str(path)!r}: expected a mapping at top level")
    unknown = set(doc) - {"closed_loop", "type", "name_mot", "springs", "locked"}
    if unknown:
        raise ModelFileError(
            f"closure file {str(path)!r}: unknown key(s) {sorted(unknown)}; expected "
            "closed_loop, type, name_mot, springs, locked"
        )
    pairs = doc.get("closed_loop") or []
    types = doc.get("type") or []
    if not isinstance(pairs, list) or any(
        not isinstance(p, list | tuple) or len(p) != 2 or not all(isinstance(n, str) for n in p)
        for p in pairs
    ):
        raise ModelFileError(
            f"closure file {str(path)!r}: closed_loop must be a list of [frameA, frameB] "
            f"name pairs, got {pairs!r}"
        )
    if not isinstance(types, list) or len(types) != len(pairs):
        raise ModelFileError(
            f"closure file {str(path)!r}: type must list one of '3d'/'6d' per closed_loop "
            f"pair ({len(pairs)}), got {types!r}"
        )
    bad = [t for t in types if t not in ("3d", "6d")]
    if bad:
        raise ModelFileError(f"closure file {str(path)!r}: type {bad[0]!r}; expected '3d' or '6d'")
    springs = doc.get("springs") or {}
    if not isinstance(springs, dict):
        raise ModelFileError(
            f"closure file {str(path)!r}: springs must be a mapping joint -> value"
        )
    names = doc.get("name_mot") or []
    locked = doc.get("locked") or []
    for key, val in (("name_mot", names), ("locked", locked)):
        if not isinstance(val, list) or not all(isinstance(n, str) for n in val):
            raise ModelFileError(f"closure file {str(path)!r}: {key} must be a list of joint names")
    return ClosureSpec(
        tuple(tuple(p) for p in pairs), tuple(types), tuple(names), dict(springs), tuple(locked)
    )


def load_urdf(
    urdf: str | Path,
    closures: str | Path | None = None,
    *,
    springs: dict | None = None,
    actuated: tuple[str, ...] | None = None,
) -> ClosedLoopModel:
    """Load a URDF tree and (optionally) its closure file.

    Args:
        urdf: path of the URDF file.
        closures: path of the closure file; ``None`` for a serial robot.
        springs: joint -> stiffness, overriding the closure file's entries.
        actuated: actuated joints, overriding ``name_mot`` (default for a serial robot
            without closure file: every 1-dof joint).
    """
    urdf = _existing(urdf, "robot file")
    try:
        model = pin.buildModelFromUrdf(str(urdf))
        visual = pin.buildGeomFromUrdf(
            model,
            str(urdf),
            pin.GeometryType.VISUAL,
            package_dirs=[
                str(urdf.parent),
                str(urdf.parent.parent),
                str(urdf.parent.parent.parent),
            ],
        )
    except (RuntimeError, ValueError) as e:
        raise ModelFileError(f"robot file {str(urdf)!r} cannot be parsed: {e}") from None
    spec = read_closure_file(closures) if closures is not None else ClosureSpec()
    loops = [
        closure_between_frames(model, a, b, t)
        for (a, b), t in zip(spec.pairs, spec.types, strict=True)
    ]
    if actuated is None:
        actuated = (
            spec.actuated
            if closures is not None
            else tuple(model.names[j] for j in range(1, model.njoints) if model.joints[j].nq == 1)
        )
    all_springs = {**spec.springs, **(springs or {})}
    return ClosedLoopModel(
        model, loops, actuated, all_springs, spec.locked, visual_model=visual, name=model.name
    )


def robot_data_dir() -> Path:
    """Folder ``robots/`` of the installed example-robot-data distribution.

    The package ships no Python module, only files under its cmeel prefix; they are
    located through the distribution's file list.
    """
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        raise ModelFileError("example-robot-data is not installed") from None
    for f in dist.files or ():
        parts = Path(f).parts
        if "example-robot-data" in parts and "robots" in parts:
            i = parts.index("robots")
            return Path(dist.locate_file(Path(*parts[: i + 1])))
    raise ModelFileError("example-robot-data is installed but its robots folder was not found")
