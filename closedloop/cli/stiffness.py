"""``closedloop stiffness``: the Cartesian stiffness K and compliance C of a frame, as a
report or as JSON.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

import numpy as np

from closedloop.cli.options import mode_line, model_from_args, preload_from_args
from closedloop.cli.outputs import print_json
from closedloop.cli.parser import UsageError
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
from closedloop.exceptions import EXIT_OK, EXIT_RANK_DEFICIENT
from closedloop.model.closed_loop import ClosedLoopModel

WRENCH_LABELS = ("fx", "fy", "fz", "nx", "ny", "nz")


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
        *filter(None, [mode_line(clm, res.q)]),
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
        from closedloop.kinematics.assembly_modes import passive_values  # JSON only

        doc = {"model": clm.name, **res.to_dict(), "q": res.q.tolist(),
               "passive": passive_values(clm, res.q)}  # fmt: skip
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
