"""Natural frequencies of a flexible closed loop against OpenSees' ``eigen`` (openseespy).

A portal frame of steel rods in the x-z plane: columns A-B and D-C, beam B-C, clamped at
A, and welded to the ground at D by a loop closure (6d). In the library each member is one
beam link with ``density:``; in OpenSees one ``elasticBeamColumn`` with the same E, G, A,
I, J and the consistent mass (``-mass rho A -cMass``; its torsional inertia rho J L / 3,
J = Iy + Iz for a circle, as the library's rho Ip), the clamped feet fixed, eigenvalues by
the dense generalised LAPACK solver.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
from helpers import opensees

import closedloop as cl

E, G, RHO, D = 2.1e11, 8.1e10, 7850.0, 0.02
NODES = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.4], [0.5, 0.0, 0.4], [0.5, 0.0, 0.0]])
#: The same element matrices assembled by two codes, solved by two dense eigensolvers:
#: the frequencies agree to rounding times the condition of K and M (about 1e4 here).
RTOL_OPENSEES = 1e-6


def portal(tmp_path) -> cl.ClosedLoopModel:
    """The portal frame as three beam links welded by fixed joints, closed at D."""
    links = ["ground", "m0", "m1", "m2", "end", "anchor"]
    joints = [("j0", "ground", "m0", NODES[0])]
    joints += [(f"j{i}", f"m{i - 1}", links[i + 1], NODES[i] - NODES[i - 1]) for i in (1, 2, 3)]
    joints.append(("ja", "ground", "anchor", NODES[3]))
    body = "".join(f'<link name="{n}"/>' for n in links)
    body += "".join(
        f'<joint name="{n}" type="fixed"><parent link="{p}"/><child link="{c}"/>'
        f'<origin xyz="{" ".join(map(repr, map(float, xyz)))}"/></joint>'
        for n, p, c, xyz in joints
    )
    (tmp_path / "portal.urdf").write_text(f'<robot name="portal">{body}</robot>')
    (tmp_path / "portal.yaml").write_text(
        "closed_loop: [[end, anchor]]\ntype: ['6d']\nname_mot: []\n"
    )
    beam = {"E": E, "G": G, "section": {"shape": "circle", "d": D}, "density": RHO}
    beams = {f"m{i}": {**beam, "end": f"j{i + 1}"} for i in range(3)}
    return cl.load_model(tmp_path / "portal.urdf", tmp_path / "portal.yaml", beams=beams)


def opensees_frequencies(n: int) -> np.ndarray:
    """The n lowest frequencies [Hz] of the portal frame in OpenSees."""
    ops = opensees()
    A, I = math.pi * D**2 / 4, math.pi * D**4 / 64
    ops.wipe()
    ops.model("basic", "-ndm", 3, "-ndf", 6)
    for k, xyz in enumerate(NODES, start=1):
        ops.node(k, *map(float, xyz))
    for k in (1, 4):
        ops.fix(k, 1, 1, 1, 1, 1, 1)
    ops.geomTransf("Linear", 1, 0.0, 1.0, 0.0)  # local x-z planes: every member's is x-z
    for k, (i, j) in enumerate(((1, 2), (2, 3), (3, 4)), start=1):
        ops.element("elasticBeamColumn", k, i, j, A, E, G, 2 * I, I, I, 1,
                    "-mass", RHO * A, "-cMass")  # fmt: skip
    omega2 = np.array(ops.eigen("-fullGenLapack", n))
    ops.wipe()
    return np.sqrt(omega2) / (2 * math.pi)


def test_portal_frame_against_opensees(tmp_path):
    clm = portal(tmp_path)
    res = cl.modes(clm, pin.neutral(clm.model), n=5)
    assert res.mobility == 12 and res.n_rigid == 0  # two free nodes, 6 dof each
    np.testing.assert_allclose(res.frequencies, opensees_frequencies(5), rtol=RTOL_OPENSEES)
