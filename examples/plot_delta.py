"""
Delta robot: translations only
==============================

The bundled Delta (``urdf/delta.xml``) has three motors, each driving a parallelogram of
ball-ball rods. The platform only translates: the compliance has rank 3 (translations), and
the rotations are rigid directions. The rigid-rod closed form J^-1 diag(1/k) J^-T checks it
in the tests.
"""

import matplotlib.pyplot as plt
import numpy as np

import closedloop as cl

robot = cl.load_model(cl.data.path("delta.xml"))
q = cl.assemble(robot, None, robot.reference_configuration()).q
res = cl.compliance(robot, q, "platform")
print("rank", res.rank, "; rigid directions (columns):")
print(np.round(res.rigid_directions, 3))  # res.K would raise RigidDirectionsError
Ct = res.C[:3, :3]
w, V = np.linalg.eigh(Ct)
print("principal translational compliances [m/N]:", ", ".join(f"{x:.3g}" for x in w))

fig, ax = plt.subplots(figsize=(6, 3.5))
im = ax.imshow(np.abs(res.C), cmap="viridis")
ax.set_xticks(range(6), ["fx", "fy", "fz", "nx", "ny", "nz"])
ax.set_yticks(range(6), ["dx", "dy", "dz", "rx", "ry", "rz"])
fig.colorbar(im, ax=ax, label="|C| [SI]")
ax.set_title("Delta: only the translational block is non-zero")
fig.tight_layout()
