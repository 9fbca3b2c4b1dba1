"""Closure files: the YAML file beside a URDF (loop closures, actuated joints, springs,
locked joints, beams, ball joints), the side file of an MJCF or SDF model (actuated joints,
springs, locked joints, beams) and the springs file, read strictly
(:mod:`closedloop.io.strict_yaml`) with errors that name the file and the key.

Closure file (YAML), after the "Extended URDF" convention, extended with springs::

    closed_loop: [[frameA, frameB], ...]   # frame pairs made to coincide
    type: ['3d' | '6d' | 'revolute' | 'prismatic' | 'cylindrical' | 'universal', ...]
                                           # one per pair (closedloop.model.closures)
    closure_springs: {0: [dx, dy, dz, rx, ry, rz] | 6x6, ...}  # optional, pair index ->
                                           # stiffness of B's motion in A's axes
                                           # (closedloop.model.elastic_closures)
    name_mot: [joint, ...]                 # actuated joints
    springs: {joint: stiffness, ...}       # optional [N m/rad or N/m]; list per coordinate
    locked: [joint, ...]                   # optional rigid joints
    beams: {link: {end: joint, E: 2.1e11, G: 8.1e10, section: {shape: circle, d: 0.03}}}
                                           # optional flexible links (closedloop.model.beams);
                                           # section: geometry = the link's URDF shape
    start: {joint: value | [v1, ..., v_nq], ...}  # optional start of the assembly [rad, m]

``start:`` gives the assembly's start configuration, which picks the assembly mode: the
joints it names at their values (a list of the joint's nq values for a multi-coordinate
joint: a free flyer's x y z qx qy qz qw), the others as in the model's own reference
configuration (MJCF ``qpos0``, SDF springs' rest, else neutral); it is stored as
``model.referenceConfigurations["start"]``, which
:meth:`closedloop.model.closed_loop.ClosedLoopModel.reference_configuration` returns first.
It may also stand in the side file of an MJCF or SDF model.

A stiffness is a number >= 0 (``.inf`` locks the joint); a string that reads as a
number (``1e5``, which YAML 1.1 leaves as a string) is accepted. A value may be a
placeholder ``${expr}`` of the model's arguments (``load_model(..., args=)``), computed
before the YAML is read (:func:`closedloop.io.expressions.substitute`).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import decimal, overflowing, real_number
from closedloop.common.input_files import read_text
from closedloop.exceptions import InvalidInputError, ModelFileError, NameNotFoundError
from closedloop.io.expressions import Arguments, substitute
from closedloop.model.closures import CLOSURE_TYPES, joint_id, unknown_type
from closedloop.model.coordinates import UNIT_NORM_TOL
from closedloop.model.reference import START, reference_of
from closedloop.model.spring_spec import check_locked_springs

CLOSURE_KEYS = ("closed_loop", "type", "closure_springs", "name_mot", "springs", "locked",
                "beams", "balls", "start")  # fmt: skip
#: Keys of the side file of an MJCF or SDF model (no closures: the model file has them).
SIDE_FILE_KEYS = ("name_mot", "springs", "locked", "beams", "start")
Stiffness = float | list[float]


@dataclass(frozen=True)
class ClosureSpec:
    """Contents of a closure file (see the module docstring), by key.

    Attributes:
        pairs: the frame pairs of ``closed_loop``, (frame A, frame B) each.
        types: the ``type`` of each pair.
        actuated: the joints of ``name_mot``; None when the file has no such key.
        springs: joint -> stiffness [N m/rad or N/m] (a list: one per coordinate).
        locked: the joints of ``locked``.
        beams: link -> its beam (:mod:`closedloop.model.beams`).
        balls: URDF joints read as ball joints (:mod:`closedloop.model.balls`).
        closure_springs: pair index -> its spring (6 values or a 6x6).
        start: joint -> its values of ``start:`` (nq of the joint) [rad, m].
    """

    pairs: tuple[tuple[str, str], ...] = ()
    types: tuple[str, ...] = ()
    actuated: tuple[str, ...] | None = None
    springs: dict[str, Stiffness] = field(default_factory=dict)
    locked: tuple[str, ...] = ()
    beams: dict[str, dict] = field(default_factory=dict)  # link -> beam (closedloop.model.beams)
    balls: tuple[str, ...] = ()  # URDF joints read as ball joints (closedloop.model.balls)
    closure_springs: dict = field(default_factory=dict)  # pair index -> 6 values or 6x6
    start: dict[str, tuple[float, ...]] = field(default_factory=dict)  # joint -> its q values


def existing_path(path: str | Path, what: str) -> Path:
    """``path`` as a Path, once it is a file that can be opened (Pinocchio's readers say
    "does not exist" of a file they cannot read)."""
    path = Path(path)
    if not path.is_file():
        raise ModelFileError(f"{what} {str(path)!r} does not exist or is not a file")
    try:
        path.open("rb").close()
    except OSError as e:
        raise ModelFileError(f"{what} {str(path)!r} cannot be read: {e.strerror}") from None
    return path


def read_yaml_mapping(
    path: str | Path, what: str, arguments: Arguments | None = None
) -> tuple[Path, dict]:
    """(path, the mapping of a YAML file) read strictly (:mod:`closedloop.io.strict_yaml`),
    its ``${expr}`` placeholders computed first (:func:`closedloop.io.expressions.substitute`,
    the names of ``arguments``); ``what`` names the file in the errors (``"closure file"``).

    Raises:
        ModelFileError: a missing or unreadable file, invalid YAML, not a mapping.
        ExpressionError: a placeholder refused or without a value.
    """
    import yaml  # on demand, as below: a model without such a file reads no YAML

    from closedloop.io import strict_yaml

    path = existing_path(path, what)
    text = read_text(path, f"{what} {str(path)!r}", "YAML")
    if "${" in text:  # placeholders: their values first (no argument: the constants)
        text = substitute(text, arguments or Arguments(), path, what)
    try:
        doc = strict_yaml.load(text)
    except yaml.YAMLError as e:
        msg = " ".join(str(e).split())
        raise ModelFileError(f"{what} {str(path)!r} is not valid YAML: {msg}") from None
    if not isinstance(doc, dict):
        raise ModelFileError(
            f"{what} {str(path)!r}: expected a mapping at top level, got "
            + ("an empty file" if doc is None else type(doc).__name__)
        )
    return path, doc


def file_number(value, where: str, name: str) -> float:
    """The stiffness ``value`` of joint ``name`` read from a file (``where``): a number
    >= 0 or a string in ASCII decimal notation (:func:`closedloop.common.arrays.real_number`).

    Raises:
        ModelFileError: naming the file, the joint and the value.
    """
    if isinstance(value, str) and overflowing(value):
        raise ModelFileError(
            f"{where}: stiffness of joint {name!r} is {value!r}, beyond the floating point "
            "range (about 1.8e308); expected a number, or .inf to lock the joint"
        )
    try:
        value = real_number(value)
    except (TypeError, ValueError):
        raise ModelFileError(
            f"{where}: stiffness of joint {name!r} is {value!r}; expected a number"
        ) from None
    if math.isnan(value) or value < 0:
        raise ModelFileError(
            f"{where}: stiffness of joint {name!r} is {value!r}; expected a number >= 0 "
            "(0 = passive, .inf = locked)"
        )
    return value


def _check_springs(springs, where: str) -> dict[str, Stiffness]:
    """Validated joint -> stiffness mapping (a number or a list of numbers per joint)."""
    if not isinstance(springs, dict) or not all(isinstance(k, str) for k in springs):
        raise ModelFileError(f"{where}: springs must be a mapping joint name -> stiffness")
    out: dict[str, Stiffness] = {}
    for name, value in springs.items():
        if isinstance(value, list) and value:
            out[name] = [file_number(v, where, name) for v in value]
        else:
            out[name] = file_number(value, where, name)
    return out


def _value(doc: dict, key: str, empty):
    """``doc[key]``, or ``empty`` when it is absent or null (a ``0`` or ``false`` stays, for
    the type check to refuse)."""
    value = doc.get(key)
    return empty if value is None else value


def _name_list(doc: dict, key: str, where: str) -> tuple[str, ...] | None:
    if key not in doc:
        return None
    names = doc[key] if doc[key] is not None else []
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise ModelFileError(f"{where}: {key} must be a list of joint names, got {names!r}")
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ModelFileError(f"{where}: {key} names {twice} more than once; expected each once")
    return tuple(names)


def read_closure_file(
    path: str | Path, keys: Sequence[str] = CLOSURE_KEYS, arguments: Arguments | None = None
) -> ClosureSpec:
    """Parse and validate a closure file.

    Args:
        path: YAML file (see the module docstring).
        keys: keys allowed at top level (:data:`SIDE_FILE_KEYS` for an MJCF side file).
        arguments: the values of its ``${expr}`` placeholders' names (None: none).

    Raises:
        ModelFileError: missing or unreadable file, invalid YAML, unknown key, malformed
            value; the message names the file and the fault.
        ExpressionError: a placeholder refused or without a value (its line and name).
    """
    path, doc = read_yaml_mapping(path, "closure file", arguments)
    where = f"closure file {str(path)!r}"
    unknown = set(doc) - set(keys)
    if unknown:
        raise ModelFileError(
            f"{where}: unknown key(s) {sorted(map(str, unknown))}; expected {', '.join(keys)}"
        )
    pairs, types = _value(doc, "closed_loop", []), _value(doc, "type", [])
    if not isinstance(pairs, list) or any(
        not isinstance(p, list) or len(p) != 2 or not all(isinstance(n, str) for n in p)
        for p in pairs
    ):
        raise ModelFileError(
            f"{where}: closed_loop must be a list of [frameA, frameB] name pairs, got {pairs!r}"
        )
    if not isinstance(types, list) or len(types) != len(pairs):
        raise ModelFileError(
            f"{where}: type must list one of {', '.join(map(repr, CLOSURE_TYPES))} per "
            "closed_loop pair "
            f"({len(pairs)}), got {types!r}"
        )
    bad = [t for t in types if not isinstance(t, str) or t not in CLOSURE_TYPES]
    if bad:
        raise ModelFileError(f"{where}: {unknown_type(bad[0])}")
    return ClosureSpec(
        pairs=tuple((a, b) for a, b in pairs),
        types=tuple(types),
        closure_springs=_closure_springs(doc, len(pairs), where),
        actuated=_name_list(doc, "name_mot", where),
        springs=_check_springs(_value(doc, "springs", {}), where),
        locked=_name_list(doc, "locked", where) or (),
        beams=_check_beams(_value(doc, "beams", {}), where),
        balls=_name_list(doc, "balls", where) or (),
        start=_start(_value(doc, "start", {}), where),
    )


def _start(start, where: str) -> dict[str, tuple[float, ...]]:
    """``start:``: joint name -> a finite number or a list of them
    (:func:`closedloop.common.arrays.real_number`), as tuples; the counts are checked
    against the model (:func:`start_configuration`)."""
    if not isinstance(start, dict) or not all(isinstance(k, str) for k in start):
        raise ModelFileError(
            f"{where}: start must be a mapping joint name -> value [rad, m] (a list of its "
            f"nq values for a multi-coordinate joint), got {start!r}"
        )
    out = {}
    for name, value in start.items():
        given = value if isinstance(value, list) and value else [value]
        try:
            values = tuple(map(real_number, given))
        except (TypeError, ValueError):
            values = (math.nan,)
        if not all(map(math.isfinite, values)):
            raise ModelFileError(
                f"{where}: start of joint {name!r} is {value!r}; expected a finite number "
                "[rad, m] or a list of the joint's nq values"
            )
        out[name] = values
    return out


def start_configuration(model: pin.Model, start: dict, where: str) -> np.ndarray:
    """(nq,) the start configuration of ``start`` (:attr:`ClosureSpec.start`, its names
    checked by :func:`check_spec_names`): ``model``'s reference configuration
    (:func:`closedloop.model.reference.reference_of`) with the named joints at their
    values.

    Raises:
        ModelFileError: a joint given a wrong number of values, or a quaternion or unit
            complex number not of norm 1 (to
            :data:`closedloop.model.coordinates.UNIT_NORM_TOL`).
    """
    q = reference_of(model)
    for name, values in start.items():
        jm = model.joints[model.getJointId(name)]
        if len(values) != jm.nq:
            raise ModelFileError(
                f"{where}: start of joint {name!r} has {len(values)} value(s); expected its "
                f"{jm.nq} configuration value(s)"
            )
        q[jm.idx_q : jm.idx_q + jm.nq] = values
        alone = pin.neutral(model)
        alone[jm.idx_q : jm.idx_q + jm.nq] = values
        if not pin.isNormalized(model, alone, UNIT_NORM_TOL):
            raise ModelFileError(
                f"{where}: start of joint {name!r} is {list(values)}: its quaternion or unit "
                f"complex number is not of norm 1 (to {UNIT_NORM_TOL:g})"
            )
    return pin.normalize(model, q)


def _closure_springs(doc: dict, n: int, where: str) -> dict:
    """``closure_springs:``: pair index -> 6 numbers or a 6x6 list of lists (a string
    that reads as a number accepted); {} when absent. The values' meaning is checked by
    :func:`closedloop.model.elastic_closures.closure_spring`."""
    springs = _value(doc, "closure_springs", {})
    if not isinstance(springs, dict):
        raise ModelFileError(
            f"{where}: closure_springs must be a mapping closed_loop pair index (0..{n - 1}) "
            f"-> 6 stiffnesses or a 6x6 matrix, got {springs!r}"
        )
    out = {}
    for i, value in springs.items():
        if isinstance(i, bool) or not isinstance(i, int) or not 0 <= i < n:
            raise ModelFileError(
                f"{where}: closure_springs index {i!r}; expected the 0-based index of a "
                f"closed_loop pair, 0..{n - 1}"
            )
        out[i] = _numbers(value)
    return out


def _numbers(value):
    """``value`` with its strings that read as numbers (YAML 1.1's ``1e5``) as floats,
    through nested lists."""
    if isinstance(value, list):
        return [_numbers(v) for v in value]
    if isinstance(value, str):
        try:
            return decimal(value.strip())
        except ValueError:
            return value
    return value


def _check_beams(beams, where: str) -> dict[str, dict]:
    """``beams:`` mapping link name -> beam mapping (or a list of them, several beams on
    the link); the beams module checks the contents."""
    if not isinstance(beams, dict) or not all(
        isinstance(k, str) and isinstance(v, dict | list) for k, v in beams.items()
    ):
        raise ModelFileError(
            f"{where}: beams must be a mapping link name -> {{end, E, G, section, theory}} "
            f"or {{end, stiffness_6x6}} (or a list of them), got {beams!r}"
        )
    return beams


@contextmanager
def in_file(where: str) -> Iterator[None]:
    """Put ``where`` (the file that gave the names) first in the message of a name or value
    error raised inside; the error keeps its type."""
    try:
        yield
    except (NameNotFoundError, InvalidInputError) as e:
        e.args = (f"{where}: {e.args[0]}", *e.args[1:])
        raise


def check_spec_names(model: pin.Model, spec: ClosureSpec, where: str) -> None:
    """:class:`NameNotFoundError` or :class:`InvalidInputError`, naming the file ``where``,
    for a joint of the file's ``name_mot``, ``springs`` or ``locked`` that ``model`` lacks,
    or one both locked and given a spring there."""
    with in_file(where):
        for name in (*(spec.actuated or ()), *spec.springs, *spec.locked, *spec.start):
            joint_id(model, name)
        check_locked_springs(spec.springs, spec.locked)


def apply_start(model: pin.Model, spec: ClosureSpec, where: str) -> None:
    """The file's ``start:`` (its names checked) written into
    ``model.referenceConfigurations`` (:data:`closedloop.model.reference.START`), if any."""
    if spec.start:
        model.referenceConfigurations[START] = start_configuration(model, spec.start, where)


def read_side_file(
    model: pin.Model, side_file, springs: dict, arguments: Arguments | None = None
) -> tuple[ClosureSpec, dict]:
    """(the side file's contents, its joint names checked and its ``start:`` applied
    (:func:`apply_start`); the robot file's ``springs`` with those of the side file
    merged over them, those of the joints it locks removed); ``arguments``: its
    placeholders' values."""
    if side_file is None:
        return ClosureSpec(), springs
    spec = read_closure_file(side_file, SIDE_FILE_KEYS, arguments)
    check_spec_names(model, spec, f"closure file {str(side_file)!r}")
    apply_start(model, spec, f"closure file {str(side_file)!r}")
    kept = {n: k for n, k in springs.items() if n not in spec.locked}
    return spec, {**kept, **spec.springs}


def read_springs_file(path: str | Path) -> dict[str, Stiffness]:
    """Joint -> stiffness mapping [N m/rad or N/m] from a YAML file ``{joint: value}``.

    Raises:
        ModelFileError: missing file, invalid YAML, a value that is not a number >= 0.
    """
    path, doc = read_yaml_mapping(path, "springs file")
    return _check_springs(doc, f"springs file {str(path)!r}")
