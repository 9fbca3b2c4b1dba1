"""Options shared by the ``cahyman`` subcommands: the pose in the paper's units (deg, mm)
converted once to SI, the backend and K_s choices, masses. The conventions both command
lines share (parser, usage error, finite numbers, JSON, exit statuses) are
:mod:`closedloop.cli.common`'s."""

from __future__ import annotations

import argparse
import math
import warnings

import numpy as np

from cahyman_pin.api import CaHyManStiffness, stiffness
from cahyman_pin.backends.registry import backend_names
from cahyman_pin.params import DEFAULT_PARAMS, K_S_ASSUMED, K_S_PRINTED, LEG_MASSES
from closedloop.cli.parser import UsageError, finite_float, needs_gravity

#: Table 1's configuration, the default pose: alpha_k [deg], alpha_4 [deg], s_4 [mm].
DEFAULT_POSE = {"alpha": (90.0, 90.0, 90.0), "alpha4": 90.0, "s4": 50.0}
KS_PRESETS = {"assumed": K_S_ASSUMED, "printed": K_S_PRINTED}


#: What each backend is, for the help of --backend.
BACKEND_HELP = {
    "generic": "generic (Pinocchio model)",
    "consistent": "consistent (closed form)",
    "published": "published (the paper's matrices as printed, in its own coordinates)",
}


def add_backend_arguments(
    parser: argparse.ArgumentParser, backends: tuple[str, ...] | None = None
) -> None:
    """Options --ks and --backend (choices and defaults in the help); ``backends``: the
    choices (default: every registered backend)."""
    choices = backend_names() if backends is None else backends
    parser.add_argument(
        "--ks",
        choices=sorted(KS_PRESETS),
        default="assumed",
        help="K_s for every backend: assumed 0.697e6 N/m or printed 0.697 N/m, the paper's "
        "value (default: %(default)s)",
    )
    parser.add_argument(
        "--backend",
        choices=choices,
        default="generic",
        help="stiffness backend: "
        + ", ".join(BACKEND_HELP.get(name, name) for name in choices)
        + " (default: %(default)s)",
    )


def add_pose_arguments(
    parser: argparse.ArgumentParser, backends: tuple[str, ...] | None = None
) -> None:
    """Options --alpha, --alpha4, --s4 (paper units), --ks, --backend (``backends``, as
    for :func:`add_backend_arguments`), --json."""
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
    add_backend_arguments(parser, backends)
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


def _masses(args: argparse.Namespace, weight: bool = True) -> dict[str, float]:
    """The --mass values {name: kg}; ``weight``: they are weights (need --gravity)."""
    out = {}
    for item in getattr(args, "mass", []):
        if weight:
            needs_gravity(f"--mass {item}", args.gravity)
        name, _, value = item.partition("=")
        if name not in MASS_NAMES or not value:
            raise UsageError(f"--mass {item!r}: expected NAME=KG with NAME one of "
                             f"{', '.join(MASS_NAMES)}")  # fmt: skip
        if name in out:
            raise UsageError(f"--mass {name} given twice ({out[name]:g} and {value} kg)")
        try:
            out[name] = finite_float(value)
        except argparse.ArgumentTypeError as e:
            raise UsageError(f"--mass {item!r}: {e}") from None
    return out


def stiffness_from_args(args: argparse.Namespace) -> CaHyManStiffness:
    """Stiffness at the pose given by :func:`add_pose_arguments`' options (converted to SI).

    Raises:
        EquilibriumError: with ``--gravity``, an unstable equilibrium
            (:func:`closedloop.elastostatics.preload.require_stable`).
    """
    params = DEFAULT_PARAMS.with_ks(args.ks)
    masses = _masses(args)
    params = params.replace(**masses) if masses else params
    weight = getattr(args, "gravity", False)
    if weight and not any(getattr(params, name) for name in MASS_NAMES):  # 0 by default
        warnings.warn("--gravity: every mass is 0, so the sag is 0; give the masses with "
                      "--mass NAME=KG", stacklevel=2)  # fmt: skip
    result = stiffness(
        *pose_si(args),
        params=params,
        backend=args.backend,
        weight=weight,
    )
    if weight:  # a command line answers at stable equilibria only
        from closedloop.elastostatics.preload import require_stable

        require_stable(result.details["compliance"])
    return result


def radians_note(option: str, values) -> None:
    """Warn (one line on stderr from a command) when every value of the angle ``option``
    [deg] looks like radians: each below 2 pi in magnitude with a fractional part
    (``--alpha 0.785 1.047 1.309``); the values stay degrees."""
    values = np.asarray(values, dtype=float).reshape(-1)
    if values.size and np.all((np.abs(values) < 2 * math.pi) & (values != np.round(values))):
        shown = " ".join(f"{v:g}" for v in values[:6]) + (" ..." if values.size > 6 else "")
        warnings.warn(
            f"{option} {shown}: every value is below 2 pi with a fraction, as angles in "
            f"radians are; {option} is in degrees, and the values are taken as degrees",
            stacklevel=2,
        )


def pose_si(args: argparse.Namespace) -> tuple[np.ndarray, float, float]:
    """(alpha_1..3 (3,) [rad], alpha_4 [rad], s_4 [m]) of :func:`add_pose_arguments`'
    options (deg, mm), with the note of :func:`radians_note` for ``--alpha``."""
    radians_note("--alpha", args.alpha)
    return np.deg2rad(args.alpha), math.radians(args.alpha4), args.s4 / 1000.0


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
