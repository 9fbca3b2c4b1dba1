"""``closedloop info``: what a model holds, before any query.

    closedloop info MODEL [--closures F] [--joint-stiffness K | --springs FILE] [--json]

Prints the sizes (nq, nv), the characteristic length L, every joint (type, position limits,
role: actuated, passive, locked or sprung, its spring), the beams, the closures with their
types, the mimic joints, the start of the assembly (the model's reference configuration:
a closure file's ``start:``, MJCF ``qpos0``, the springs' rest configuration or neutral)
with the assembly mode there (the passive joints' values once its loops are closed; the
mode every query continues from unless given ``--start`` or ``--near``), and every frame:
the names that ``--frame``, ``--springs`` and the closure files take. The springs are those
of the model with the options given, as a query would use them. Exit status: 0; 2 bad
input (a missing file, an unknown name).
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from closedloop.cli.outputs import print_json
from closedloop.exceptions import EXIT_OK, AssemblyError, SingularConfigurationError
from closedloop.kinematics.limits import UNBOUNDED_LIMIT
from closedloop.model.beam_joints import inserted_beams
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.model.reference import REST, START, reference_key

#: Joint kinds by the start of Pinocchio's short name (after ``JointModel``), first match.
JOINT_KINDS = (
    ("RUB", "continuous"),
    ("R", "revolute"),
    ("P", "prismatic"),
    ("Spherical", "spherical"),
    ("FreeFlyer", "free-flyer"),
    ("Planar", "planar"),
    ("Translation", "translation"),
    ("Mimic", "mimic"),
    ("Composite", "composite"),
)
#: What each key of :data:`closedloop.model.reference.REFERENCE_KEYS` is (None: neutral).
START_SOURCES = {
    START: "the closure file's start:",
    "qpos0": "the MJCF qpos0",
    REST: "the springs' rest configuration",
    None: "the neutral configuration",
}


def add_parser(sub, source_arguments) -> None:
    """The ``info`` subparser; ``source_arguments(p, frame=False)`` adds MODEL, --closures
    and the springs options."""
    p = sub.add_parser(
        "info",
        help="joints, frames, closures, springs and sizes of a model",
        description=__doc__.split("\n\n", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    source_arguments(p, frame=False)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run_info)


def joint_kind(short_name: str) -> str:
    """Readable kind of a Pinocchio joint from its short name (``JointModelRZ``:
    ``revolute``); the short name without ``JointModel`` when none matches."""
    name = short_name.removeprefix("JointModel")
    return next((kind for start, kind in JOINT_KINDS if name.startswith(start)), name)


def _bound(value: float) -> float | None:
    return value if math.isfinite(value) and abs(value) < UNBOUNDED_LIMIT else None


def _joint(clm: ClosedLoopModel, j: int, beams: set[str]) -> dict:
    """One joint's entry of :func:`model_info`; ``beams``: the names of the beams' virtual
    joints."""
    pm = clm.model
    jm, name = pm.joints[j], pm.names[j]
    kind = joint_kind(jm.shortname())
    k = clm.stiffness[jm.idx_v : jm.idx_v + jm.nv]
    entry: dict = {"name": name, "type": kind, "nq": jm.nq, "nv": jm.nv}
    if jm.nq == 1 and kind in ("revolute", "prismatic"):
        lo, hi = float(pm.lowerPositionLimit[jm.idx_q]), float(pm.upperPositionLimit[jm.idx_q])
        entry["limits"] = [_bound(lo), _bound(hi)] if lo < hi else [None, None]
    if kind == "mimic":
        leader = [pm.names[i] for i in range(1, pm.njoints)
                  if pm.joints[i].nv and pm.joints[i].idx_q == jm.idx_q]  # fmt: skip
        entry["role"], entry["follows"] = "mimic", leader[0] if leader else None
        return entry
    finite = k[np.isfinite(k)]
    if name in clm.spring_blocks:
        entry["role"] = "beam" if name in beams else "sprung"
        entry["spring"] = np.asarray(clm.spring_blocks[name]).tolist()
        return entry
    if name in clm.actuated:
        entry["role"] = "actuated"
    elif name in clm.locked or (k.size and np.isinf(k).all()):
        entry["role"] = "locked"
    elif finite.size and np.any(finite > 0):
        entry["role"] = "sprung"
    else:
        entry["role"] = "passive"
    # per coordinate [N m/rad, N/m]; None: rigid (an actuated joint without spring, locked)
    entry["spring"] = [float(v) if math.isfinite(v) else None for v in k]
    return entry


def model_info(clm: ClosedLoopModel) -> dict:
    """JSON-ready description of ``clm``: name, nq, nv, length L [m], joints (name, type,
    nq, nv, limits [rad or m; None: unbounded], role, spring [SI per coordinate; None:
    rigid; a matrix for a block]), closures (name, type: one of
    :data:`closedloop.model.closures.CLOSURE_TYPES`), beams, mimic
    joints, frames (name, type, parent joint), in the model's order; unweighed bodies
    (body name -> why its inertia is not the robot file's: no natural frequencies, no
    gravity: ``ClosedLoopModel.unweighed_bodies``); the start of the assembly (source, and
    the passive joints' values of its assembly mode, or the error that the assembly
    gives)."""
    pm = clm.model
    beams = {b.name for b in inserted_beams(pm)}  # by the model's structure, not by name
    joints = [_joint(clm, j, beams) for j in range(1, pm.njoints)]
    return {
        "model": clm.name,
        "nq": pm.nq,
        "nv": pm.nv,
        "length": clm.length,
        "actuated": list(clm.actuated),
        "joints": joints,
        "closures": [{"name": c.name, "type": c.kind} for c in clm.closures],
        "beams": [j["name"] for j in joints if j["role"] == "beam"],
        "mimic": [j["name"] for j in joints if j["role"] == "mimic"],
        "frames": [
            {
                "name": f.name,
                "type": str(f.type).rsplit(".", 1)[-1].lower(),
                "joint": pm.names[f.parentJoint],
            }
            for f in pm.frames
        ],
        "unweighed_bodies": dict(clm.unweighed_bodies),
        "start": _start(clm),
    }


def _start(clm: ClosedLoopModel) -> dict:
    """The start of the assembly: where it comes from, and the assembly mode there (the
    passive joints' values [rad, m] of the reference configuration assembled), or why it
    does not assemble."""
    out: dict = {"source": START_SOURCES[reference_key(clm.model)], "passive": None}
    if clm.closures:  # the assembly's modules for a model with loops only (start-up)
        from closedloop.kinematics.assembly import assemble
        from closedloop.kinematics.assembly_modes import passive_values

        try:
            out["passive"] = passive_values(clm, assemble(clm).q)
        except (AssemblyError, SingularConfigurationError) as e:
            out["error"] = " ".join(str(e).split())
    return out


def _spring_text(entry: dict) -> str:
    spring = entry.get("spring")
    if entry["role"] == "mimic":
        return f"follows {entry['follows']}"
    if spring is None or entry["role"] == "locked":
        return ""
    if spring and isinstance(spring[0], list):
        return f"block {len(spring)}x{len(spring)}, diagonal " + " ".join(
            f"{row[i]:.4g}" for i, row in enumerate(spring)
        )
    if entry["role"] == "actuated" and all(v is None for v in spring):
        return "rigid (no spring)"
    if all(v in (None, 0.0) for v in spring):
        return ""
    return " ".join("rigid" if v is None else f"{v:.4g}" for v in spring)


def _limits_text(entry: dict) -> str:
    if "limits" not in entry:
        return ""
    lo, hi = entry["limits"]
    return f"[{'-inf' if lo is None else f'{lo:.6g}'}, {'inf' if hi is None else f'{hi:.6g}'}]"


def format_info(info: dict) -> str:
    """Text of :func:`model_info`: sizes, a table of the joints, closures, frames (the name
    columns as wide as the longest name, at least 24 and 32 characters)."""
    w = max([24, *(len(j["name"]) for j in info["joints"])])
    wf = max([32, *(len(f["name"]) for f in info["frames"])])
    lines = [
        f"model {info['model']!r}: nq {info['nq']}, nv {info['nv']}, "
        f"L = {info['length']:.4g} m (characteristic length)",
        f"actuated: {', '.join(info['actuated']) or 'none'}",
        "",
        f"joints ({len(info['joints'])}; limits [rad or m], springs [N m/rad or N/m]):",
        f"  {'name':<{w}} {'type':<11} {'role':<9} {'limits':<24} spring",
    ]
    lines += [
        f"  {j['name']:<{w}} {j['type']:<11} {j['role']:<9} {_limits_text(j):<24} "
        f"{_spring_text(j)}".rstrip()
        for j in info["joints"]
    ]
    if not any(j["role"] in ("sprung", "beam") or
               (j["role"] == "actuated" and any(v is not None for v in j["spring"]))
               for j in info["joints"]):  # fmt: skip
        lines.append("  no spring: every query finds C = 0 (--joint-stiffness K or --springs FILE)")
    closures = ", ".join(f"{c['name']} ({c['type']})" for c in info["closures"])
    lines += ["", f"closures ({len(info['closures'])}): {closures or 'none (a serial robot)'}"]
    lines.append(f"beams: {', '.join(info['beams']) or 'none'}")
    lines.append(f"mimic joints: {', '.join(info['mimic']) or 'none'}")
    start = info["start"]
    lines.append(f"assembly start: {start['source']}")
    if start["passive"] is not None:
        from closedloop.cli.options import passive_text

        lines.append(f"assembly mode there: passive joints {passive_text(start['passive'])} "
                     "[rad, m]")  # fmt: skip
    elif "error" in start:
        lines.append(f"assembly mode there: none, the loops do not close ({start['error']})")
    lines += [
        f"inertia not the file's (no modes, no gravity; give it an <inertial>): {b} ({why})"
        for b, why in info["unweighed_bodies"].items()
    ]
    lines += ["", f"frames ({len(info['frames'])}; name, type, on joint):"]
    lines += [f"  {f['name']:<{wf}} {f['type']:<12} {f['joint']}" for f in info["frames"]]
    return "\n".join(lines)


def run_info(args) -> int:
    """Run ``closedloop info``; returns the exit code (0)."""
    from closedloop.cli.options import load_from_args  # the command line's loader

    info = model_info(load_from_args(args))
    if args.json:
        print_json(info)
    else:
        print(format_info(info))
    return EXIT_OK
