"""``cahyman modes``: natural frequencies and mode shapes of CaHyMan at a pose, with the
effective masses at M (:func:`closedloop.analysis.vibration.modes` on the generic model).

The paper names no masses and CaHyMan's default ones are 0: give them with ``--mass
NAME=KG`` (a machine without mass has no natural frequency: a one-line error).
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from cahyman_pin.cli.options import (
    DEFAULT_PARAMS,
    MASS_NAMES,
    _masses,
    add_pose_arguments,
    inputs_echo,
)
from closedloop.cli.outputs import print_json
from closedloop.exceptions import EXIT_OK


def add_parser(subparsers) -> None:
    """The ``modes`` subparser."""
    p = subparsers.add_parser(
        "modes",
        help="natural frequencies at a pose (give the masses)",
        description=__doc__.split("\n\n", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_pose_arguments(p, backends=("generic",))
    p.add_argument(
        "--mass", action="append", default=[], metavar="NAME=KG",
        help=f"a mass [kg], NAME one of {', '.join(MASS_NAMES)} (default 0)",
    )  # fmt: skip
    p.add_argument("--n", type=int, metavar="N", help="number of lowest modes (default: all)")
    p.set_defaults(func=_run_modes)


def _run_modes(args: argparse.Namespace) -> int:
    from cahyman_pin.model import cahyman_model
    from closedloop.analysis.vibration import modes
    from closedloop.cli.modes import format_modes

    params = DEFAULT_PARAMS.with_ks(args.ks)
    masses = _masses(args, weight=False)
    machine = cahyman_model(params.replace(**masses) if masses else params)
    q = machine.assemble(np.deg2rad(args.alpha), math.radians(args.alpha4), args.s4 / 1000.0)
    res = modes(machine.clm, q, n=args.n, frame="M")
    if args.json:
        print_json({"model": "cahyman", "inputs": inputs_echo(args), "masses_kg": masses,
                    **res.to_dict()})  # fmt: skip
    else:
        print(format_modes("cahyman", res))
    return EXIT_OK
