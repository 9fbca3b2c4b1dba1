"""``closedloop modes MODEL [--frame NAME] [--n N] ...``: natural frequencies and mode
shapes at a pose (:func:`closedloop.analysis.vibration.modes`).

The pose and springs options are those of ``closedloop stiffness``; ``--density`` weighs
the beams that have no ``density:`` key, ``--gravity`` adds the weight's tangent stiffness
about the equilibrium where the mechanism settles; ``--payload`` puts a point mass at the
frame, with or without ``--gravity`` (its mass counts without its weight). Prints the
frequencies [Hz], ascending, rigid-body modes as 0, and with ``--frame`` each mode's
effective masses at the frame; ``--json`` one object whose ``frequencies`` are those [Hz].
``--html FILE`` (with ``--frame``) writes a self-contained page that plays mode ``--mode
K`` (1: the lowest), its shape amplified ``--scale`` times (default: automatic), the
legend giving its frequency and the amplification.
"""

from __future__ import annotations

import argparse

import numpy as np

from closedloop.cli.outputs import print_json
from closedloop.cli.parser import UsageError, finite_float
from closedloop.exceptions import EXIT_OK


def add_parser(sub, model_arguments) -> None:
    """The ``modes`` subparser (``model_arguments`` unused: the pose options of
    ``closedloop stiffness`` are added)."""
    from closedloop.cli.options import add_model_arguments, add_preload_arguments

    p = sub.add_parser(
        "modes",
        help="natural frequencies and mode shapes at a pose",
        description=__doc__.split("\n\n", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_model_arguments(p, frame=False)
    p.add_argument("--frame", metavar="NAME", help="frame of the twists and effective masses")
    p.add_argument("--axes", choices=("world", "local"), default="world", help="axes of twists")
    p.add_argument("--n", type=int, metavar="N", help="number of lowest modes (default: all)")
    p.add_argument(
        "--density", type=finite_float, metavar="RHO",
        help="density [kg/m^3] of the beams without a density: key",
    )  # fmt: skip
    add_preload_arguments(
        p,
        payload_help="MASS [kg] [X Y Z]: a point mass at --frame, offset in its axes [m] (its "
        "weight too with --gravity)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--html", metavar="FILE", help="write a page that plays mode --mode")
    p.add_argument("--mode", type=int, default=1, metavar="K", help="mode to play (1: lowest)")
    p.add_argument("--scale", type=finite_float, metavar="S",
                   help="amplification of the played shape (default: automatic)")  # fmt: skip
    p.set_defaults(func=run_modes)


def run_modes(args: argparse.Namespace) -> int:
    """Run ``closedloop modes``; returns the exit code (0)."""
    from closedloop.analysis.vibration import modes
    from closedloop.cli.options import mode_line, model_from_args, preload_from_args
    from closedloop.kinematics.assembly_modes import passive_values

    if args.preload is not None:
        raise UsageError("--preload: modes take the weight (--gravity), not a dead load")
    if args.payload is not None and args.frame is None:
        raise UsageError("--payload needs --frame (the payload sits at that frame)")
    if args.html is not None and args.frame is None:
        raise UsageError("--html needs --frame (the played mode is scaled and drawn there)")
    # a payload's mass counts without gravity: its option read as with a weight, which is
    # then left out (the preload options are the stiffness command's, where it is one)
    weighed = argparse.Namespace(**{**vars(args), "gravity": args.gravity or []})
    options = preload_from_args(weighed)
    if args.gravity is None:
        del options["gravity"]
    page = None
    if args.html is not None:
        from closedloop.viewer.viewer import check_output_path

        page = check_output_path(args.html)  # before any work
    clm, state = model_from_args(args, geometry=page is not None)
    res = modes(state, n=args.n, frame=args.frame, axes=args.axes, density=args.density,
                **options)  # fmt: skip
    if page is not None:
        play_mode(clm, res, args.mode, page, args.scale)
    elif args.json:
        print_json({"model": clm.name, **res.to_dict(), "q": res.q.tolist(),
                    "passive": passive_values(clm, res.q)})  # fmt: skip
        return EXIT_OK
    print(format_modes(clm.name, res, mode_line(clm, res.q)))
    return EXIT_OK


def play_mode(clm, res, number: int, page, scale: float | None) -> None:
    """Write the page of mode ``number`` (1: the lowest) of ``res`` to ``page``."""
    from closedloop.exceptions import InvalidInputError
    from closedloop.viewer.scene import mode_scene
    from closedloop.viewer.viewer import DeflectionViewer

    if not 1 <= number <= res.frequencies.size:
        raise InvalidInputError(
            f"--mode {number}; expected 1 to {res.frequencies.size} (the modes computed)"
        )
    k = number - 1
    scene = mode_scene(clm, res.q, res.shapes[:, k], res.frequencies[k], number, res.frame,
                       scale=scale)  # fmt: skip
    with DeflectionViewer(clm) as viewer:
        viewer.show(scene, autoplay=True)
        print(f"wrote {viewer.save_html(page)} (mode {number}, {res.frequencies[k]:.6g} Hz, "
              f"amplified x{scene.scale:.4g})")  # fmt: skip


def format_modes(name: str, res, mode: str = "") -> str:
    """The modes as text: one line a mode, frequency [Hz] and, with a frame, the effective
    masses at it (translations [kg], rotations [kg m^2]); ``mode`` the line of the
    configuration's assembly mode (:func:`closedloop.cli.options.mode_line`) if any."""
    lines = [
        f"model: {name}",
        *filter(None, [mode]),
        f"modes: {res.frequencies.size} of {res.n_modes} (admissible motions {res.mobility}, "
        f"massless condensed {res.n_massless}, left out {res.n_internal}; mass condition "
        f"{res.mass_condition:.3g})",
    ]
    if res.n_rigid:
        lines.append(f"rigid-body modes (a mechanism, frequency 0): {res.n_rigid}")
    head = f"{'mode':>4} {'frequency [Hz]':>15}"
    if res.frame is not None:
        lines.append(
            f"effective masses at {res.frame!r} ({res.axes} axes) [kg; rotations kg m^2], "
            "'-' where the mode does not move it:"
        )
        head += " " + " ".join(f"{label:>10}" for label in ("x", "y", "z", "rx", "ry", "rz"))
    lines.append(head)
    for i, f in enumerate(res.frequencies):
        line = f"{i + 1:>4} {f:>15.6g}"
        if res.frame is not None:
            masses = res.effective_masses[:, i]
            line += " " + " ".join(
                f"{m:>10.4g}" if np.isfinite(m) else f"{'-':>10}" for m in masses
            )
        lines.append(line)
    return "\n".join(lines)
