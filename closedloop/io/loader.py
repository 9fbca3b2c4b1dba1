"""Loading models: URDF + closure file, MJCF with equality constraints, serial robots.

The closure file and the side file: :mod:`closedloop.io.closure_file`.

Sources of actuated joints and springs, later ones overriding earlier ones:

* URDF with a closure file: the file (no ``name_mot``: nothing actuated).
* URDF without closure file (serial robot): the 1-dof joints of the main chain, from
  the root to the first joint with several child joints, are actuated; the 1-dof joints
  beyond that branching (the Panda's fingers) are locked, so that a gripper neither adds
  inputs nor takes a joint spring, unless the keyword ``springs`` or ``actuated`` names
  them. A tree that branches at its root needs a closure file.
* MJCF: every ``<actuator>`` child with a ``joint`` attribute makes that joint actuated;
  a joint ``stiffness`` attribute > 0 (``<default>`` classes resolved) is a spring.
  Pinocchio's model does not keep either, so they are read from the XML. A side
  file in the closure-file format with only ``name_mot``/``springs``/``locked`` overrides
  them (``name_mot`` replaces the actuator list; springs are merged; locked added, a joint
  it locks losing the robot file's spring). An SDF's side file likewise.
* Keyword ``springs``: merged over all of the above.
* Keyword ``joint_stiffness``: given to every actuated joint that has no spring yet.

Parametric models: a xacro file (``*.xacro``, a URDF after :mod:`closedloop.io.xacro_files`)
with its ``<xacro:arg>`` elements, and a closure or side file with ``${expr}`` placeholders
(:mod:`closedloop.io.expressions`), take their values from the keyword ``args``.

The files of each format are read by :mod:`closedloop.io.robot_files`. The readers of a
format, of beams, balls and elastic closures are imported when a file needs them: a URDF
query loads no MJCF or SDF reader, nor beam theory without beams.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

from closedloop.common.arrays import real_number
from closedloop.common.input_files import refuse_xml_entities
from closedloop.exceptions import InvalidInputError, ModelFileError, close_names
from closedloop.io.closure_file import (
    SIDE_FILE_KEYS,
    Stiffness,
    existing_path,
    in_file,
    read_closure_file,
)
from closedloop.io.closure_file import (
    read_springs_file as read_springs_file,  # importable from here too
)
from closedloop.io.data import BUNDLED_MODELS, ROBOTS
from closedloop.io.data import (
    robot_data_dir as robot_data_dir,  # its former home; cl.robot_data_dir
)
from closedloop.io.expressions import Arguments
from closedloop.io.robot_files import read_mjcf, read_sdf, read_urdf
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.model.closures import joint_names

#: Model-file suffixes and their format.
MODEL_SUFFIXES = {".urdf": "urdf", ".xml": "mjcf", ".mjcf": "mjcf", ".sdf": "sdf",
                  ".xacro": "xacro"}  # fmt: skip


def _by_name_hint(path: str | os.PathLike) -> str:
    """Where a robot named like the command line's MODEL (``"ur5"``, ``"fourbar"``) is
    found from Python, for the message of a path without a suffix; else ""."""
    name = os.fspath(path)
    if name in ROBOTS:
        return f"; the robot {name!r} by name is cl.load_model(cl.data.robot_file({name!r}))"
    if name in BUNDLED_MODELS:
        files = ", ".join(f"cl.data.path({f!r})" for f in BUNDLED_MODELS[name] if f)
        return f"; the bundled model {name!r} is cl.load_model({files})"
    close = close_names(name, [*BUNDLED_MODELS, *ROBOTS])
    if close and not Path(name).suffix and not Path(name).exists():  # a mistyped name
        return f" (did you mean {' or '.join(map(repr, close))}?){_by_name_hint(close[0])}"
    return ""


def load_model(
    path: str | Path,
    closures: str | Path | None = None,
    *,
    springs: Mapping[str, Stiffness] | None = None,
    joint_stiffness: float | None = None,
    actuated: Sequence[str] | None = None,
    geometry: bool = True,
    file_format: str | None = None,
    free_base: bool = False,
    beams: Mapping[str, Mapping] | None = None,
    closure_springs: Mapping[int, Sequence] | None = None,
    args: Mapping[str, float] | None = None,
) -> ClosedLoopModel:
    """Load a URDF (``.urdf``), xacro (``.xacro``), MJCF (``.xml``, ``.mjcf``) or SDF
    (``.sdf``) model.

    A xacro file is a URDF with macros, properties and ``<xacro:arg>`` arguments (ROS's
    macro language), expanded with its arguments set from ``args`` once every file it
    reads is checked (:mod:`closedloop.io.xacro_files`: no code runs, no other file is
    read). A closure or side file may hold ``${expr}`` placeholders: arithmetic on the
    names of ``args`` (and the xacro file's numeric defaults), ``pi``, ``e``, ``tau`` and
    math functions (:mod:`closedloop.io.expressions`), e.g. ``d: ${0.1 * L}``.

    An SDF model's loops are its loop-closing joints and its springs the joints'
    ``spring_stiffness`` (:mod:`closedloop.io.sdf`; it names no actuated joint: give them as
    ``actuated`` or springs); its rest configuration puts the springs at their
    ``spring_reference`` (:meth:`ClosedLoopModel.reference_configuration`).

    An MJCF model's loops are its ``<equality><connect|weld>`` constraints. Pinocchio
    computes the ``<connect>`` anchor on the second body at ``qpos0``, so the file's
    reference pose must be assembled; :meth:`ClosedLoopModel.reference_configuration` returns it.

    Args:
        path: robot file.
        closures: closure file (URDF; ``None`` for a serial robot) or side file (MJCF,
            only ``name_mot``, ``springs``, ``locked``).
        springs: joint -> stiffness [N m/rad or N/m], merged over the files' springs.
        joint_stiffness: stiffness [N m/rad or N/m] of every actuated joint that has no
            spring otherwise: a number >= 0 (``math.inf`` locks them) or a string in ASCII
            decimal notation (``"1e999"``, beyond the double range, refused); not a bool.
        actuated: actuated joints, replacing those of the files or the serial default.
        geometry: also load the visual geometry (meshes must be found).
        file_format: ``"urdf"``, ``"mjcf"`` or ``"sdf"``; default: from the file suffix.
        free_base: SDF only: a free-flyer root joint instead of the root link fixed.
        beams: flexible links, link name -> beam (:mod:`closedloop.model.beams`), merged over
            the file's ``beams:``; each adds a 6-dof virtual joint ``<link>_beam`` (a list
            of beams on a link, ``<link>_beam_<end>`` each; map a
            configuration with :func:`closedloop.model.beams.map_configuration`).
        closure_springs: elastic closures, loop index (0-based: a closure file's pair, an
            MJCF equality, an SDF loop-closing joint, in file order) -> 6 stiffnesses [N/m,
            N m/rad] or a 6x6 matrix, merged over a closure file's ``closure_springs:``
            (:mod:`closedloop.model.elastic_closures`); the model's reference
            configurations (:meth:`ClosedLoopModel.reference_configuration`) are extended
            with the values of the joints added at the cuts.
        args: the values of a parametric model's arguments, name -> number (SI): a xacro
            file's ``<xacro:arg>`` elements and the closure file's placeholders' names; each must
            be used by one of the files.

    Raises:
        ModelFileError: missing or unparsable robot or closure file, unknown format; the
            message names the file and the fault.
        NameNotFoundError: a frame or joint name that the model does not have.
        InvalidInputError: a negative or NaN stiffness given as keyword; a path that is
            not a str or os.PathLike; an argument of ``args`` that is not a finite number
            or that no file uses.
        ExpressionError: a placeholder or xacro expression that is refused or has no
            value, a missing argument; the message names the file, the line and the name.
    """
    for name, value in (("path", path), ("closures", closures)):
        if not isinstance(value, str | os.PathLike) and (name == "path" or value is not None):
            raise InvalidInputError(
                f"load_model: {name} must be a file path (str or os.PathLike), got {value!r}"
            )
    for name, value, what in (("springs", springs, "joint name -> stiffness"),
                              ("beams", beams, "link name -> beam"),
                              ("closure_springs", closure_springs, "index -> spring")):  # fmt: skip
        if value is not None and not isinstance(value, Mapping):
            raise InvalidInputError(
                f"load_model: {name} must be a mapping {what}, got {type(value).__name__}"
            )
    arguments = Arguments(args)
    kind = file_format or MODEL_SUFFIXES.get(Path(path).suffix.lower())
    if kind not in ("urdf", "mjcf", "sdf", "xacro") or (free_base and kind != "sdf"):
        raise ModelFileError(
            f"robot file {str(path)!r}: unknown format {kind or Path(path).suffix!r}; expected "
            f"a suffix {', '.join(MODEL_SUFFIXES)} or file_format 'urdf', 'mjcf', 'sdf' or "
            "'xacro' (free_base: SDF only)" + _by_name_hint(path)
        )
    path = existing_path(path, "robot file")
    if kind == "sdf":
        tree = read_sdf(path, closures, geometry, free_base, arguments)
    elif kind == "mjcf":
        tree = read_mjcf(path, closures, geometry, arguments)
    else:
        tree = read_urdf(path, closures, geometry, beams or {}, closure_springs, arguments,
                         xacro=kind == "xacro")  # fmt: skip
    if tree.visual is not None:  # read by Pinocchio, whose assimp expands no entity
        meshes = (g.meshPath for g in tree.visual.geometryObjects)
        refuse_xml_entities(meshes, f"robot file {str(path)!r}")
    if actuated is None and tree.undriven:
        raise ModelFileError(
            f"robot file {str(path)!r}: actuator(s) {list(tree.undriven)} drive no joint "
            "directly; list the actuated joints (name_mot in a side file, or actuated=)"
        )
    locked = tree.locked
    if tree.by_default:  # a joint named by a keyword is no longer locked by the default
        named = {*(springs or {}), *(() if actuated is None else actuated)}
        locked = tuple(n for n in locked if n not in named)
    clash = sorted(set(springs or {}) & set(tree.beam_joints))
    if clash:
        raise InvalidInputError(
            f"load_model: springs name the beam joint(s) {clash}, whose stiffness is their "
            "beam's (give E, G and section, or stiffness_6x6, in beams=)"
        )
    actuated = tree.actuated if actuated is None else joint_names("actuated", actuated)
    given = tuple(springs or ())
    springs = {**tree.springs, **(springs or {})}
    if joint_stiffness is not None:
        try:
            k = real_number(joint_stiffness)  # not np.bool_(True), nor "1e999"
        except (TypeError, ValueError):
            k = math.nan
        if math.isnan(k) or k < 0:
            raise InvalidInputError(
                f"joint stiffness {joint_stiffness!r}; expected a number >= 0 "
                "[N m/rad or N/m] (0 = passive, inf = locked)"
            )
        for name in actuated:
            springs.setdefault(name, k)
    if tree.balls:  # the keyword's springs of a ball too: on its rotations, as the file's
        from closedloop.model.balls import ball_springs

        springs = ball_springs(springs, tree.balls, locked=locked, keyword=given, file=closures)
    clm = ClosedLoopModel(
        tree.model,
        tree.loops,
        actuated,
        springs,
        locked,
        visual_model=tree.visual,
        beam_masses=dict(tree.beam_masses),
        unweighed_bodies=dict(tree.unweighed),
    )
    if kind not in ("urdf", "xacro"):  # MJCF, SDF: the beams of the side file and the keyword
        side = read_closure_file(closures, SIDE_FILE_KEYS, arguments).beams if closures else {}
        if side or beams:
            clm = clm.with_beams({**side, **(beams or {})})
        if closure_springs:
            clm = _with_closure_springs(clm, closure_springs, path)
    arguments.check_used([str(path), *([str(closures)] if closures else [])])
    return clm


def _with_closure_springs(clm: ClosedLoopModel, springs: Mapping, path: Path) -> ClosedLoopModel:
    """An MJCF or SDF model with the closures of ``springs`` made elastic
    (:meth:`ClosedLoopModel.with_closure_springs`), refused on a loop that the file made
    elastic already (an SDF loop joint's spring)."""
    from closedloop.model.elastic_closures import check_closure_springs

    with in_file(f"robot file {str(path)!r}, closure_springs= of load_model"):
        checked = check_closure_springs(list(clm.closures), springs)
        taken = sorted(i for i in checked if clm.closures[i].cut)
        if taken:
            raise InvalidInputError(
                f"closure_springs given to the loops {taken} ("
                f"{[clm.closures[i].name for i in taken]}), whose loop-closing joints have "
                "a spring in the file; expected closure springs only for loops without one"
            )
        return clm.with_closure_springs(checked)


def load_urdf(urdf: str | Path, closures: str | Path | None = None, **options) -> ClosedLoopModel:
    """:func:`load_model` for a URDF file, whatever its suffix (same keyword options)."""
    return load_model(urdf, closures, file_format="urdf", **options)
