"""The options that the subcommands of ``closedloop`` share, and what they make of them: the
model (MODEL, ``--closures``, ``--springs``...), its configuration (``--q``,
``--actuated``), the preload (``--gravity``, ``--payload``, ``--preload``) and the wrench.
"""

from __future__ import annotations

import argparse

from closedloop.cli.parser import finite_float, needs_gravity, number, path_text
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
    p.add_argument(
        "--no-limits",
        action="store_true",
        help="accept a configuration outside the joints' position limits (refused by default: "
        "an angle in degrees is the usual cause)",
    )


def add_source_arguments(p: argparse.ArgumentParser, frame: bool = True) -> None:
    """MODEL, --closures, --frame (if ``frame``), --joint-stiffness | --springs."""
    p.add_argument(
        "model",
        type=path_text,
        metavar="MODEL",
        help="robot file (.urdf, .xml/.mjcf MJCF, .sdf), a bundled model by name "
        f"({', '.join(BUNDLED_MODELS)}) or an example-robot-data robot by name "
        f"({', '.join(ROBOTS)})",
    )
    p.add_argument(
        "--closures",
        type=path_text,
        metavar="FILE",
        help="closure file (URDF) or side file with name_mot/springs/locked (MJCF, SDF)",
    )
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


def add_preload_arguments(p: argparse.ArgumentParser, payload_help: str = PAYLOAD_HELP) -> None:
    """--gravity [GX GY GZ], --payload MASS [X Y Z], --preload FX FY FZ NX NY NZ (SI);
    ``payload_help`` the help of ``--payload`` (a command whose payload means more)."""
    p.add_argument(
        "--gravity", nargs="*", type=finite_float, metavar="G",
        help="weigh the model's link inertias: GX GY GZ [m/s^2], world axes (no values: "
        "0 0 -9.80665, standard gravity); q is then the springs' rest configuration and the "
        "result the tangent compliance where the mechanism settles, with its sag",
    )  # fmt: skip
    p.add_argument("--payload", nargs="+", type=finite_float, metavar="V", help=payload_help)
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
    clm: ClosedLoopModel, q=None, actuated=None, check_limits: bool = True
) -> Configuration:
    """The configuration of the analysis from ``--q`` or ``--actuated`` values.

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

        start = clm.reference_configuration()
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


def load_from_args(args: argparse.Namespace, geometry: bool = False) -> ClosedLoopModel:
    """The model of :func:`add_source_arguments`' options (MODEL, --closures, springs)."""
    springs = read_springs_file(args.springs) if args.springs else None
    robot, closures = resolve(args.model, args.closures)
    return load_model(
        robot,
        closures,
        springs=springs,
        joint_stiffness=args.joint_stiffness,
        geometry=geometry,
    )


def model_from_args(args: argparse.Namespace, geometry: bool = False):
    """(model, :class:`Configuration`) from :func:`add_model_arguments`' options (a frame
    checked when one is given)."""
    clm = load_from_args(args, geometry)
    if args.frame is not None:
        clm.frame_id(args.frame)  # unknown frame: fail before any assembly
    return clm, configuration(clm, args.q, args.actuated, not args.no_limits)
