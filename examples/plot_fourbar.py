"""
Four-bar linkage: a planar loop
===============================

The bundled four-bar (``urdf/fourbar.urdf`` with its closure file ``fourbar.yaml``) has one
motor (the crank) and springs on the crank and on the axial compliance of two links. A
planar loop is rigid out of its plane, so its 6x6 compliance has rank 3 and no stiffness
matrix exists: the result says so and names the rigid directions.
"""

import matplotlib.pyplot as plt
import numpy as np

import closedloop as cl

robot = cl.load_model(cl.data.path("fourbar.urdf"), cl.data.path("fourbar.yaml"))
state = cl.Configuration(robot, cl.assemble(robot, actuated=[0.3]).q)
res = cl.compliance(state, "P")
print("rank", res.rank, "of 6; rigid directions (columns):")
print(np.round(res.rigid_directions, 3))

# %%
# The in-plane compliance along the crank's turn: the translational compliance of the
# coupler point P along x and z (world axes; the loop moves in the x-z plane) for crank
# angles from 0.2 to 2.8 rad. Each configuration is assembled from the previous one, in
# steps of 0.05 rad, so that the loop stays on one assembly mode.
cranks = np.arange(0.2, 2.8001, 0.05)
Q, q = [], None
for a in cranks:
    q = cl.assemble(robot, actuated=[a], q0=q).q
    Q.append(q)
C = cl.compliances(robot, Q, "P").C
fig, ax = plt.subplots(figsize=(6, 3.5))
ax.semilogy(cranks, C[:, 0, 0], label="$C_{xx}$")
ax.semilogy(cranks, C[:, 2, 2], label="$C_{zz}$")
ax.set_xlabel("crank angle [rad]")
ax.set_ylabel("compliance at P [m/N]")
ax.set_title("Four-bar: compliance of the coupler point")
ax.legend()
fig.tight_layout()

# %%
# The same deflection in 3D: the viewer's self-contained page (``closedloop view fourbar
# --frame P --actuated 0.3 --force 3 0 -20 --html fourbar_view.html``), with the unloaded
# pose as a grey ghost, the deflected pose amplified and coloured by its real displacement,
# and the load as an arrow. Drag to rotate; the time slider of the "Animations" panel ramps
# the load.
#
# .. raw:: html
#
#     <iframe src="../_static/fourbar_view.html" title="Four-bar deflection, 3D view"
#       width="100%" height="480" style="border: 1px solid #ccc"></iframe>
