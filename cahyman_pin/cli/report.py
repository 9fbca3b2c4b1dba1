"""``cahyman report [--out DIR] [--params FILE]``: the comparison report against the paper.

Writes ``report.md``, a self-contained ``report.html`` and the figures (PNG) into DIR
(default ``./cahyman-report``); FILE is a YAML mapping of
:class:`cahyman_pin.params.CaHyManParams` fields (SI) that replace the defaults.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from cahyman_pin.paper.report import build_report
from cahyman_pin.params import DEFAULT_PARAMS, CaHyManParams, read_params_file
from closedloop.cli.outputs import output_folder
from closedloop.cli.parser import path_text

DEFAULT_OUT = Path("cahyman-report")


def add_parser(subparsers) -> None:
    """The ``report`` subcommand."""
    p = subparsers.add_parser(
        "report",
        help="write the comparison report against the paper",
        description="The comparison report against the paper: report.md, report.html and "
        "the figures in --out.",
    )
    p.add_argument("--out", type=path_text, default=DEFAULT_OUT,
                   help=f"output folder (default: ./{DEFAULT_OUT})")  # fmt: skip
    p.add_argument("--params", type=path_text, metavar="FILE",
                   help="YAML mapping of CaHyMan parameters (SI) replacing the defaults, e.g. "
                   "'K_s: 0.697' or 'b: 0.09'; fields: " + ", ".join(CaHyManParams.field_names())
                   )  # fmt: skip
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    params = DEFAULT_PARAMS if args.params is None else read_params_file(args.params)
    out = output_folder(args.out)  # a bad --out stops here, before the computations
    start = time.perf_counter()
    build_report(out, params, args.params)
    print(f"report written to {out / 'report.md'} and {out / 'report.html'} "
          f"in {time.perf_counter() - start:.1f} s")  # fmt: skip
    return 0
