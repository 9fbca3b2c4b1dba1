"""Robot files read by format: a URDF (or expanded xacro) with its closure file, an MJCF
or an SDF with its side file, each into the kinematic tree with the loops, actuated
joints, springs and locked joints the files give, before the keyword overrides of
:func:`closedloop.io.loader.load_model` (whose docstring lists the sources, and the
serial robot's defaults).

Each reader returns a :class:`RobotTree`.

Pinocchio's parsers run through :func:`run_parser`, which turns a failure, or an element
dropped, into a one-line :class:`~closedloop.exceptions.ModelFileError`. The readers of
MJCF and SDF, of balls, beams and elastic closures are imported when a file needs them.
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from closedloop.common.input_files import read_xml
from closedloop.exceptions import InvalidInputError, ModelFileError
from closedloop.io.closure_file import (
    ClosureSpec,
    Stiffness,
    apply_start,
    check_spec_names,
    file_number,
    in_file,
    read_closure_file,
    read_side_file,
)
from closedloop.io.expressions import Arguments
from closedloop.model.closures import Closure, closure_between_frames
from closedloop.model.reference import REST

#: Held while a parser's native output is captured (:func:`run_parser`).
_PARSE_LOCK = threading.Lock()


def run_parser(build: Callable, path: Path, what: str):
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
    return run_parser(build, path, "geometry of robot file") if wanted else None


def _package_dirs(path: Path) -> list[str]:
    # ``package://pkg/...`` resolves against any folder that holds ``pkg``: try every
    # ancestor of the file (example-robot-data uses package://example-robot-data/robots/...).
    return [str(p) for p in path.resolve().parents]


def _serial_defaults(model: pin.Model, path: Path) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(actuated, locked) joints of a robot file without closures (the docstring of
    :mod:`closedloop.io.loader`)."""
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
class RobotTree:
    """What a robot file gives before the keyword overrides of
    :func:`closedloop.io.loader.load_model`."""

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


def read_urdf(
    path: Path, closures: str | Path | None, geometry: bool, beams=None, elastic=None,
    arguments: Arguments | None = None, xacro: bool = False,
) -> RobotTree:  # fmt: skip
    """The URDF file ``path`` (with ``xacro``, a xacro file expanded first with
    ``arguments``) and its closure file ``closures`` (None: a serial robot): its balls,
    beams (the file's and ``beams``) and elastic closures (the file's and ``elastic``);
    ``geometry``: with the visual geometry."""
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
) -> RobotTree:
    root = read_xml(path, f"robot file {str(shown or path)!r}")  # before Pinocchio reads it
    # mimic joints follow their leader (nq = nv = 0), as the file says
    build = lambda: pin.buildModelFromUrdf(str(path), mimic=True)  # noqa: E731
    model = run_parser(build, shown or path, "robot file")
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
        return RobotTree(model, [], actuated, blocks, locked, visual, by_default=True,
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
    return RobotTree(model, loops, spec.actuated or (), {**spec.springs, **blocks, **cuts},
                     spec.locked, visual, beam_joints=tuple(blocks), balls=spec.balls,
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


def read_mjcf(
    path: Path, side_file: str | Path | None, geometry: bool, arguments=None
) -> RobotTree:
    """The MJCF file ``path`` with its side file (:mod:`closedloop.io.mjcf`)."""
    try:
        return _read_mjcf_tree(path, side_file, geometry, arguments)
    except RecursionError:  # the readers follow the bodies and defaults recursively
        raise ModelFileError(
            f"MJCF file {str(path)!r}: its elements (bodies, default classes) are nested too "
            f"deep for the reader (Python's recursion limit, {sys.getrecursionlimit()}); "
            "expected a shallower tree"
        ) from None


def _read_mjcf_tree(
    path: Path, side_file: str | Path | None, geometry: bool, arguments
) -> RobotTree:
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
        model, points, welds = run_parser(
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
    return RobotTree(
        model,
        [Closure(c, n) for c, n in zip(constraints, extras.closures, strict=True)],
        extras.actuated if spec.actuated is None else spec.actuated,
        springs,
        spec.locked,
        visual,
        extras.undriven if spec.actuated is None else (),
        unweighed=tuple(extras.unweighed.items()),
    )


def read_sdf(path: Path, side_file, geometry: bool, free_base: bool = False,
             arguments=None) -> RobotTree:  # fmt: skip
    """The SDF file ``path`` with its side file (:mod:`closedloop.io.sdf`)."""
    from closedloop.io.sdf import load_sdf

    robot = load_sdf(path, free_base=free_base, geometry=geometry)  # closedloop.io.sdf
    _check_masses(robot.model, path)
    spec, springs = read_side_file(robot.model, side_file, robot.springs, arguments)
    return RobotTree(robot.model, robot.closures, spec.actuated or (), springs, spec.locked,
                     robot.visual)  # fmt: skip
