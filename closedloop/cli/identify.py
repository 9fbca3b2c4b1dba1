"""``closedloop identify``: spring stiffnesses fitted to measured deflections.

    closedloop identify MODEL [--closures F] --measurements FILE --fit NAME [NAME ...]
        [--joint-stiffness K | --springs FILE] [--start Q ... | --near JOINT=VALUE ...]
        [--no-limits] [--json]

``--fit`` names joints; ``a+b`` ties joints a and b to one value; a joint with a block
spring (a beam's ``<link>_beam``) is fitted as a factor of its block. Start values come
from the model file (or ``--joint-stiffness`` / ``--springs``). The ``actuated`` values of a
measurement are driven from the model's reference configuration on its assembly mode, as
``closedloop stiffness --actuated`` drives them (``--start``, ``--near``: from that start
instead). The measurement file is the
YAML or CSV of ``closedloop.analysis.measurements.read_measurements``. Each estimate is
printed with its unit (N m/rad, N/m, or 1 for a block's factor). Exit status: 0 every
parameter identified and the model fits the data, 1 some cannot be identified from these
data (named, no value) or the model does not fit them (a residual RMS above what the sd
allow: one warning line, which names the measurements that misfit most and those
assembled on another assembly mode, the standard errors do not hold), 2 bad input, 3 the
computation failed. A measurement outside the joints' limits is bad input, unless
``--no-limits``.
"""

from __future__ import annotations

import argparse

from closedloop.cli.options import add_start_arguments, start_from_args
from closedloop.cli.outputs import print_json
from closedloop.cli.parser import path_text
from closedloop.exceptions import EXIT_OK, EXIT_RANK_DEFICIENT, NumericalError


def add_parser(sub, model_arguments) -> None:
    """The ``identify`` subparser; ``model_arguments(p, frame=False)`` adds MODEL,
    --closures and the springs options."""
    p = sub.add_parser(
        "identify",
        help="fit spring stiffnesses to measured deflections",
        description=__doc__.split("\n\n", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    model_arguments(p, frame=False)
    add_start_arguments(p)
    p.add_argument("--measurements", required=True, type=path_text, metavar="FILE",
                   help="YAML or CSV")  # fmt: skip
    p.add_argument("--fit", required=True, nargs="+", metavar="NAME", help="joints (a+b: tied)")
    p.add_argument("--no-limits", action="store_true",
                   help="accept measurements outside the joints' position limits (refused by "
                   "default: an angle in degrees is the usual cause)")  # fmt: skip
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run_identify)


def run_identify(args) -> int:
    """Run ``closedloop identify``; returns the exit code (0; 1 if a parameter is not
    identifiable or the model does not fit the data: ``Fit.consistent`` False, whose
    :class:`~closedloop.exceptions.ModelMisfitWarning` is the one line on stderr; 3 if the
    optimiser did not converge (NumericalError: one line on stderr, no estimates: they are
    not a least-squares solution))."""
    from closedloop.analysis.identification import identify  # scipy.optimize: on demand
    from closedloop.analysis.measurements import read_measurements
    from closedloop.cli.map import model_source  # MODEL, --closures and springs, as for a map

    clm = model_source(args).load()
    frame, data = read_measurements(args.measurements)
    groups = [tuple(name.split("+")) if "+" in name else name for name in args.fit]
    fit = identify(clm, data, frame, groups, check_limits=not args.no_limits,
                   q0=start_from_args(clm, args))  # fmt: skip
    status = EXIT_RANK_DEFICIENT if fit.unidentifiable or not fit.consistent else EXIT_OK
    if not fit.success:
        raise NumericalError(
            "the optimiser did not converge: the estimates are not a least-squares solution "
            "(check the start springs and the data)"
        )
    if args.json:
        print_json({"model": clm.name, "frame": frame, **fit.to_dict()})
        return status
    print(
        f"model {clm.name!r}, frame {frame!r}: {fit.n_measurements} measurements, "
        f"weighted residual RMS {fit.residual_rms:.3g}"
    )
    for name in fit.names:
        if fit.estimates[name] is None:
            print(f"  {name}: not identifiable from these data")
        else:
            unit = "(factor of its block)" if fit.units[name] == "1" else f"[{fit.units[name]}]"
            print(f"  {name} = {fit.estimates[name]:.6g} +- {fit.std_errors[name]:.2g} {unit}")
    for names in fit.confounded:
        print(f"  seen only together: {', '.join(names)}")
    return status
