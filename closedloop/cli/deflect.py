"""``closedloop deflect``: how far a frame moves under a load, and which joints give.

    closedloop deflect MODEL --frame NAME --force FX FY FZ --torque NX NY NZ
        [--q Q ... | --actuated A ...] [--joint-stiffness K | --springs FILE] [--json]

The load (force [N], torque [N m], world axes, at the frame origin; default 0) gives, to
first order, the twist of the frame t = C w (dx dy dz [m], rx ry rz [rad], world axes), the
joint deflections dq = G w (one value per coordinate of the tangent of q, rad or m) and
the share of the deflection energy stored in each spring and beam. The pose options are
those of ``closedloop stiffness``. Exit status: 0; 1 the compliance is rank deficient (K
does not exist: the twist is that of the directions the springs allow, the rigid ones
are named); 2 bad input; 3 the computation failed.
"""

from __future__ import annotations

import argparse

import numpy as np

from closedloop.cli.options import mode_line
from closedloop.cli.outputs import print_json
from closedloop.common.conditioning import twist_scaling
from closedloop.common.rounding import without_rounding
from closedloop.elastostatics.compliance import TWIST_LABELS, describe_directions, energy_shares
from closedloop.exceptions import EXIT_OK, EXIT_RANK_DEFICIENT


def add_parser(sub, source_arguments) -> None:
    """The ``deflect`` subparser, with the pose options of ``stiffness``."""
    from closedloop.cli.app import EPILOG
    from closedloop.cli.options import add_model_arguments, add_wrench_arguments

    p = sub.add_parser(
        "deflect",
        help="twist of a frame and joint deflections under a load",
        description=__doc__.split("\n\n", 1)[1],
        epilog=EPILOG.split("\n\nOutput:")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_model_arguments(p)
    add_wrench_arguments(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run_deflect)


def deflection_report(clm, res, wrench: np.ndarray) -> dict:
    """JSON-ready deflection of ``res`` (a world-axes compliance of ``clm``) under
    ``wrench`` (6,) [N, N m]: the configuration q and its assembly mode (the passive
    joints' values [rad, m], and the line that shows them), twist (6,) [m, rad], joint
    deflections by coordinate (joint name, index in the tangent of q, value [rad or m]),
    energy shares, rank, length L [m] of the unit-free rules."""
    from closedloop.kinematics.assembly_modes import passive_values  # what the output needs

    twist = res.deflection(wrench)
    dq = res.joint_deflection(wrench)
    units = np.where(clm.linear_coordinates, "m", "rad")
    return {
        "model": clm.name,
        "frame": res.frame,
        "axes": res.axes,
        "point": res.point.tolist(),
        "q": res.q.tolist(),
        "passive": passive_values(clm, res.q),
        "mode": mode_line(clm, res.q),
        "wrench": wrench.tolist(),
        "twist": twist.tolist(),
        "order": list(TWIST_LABELS),
        "joint_deflections": [
            {
                "joint": clm.coordinate_joint(i),
                "coordinate": i,
                "value": float(dq[i]),
                "unit": str(units[i]),
            }
            for i in range(dq.size)
        ],
        "energy_shares": energy_shares(clm, res, wrench),
        "rank": res.rank,
        "length": res.length,
        "rigid_directions": res.rigid_directions.T.tolist(),
        "note": res.note,
    }


def format_deflection(doc: dict) -> str:
    """Text of :func:`deflection_report`; rounding noise shown as 0
    (:func:`closedloop.common.rounding.without_rounding`)."""
    t = without_rounding(doc["twist"], twist_scaling(doc["length"]))
    per_m = [1.0 / doc["length"] if d["unit"] == "m" else 1.0 for d in doc["joint_deflections"]]
    dq = without_rounding([d["value"] for d in doc["joint_deflections"]], per_m)
    w = doc["wrench"]
    lines = [
        f"model {doc['model']!r}, frame {doc['frame']!r}, world-aligned axes, at the frame "
        f"origin {', '.join(f'{x:.6g}' for x in doc['point'])} m",
        *filter(None, [doc["mode"]]),
        f"load: force {' '.join(f'{x:.6g}' for x in w[:3])} N, "
        f"torque {' '.join(f'{x:.6g}' for x in w[3:])} N m",
        f"displacement dx dy dz: {' '.join(f'{x:.6g}' for x in t[:3])} m "
        f"({' '.join(f'{1e3 * x:.6g}' for x in t[:3])} mm)",
        f"rotation rx ry rz: {' '.join(f'{x:.6g}' for x in t[3:])} rad "
        f"({' '.join(f'{x:.6g}' for x in np.degrees(t[3:]))} deg)",
    ]
    if doc["rank"] < 6:
        lines.append(
            f"rank of C {doc['rank']}/6: rigid along "
            f"{describe_directions(np.array(doc['rigid_directions']).T)}"
            + (f"; {doc['note']}" if doc["note"] else "")
        )
    lines += ["", "joint deflections (tangent of q):"]
    lines += [
        f"  {d['joint']:<24} {x:13.6g} {d['unit']}"
        for d, x in zip(doc["joint_deflections"], dq, strict=True)
    ]
    shares = doc["energy_shares"]
    if shares:
        lines += ["", "energy shares:"]
        lines += [f"  {share:7.2%}  {name}" for name, share in shares.items()]
    return "\n".join(lines)


def run_deflect(args) -> int:
    """Run ``closedloop deflect``; returns the exit code (0, or 1 when K does not exist)."""
    from closedloop.cli.options import model_from_args
    from closedloop.elastostatics.compliance import compliance

    clm, state = model_from_args(args)
    res = compliance(state, args.frame, axes="world")
    doc = deflection_report(clm, res, np.r_[args.force, args.torque])
    if args.json:
        print_json(doc)
    else:
        print(format_deflection(doc))
    return EXIT_OK if res.is_full_rank else EXIT_RANK_DEFICIENT
