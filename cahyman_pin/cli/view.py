"""``cahyman view``: the deflection of CaHyMan under a wrench at M, in a meshcat viewer.

Pose options as for the other subcommands (deg, mm); the wrench is SI, world axes, at M.
With ``--html FILE`` a self-contained page is written (it opens offline); without it the
viewer is served on 127.0.0.1, its URL printed, until Ctrl-C (or ``--duration`` seconds).
Examples::

    cahyman view --alpha 45 60 75 --alpha4 45 --s4 0 --force 10 0 -20 --html cahyman.html
    cahyman view --force 0 0 -50 --scale 200          # live, amplification 200

The drawing (ghost of the nominal pose, amplified deflected pose, arrows, compliance
ellipsoids, grid, HTML legend with the pose below, load-ramp animation) is
:mod:`closedloop.viewer.viewer`'s; the model is the Pinocchio
model of :mod:`cahyman_pin.model`, hence ``--backend`` has the one choice ``generic``. With
``--json`` the summary is printed as one JSON object and the other lines go to stderr.
"""

from __future__ import annotations

import argparse
import sys

from cahyman_pin.cli.options import add_pose_arguments, pose_si
from cahyman_pin.model import cahyman_model
from cahyman_pin.params import DEFAULT_PARAMS
from cahyman_pin.urdf_builder import FRAME_M
from closedloop.cli.outputs import print_json
from closedloop.cli.view import add_view_arguments, view_from_args


def _stderr(line: str) -> None:
    print(line, file=sys.stderr)


def run(args: argparse.Namespace) -> int:
    """Run ``cahyman view``; returns the exit status (0)."""
    model = cahyman_model(DEFAULT_PARAMS.with_ks(args.ks))
    q = model.assemble(*pose_si(args))
    model.require_within_limits(q)
    pose = (
        f"alpha = ({', '.join(f'{a:g}' for a in args.alpha)}) deg, alpha4 = {args.alpha4:g} deg, "
        f"s4 = {args.s4:g} mm, K_s {args.ks}"
    )
    out = _stderr if args.json else print
    scene = view_from_args(model.clm, q, FRAME_M, args, out=out, pose=pose, prog="cahyman")
    if args.json:
        print_json({**scene.to_dict(), "html": args.html})
    return 0


def add_parser(subparsers) -> None:
    """Add the ``view`` subcommand."""
    p = subparsers.add_parser(
        "view",
        help="meshcat view of the deflection under a wrench at M",
        description="Deflection of CaHyMan under a wrench at M (SI, world axes) in a meshcat "
        "viewer: --html writes a self-contained page, else the viewer is served on "
        "127.0.0.1 until Ctrl-C.",
    )
    add_pose_arguments(p, backends=("generic",))  # the model it draws
    add_view_arguments(p)
    p.set_defaults(func=run)
