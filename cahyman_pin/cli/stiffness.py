"""``cahyman stiffness`` and ``cahyman deflect``: K, C and the deflection at a pose."""

from __future__ import annotations

import argparse
import math

import numpy as np

from cahyman_pin.api import CaHyManStiffness
from cahyman_pin.cli.options import (
    add_pose_arguments,
    add_weight_arguments,
    finite_float,
    inputs_echo,
    stiffness_from_args,
)
from closedloop.cli.common import EXIT_HELP
from closedloop.cli.outputs import check_finite, print_json
from closedloop.common.conditioning import twist_scaling
from closedloop.common.rounding import without_rounding
from closedloop.exceptions import EXIT_OK, EXIT_RANK_DEFICIENT


def _matrix(name: str, A: np.ndarray, unit: str, axes: str = "world") -> str:
    rows = "\n".join("  " + " ".join(f"{x: .6e}" for x in row) for row in A)
    where = "at M, world axes" if axes == "world" else f"coordinates of the {axes}"
    return f"{name} [{unit}] (order dx dy dz rx ry rz; {where}):\n{rows}"


def _vec(v, scale: float = 1.0, fmt: str = "{: .6g}") -> str:
    return "(" + ", ".join(fmt.format(x * scale) for x in v) + ")"


def _twist_lines(name: str, t: np.ndarray, length: float) -> list[str]:
    """A twist (6,) [m, rad] in mm and deg; rounding next to its largest component
    (unit-free, lengths per ``length`` L [m]) shown as 0."""
    t = without_rounding(t, twist_scaling(length))
    return [
        f"{name}: displacement {_vec(t[:3], 1e3)} mm = {_vec(t[:3])} m",
        f"{' ' * len(name)}  rotation {_vec(t[3:], 180 / math.pi)} deg = {_vec(t[3:])} rad",
    ]


def _pose_lines(r: CaHyManStiffness) -> list[str]:
    """The pose (the sagged one with --gravity) and, with --gravity, the sag of M."""
    p, L = r.pose, r.params.length
    angles = without_rounding([p.phi, p.theta, p.psi])  # rounding next to 90 deg: 0
    lines = [
        f"platform H = {_vec(without_rounding(p.H), 1e3)} mm; phi, theta, psi = "
        f"{_vec(angles, 180 / math.pi)} deg",
        f"extremity M = {_vec(without_rounding(p.M), 1e3)} mm",
    ]
    if r.sag_M is not None:
        lines += _twist_lines("sag of M under the weight (world axes)", r.sag_M, L)
    return lines


# ------------------------------------------------------------------ stiffness
def _run_stiffness(args: argparse.Namespace) -> int:
    r = stiffness_from_args(args)
    out = r.to_dict()
    out["inputs"] = inputs_echo(args)
    status = EXIT_OK if r.is_full_rank else EXIT_RANK_DEFICIENT
    if args.json:
        print_json(out)
        return status
    check_finite(out)  # as the JSON: no inf or NaN printed as a result
    print(f"CaHyMan at alpha = {args.alpha} deg, alpha4 = {args.alpha4} deg, "
          f"s4 = {args.s4} mm (K_s {args.ks}, backend {args.backend})")  # fmt: skip
    print("\n".join(_pose_lines(r)))
    if r.is_full_rank:
        print(_matrix("K", r.K, "N/m, N/rad, N m/m, N m/rad", r.axes))
        det = out["det_K"]
        print(f"det K = {det:.6e} N^6/rad^3" if det is not None else out["missing"]["det_K"])
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


def add_stiffness(subparsers) -> None:
    """Add ``cahyman stiffness`` (K and C at M) to ``subparsers``."""
    p = subparsers.add_parser("stiffness", help="6x6 stiffness and compliance at M",
                              description="Stiffness K and compliance C at M (SI).",
                              epilog=EXIT_HELP)  # fmt: skip
    add_pose_arguments(p)
    add_weight_arguments(p)
    p.set_defaults(func=_run_stiffness)


# ------------------------------------------------------------------ deflect
def _twist_dict(t: np.ndarray) -> dict:
    """SI and mm/deg copies; an overflow of the copies is left to :func:`check_finite`."""
    with np.errstate(over="ignore"):
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
        "sag_M": None if r.sag_M is None else _twist_dict(r.sag_M),
        "inputs": inputs_echo(args),
        "units": "SI, with _mm and _deg copies; twists at M (arm link) and at H (plate) "
        "under the wrench, and sag_M of M under the weight (--gravity, else null), world "
        "axes; rotations are small rotation vectors",
        "axes": r.axes,
    }
    if r.axes != "world":
        out["units"] = f"SI, with _mm and _deg copies; twist of M in the {r.axes}"
    if args.json:
        print_json(out)
        return 0
    check_finite(out)
    read = ("world axes" if r.axes == "world"  # the published formulation: its own reading
            else "read as the paper's formulation reads them: M_FT in the arm frame, K_SER "
            "in world axes")  # fmt: skip
    print(f"force {args.force} N, torque {args.torque} N m at M, {read}")
    print("\n".join(_pose_lines(r)))
    if r.axes != "world":  # the published backend: its own coordinates
        print(f"the twists below are in the coordinates of the {r.axes}")
    rows = [("M (arm extremity)", d.M)] + ([] if d.H is None else [("H (platform)", d.H)])
    for name, t in rows:
        print("\n".join(_twist_lines(name, t, r.params.length)))
    return 0


def add_deflect(subparsers) -> None:
    """Add ``cahyman deflect`` (the deflection under a wrench at M) to ``subparsers``."""
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
