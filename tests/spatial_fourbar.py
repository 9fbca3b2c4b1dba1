"""The spatial four-bar of urdf/fourbar.urdf cut at its pin C, written in several
equivalent descriptions: a typed closure at C ('revolute', 'cylindrical', 'universal',
'prismatic'), two point closures, or the joint at C kept in the tree and the loop welded in
the rocker; and elastic closures (``closure_springs``) against sprung joints in the tree.

A plain module, not a test module: the tests of every layer that compare a typed or
elastic closure with its tree-equivalent description build the models here.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pinocchio as pin

import closedloop as cl
from closedloop.io.loader import load_model
from closedloop.model.closed_loop import ClosedLoopModel

HALF_PI = math.pi / 2
INF = math.inf
SPRINGS = {"crank": 50.0, "crank_axial": 1e5, "crank_tilt": 20.0, "coupler_twist": 30.0,
           "rocker_tilt": 25.0, "crank_yaw": 15.0, "rocker_yaw": 18.0}  # fmt: skip
#: The four-bar of urdf/fourbar.urdf (ground pivots A = 0, D = (0.3, 0, 0), crank 0.1 m,
#: rocker 0.15 m) made spatial: sprung tilts of the crank and rocker about x and a twist of
#: the coupler, sprung turns of both about z, so that the pin at C holds moments, not
#: only forces, and P moves out of the plane.
SHARED = [
    ("crank", "ground", "crank_link", (0, 0, 0), (0, 0, 0), "revolute", (0, 1, 0)),
    ("crank_axial", "crank_link", "crank_end", (0, 0, 0.1), (0, 0, 0), "prismatic", (0, 0, 1)),
    ("crank_yaw", "crank_end", "yaw_link", (0, 0, 0), (0, 0, 0), "revolute", (0, 0, 1)),
    ("crank_tilt", "yaw_link", "tilt_link", (0, 0, 0), (0, 0, 0), "revolute", (1, 0, 0)),
    ("coupler", "tilt_link", "coupler_link", (0, 0, 0), (0, 0, 0), "revolute", (0, 1, 0)),
    ("coupler_twist", "coupler_link", "coupler_body", (0, 0, 0), (0, 0, 0), "revolute", (1, 0, 0)),
    ("P_joint", "coupler_body", "P", (0.15, 0, 0.08), (0, 0, 0), "fixed", None),
    ("rocker", "ground", "rocker_base", (0.3, 0, 0), (0, 0, 0), "revolute", (0, 1, 0)),
    ("rocker_yaw", "rocker_base", "rocker_turn", (0, 0, 0), (0, 0, 0), "revolute", (0, 0, 1)),
    ("rocker_tilt", "rocker_turn", "rocker_link", (0, 0, 0), (0, 0, 0), "revolute", (1, 0, 0)),
]
C_COUPLER, C_ROCKER = (0.3, 0, 0.05), (0, 0, 0.15)  # the pin C on either side, z along -y
#: The rocker cut in two at its middle, the halves welded (the loop closed there).
_ROCKER_CUT = [
    ("wA_joint", "rocker_top", "wA", (0, 0, -0.075), (0, 0, 0), "fixed", None),
    ("wB_joint", "rocker_link", "wB", (0, 0, 0.075), (0, 0, 0), "fixed", None),
]
DESCRIPTIONS = {
    "revolute closure": (
        [("cA_joint", "coupler_body", "cA", C_COUPLER, (HALF_PI, 0, 0), "fixed", None),
         ("cB_joint", "rocker_link", "cB", C_ROCKER, (HALF_PI, 0, 0), "fixed", None)],
        [["cA", "cB"]], ["revolute"],
    ),
    "two point closures": (
        [("cA_joint", "coupler_body", "cA", C_COUPLER, (0, 0, 0), "fixed", None),
         ("cB_joint", "rocker_link", "cB", C_ROCKER, (0, 0, 0), "fixed", None),
         ("cA2_joint", "coupler_body", "cA2", (0.3, 0.02, 0.05), (0, 0, 0), "fixed", None),
         ("cB2_joint", "rocker_link", "cB2", (0, 0.02, 0.15), (0, 0, 0), "fixed", None)],
        [["cA", "cB"], ["cA2", "cB2"]], ["3d", "3d"],
    ),
    "pin in the tree, rocker welded": (  # the rocker cut in two at its middle
        [("pin_C", "coupler_body", "rocker_top", C_COUPLER, (0, 0, 0), "revolute", (0, 1, 0)),
         *_ROCKER_CUT],
        [["wA", "wB"]], ["6d"],
    ),
    "universal closure": (  # the pin C replaced by a universal joint: axes y, then x
        [("cA_joint", "coupler_body", "cA", C_COUPLER, (HALF_PI, 0, 0), "fixed", None),
         ("cB_joint", "rocker_link", "cB", C_ROCKER, (0, HALF_PI, 0), "fixed", None)],
        [["cA", "cB"]], ["universal"],
    ),
    "universal in the tree, rocker welded": (
        [("u1", "coupler_body", "u_mid", C_COUPLER, (0, 0, 0), "revolute", (0, 1, 0)),
         ("u2", "u_mid", "rocker_top", (0, 0, 0), (0, 0, 0), "revolute", (1, 0, 0)),
         *_ROCKER_CUT],
        [["wA", "wB"]], ["6d"],
    ),
    "cylindrical closure": (  # the pin C replaced by a cylindrical joint along y
        [("cA_joint", "coupler_body", "cA", C_COUPLER, (HALF_PI, 0, 0), "fixed", None),
         ("cB_joint", "rocker_link", "cB", C_ROCKER, (HALF_PI, 0, 0), "fixed", None)],
        [["cA", "cB"]], ["cylindrical"],
    ),
    "cylindrical in the tree, rocker welded": (
        [("c1", "coupler_body", "c_mid", C_COUPLER, (0, 0, 0), "revolute", (0, 1, 0)),
         ("c2", "c_mid", "rocker_top", (0, 0, 0), (0, 0, 0), "prismatic", (0, 1, 0)),
         *_ROCKER_CUT],
        [["wA", "wB"]], ["6d"],
    ),
}  # fmt: skip


#: The four-bar closed at C by other closures (not assembled away from the drawing: a
#: prismatic closure at C locks the crank) and their tree equivalents.
_REVOLUTE_AT_C = DESCRIPTIONS["revolute closure"][0]
_ROCKER_WELDED = _ROCKER_CUT[1:]
ELASTIC_DESCRIPTIONS = {
    "weld at C": (_REVOLUTE_AT_C, [["cA", "cB"]], ["6d"]),
    "prismatic closure": (_REVOLUTE_AT_C, [["cA", "cB"]], ["prismatic"]),
    "slides in the tree, rocker welded": (  # along A's x (world x) and z (world -y)
        [("s_x", "coupler_body", "s_mid", C_COUPLER, (0, 0, 0), "prismatic", (1, 0, 0)),
         ("s_z", "s_mid", "rocker_top", (0, 0, 0), (0, 0, 0), "prismatic", (0, -1, 0)),
         *_ROCKER_CUT],
        [["wA", "wB"]], ["6d"],
    ),
    "bushing in the tree, rocker welded": (  # a free flyer in A's axes (x, -z, y of world)
        [("bushing", "coupler_body", "rocker_top", C_COUPLER, (HALF_PI, 0, 0), "floating",
          None),
         ("wA_joint", "rocker_top", "wA", (0, -0.075, 0), (-HALF_PI, 0, 0), "fixed", None),
         *_ROCKER_WELDED],
        [["wA", "wB"]], ["6d"],
    ),
}  # fmt: skip


def urdf_text(joints, visual: bool = False) -> str:
    """The URDF of the four-bar's ``joints``; ``visual``: a box on each link of a shared
    moving joint, off its joint's origin (so that its drawn placement turns with it)."""
    links = {"ground"} | {j[2] for j in joints}
    inertial = ('<inertial><mass value="0.1"/><inertia ixx="1e-4" iyy="1e-4" izz="1e-4" '
                'ixy="0" ixz="0" iyz="0"/></inertial>')  # fmt: skip
    box = ('<visual><origin xyz="0.02 0.01 0.03" rpy="0 0 0"/><geometry>'
           '<box size="0.03 0.02 0.01"/></geometry></visual>') if visual else ""  # fmt: skip
    body = ['<robot name="spatial_fourbar">']
    heavy = {j[2] for j in SHARED if j[5] != "fixed"}  # the frames and cut halves weigh 0
    body += [f'<link name="{n}">{inertial + box if n in heavy else ""}</link>'
             for n in sorted(links)]  # fmt: skip
    for name, parent, child, xyz, rpy, kind, axis in joints:
        body.append(
            f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="{" ".join(map(str, xyz))}" '
            f'rpy="{" ".join(map(str, rpy))}"/>'
            + (f'<axis xyz="{" ".join(map(str, axis))}"/>' if axis else "")
            + ('<limit lower="-3" upper="3" effort="1" velocity="1"/>' if kind != "fixed" else "")
            + "</joint>"
        )
    return "\n".join([*body, "</robot>"])


def fourbar_files(
    tmp_path: Path,
    description: str,
    *,
    flip: bool = False,
    closure_springs=None,
    springs=None,
    visual: bool = False,
) -> tuple[Path, Path]:
    """(URDF, closure file) of the spatial four-bar of one description of
    :data:`DESCRIPTIONS` or :data:`ELASTIC_DESCRIPTIONS`, written in ``tmp_path``: the
    crank actuated, the springs :data:`SPRINGS`. ``flip`` turns B's frame of the revolute
    closure over (its z axis opposite A's); ``closure_springs`` (the file's mapping),
    ``springs`` (added to :data:`SPRINGS`); ``visual``: :func:`urdf_text`."""
    extra, pairs, types = {**DESCRIPTIONS, **ELASTIC_DESCRIPTIONS}[description]
    if flip:
        extra = [extra[0], (*extra[1][:4], (-HALF_PI, 0, 0), *extra[1][5:])]
    stem = description.replace(" ", "_").replace(",", "") + ("_flipped" if flip else "")
    stem += "_sprung" if closure_springs or springs else ""
    urdf, closures = tmp_path / f"{stem}.urdf", tmp_path / f"{stem}.yaml"
    urdf.write_text(urdf_text(SHARED + extra, visual))
    quoted = ", ".join(f"'{t}'" for t in types)
    text = f"closed_loop: {pairs}\ntype: [{quoted}]\nname_mot: [crank]\n"
    text += f"springs: { ({**SPRINGS, **(springs or {})}) }\n"
    if closure_springs is not None:
        text += f"closure_springs: {yaml_springs(closure_springs)}\n"
    closures.write_text(text.replace("None", "null"))
    return urdf, closures


def fourbar_as(
    tmp_path: Path,
    description: str,
    *,
    flip: bool = False,
    closure_springs=None,
    springs=None,
    **options,
) -> ClosedLoopModel:
    """The model of :func:`fourbar_files` (the same arguments), loaded without geometry
    unless ``geometry=True`` (then with the visual boxes); ``springs_keyword``: the
    keyword ``springs`` of :func:`load_model`; other ``options`` to :func:`load_model`."""
    keyword = options.pop("springs_keyword", None)
    geometry = options.pop("geometry", False)
    urdf, closures = fourbar_files(tmp_path, description, flip=flip,
                                   closure_springs=closure_springs, springs=springs,
                                   visual=geometry)  # fmt: skip
    return load_model(
        urdf,
        closures,
        geometry=geometry,
        **({"springs": keyword} if keyword else {}),
        **options,
    )


def yaml_springs(springs: dict) -> str:
    """A closure_springs mapping written as YAML (``.inf`` for infinity)."""

    def value(v):
        if isinstance(v, list | tuple | np.ndarray):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return ".inf" if math.isinf(v) else repr(float(v))

    return "{" + ", ".join(f"{i}: {value(v)}" for i, v in springs.items()) + "}"


SHARED_JOINTS = tuple(j[0] for j in SHARED if j[5] != "fixed")


def shared_values(clm: ClosedLoopModel, q: np.ndarray) -> np.ndarray:
    """The values of the joints every description has, in one order."""
    return np.array([q[clm.model.joints[clm.model.getJointId(n)].idx_q] for n in SHARED_JOINTS])


PIN = [INF] * 5 + [20.0]  # the example: a pin with a 20 N m/rad torsion spring
#: The cut's rotation of the revolute closure at C (A's z is world -y, the tree's pin axis
#: +y: minus the pin's angle).
PIN_CUT = {"cA<->cB_rz": ("pin_C", -1.0)}


def assembled_fourbars(tmp_path) -> dict:
    """{description of :data:`DESCRIPTIONS`: (model, q assembled at crank = 0.4 rad)}."""
    out = {}
    for d in DESCRIPTIONS:
        clm = fourbar_as(tmp_path, d)
        out[d] = clm, np.array(cl.assemble(clm, [0.4]).q)
    return out


def mapped_configuration(
    clm: ClosedLoopModel, tree: ClosedLoopModel, q_tree: np.ndarray, cut: dict
) -> np.ndarray:
    """q of ``clm`` from ``q_tree``: the joints both have by name, ``cut`` {joint of clm:
    (joint of tree, sign)} for the joints at the cut."""
    q = pin.neutral(clm.model)
    for j in range(1, clm.model.njoints):
        name, jm = clm.model.names[j], clm.model.joints[j]
        other, sign = cut.get(name, (name, 1.0))
        if tree.model.existJointName(other):
            tm = tree.model.joints[tree.model.getJointId(other)]
            q[jm.idx_q : jm.idx_q + jm.nq] = sign * q_tree[tm.idx_q : tm.idx_q + tm.nq]
    return q


def sprung_pins(tmp_path, fourbars: dict) -> dict:
    """{description: (model, Q)}: the issue's pin at C as a spring on a '6d' and on a
    'revolute' closure, and kept in the tree, at crank 0.4 and 0.2 rad (the tree's
    assembly, where the pin turns, carried over; the springs at rest there).

    Args:
        tmp_path: folder for the model files.
        fourbars: the models of :func:`assembled_fourbars`.
    """
    tree0, q0 = fourbars["pin in the tree, rocker welded"]
    Q_tree = np.array([q0, cl.assemble(tree0, [0.2], q0).q])
    tree = fourbar_as(tmp_path, "pin in the tree, rocker welded", springs={"pin_C": 20.0})
    out = {"tree": (tree, Q_tree)}
    for d in ("weld at C", "revolute closure"):
        clm = fourbar_as(tmp_path, d, closure_springs={0: PIN})
        out[d] = clm, np.array([mapped_configuration(clm, tree, q, PIN_CUT) for q in Q_tree])
    return out
