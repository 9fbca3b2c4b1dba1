"""Command-line front end: ``closedloop stiffness MODEL --frame NAME ...``.

``closedloop view MODEL --frame NAME [--force ...] [--html FILE]`` shows the deflection
under a wrench in a meshcat viewer (see :mod:`closedloop.viewer.viewer`); ``closedloop deflect``
prints it (:mod:`closedloop.cli.deflect`), ``closedloop info MODEL`` lists what a model
holds (:mod:`closedloop.cli.info`), ``closedloop modes MODEL ...`` gives the natural
frequencies (:mod:`closedloop.cli.modes`).

MODEL is a robot file, a bundled model by name (``fourbar``, ``stewart``, ... with its
closure file; ``fourbar_mjcf``, ... the MJCF: :data:`closedloop.io.data.BUNDLED_MODELS`) or an
example-robot-data robot by name (``ur5``, ``panda``, ...; see :mod:`closedloop.io.data`).
A configuration outside the joints' limits is bad input (``--no-limits`` takes it).

Exit codes (the same for ``cahyman``; :func:`closedloop.exceptions.exit_status`):

* ``0`` - the stiffness K exists; K and C printed.
* ``1`` - the analysis succeeded but C is rank deficient: the frame is rigid along some
  directions, K does not exist. C and the rigid directions are printed (JSON: ``"K": null``).
  This is an answer, not an error, hence not 2; it differs from 0 so that scripts notice.
* ``2`` - bad input (missing file, unknown frame or joint, malformed closure file, wrong
  number of values, NaN, negative stiffness, joints outside their limits, an output
  path that cannot be written, a ``--q`` that does not close the loops): one line
  ``closedloop: error: <message>`` on stderr, a command-line syntax error included
  (:class:`closedloop.cli.common.UsageError`).
* ``3`` - the computation failed on valid input (loops that cannot be closed for these
  actuated values, no static equilibrium, a singular configuration or a mechanism, a result
  that is not finite): one line on stderr.
* ``141`` - standard output was closed early (``| head``); nothing more is written.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

import numpy as np

from closedloop import __version__
from closedloop.cli.common import (
    EXIT_HELP,
    Parser,
    UsageError,
    add_subcommands,
    command_of,
    finite_float,
    needs_gravity,
    number,
    path_text,
    print_json,
    run_main,
)
from closedloop.common.conditioning import ILL_CONDITIONED, twist_scaling
from closedloop.common.rounding import without_rounding
from closedloop.elastostatics.compliance import (
    TWIST_LABELS,
    UNITS,
    ComplianceResult,
    compliance,
    describe_directions,
    energy_shares,
)
from closedloop.exceptions import EXIT_OK, EXIT_RANK_DEFICIENT, InvalidInputError, OpenLoopError
from closedloop.io.data import BUNDLED_MODELS, ROBOTS, resolve
from closedloop.io.loader import load_model, read_springs_file, reference_configuration
from closedloop.kinematics.assembly import assemble
from closedloop.kinematics.configuration import Configuration
from closedloop.kinematics.driving import assemble_connected
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.model.gravity import Payload

PROG = "closedloop"
WRENCH_LABELS = ("fx", "fy", "fz", "nx", "ny", "nz")

EPILOG = """\
Configuration: --q gives every coordinate of the model (nq values, SI: rad, m); --actuated
gives the actuated joints' values and the loops are closed by moving the passive joints
(start: MJCF qpos0, else the neutral configuration). Without either: that start, assembled.
A configuration outside the joints' position limits is refused (angles in degrees are);
--no-limits takes it as it is.
A --q of a model with loops must close them to 1e-6 (metres per size of the mechanism, rad).

Springs: --joint-stiffness K gives stiffness K [N m/rad or N/m] to every actuated joint
that has no spring in the closure file; --springs FILE is a YAML mapping joint -> stiffness
merged over the closure file's springs (.inf locks a joint). Actuated joints without a
spring are rigid. A URDF without closure file is a serial robot: the joints of its main
chain are actuated, joints beyond a branching (gripper fingers) are locked.

Output: C is the twist (dx dy dz [m], rx ry rz [rad]) per wrench (fx fy fz [N], nx ny nz
[N m]) at the frame origin, in world-aligned axes (--axes world) or the frame's own axes
(--axes local); K = C^-1, from a square-root factor of C. The rank and the condition
number are unit-free: lengths are divided by the size L of the mechanism. Above a scaled
condition number of 1e8 the result is flagged ill-conditioned (near a singular pose); below
an eigenvalue ratio of 1e-14 C is rank deficient.

Exit status: 0 K exists; 1 C is rank deficient (the rigid directions are named, K does
not exist, JSON "K": null); 2 bad input; 3 the computation failed (loops that cannot be
closed, no equilibrium, a singular configuration); 141 output closed early; errors are one
line on stderr.

Examples:
  closedloop stiffness ur5 --frame tool0 --q 0 -1.0 1.5 -0.5 1.2 0.3 --joint-stiffness 1e4
  closedloop stiffness fourbar --frame P --actuated 0.3
"""


#: Further subcommands: name -> (module defining ``add_parser(subparsers, arguments)``,
#: help line); imported only when they run (the map's imports Dask's and tqdm's code).
SUBCOMMAND_MODULES: dict[str, tuple[str, str]] = {
    "map": (
        "closedloop.cli.map",
        "a stiffness index over a grid of actuated inputs (NPZ, CSV, PNG)",
    ),
    "identify": ("closedloop.cli.identify", "fit spring stiffnesses to measured deflections"),
    "modes": ("closedloop.cli.modes", "natural frequencies and mode shapes at a pose"),
    "info": ("closedloop.cli.info", "joints, frames, closures, springs and sizes of a model"),
    "deflect": ("closedloop.cli.deflect", "twist of a frame and joint deflections under a load"),
}


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """Argument parser of the ``closedloop`` command; of the subcommands of
    :data:`SUBCOMMAND_MODULES`, only ``command``'s module is imported."""
    parser = Parser(
        prog=PROG,
        description="Stiffness and compliance of robots with closed loops. " + EXIT_HELP,
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    p = sub.add_parser(
        "stiffness",
        help="Cartesian stiffness K and compliance C of a frame",
        description="Cartesian stiffness K and compliance C of a frame (SI units).",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_model_arguments(p)
    p.add_argument("--axes", choices=("world", "local"), default="world", help="axes of K and C")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument(
        "--wrench", nargs=6, type=finite_float, metavar="W",
        help="fx fy fz [N] nx ny nz [N m] at the frame (in --axes): print the share of the "
        "deflection energy stored in each spring and beam (none when the wrench does no "
        "work)",
    )  # fmt: skip
    add_preload_arguments(p)
    p.set_defaults(func=stiffness)
    v = sub.add_parser(
        "view",
        help="meshcat view of the deflection under a wrench",
        description="Nominal pose (translucent ghost), amplified deflected pose, wrench arrows,\n"
        "compliance ellipsoids and an HTML legend (load, amplification, real displacements\n"
        "in mm and deg, colour key) in a meshcat viewer. --html writes a self-contained\n"
        "page; without it the viewer is served on 127.0.0.1 until Ctrl-C or SIGTERM.",
        epilog=EPILOG.split("\n\nOutput:")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_model_arguments(v)
    add_view_arguments(v)
    v.set_defaults(func=view)
    add_subcommands(sub, SUBCOMMAND_MODULES, command, add_source_arguments)
    return parser


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


def add_preload_arguments(p: argparse.ArgumentParser) -> None:
    """--gravity [GX GY GZ], --payload MASS [X Y Z], --preload FX FY FZ NX NY NZ (SI)."""
    p.add_argument(
        "--gravity", nargs="*", type=finite_float, metavar="G",
        help="weigh the model's link inertias: GX GY GZ [m/s^2], world axes (no values: "
        "0 0 -9.80665, standard gravity); q is then the springs' rest configuration and the "
        "result the tangent compliance where the mechanism settles, with its sag",
    )  # fmt: skip
    p.add_argument(
        "--payload", nargs="+", type=finite_float, metavar="V",
        help="MASS [kg] [X Y Z]: a point mass at the loaded frame, offset in its axes [m] "
        "(needs --gravity)",
    )  # fmt: skip
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


def add_view_arguments(p: argparse.ArgumentParser) -> None:
    """Options of a deflection view: wrench, amplification, output (SI)."""
    add_wrench_arguments(p)
    p.add_argument(
        "--scale",
        type=finite_float,
        metavar="S",
        help="amplification of the deflection (default: automatic, the largest "
        "point displacement shown as at most 10%% of the model size and the largest link "
        "rotation as at most 20 deg)",
    )
    p.add_argument(
        "--nonlinear", action="store_true", help="nonlinear static equilibrium along the load ramp"
    )
    p.add_argument(
        "--close-loops",
        action="store_true",
        help="draw the amplified joint deflection with its loops re-closed by the passive "
        "joints, instead of each link moved along its own twist",
    )
    p.add_argument(
        "--rotational", action="store_true", help="also the rotational compliance ellipsoid"
    )
    p.add_argument(
        "--html", type=path_text, metavar="FILE", help="write a self-contained HTML page"
    )
    p.add_argument(
        "--duration",
        type=finite_float,
        metavar="SECONDS",
        help="without --html: serve for this long (default: until Ctrl-C)",
    )
    p.add_argument(
        "--autoplay",
        action="store_true",
        help="play the load ramp (looping) once the page has loaded",
    )
    p.add_argument("--no-legend", action="store_true", help="no HTML legend on the page")


def view_from_args(
    clm: ClosedLoopModel,
    q: np.ndarray,
    frame: str,
    args,
    out=print,
    pose=None,
    prog=PROG,
    check_limits: bool = True,
):
    """Run :func:`closedloop.viewer.viewer.run_view` with :func:`add_view_arguments`' options.

    Warnings (a view without load) go to stderr, one line each, prefixed by ``prog``.
    ``pose``: the pose as the page's legend writes it (default q). ``check_limits``: refuse
    a q outside the joints' limits (False: ``--no-limits``, or the file's own
    configuration, as :func:`configuration`).
    """
    from closedloop.viewer.viewer import run_view  # meshcat is imported only for a view

    def warn(line: str) -> None:
        print(f"{prog}: warning: {line}", file=sys.stderr)

    return run_view(
        clm,
        q,
        frame,
        np.r_[args.force, args.torque],
        scale=args.scale,
        nonlinear=args.nonlinear,
        close_loops=args.close_loops,
        rotational=args.rotational,
        html=args.html,
        duration=args.duration,
        autoplay=args.autoplay,
        legend=not args.no_legend,
        pose=pose,
        out=out,
        warn=warn,
        check_limits=check_limits,
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
    if q is None:
        start = reference_configuration(clm)
        if actuated is None:
            q = assemble(clm, None, start).q  # the file's own configuration, as drawn
        elif check_limits:
            q = assemble_connected(clm, actuated, start, jacobian=False).q  # start's mode
        else:
            q = assemble(clm, actuated, start, jacobian=False).q
    state = Configuration(clm, q, check_limits=check_limits and given)
    try:
        return state.require_closed()
    except OpenLoopError as e:
        raise OpenLoopError(
            f"--q: {e}; or give --actuated values", e.residual, e.tolerance
        ) from None


def _matrix(M: np.ndarray, rows: Sequence[str], cols: Sequence[str]) -> str:
    """Columns of 14 characters, each value after a space (-1.23457e+300 has 13)."""
    head = " " * 4 + "".join(f"{c:>14}" for c in cols)
    body = [
        f"  {r:<2}" + "".join(f" {v:13.5e}" for v in row) for r, row in zip(rows, M, strict=True)
    ]
    return "\n".join([head, *body])


def format_report(clm: ClosedLoopModel, res: ComplianceResult) -> str:
    """Readable report of a compliance result: configuration, C, then K or rigid directions
    (every entry as computed: an entry 1e-13 of the largest may be rounding or, in an
    ill-conditioned C, a true stiff direction)."""
    axes = "world-aligned axes" if res.axes == "world" else f"axes of frame {res.frame!r}"
    condition = (
        f"condition number of the scaled K {res.condition_number:.3e}"
        + (" over the rank of C" if res.rank < 6 else "")
        + f" (lengths per L = {res.length:.4g} m)"
        if res.rank
        else "condition number of the scaled K: none (C = 0: no wrench moves the frame)"
        + (f"; {res.note}" if res.note else "")
    )
    lines = [
        f"model {clm.name!r}, frame {res.frame!r}",
        f"q = {np.array2string(res.q, precision=6, separator=', ')} [rad, m]",
        f"reference point (frame origin, world) = "
        f"{np.array2string(res.point, precision=6, separator=', ')} m; {axes}",
        f"closure residual {res.closure_residual:.1e} [m, rad]; rank of C {res.rank}/6",
        condition
        + (
            f"; ILL-CONDITIONED (> {ILL_CONDITIONED:.0e}): near a singular configuration"
            if res.ill_conditioned
            else ""
        ),
        "",
        f"compliance C: twist per wrench [{UNITS['C']}]",
        _matrix(res.C, TWIST_LABELS, WRENCH_LABELS),
        "",
    ]
    if res.is_full_rank:
        lines += [f"stiffness K = C^-1: wrench per twist [{UNITS['K']}]"]
        lines += [_matrix(res.K, WRENCH_LABELS, TWIST_LABELS)]
    else:
        lines += [
            f"rigid directions (no wrench produces these twists): "
            f"{describe_directions(res.rigid_directions)}",
            f"stiffness K: does not exist (C has rank {res.rank} < 6: the stiffness is "
            "infinite along the rigid directions)",
        ]
    return "\n".join(lines)


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


def _vector(v) -> str:
    return "(" + ", ".join(f"{x:.6g}" for x in v) + ")"


def stiffness(args: argparse.Namespace) -> int:
    """Run ``closedloop stiffness``; returns the exit code (0 or 1)."""
    preload = preload_from_args(args)
    if args.wrench and preload:
        raise UsageError(
            "--wrench splits the deflection energy of the unloaded compliance among the "
            "springs; under --gravity, --payload or --preload the preload's own energy terms "
            "are not split: give --wrench without them"
        )
    clm, state = model_from_args(args)
    res = compliance(state, args.frame, axes=args.axes, **preload)
    if getattr(res, "equilibrium", None) is not None:
        from closedloop.elastostatics.preload import require_stable  # only with a preload

        require_stable(res)
    shares = energy_shares(clm, res, args.wrench) if args.wrench else None
    if args.json:
        doc = {"model": clm.name, **res.to_dict(), "q": res.q.tolist()}
        print_json(doc | ({} if shares is None else {"energy_shares": shares}))
    else:
        print(format_report(clm, res))
        if getattr(res, "equilibrium", None) is not None:
            sag = without_rounding(res.sag, twist_scaling(res.length))
            print(f"sag under the preload: {_vector(1e3 * sag[:3])} mm, "
                  f"{_vector(np.degrees(sag[3:]))} deg (world axes); stability margin "
                  f"{res.stability_margin:.3g}")  # fmt: skip
        for name, share in (shares or {}).items():  # the per-element breakdown
            print(f"energy share {share:7.2%}  {name}")
        if shares == {}:
            print("energy shares: none, the wrench stores no deflection energy (w^T C w = 0: "
                  "a zero wrench, or one that only the rigid directions take)")  # fmt: skip
    return EXIT_OK if res.is_full_rank else EXIT_RANK_DEFICIENT


def view(args: argparse.Namespace) -> int:
    """Run ``closedloop view``; returns the exit code (0)."""
    clm, state = model_from_args(args, geometry=True)
    given = args.q is not None or args.actuated is not None  # else the file's configuration
    view_from_args(clm, state.q, args.frame, args, check_limits=given and not args.no_limits)
    return EXIT_OK


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``closedloop`` command; returns the exit code (see module doc)."""
    return run_main(PROG, lambda words: build_parser(command_of(words)), argv)


if __name__ == "__main__":
    sys.exit(main())
