"""``cahyman modes``: natural frequencies and mode shapes of CaHyMan at a pose, with the
effective masses at M (:func:`closedloop.analysis.vibration.modes` on the generic model).

The paper names no masses and CaHyMan's default ones are 0: give them with ``--mass
NAME=KG``, or model the links as beams (``--links-as-beams``, tubes of the default sections)
and give their density ``--density RHO`` (a machine without mass has no natural frequency: a
one-line error). ``--gravity``: the modes about the equilibrium where the machine settles
under the weight of those masses (the pose given is the springs' rest pose, as for ``cahyman
stiffness --gravity``), with the weight's tangent stiffness.
"""

from __future__ import annotations

import argparse

from cahyman_pin.cli.options import (
    DEFAULT_PARAMS,
    MASS_NAMES,
    UsageError,
    _masses,
    add_pose_arguments,
    inputs_echo,
    pose_si,
)
from closedloop.cli.outputs import print_json
from closedloop.cli.parser import finite_float
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
    p.add_argument(
        "--gravity", action="store_true",
        help="about the equilibrium under the weight (g = 9.81 m/s^2 along -z); the pose is "
        "the springs' rest pose",
    )  # fmt: skip
    p.add_argument(
        "--links-as-beams", action="store_true",
        help="the legs' and the arm's links as elastic tubes (links_as_beams)",
    )  # fmt: skip
    p.add_argument(
        "--density", type=finite_float, metavar="RHO",
        help="density [kg/m^3] of the links as beams (needs --links-as-beams)",
    )  # fmt: skip
    p.add_argument("--n", type=int, metavar="N", help="number of lowest modes (default: all)")
    p.set_defaults(func=_run_modes)


def _run_modes(args: argparse.Namespace) -> int:
    from cahyman_pin.model import cahyman_model
    from closedloop.analysis.vibration import modes
    from closedloop.cli.modes import format_modes

    if args.density is not None and not args.links_as_beams:
        raise UsageError("--density weighs the links as beams; give --links-as-beams too")
    params = DEFAULT_PARAMS.with_ks(args.ks)
    masses = _masses(args, weight=False)
    params = params.replace(**masses, links_as_beams=args.links_as_beams)
    machine = cahyman_model(params)
    q = machine.assemble(*pose_si(args))
    machine.require_within_limits(q)
    gravity = (0.0, 0.0, -params.gravity) if args.gravity else None
    res = modes(machine.clm, q, n=args.n, frame="M", gravity=gravity, density=args.density)
    if args.json:
        print_json({"model": "cahyman", "inputs": inputs_echo(args), "masses_kg": masses,
                    "links_as_beams": args.links_as_beams, "density_kg_per_m3": args.density,
                    "gravity_m_per_s2": gravity, **res.to_dict(), "q": res.q.tolist()})  # fmt: skip
    else:
        print(format_modes("cahyman", res))
    return EXIT_OK
