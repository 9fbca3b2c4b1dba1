"""Command line ``cahyman``: stiffness and deflection of CaHyMan at a pose.

Inputs are in the paper's units (degrees, millimetres); outputs are SI (JSON with
``--json``) with the paper's units beside them in the readable print. Examples::

    cahyman stiffness --alpha 45 60 75 --alpha4 45 --s4 0 --json
    cahyman deflect --force 1 1 1 --torque 0 0 0

Subcommands: every module named in :data:`SUBCOMMAND_MODULES` provides
``add_parser(subparsers)``, which adds its parser and sets ``func`` (``args -> int``) as
its default; :func:`add_pose_arguments` and :func:`stiffness_from_args` are shared. Only
the module of the subcommand that runs is imported (the others stand in by their help
line), so that ``cahyman stiffness`` does not pay for matplotlib or the sweep machinery.

Exit status (as for ``closedloop``, :func:`closedloop.exceptions.exit_status`): 0 ok; 1 the
compliance is rank deficient (K does not exist); 2 bad input; 3 the computation failed on
valid input (an unreachable pose, a singular configuration); 141 standard output closed
early (``| head``). Errors are one line ``cahyman: error: ...`` on stderr.
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import sys
from collections.abc import Sequence

import numpy as np

from closedloop import __version__
from closedloop.blas import single_threaded_blas
from closedloop.cli_common import Parser, error_line, run_command
from closedloop.exceptions import (
    EXIT_BAD_INPUT,
    EXIT_FAILED,
    EXIT_OK,
    EXIT_RANK_DEFICIENT,
    InvalidInputError,
)

from .api import CaHyManStiffness, backend_names, stiffness
from .params import DEFAULT_PARAMS, K_S_ASSUMED, K_S_PRINTED, LEG_MASSES

PROG = "cahyman"
#: Further subcommands: name -> (module defining ``add_parser(subparsers)``, help line).
SUBCOMMAND_MODULES: dict[str, tuple[str, str]] = {
    "report": ("cahyman_pin.report", "write the comparison report against the paper"),
    "map": ("cahyman_pin.map_cli", "a stiffness index over swept inputs (NPZ, CSV, PNG)"),
    "view": ("cahyman_pin.view", "meshcat view of the deflection under a wrench at M"),
}
#: Table 1's configuration, the default pose: alpha_k [deg], alpha_4 [deg], s_4 [mm].
DEFAULT_POSE = {"alpha": (90.0, 90.0, 90.0), "alpha4": 90.0, "s4": 50.0}
KS_PRESETS = {"assumed": K_S_ASSUMED, "printed": K_S_PRINTED}


class UsageError(InvalidInputError):
    """A command-line error (bad option or value): exit status 2."""


#: The exit statuses, as the help states them.
EXIT_HELP = (
    f"Exit status: {EXIT_OK} ok; {EXIT_RANK_DEFICIENT} rank deficient (K does not exist); "
    f"{EXIT_BAD_INPUT} bad input; {EXIT_FAILED} computation failed (unreachable pose, "
    "singular configuration)."
)


class _Parser(Parser):
    def error(self, message: str):  # one line, no usage block
        raise UsageError(message)


def add_backend_arguments(parser: argparse.ArgumentParser) -> None:
    """Options --ks and --backend (choices and defaults in the help)."""
    parser.add_argument(
        "--ks",
        choices=sorted(KS_PRESETS),
        default="assumed",
        help="K_s for every backend: assumed 0.697e6 N/m or printed 0.697 N/m, the paper's "
        "value (default: %(default)s)",
    )
    parser.add_argument(
        "--backend",
        choices=backend_names(),
        default="generic",
        help="stiffness backend: generic (Pinocchio model), consistent (closed form), "
        "published (the paper's matrices as printed, in its own coordinates) "
        "(default: %(default)s)",
    )


def finite_float(text: str) -> float:
    """argparse type: a finite real number."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return value


def add_pose_arguments(parser: argparse.ArgumentParser) -> None:
    """Options --alpha, --alpha4, --s4 (paper units), --ks, --backend, --json."""
    d = DEFAULT_POSE
    parser.add_argument(
        "--alpha",
        nargs=3,
        type=finite_float,
        default=list(d["alpha"]),
        metavar=("A1", "A2", "A3"),
        help="crank angles alpha_1..3 [deg] (default: %(default)s)",
    )
    parser.add_argument(
        "--alpha4",
        type=finite_float,
        default=d["alpha4"],
        metavar="A4",
        help="arm angle alpha_4 [deg] (default: %(default)s)",
    )
    parser.add_argument(
        "--s4",
        type=finite_float,
        default=d["s4"],
        metavar="S4",
        help="telescope stroke s_4 [mm] (default: %(default)s)",
    )
    add_backend_arguments(parser)
    parser.add_argument("--json", action="store_true", help="print SI JSON")  # fmt: skip


#: Masses settable with --mass.
MASS_NAMES = ("m_HQ", "m_QM", "m_MM2", "m_M4", "m_M5", *LEG_MASSES)


def add_weight_arguments(parser: argparse.ArgumentParser) -> None:
    """Options --gravity and --mass NAME=KG (the masses of the paper's eq. 11)."""
    parser.add_argument(
        "--gravity", action="store_true",
        help="the machine under the weight of its masses (generic backend): the tangent "
        "compliance at the sagged pose, and the sag of M",
    )  # fmt: skip
    parser.add_argument(
        "--mass", action="append", default=[], metavar="NAME=KG",
        help="a mass [kg]: the paper's m_HQ, m_QM, m_MM2, m_M4, m_M5, or a leg link's "
        "m_b, m_c, m_d, m_h (default 0)",
    )  # fmt: skip


def _masses(args: argparse.Namespace) -> dict[str, float]:
    out = {}
    for item in getattr(args, "mass", []):
        name, _, value = item.partition("=")
        if name not in MASS_NAMES or not value:
            raise UsageError(f"--mass {item!r}: expected NAME=KG with NAME one of "
                             f"{', '.join(MASS_NAMES)}")  # fmt: skip
        out[name] = finite_float(value)
    return out


def stiffness_from_args(args: argparse.Namespace) -> CaHyManStiffness:
    """Stiffness at the pose given by :func:`add_pose_arguments`' options (converted to SI)."""
    params = DEFAULT_PARAMS.with_ks(args.ks)
    masses = _masses(args)
    return stiffness(
        np.deg2rad(args.alpha),
        math.radians(args.alpha4),
        args.s4 / 1000.0,
        params=params.replace(**masses) if masses else params,
        backend=args.backend,
        weight=getattr(args, "gravity", False),
    )


def inputs_echo(args: argparse.Namespace) -> dict:
    """The pose options as given (paper units) and in SI."""
    return {
        "alpha_deg": list(args.alpha),
        "alpha4_deg": args.alpha4,
        "s4_mm": args.s4,
        "alpha_rad": np.deg2rad(args.alpha).tolist(),
        "alpha4_rad": math.radians(args.alpha4),
        "s4_m": args.s4 / 1000.0,
        "ks": args.ks,
        "K_s_N_per_m": KS_PRESETS[args.ks],
        "backend": args.backend,
    }


def _matrix(name: str, A: np.ndarray, unit: str, axes: str = "world") -> str:
    rows = "\n".join("  " + " ".join(f"{x: .6e}" for x in row) for row in A)
    where = "at M, world axes" if axes == "world" else f"coordinates of the {axes}"
    return f"{name} [{unit}] (order dx dy dz rx ry rz; {where}):\n{rows}"


def _vec(v, scale: float = 1.0, fmt: str = "{: .6g}") -> str:
    return "(" + ", ".join(fmt.format(x * scale) for x in v) + ")"


def _pose_lines(r: CaHyManStiffness) -> list[str]:
    p = r.pose
    return [
        f"platform H = {_vec(p.H, 1e3)} mm; phi, theta, psi = "
        f"{_vec([p.phi, p.theta, p.psi], 180 / math.pi)} deg",
        f"extremity M = {_vec(p.M, 1e3)} mm",
    ]


# ------------------------------------------------------------------ stiffness
def _run_stiffness(args: argparse.Namespace) -> int:
    r = stiffness_from_args(args)
    out = r.to_dict()
    out["inputs"] = inputs_echo(args)
    status = EXIT_OK if r.is_full_rank else EXIT_RANK_DEFICIENT
    if args.json:
        print(json.dumps(out, indent=2, allow_nan=False))
        return status
    print(f"CaHyMan at alpha = {args.alpha} deg, alpha4 = {args.alpha4} deg, "
          f"s4 = {args.s4} mm (K_s {args.ks}, backend {args.backend})")  # fmt: skip
    print("\n".join(_pose_lines(r)))
    if r.is_full_rank:
        print(_matrix("K", r.K, "N/m, N/rad, N m/m, N m/rad", r.axes))
        print(f"det K = {r.det_K:.6e} N^6/rad^3")
        print(f"eigenvalues of K [SI] = {_vec(np.real_if_close(r.eigenvalues))}")
        print(f"condition number of K [SI] = {r.condition_number:.6g}")
    else:
        print(f"K does not exist: compliance rank {out['rank']} < 6")

    if r.indices is not None:
        flag = "; ILL-CONDITIONED: near a singular pose" if r.indices.ill_conditioned else ""
        print(f"condition number of the scaled K = {r.indices.scaled_condition_number:.3e} "
              f"(lengths per L = {r.params.length:.4g} m){flag}")  # fmt: skip
    print(_matrix("C", r.C, "m/N, m/(N m), rad/N, rad/(N m)", r.axes))
    return status


def _add_stiffness(subparsers) -> None:
    p = subparsers.add_parser("stiffness", help="6x6 stiffness and compliance at M",
                              description="Stiffness K and compliance C at M (SI).",
                              epilog=EXIT_HELP)  # fmt: skip
    add_pose_arguments(p)
    add_weight_arguments(p)
    p.set_defaults(func=_run_stiffness)


# ------------------------------------------------------------------ deflect
def _twist_dict(t: np.ndarray) -> dict:
    return {
        "displacement_m": t[:3].tolist(),
        "displacement_mm": (t[:3] * 1e3).tolist(),
        "rotation_rad": t[3:].tolist(),
        "rotation_deg": np.rad2deg(t[3:]).tolist(),
    }


def _run_deflect(args: argparse.Namespace) -> int:
    r = stiffness_from_args(args)
    d = r.deflection(np.r_[args.force, args.torque])
    out = {
        "wrench": {"force_N": list(args.force), "torque_N_m": list(args.torque)},
        "M": _twist_dict(d.M),
        "platform": None if d.H is None else _twist_dict(d.H),
        "pose": r.pose.to_dict(),
        "inputs": inputs_echo(args),
        "units": "SI, with _mm and _deg copies; twists at M (arm link) and at H (plate), "
        "world axes; rotations are small rotation vectors",
        "axes": r.axes,
    }
    if r.axes != "world":
        out["units"] = f"SI, with _mm and _deg copies; twist of M in the {r.axes}"
    if args.json:
        print(json.dumps(out, indent=2, allow_nan=False))
        return 0
    print(f"force {args.force} N, torque {args.torque} N m at M")
    print("\n".join(_pose_lines(r)))
    rows = [("M (arm extremity)", d.M)] + ([] if d.H is None else [("H (platform)", d.H)])
    for name, t in rows:
        print(f"{name}: displacement {_vec(t[:3], 1e3)} mm = {_vec(t[:3])} m")
        print(f"{' ' * len(name)}  rotation {_vec(t[3:], 180 / math.pi)} deg = {_vec(t[3:])} rad")
    return 0


def _add_deflect(subparsers) -> None:
    p = subparsers.add_parser("deflect", help="deflection of M and of the platform under a load",
                              description="Small deflection under a wrench at M.",
                              epilog=EXIT_HELP)  # fmt: skip
    add_pose_arguments(p)
    add_weight_arguments(p)
    p.add_argument(
        "--force",
        nargs=3,
        type=finite_float,
        default=[0.0, 0.0, 0.0],
        metavar=("FX", "FY", "FZ"),
        help="force at M [N], world axes",
    )
    p.add_argument("--torque", nargs=3, type=finite_float, default=[0.0, 0.0, 0.0],
                   metavar=("NX", "NY", "NZ"), help="torque [N m], world axes")  # fmt: skip
    p.set_defaults(func=_run_deflect)


# ------------------------------------------------------------------ entry point
def command_of(argv: Sequence[str]) -> str | None:
    """The subcommand named by ``argv`` (its first word that is not an option), or None."""
    return next((a for a in argv if not a.startswith("-")), None)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """Parser with the built-in subcommands and those of :data:`SUBCOMMAND_MODULES`.

    Args:
        command: the subcommand that will run: only its module is imported; the other
            modules' subcommands are placeholders that carry their help line (enough for
            ``cahyman --help`` and for the list of choices of an unknown command).
    """
    parser = _Parser(
        prog=PROG, description="Stiffness of CaHyMan (Cassino Hybrid Manipulator). " + EXIT_HELP
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    _add_stiffness(subparsers)
    _add_deflect(subparsers)
    for name, (module, help_line) in SUBCOMMAND_MODULES.items():
        if command == name:
            importlib.import_module(module).add_parser(subparsers)
        else:
            subparsers.add_parser(name, help=help_line, add_help=False)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status (see the module docstring)."""
    single_threaded_blas()  # small matrices: BLAS threads cost more than they give
    try:
        argv = sys.argv[1:] if argv is None else list(argv)
        args = build_parser(command_of(argv)).parse_args(argv)
    except UsageError as e:
        print(error_line(PROG, e), file=sys.stderr)
        return EXIT_BAD_INPUT
    except SystemExit as e:  # --help, --version
        return e.code if isinstance(e.code, int) else 0
    return run_command(PROG, args)


if __name__ == "__main__":
    raise SystemExit(main())
