"""The options that the subcommands of ``closedloop`` share, and what they make of them: the
model (MODEL, ``--closures``, ``--springs``...), its configuration (``--q``,
``--actuated``), the preload (``--gravity``, ``--payload``, ``--preload``) and the wrench.
"""

from __future__ import annotations

import argparse

import numpy as np

from closedloop.cli.parser import UsageError, finite_float, needs_gravity, number, path_text
from closedloop.common.rounding import without_rounding
from closedloop.exceptions import InvalidInputError, OpenLoopError
from closedloop.io.data import BUNDLED_MODELS, ROBOTS, resolve
from closedloop.io.loader import load_model, read_springs_file
from closedloop.kinematics.configuration import Configuration
from closedloop.model.closed_loop import ClosedLoopModel

PROG = "closedloop"


def add_model_arguments(p: argparse.ArgumentParser, frame: bool = True) -> None:
    """MODEL, --closures, --frame (if ``frame``), --q | --actuated, --joint-stiffness |
    --springs."""
    add_source_arguments(p, frame)
    config = p.add_mutually_exclusive_group()
    config.add_argument(
        "--q", nargs="+", type=finite_float, metavar="Q", help="full configuration (nq values)"
    )
    config.add_argument(
        "--actuated", nargs="+", type=finite_float, metavar="A", help="actuated joint values"
    )
    add_start_arguments(p)
    p.add_argument(
        "--no-limits",
        action="store_true",
        help="accept a configuration outside the joints' position limits (refused by default: "
        "an angle in degrees is the usual cause)",
    )


def add_start_arguments(p: argparse.ArgumentParser) -> None:
    """--start Q | --near JOINT=VALUE: the start of the assembly, which picks its mode."""
    start = p.add_mutually_exclusive_group()
    start.add_argument(
        "--start", nargs="+", type=finite_float, metavar="Q",
        help="start of the assembly, a full configuration (nq values, SI), which picks the "
        "assembly mode (default: the model's reference configuration, its start: key, "
        "MJCF qpos0 or springs' rest)",
    )  # fmt: skip
    start.add_argument(
        "--near", nargs="+", type=joint_value, metavar="JOINT=VALUE",
        help="start of the assembly: the reference configuration with these joints' values "
        "(V1,V2,... for a multi-coordinate joint; SI), e.g. a passive joint near another "
        "assembly mode, or the rest value of a sprung joint",
    )  # fmt: skip


def joint_value(text: str) -> tuple[str, tuple[float, ...]]:
    """Option type of ``--near``: ``JOINT=VALUE`` or ``JOINT=V1,V2,...`` [rad, m]."""
    name, sep, values = text.partition("=")
    try:
        if sep and name:
            return name, tuple(finite_float(v) for v in values.split(","))
    except argparse.ArgumentTypeError:
        pass
    raise argparse.ArgumentTypeError(
        f"{text!r}: expected JOINT=VALUE or JOINT=V1,V2,... (finite numbers, SI)"
    )


def start_from_args(clm: ClosedLoopModel, args: argparse.Namespace):
    """(nq,) the start of ``--start`` or ``--near`` (:func:`add_start_arguments`), or None
    (the model's reference configuration).

    Raises:
        InvalidInputError: a ``--start`` of the wrong size or not normalised, a ``--near``
            joint that is actuated (its value is ``--actuated``'s) or given the wrong
            number of values.
        NameNotFoundError: a ``--near`` joint the model does not have.
    """
    if args.start is not None:
        try:
            return clm.check_configuration(np.array(args.start))
        except InvalidInputError as e:
            raise InvalidInputError(f"--start: {e}") from None
    if args.near is None:
        return None
    q, model = clm.reference_configuration(), clm.model
    for name, values in args.near:
        jm = model.joints[clm.joint_id(name)]
        shown = f"--near {name}={','.join(f'{v:g}' for v in values)}"
        if name in clm.actuated:
            raise InvalidInputError(f"{shown}: {name!r} is actuated; give its value with "
                                    "--actuated (--near: passive and sprung joints)")  # fmt: skip
        if len(values) != jm.nq:
            raise InvalidInputError(f"{shown}: {len(values)} value(s); joint {name!r} has "
                                    f"{jm.nq} configuration value(s)")  # fmt: skip
        q[jm.idx_q : jm.idx_q + jm.nq] = values
    try:
        return clm.check_configuration(q)
    except InvalidInputError as e:
        raise InvalidInputError(f"--near: {e}") from None


def passive_text(values: dict) -> str:
    """``name value, name (v1 v2 ...)`` of passive joints' values (joint -> a number or a
    list, :func:`closedloop.kinematics.assembly_modes.passive_values`), rounding noise
    shown as 0 (:func:`closedloop.common.rounding.without_rounding`), or "none"."""
    flat = without_rounding([x for v in values.values() for x in np.ravel(v)])
    parts, k = [], 0
    for name, v in values.items():
        n = np.size(v)
        shown = " ".join(f"{x:.6g}" for x in flat[k : k + n])
        parts.append(f"{name} {shown}" if isinstance(v, float) else f"{name} ({shown})")
        k += n
    return ", ".join(parts) or "none"


def mode_line(clm: ClosedLoopModel, q) -> str:
    """The assembly mode of q (nq,) in a line: its passive joints' values
    (:func:`closedloop.kinematics.assembly_modes.passive_values`), "" for a model without
    loops."""
    if not clm.closures:
        return ""
    from closedloop.kinematics.assembly_modes import passive_values  # a model with loops only

    return (f"assembly mode: passive joints {passive_text(passive_values(clm, q))} [rad, m] "
            "(another mode: --start Q or --near JOINT=VALUE; closedloop.assembly_modes lists "
            "those found)")  # fmt: skip


def add_source_arguments(p: argparse.ArgumentParser, frame: bool = True) -> None:
    """MODEL, --closures, --frame (if ``frame``), --joint-stiffness | --springs."""
    p.add_argument(
        "model",
        type=path_text,
        metavar="MODEL",
        help="robot file (.urdf, .xacro, .xml/.mjcf MJCF, .sdf), a bundled model by name "
        f"({', '.join(BUNDLED_MODELS)}) or an example-robot-data robot by name "
        f"({', '.join(ROBOTS)})",
    )
    p.add_argument(
        "--closures",
        type=path_text,
        metavar="FILE",
        help="closure file (URDF) or side file with name_mot/springs/locked (MJCF, SDF)",
    )
    p.add_argument(
        "--arg", type=model_argument, action="append", default=[], metavar="NAME=VALUE",
        help="an argument of a parametric model (repeatable): a xacro file's <xacro:arg>, "
        "a name of the closure file's ${...} placeholders",
    )  # fmt: skip
    if frame:
        p.add_argument("--frame", required=True, metavar="NAME", help="loaded frame")
    springs = p.add_mutually_exclusive_group()
    springs.add_argument(
        "--joint-stiffness",
        type=number,
        metavar="VALUE",
        help="stiffness of every actuated joint without spring [N m/rad or N/m]",
    )
    springs.add_argument(
        "--springs", type=path_text, metavar="FILE", help="YAML mapping joint -> stiffness"
    )


#: Help of ``--payload`` where the payload loads the queried frame (``stiffness``).
PAYLOAD_HELP = (
    "MASS [kg] [X Y Z]: a point mass at the loaded frame, offset in its axes [m] (needs --gravity)"
)


def add_preload_arguments(
    p: argparse.ArgumentParser, payload_help: str = PAYLOAD_HELP, preload: bool = True
) -> None:
    """--gravity [GX GY GZ], --payload MASS [X Y Z], --preload FX FY FZ NX NY NZ (SI);
    ``payload_help`` the help of ``--payload`` (a command whose payload means more);
    ``preload`` False: no --preload (a command with a load of its own)."""
    p.add_argument(
        "--gravity", nargs="*", type=finite_float, metavar="G",
        help="weigh the model's link inertias: GX GY GZ [m/s^2], world axes (no values: "
        "0 0 -9.80665, standard gravity); q is then the springs' rest configuration and the "
        "result the tangent compliance where the mechanism settles, with its sag",
    )  # fmt: skip
    p.add_argument("--payload", nargs="+", type=finite_float, metavar="V", help=payload_help)
    if not preload:
        p.set_defaults(preload=None)
        return
    p.add_argument(
        "--preload", nargs=6, type=finite_float, metavar="W",
        help="dead-load wrench fx fy fz [N] nx ny nz [N m] at the frame, world axes",
    )  # fmt: skip


def preload_from_args(args: argparse.Namespace) -> dict:
    """Keyword arguments of :func:`closedloop.elastostatics.compliance.compliance` for the
    preload."""
    out: dict = {}
    if args.gravity is not None:
        if len(args.gravity) not in (0, 3):
            raise InvalidInputError(f"--gravity takes 0 or 3 values, got {len(args.gravity)}")
        from closedloop.model.gravity import STANDARD_GRAVITY  # with the preload, on demand

        out["gravity"] = tuple(args.gravity) or STANDARD_GRAVITY
    if args.payload is not None:
        if len(args.payload) not in (1, 4):
            raise InvalidInputError(
                f"--payload takes MASS or MASS X Y Z, got {len(args.payload)} values"
            )
        needs_gravity(f"--payload {' '.join(f'{v:g}' for v in args.payload)}",
                      args.gravity is not None)  # fmt: skip
        from closedloop.model.gravity import Payload  # with a payload only: start-up

        offset = args.payload[1:] or [0.0, 0.0, 0.0]
        out["payloads"] = [Payload(args.payload[0], args.frame, offset)]
    if args.preload is not None:
        out["preload"] = args.preload
    return out


def add_wrench_arguments(p: argparse.ArgumentParser) -> None:
    """--force FX FY FZ [N], --torque NX NY NZ [N m] at the frame origin, world axes
    (default 0)."""
    for name, labels, unit in (
        ("--force", ("FX", "FY", "FZ"), "N"),
        ("--torque", ("NX", "NY", "NZ"), "N m"),
    ):
        p.add_argument(
            name,
            nargs=3,
            type=finite_float,
            default=[0.0] * 3,
            metavar=labels,
            help=f"{name[2:]} at the frame origin, world axes [{unit}]",
        )


def configuration(
    clm: ClosedLoopModel, q=None, actuated=None, check_limits: bool = True, start=None
) -> Configuration:
    """The configuration of the analysis from ``--q`` or ``--actuated`` values, the
    latter driven from ``start`` (nq,; ``--start``, ``--near``; default the reference
    configuration) on its assembly mode (:func:`closedloop.kinematics.assembly.assemble`).

    ``check_limits`` False (``--no-limits``): the joints' position limits are not checked;
    neither are they for the file's own configuration (no values given: a file may count
    a joint's zero outside its limits, as Cassie's SDF does).

    Raises:
        InvalidInputError: wrong count, non-finite values.
        OutsideLimitsError: ``check_limits`` and joints of the configuration outside their
            limits (with ``--actuated``: an actuated value outside, InvalidInputError, a
            map's ``invalid`` point: the robot is not driven there).
        OpenLoopError: a ``--q`` that does not close the loops (the one closure tolerance,
            :data:`closedloop.kinematics.configuration.CLOSURE_TOL`, relative to the mechanism
            size).
        AssemblyError: the loops cannot be closed for these actuated values.
    """
    given = q is not None or actuated is not None  # else the file's own configuration
    if q is None:  # the assembly's modules only then: a --q loads none (start-up)
        from closedloop.kinematics.assembly import assemble
        from closedloop.kinematics.driving import assemble_connected

        start = clm.reference_configuration() if start is None else start
        if actuated is None:
            q = assemble(clm, None, start).q  # the file's own configuration, as drawn
        else:  # driven there on the start's assembly mode, limits checked or not
            q = assemble_connected(
                clm, actuated, start, jacobian=False, check_limits=check_limits
            ).q
    state = Configuration(clm, q, check_limits=check_limits and given)
    try:
        return state.require_closed()
    except OpenLoopError as e:
        raise OpenLoopError(
            f"--q: {e}; or give --actuated values", e.residual, e.tolerance
        ) from None


def model_argument(text: str) -> tuple[str, float]:
    """Option type of ``--arg NAME=VALUE``: (name, finite number)."""
    name, sep, value = text.partition("=")
    if not sep or not name.strip():
        raise argparse.ArgumentTypeError(f"{text!r}: expected NAME=VALUE (VALUE a number, SI)")
    return name.strip(), finite_float(value)


def model_arguments(args: argparse.Namespace) -> dict[str, float] | None:
    """name -> value of the ``--arg`` options, or None without any.

    Raises:
        UsageError: a name given twice.
    """
    names = [name for name, _ in args.arg]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise UsageError(f"--arg {twice[0]}=... given {names.count(twice[0])} times; expected "
                         "one value a name")  # fmt: skip
    return dict(args.arg) or None


def load_from_args(args: argparse.Namespace, geometry: bool = False) -> ClosedLoopModel:
    """The model of :func:`add_source_arguments`' options (MODEL, --closures, springs,
    --arg)."""
    springs = read_springs_file(args.springs) if args.springs else None
    robot, closures = resolve(args.model, args.closures)
    return load_model(
        robot,
        closures,
        springs=springs,
        joint_stiffness=args.joint_stiffness,
        geometry=geometry,
        args=model_arguments(args),
    )


def model_from_args(args: argparse.Namespace, geometry: bool = False):
    """(model, :class:`~closedloop.Configuration`) from :func:`add_model_arguments`' options
    (a frame checked when one is given)."""
    clm = load_from_args(args, geometry)
    if args.frame is not None:
        clm.frame_id(args.frame)  # unknown frame: fail before any assembly
    if args.q is not None and (args.start is not None or args.near is not None):
        raise UsageError(f"{'--start' if args.start is not None else '--near'} with --q: --q "
                         "is a closed configuration already; give --actuated values to assemble "
                         "from the start, or --q alone")  # fmt: skip
    start = start_from_args(clm, args)
    return clm, configuration(clm, args.q, args.actuated, not args.no_limits, start)
