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
  Pinocchio's model does not keep either, so they are read from the XML here. A side
  file in the closure-file format with only ``name_mot``/``springs``/``locked`` overrides
  them (``name_mot`` replaces the actuator list; springs are merged; locked added, a joint
  it locks losing the robot file's spring). An SDF's side file likewise.
* Keyword ``springs``: merged over all of the above.
* Keyword ``joint_stiffness``: given to every actuated joint that has no spring yet.

Parametric models: a xacro file (``*.xacro``, a URDF after :mod:`closedloop.io.xacro_files`)
with its ``<xacro:arg>`` elements, and a closure or side file with ``${expr}`` placeholders
(:mod:`closedloop.io.expressions`), take their values from the keyword ``args``.

The readers of a format, of beams, balls and elastic closures are imported when a file
needs them: a URDF query loads no MJCF or SDF reader, nor beam theory without beams.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import threading
import xml.etree.ElementTree as ET
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import real_number
from closedloop.common.input_files import read_xml, refuse_xml_entities
from closedloop.exceptions import InvalidInputError, ModelFileError, close_names
from closedloop.io.closure_file import (
    SIDE_FILE_KEYS,
    ClosureSpec,
    Stiffness,
    apply_start,
    check_spec_names,
    existing_path,
    file_number,
    in_file,
    read_closure_file,
    read_side_file,
)
from closedloop.io.closure_file import (
    read_springs_file as read_springs_file,  # importable from here too
)
from closedloop.io.data import BUNDLED_MODELS, ROBOTS
from closedloop.io.data import (
    robot_data_dir as robot_data_dir,  # its former home; cl.robot_data_dir
)
from closedloop.io.expressions import Arguments
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.model.closures import Closure, closure_between_frames, joint_names
from closedloop.model.reference import REST

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


# ------------------------------------------------------------------------ model files
#: Held while a parser's native output is captured (:func:`_parse`).
_PARSE_LOCK = threading.Lock()


def _parse(build: Callable, path: Path, what: str):
    """Run a Pinocchio parser; a failure becomes a one-line :class:`ModelFileError`.

    What the parser's native code writes on file descriptor 2 is captured. urdfdom's
    "Error:" lines are folded into the message of a failure, and make one of a success
    (urdfdom then has dropped the element, e.g. an inertial whose mass is not a number);
    other lines are passed on to ``sys.stderr``.
    """
    sys.stderr.flush()
    failure = None
    # file descriptor 2 is the process's: one parser at a time redirects it (two threads
    # loading models at once would each restore the other's file, leaving it in place)
    with _PARSE_LOCK, _scratch_file() as tmp:
        saved = os.dup(2)
        os.dup2(tmp.fileno(), 2)
        try:
            result = build()
        except (RuntimeError, ValueError, IndexError) as e:  # IndexError: a missing map key
            failure = e
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        tmp.seek(0)
        native = tmp.read().decode(errors="replace")
    details = [ln.strip() for ln in native.splitlines() if ln.strip().startswith("Error:")]
    detail = "; ".join(ln.removeprefix("Error:").strip() for ln in details[-2:])
    if failure is None and not details:
        sys.stderr.write(native)
        return result
    msg = " ".join(f"{failure or 'an element is dropped:'} {detail}".split())
    raise ModelFileError(f"{what} {str(path)!r} cannot be parsed: {msg}")


def _scratch_file():
    """An anonymous file in memory (Linux), else a temporary file: what a parser writes."""
    try:
        return open(os.memfd_create("closedloop-parser"), "w+b")
    except (AttributeError, OSError):  # not on Linux, or not allowed
        pass
    import tempfile  # with shutil, bz2, lzma...: on demand

    return tempfile.TemporaryFile()


def _geometry(wanted: bool, build: Callable, path: Path) -> pin.GeometryModel | None:
    return _parse(build, path, "geometry of robot file") if wanted else None


def _package_dirs(path: Path) -> list[str]:
    # ``package://pkg/...`` resolves against any folder that holds ``pkg``: try every
    # ancestor of the file (example-robot-data uses package://example-robot-data/robots/...).
    return [str(p) for p in path.resolve().parents]


def _serial_defaults(model: pin.Model, path: Path) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(actuated, locked) joints of a robot file without closures (module docstring)."""
    chain, j = [], 0
    while len(model.children[j]) == 1:
        j = model.children[j][0]
        chain.append(j)
    if model.njoints > 1 and not chain:
        raise ModelFileError(
            f"robot file {str(path)!r} branches at its root: give a closure file that lists "
            "the actuated joints (name_mot)"
        )
    one_dof = [k for k in range(1, model.njoints) if model.joints[k].nv == 1]  # continuous too
    actuated = tuple(model.names[k] for k in one_dof if k in chain)
    locked = tuple(model.names[k] for k in one_dof if k not in chain)
    return actuated, locked


@dataclass(frozen=True)
class _Tree:
    """What a robot file gives before the keyword overrides of :func:`load_model`."""

    model: pin.Model
    loops: list[Closure]
    actuated: tuple[str, ...]
    springs: dict[str, Stiffness]
    locked: tuple[str, ...]
    visual: pin.GeometryModel | None
    undriven: tuple[str, ...] = ()  # MJCF actuators that name no joint
    by_default: bool = False  # locked by the serial robot's default, not by a file
    beam_joints: tuple[str, ...] = ()  # virtual joints of the beams (URDF), springs of their own
    balls: tuple[str, ...] = ()  # URDF joints read as balls: their springs on the rotations
    beam_masses: tuple = ()  # (virtual joint name, closedloop.model.beams.BeamMass) of the beams
    unweighed: tuple = ()  # MJCF: (body name, why Pinocchio's inertia of it is wrong)


def _read_urdf(
    path: Path, closures: str | Path | None, geometry: bool, beams=None, elastic=None,
    arguments: Arguments | None = None, xacro: bool = False,
) -> _Tree:  # fmt: skip
    with contextlib.ExitStack() as stack:
        source = path
        if xacro:  # expanded first: its arguments' defaults are the placeholders' too
            from closedloop.io.xacro_files import expanded_urdf

            source = stack.enter_context(expanded_urdf(path, arguments or Arguments()))
        spec = read_closure_file(closures, arguments=arguments) if closures else ClosureSpec()
        if spec.balls:
            from closedloop.model.balls import urdf_with_balls

            source = urdf_with_balls(source, spec.balls)
            stack.callback(source.unlink)
        return _read_urdf_tree(source, spec, closures, geometry, beams, elastic, shown=path)


def _read_urdf_tree(
    path: Path, spec, closures, geometry: bool, beams, elastic, shown=None
) -> _Tree:
    root = read_xml(path, f"robot file {str(shown or path)!r}")  # before Pinocchio reads it
    # mimic joints follow their leader (nq = nv = 0), as the file says
    build = lambda: pin.buildModelFromUrdf(str(path), mimic=True)  # noqa: E731
    model = _parse(build, shown or path, "robot file")
    _check_connected(model, root, shown or path)
    _check_masses(model, shown or path)
    _check_limits(model, shown or path)
    visual = _geometry(
        geometry,
        lambda: pin.buildGeomFromUrdf(
            model, str(path), pin.GeometryType.VISUAL, package_dirs=_package_dirs(path)
        ),
        path,
    )
    tree, blocks, masses = model, {}, {}
    if spec.beams or beams:  # before the closures, whose frames may sit at beam tips
        from closedloop.model.beams import apply_beams

        both = {**spec.beams, **beams}
        model, (visual,), blocks, _, masses = apply_beams(model, [visual], both, urdf=path)
    clash = sorted(set(spec.springs) & set(blocks))
    if clash:
        raise ModelFileError(
            f"closure file {str(closures)!r}: springs name the beam joint(s) {clash}, whose "
            "stiffness is their beam's (E, G and section, or stiffness_6x6, under beams:)"
        )
    if closures is None:
        if elastic:
            raise InvalidInputError(
                f"load_model: closure_springs {elastic!r} given to a robot without closure "
                "file; expected closure springs only for the pairs of a closure file"
            )
        actuated, locked = _serial_defaults(tree, path)
        return _Tree(model, [], actuated, blocks, locked, visual, by_default=True,
                     beam_joints=tuple(blocks), beam_masses=tuple(masses.items()))  # fmt: skip
    from closedloop.model.elastic_closures import check_closure_springs, with_elastic_closures

    where = f"closure file {str(closures)!r}"
    check_spec_names(model, spec, where)
    apply_start(model, spec, where)  # before the cut's joints, which extend it
    with in_file(where):
        loops = [
            closure_between_frames(model, a, b, t)
            for (a, b), t in zip(spec.pairs, spec.types, strict=True)
        ]
        check_closure_springs(loops, spec.closure_springs)
    with in_file(f"{where}, closure_springs= of load_model"):
        check_closure_springs(loops, elastic or {})
    merged = {**spec.closure_springs, **(elastic or {})}
    if merged:  # the drawing, with the cut's joints closing it, starts the assembly
        model.referenceConfigurations[REST] = pin.neutral(model)
    with in_file(where):
        model, loops, cuts = with_elastic_closures(model, loops, merged)
    return _Tree(model, loops, spec.actuated or (), {**spec.springs, **blocks, **cuts}, spec.locked,
                 visual, beam_joints=tuple(blocks), balls=spec.balls,
                 beam_masses=tuple(masses.items()))  # fmt: skip


def _check_connected(model: pin.Model, root: ET.Element, shown: Path) -> None:
    """:class:`ModelFileError` for links of the URDF file (``root``, its root element) that
    the model lacks: those whose parent joints form a cycle away from the root (Pinocchio
    drops them)."""
    links = [link.get("name") for link in root.iter("link")]
    lost = [name for name in links if name and not model.existBodyName(name)]
    if lost:
        raise ModelFileError(
            f"robot file {str(shown)!r}: links {lost} are not connected to the root (their "
            "parent joints form a cycle); expected a tree, loops closed by a closure file"
        )


def _check_masses(model: pin.Model, path: Path) -> None:
    """:class:`ModelFileError` for a body of negative mass (the links a joint carries,
    merged by Pinocchio; the ground's too): the weight would pull it up."""
    for j in range(model.njoints):
        mass = model.inertias[j].mass
        if not mass >= 0.0:
            raise ModelFileError(
                f"robot file {str(path)!r}: the links of joint {model.names[j]!r} have mass "
                f"{mass:.6g} kg; expected masses >= 0"
            )


def _check_limits(model: pin.Model, path: Path) -> None:
    """:class:`ModelFileError` for a joint whose lower position limit exceeds its upper one."""
    lower, upper = model.lowerPositionLimit, model.upperPositionLimit
    for j in range(1, model.njoints):
        jm = model.joints[j]
        q = slice(jm.idx_q, jm.idx_q + jm.nq)
        if np.any(lower[q] > upper[q]):
            raise ModelFileError(
                f"robot file {str(path)!r}: joint {model.names[j]!r} has lower limit "
                f"{lower[q].tolist()} above its upper limit {upper[q].tolist()}; expected "
                "lower <= upper"
            )


def _read_mjcf(path: Path, side_file: str | Path | None, geometry: bool, arguments=None) -> _Tree:
    try:
        return _read_mjcf_tree(path, side_file, geometry, arguments)
    except RecursionError:  # the readers follow the bodies and defaults recursively
        raise ModelFileError(
            f"MJCF file {str(path)!r}: its elements (bodies, default classes) are nested too "
            f"deep for the reader (Python's recursion limit, {sys.getrecursionlimit()}); "
            "expected a shallower tree"
        ) from None


def _read_mjcf_tree(path: Path, side_file: str | Path | None, geometry: bool, arguments) -> _Tree:
    import tempfile

    from closedloop.io.mjcf import (
        anchor_equalities,
        match_parsed,
        pinocchio_copy,
        place_free_joints,
        read_mjcf_extras,
    )

    extras = read_mjcf_extras(path)  # the file checked before Pinocchio reads it
    with tempfile.TemporaryDirectory() as folder:  # Pinocchio reads a copy (closedloop.io.mjcf)
        parsed = str(pinocchio_copy(path, Path(folder)))
        model, points, welds = _parse(
            lambda: pin.buildModelAndConstraintsFromMJCF(parsed), path, "robot file"
        )
        match_parsed(model, len(points) + len(welds), extras, path)
        _check_masses(model, path)
        place_free_joints(model)
        constraints = anchor_equalities(model, extras)
        visual = _geometry(
            geometry, lambda: pin.buildGeomFromMJCF(model, parsed, pin.GeometryType.VISUAL), path
        )
    where = f"robot file {str(path)!r}"
    springs = {n: k for n, v in extras.stiffness.items() if (k := file_number(v, where, n)) > 0}
    spec, springs = read_side_file(model, side_file, springs, arguments)
    if spec.actuated is None:  # the actuators' joints
        check_spec_names(model, ClosureSpec(actuated=extras.actuated), where)
    return _Tree(
        model,
        [Closure(c, n) for c, n in zip(constraints, extras.closures, strict=True)],
        extras.actuated if spec.actuated is None else spec.actuated,
        springs,
        spec.locked,
        visual,
        extras.undriven if spec.actuated is None else (),
        unweighed=tuple(extras.unweighed.items()),
    )


def _read_sdf(path: Path, side_file, geometry: bool, free_base: bool = False,
              arguments=None) -> _Tree:  # fmt: skip
    from closedloop.io.sdf import load_sdf

    robot = load_sdf(path, free_base=free_base, geometry=geometry)  # closedloop.io.sdf
    _check_masses(robot.model, path)
    spec, springs = read_side_file(robot.model, side_file, robot.springs, arguments)
    return _Tree(robot.model, robot.closures, spec.actuated or (), springs, spec.locked,
                 robot.visual)  # fmt: skip


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
        tree = _read_sdf(path, closures, geometry, free_base, arguments)
    elif kind == "mjcf":
        tree = _read_mjcf(path, closures, geometry, arguments)
    else:
        tree = _read_urdf(path, closures, geometry, beams or {}, closure_springs, arguments,
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
