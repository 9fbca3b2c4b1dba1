"""``cahyman map``: a stiffness index over one or two swept inputs, as data and a figure.

Pose inputs are in the paper's units (deg, mm), like the other ``cahyman`` subcommands;
design parameters (``--param``) are CaHyManParams fields in their SI units (m, N/m,
N m/rad); not g or the beams' fields, which a map (weightless, rigid links) does not read,
nor the masses but for the index ``lowest_frequency``. A value is one of

* ``V``: a single value (fixed);
* ``START:STOP:NUM``: NUM evenly spaced values, both ends included (swept);
* ``V1,V2,...``: a list of values (swept).

Examples::

    cahyman map --alpha 30:90:61 --alpha4 60 --s4 25                    # Fig. 5a, a curve
    cahyman map --alpha1 30:90:25 --alpha2 30:90:25 --alpha3 60 --index min_translational
    cahyman map --alpha 60 --alpha4 60 --s4 50 --param b=0.04:0.12:9      # design sweep
    cahyman map --alpha 30:90:31 --param b=0.04:0.12:9 --backend consistent --out fig5b
    cahyman map --s4 0:50:21 --alpha4 0:90:19 --force 1 1 1 --index deflection_translation
    cahyman map --alpha4 0:90:19 --index lowest_frequency --mass m_HQ=2 --mass m_M4=1

``--alpha`` takes one value (alpha_1 = alpha_2 = alpha_3, swept together when a range) or
three (alpha_1, alpha_2, alpha_3). A value starting with a minus sign needs ``=``:
``--alpha4=-30:30:13``. One swept input gives a curve, two a heat map. The folder ``--out``
receives ``map.npz`` (everything, SI), ``map.csv`` when the map is small and
``map_<index>.png``. ``--start closed_form`` starts every generic assembly from CaHyMan's
closed-form geometry instead of the previous point (faster; see :mod:`cahyman_pin.sweep.engine`).
``--index lowest_frequency`` (generic backend) also computes the lowest natural frequency
[Hz] at every point, of the masses given with ``--mass NAME=KG`` (0 by default: give some).
SIGINT and SIGTERM: as ``closedloop map``'s
(:data:`~closedloop.cli.map_options.SIGNALS_EPILOG`, the epilog of the help).
"""

from __future__ import annotations

import argparse
import math
import sys
import textwrap
from pathlib import Path

import numpy as np

from cahyman_pin.cli.options import (
    DEFAULT_POSE,
    MASS_NAMES,
    UsageError,
    _masses,
    add_backend_arguments,
    finite_float,
    radians_note,
)
from cahyman_pin.model import check_inputs
from cahyman_pin.params import BEAM_FIELDS, DEFAULT_PARAMS, WEIGHT_FIELDS, CaHyManParams
from cahyman_pin.sweep import INDEX_UNITS, SweepResult, grid, sweep
from cahyman_pin.sweep.execution import STARTS
from cahyman_pin.sweep.points import param_unit
from closedloop.analysis.cluster import add_worker_timeout, dask_executor
from closedloop.analysis.interrupts import Interrupted, SignalStop, stop_on_signals
from closedloop.analysis.maps import load_text
from closedloop.cli.map_options import (
    SIGNALS_EPILOG,
    SpecError,
    check_map_size,
    index_line,
    map_wrench,
    parse_values,
    quoted,
)
from closedloop.cli.outputs import output_folder
from closedloop.cli.parser import path_text, positive_int
from closedloop.common.figures import tidy_layout
from closedloop.common.files import save_figure
from closedloop.exceptions import InvalidInputError

DEFAULT_OUT = Path("cahyman-map")
#: Failed points printed one by one; the others are counted ("... and N more").
SHOWN_FAILURES = 3
#: Pose inputs: grid axis -> (option, unit shown, factor from the shown unit to SI).
POSE_OPTIONS = {
    "alpha": ("alpha", "deg", math.pi / 180.0),
    "alpha1": ("alpha1", "deg", math.pi / 180.0),
    "alpha2": ("alpha2", "deg", math.pi / 180.0),
    "alpha3": ("alpha3", "deg", math.pi / 180.0),
    "alpha4": ("alpha4", "deg", math.pi / 180.0),
    "s4": ("s4", "mm", 1e-3),
}
#: Indices plotted on a log scale (they span decades), and display scales of the others.
LOG_INDICES = ("det_K", "condition_number", "condition_number_si")
DISPLAY = {"deflection_translation": ("mm", 1e3), "deflection_rotation": ("deg", 180 / math.pi)}


#: Axis titles of the pose inputs.
TITLES = {"alpha": "alpha_1 = alpha_2 = alpha_3", "alpha1": "alpha_1", "alpha2": "alpha_2",
          "alpha3": "alpha_3", "alpha4": "alpha_4", "s4": "s_4"}  # fmt: skip


def parse_param(text: str) -> tuple[str, np.ndarray]:
    """``NAME=SPEC`` with NAME a CaHyManParams field (values in SI)."""
    name, sep, spec = text.partition("=")
    fields = CaHyManParams.field_names()
    if not sep or name not in fields:
        raise SpecError(
            f"{quoted(text)}: expected NAME=VALUES with NAME one of {', '.join(fields)}"
        )
    return name, parse_values(spec)


def add_parser(subparsers) -> None:
    """The ``map`` subcommand."""
    p = subparsers.add_parser(
        "map",
        help="a stiffness index over swept inputs (NPZ, CSV, PNG)",
        description="A stiffness index over one or two swept inputs: V, START:STOP:NUM or "
        "V1,V2,... (pose in deg and mm; --param in SI).",
        epilog=SIGNALS_EPILOG,
    )
    d = DEFAULT_POSE
    p.add_argument("--alpha", nargs="+", type=parse_values, metavar="SPEC",
                   help="alpha_1 = alpha_2 = alpha_3 (one SPEC) or alpha_1..3 (three) [deg] "
                   f"(default {' '.join(f'{a:g}' for a in d['alpha'])})")  # fmt: skip
    for k in (1, 2, 3):
        p.add_argument(f"--alpha{k}", type=parse_values, metavar="SPEC",
                       help=f"alpha_{k} [deg], overrides --alpha")  # fmt: skip
    p.add_argument(
        "--alpha4",
        type=parse_values,
        default=np.array([d["alpha4"]]),
        metavar="SPEC",
        help=f"arm angle alpha_4 [deg] (default {d['alpha4']:g})",
    )
    p.add_argument("--s4", type=parse_values, default=np.array([d["s4"]]), metavar="SPEC",
                   help=f"telescope stroke s_4 [mm] (default {d['s4']:g})")  # fmt: skip
    p.add_argument("--param", type=parse_param, action="append", default=[],
                   metavar="NAME=SPEC", help="design parameter in SI, e.g. b=0.04:0.12:9 "
                   "(repeatable; not gravity or the beams' fields: a map is weightless, with "
                   "rigid links; the masses only for --index lowest_frequency)")  # fmt: skip
    p.add_argument("--mass", action="append", default=[], metavar="NAME=KG",
                   help=f"a mass [kg] of --index lowest_frequency, NAME one of "
                   f"{', '.join(MASS_NAMES)} (default 0)")  # fmt: skip
    add_backend_arguments(p)
    p.add_argument("--start", choices=STARTS, default="closed_form",
                   help="generic backend: assembly from the closed-form geometry "
                   "(closed_form, default, faster) or from the previous point "
                   "(neighbour)")  # fmt: skip
    p.add_argument("--index", choices=sorted(INDEX_UNITS), default="det_K",
                   help="index to plot (default det_K); all are saved")  # fmt: skip
    p.add_argument("--force", nargs=3, type=finite_float, metavar=("FX", "FY", "FZ"),
                   help="force at M [N], world axes, for the deflection indices")  # fmt: skip
    p.add_argument("--torque", nargs=3, type=finite_float, metavar=("NX", "NY", "NZ"),
                   help="torque at M [N m], world axes, for the deflection indices")  # fmt: skip
    run = p.add_mutually_exclusive_group()
    run.add_argument("--workers", type=positive_int, default=None,
                     help="worker processes (default: all cores; 1: no pool)")  # fmt: skip
    run.add_argument("--scheduler", metavar="ADDRESS",
                     help="run on a Dask cluster, e.g. tcp://HOST:8786")  # fmt: skip
    add_worker_timeout(p)
    p.add_argument("--chunk-size", type=positive_int, default=None, help="points per task")
    p.add_argument("--out", type=path_text, default=DEFAULT_OUT,
                   help=f"output folder (default ./{DEFAULT_OUT}): map.npz, map.csv and "
                   "map_INDEX.png replace those of an earlier map")  # fmt: skip
    p.set_defaults(func=_run)


def _inputs(args: argparse.Namespace) -> dict[str, tuple[np.ndarray, str, float]]:
    """Axis name -> (values in the shown unit, unit, factor to SI), pose and design."""
    alpha = args.alpha or [np.array([a]) for a in DEFAULT_POSE["alpha"]]
    if len(alpha) not in (1, 3):
        raise UsageError(f"--alpha takes 1 or 3 values, got {len(alpha)}")
    radians_note("--alpha", np.concatenate(alpha))
    given = {"alpha4": args.alpha4, "s4": args.s4}
    if len(alpha) == 1 and alpha[0].size > 1:
        given["alpha"] = alpha[0]  # alpha_1 = alpha_2 = alpha_3, swept together
    else:
        given.update({f"alpha{k + 1}": alpha[k % len(alpha)] for k in range(3)})
    for k in (1, 2, 3):
        value = getattr(args, f"alpha{k}")
        if value is not None:
            if "alpha" in given:
                raise UsageError(
                    f"--alpha{k} cannot be combined with a range in --alpha (which sweeps "
                    "alpha_1 = alpha_2 = alpha_3)"
                )
            given[f"alpha{k}"] = value
    out = {k: (v, *POSE_OPTIONS[k][1:]) for k, v in given.items()}
    for name, values in args.param:
        if name in out:
            raise UsageError(f"--param {name} given twice")
        out[name] = (values, param_unit(name), 1.0)
    _check_read(out, args.index == "lowest_frequency")
    return out


def _check_read(inputs: dict, modes: bool) -> None:
    """Refuse a design parameter that no point of the map reads: g (a map has no weight),
    a mass but with ``modes`` (the index lowest_frequency), the beams' material and
    sections (a map's links are rigid, as by default).

    Raises:
        UsageError: names the parameter and why it is not read.
    """
    for name in inputs:
        if name in WEIGHT_FIELDS and not (modes and name in MASS_NAMES):
            raise UsageError(
                f"--param {name}: a map has no weight, so {name} changes no point but for "
                "--index lowest_frequency; the weight is in cahyman stiffness --gravity "
                "--mass NAME=KG, at one pose"
            )
        if name in BEAM_FIELDS or name == "links_as_beams":
            raise UsageError(
                f"--param {name}: a map's links are rigid, so {name} changes no point; the "
                "links as beams are in Python, CaHyManParams(links_as_beams=True)"
            )


def _label(name: str, unit: str) -> str:
    return f"{name} [{unit}]"


def map_title(result: SweepResult, index: str, fixed: dict) -> str:
    """Title of the picture: the index, the backend, the fixed inputs with their units and
    the load (:func:`closedloop.analysis.maps.load_text`), in lines of at most 80 characters.

    Args:
        fixed: input name -> (value, unit) of the inputs not swept, in the units shown.
    """
    parts = [f"{TITLES.get(k, k)} = {v:.6g} {u}" for k, (v, u) in fixed.items()]
    if result.wrench is not None:
        parts.append(load_text(result.wrench))
    return "\n".join([f"{index} at M, backend {result.backend}",
                      *textwrap.wrap(", ".join(parts), 80)])  # fmt: skip


def plot_map(result: SweepResult, index: str, shown: dict, path: Path, fixed: dict) -> Path:
    """Write the PNG ``path`` of :func:`map_figure` (same arguments); returns ``path``."""
    save_figure(map_figure(result, index, shown, fixed), path, dpi=110)
    return path


def map_figure(result: SweepResult, index: str, shown: dict, fixed: dict):
    """Curve (one swept axis) or heat map (two) of ``index``, failed points left blank: a
    ``matplotlib.figure.Figure`` of pyplot (Agg).

    Args:
        result: the sweep (a grid).
        index: name of the index to show.
        shown: axis name -> (unit shown, factor from the shown unit to SI).
        fixed: as :func:`map_title`.
    """
    import matplotlib  # lazily: a second of start-up, for the figure only

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    v = result.grid_values(index)
    unit, scale = DISPLAY.get(index, (INDEX_UNITS[index], 1.0))
    v = v * scale
    label = _label(index, unit)
    if index in LOG_INDICES:
        with np.errstate(divide="ignore", invalid="ignore"):
            v = np.log10(np.abs(v))
        label = f"log10 |{index}| [{unit}]"
    axes = [
        (a, values / shown[a][1], _label(TITLES.get(a, a), shown[a][0]))
        for a, values in result.points.axes
    ]
    fig, ax = plt.subplots(figsize=(7, 5))
    if len(axes) == 1:
        (_, x, xlabel), y = axes[0], v.reshape(-1)
        order = np.argsort(x, kind="stable")  # a list of values may come in any order
        ax.plot(x[order], y[order], "k.-", ms=3)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    else:
        (_, x, xlabel), (_, y, ylabel) = axes
        ix, iy = np.argsort(x, kind="stable"), np.argsort(y, kind="stable")
        v = v[np.ix_(ix, iy)]
        mesh = ax.pcolormesh(x[ix], y[iy], np.ma.masked_invalid(v).T, shading="nearest",
                             cmap="viridis")  # fmt: skip
        fig.colorbar(mesh, ax=ax, label=label)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
    failed = int(np.count_nonzero(~np.isfinite(v)))
    note = f" ({failed} points without a value)" if failed else ""
    ax.set_title(map_title(result, index, fixed) + note, fontsize=9)
    tidy_layout(fig)  # tight, no tick labels on one another
    return fig


def describe_point(result: SweepResult, i: int, shown: dict) -> str:
    """The swept inputs of point ``i`` in the units shown (``alpha_1 = 30 deg, b = 0.08 m``).

    Args:
        result: the sweep (a grid).
        i: index of the point.
        shown: swept axis name -> (unit shown, factor from the shown unit to SI).
    """
    p = result.points
    values = {f"alpha{k + 1}": p.alpha[i, k] for k in range(3)}
    values.update(alpha=p.alpha[i, 0], alpha4=p.alpha4[i], s4=p.s4[i])
    values.update({k: v[i] for k, v in p.design.items()})
    return ", ".join(
        f"{TITLES.get(name, name)} = {float(values[name]) / factor:.6g} {unit}"
        for name, (unit, factor) in shown.items()
    )


def _check_values(inputs: dict, params: CaHyManParams) -> None:
    """Refuse values that no point could use (raises InvalidInputError).

    Each design value must make valid parameters, and each stroke must lie in
    [0, s4_max] (the largest s4_max of the map, when it is swept): a range that leaves
    them is a typing error, not a map with holes.
    """
    for name, (values, _, factor) in inputs.items():
        if name in CaHyManParams.field_names():
            for v in values * factor:
                params.replace(**{name: float(v)})
    if "s4_max" in inputs:
        values, _, factor = inputs["s4_max"]
        params = params.replace(s4_max=float(np.max(values * factor)))
    if "s4" in inputs:
        values, _, factor = inputs["s4"]
        for v in values * factor:
            try:
                check_inputs(np.zeros(3), 0.0, v, params)
            except InvalidInputError:
                raise UsageError(
                    f"--s4 {v * 1e3:g} mm is outside the stroke [0, {params.s4_max * 1e3:g}] mm "
                    "(--param s4_max=... [m] sets the stroke)"
                ) from None


def _run(args: argparse.Namespace) -> int:
    """Run ``cahyman map``; SIGINT and SIGTERM are handled from here to the last line of
    output (see the module docstring)."""
    with stop_on_signals(ignore_after=getattr(args, "program", False)) as signals:
        return _run_map(args, signals)


def _run_map(args: argparse.Namespace, signals: SignalStop) -> int:
    inputs = _inputs(args)
    swept = {k: v for k, v in inputs.items() if v[0].size > 1}
    if not swept:
        raise UsageError(
            "nothing to sweep: every input has one value; give START:STOP:NUM with NUM >= 2 "
            "or V1,V2,... to one or two inputs (one pose: cahyman stiffness)"
        )
    if len(swept) > 2:
        raise UsageError(
            f"a map sweeps one or two inputs, got {len(swept)} ({', '.join(swept)}); "
            "use cahyman_pin.sweep.engine from Python for more"
        )
    check_map_size(math.prod(v[0].size for v in swept.values()))
    wrench = map_wrench(args.index, args.force, args.torque)
    params = DEFAULT_PARAMS.with_ks(args.ks)
    modes = args.index == "lowest_frequency"
    masses = _masses(args, weight=False)
    if masses and not modes:
        raise UsageError("--mass: a map has no weight; the masses count only for --index "
                         "lowest_frequency")  # fmt: skip
    params = params.replace(**masses) if masses else params
    fixed = {k: float(v[0][0] * v[2]) for k, v in inputs.items() if k not in swept}
    design = {k: fixed.pop(k) for k in list(fixed) if k in CaHyManParams.field_names()}
    params = params.replace(**design) if design else params
    alpha = [fixed.pop(f"alpha{k}", 0.0) for k in (1, 2, 3)]
    _check_values(inputs, params)
    out = output_folder(args.out)  # a bad --out stops here, before the sweep
    points = grid(
        {k: v[0] * v[2] for k, v in swept.items()},
        alpha=alpha,
        alpha4=fixed.get("alpha4"),
        s4=fixed.get("s4"),
        params=params,
    )
    local = "serial" if args.workers == 1 else "processes"
    shown = {k: (v[1], v[2]) for k, v in swept.items()}
    fixed = {k: (float(v[0][0]), v[1]) for k, v in inputs.items() if k not in swept}

    def save(result: SweepResult) -> list[Path]:
        paths = result.save(out, "map")
        png = out / f"map_{args.index}.png"
        paths.append(plot_map(result, args.index, shown, png, fixed))
        for other in INDEX_UNITS.keys() - {args.index}:  # an earlier map's figure: not of map.npz
            (out / f"map_{other}.png").unlink(missing_ok=True)
        return paths

    with dask_executor(args.scheduler, args.worker_timeout) as executor:
        try:
            result = sweep(
                points,
                backend=args.backend,
                wrench=wrench,
                start=args.start,
                executor=local if executor is None else executor,
                workers=args.workers,
                chunk_size=args.chunk_size,
                show_progress=True,
                modes=modes,
            )
        except Interrupted as stop:  # the points computed, written before the one line
            stop.write(save, out)
            raise
        signals.hold(result.data, out)  # every point computed: a signal lets the files be written
    paths = save(result)
    print(result.summary())
    print(index_line(args.index, result.indices[args.index], INDEX_UNITS[args.index]))
    failures = result.failures()
    for i, status, reason in failures[:SHOWN_FAILURES]:
        print(f"point {i} ({describe_point(result, i, shown)}) {status}: {reason}")
    if len(failures) > SHOWN_FAILURES:
        print(f"... and {len(failures) - SHOWN_FAILURES} more (status and reason of every point "
              f"in {out / 'map.npz'})")  # fmt: skip
    print("wrote " + ", ".join(str(p) for p in paths))
    sys.stdout.flush()  # while a signal is held
    return 0
