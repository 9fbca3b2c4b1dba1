"""
3-RRR planar parallel robot
===========================

Three RRR legs carry a triangular platform in the plane. The in-plane motions (dx, dy, rz)
are compliant, the out-of-plane ones rigid: rank 3. The figure shows the in-plane
compliance ellipse of the platform's centre.
"""

import matplotlib.pyplot as plt
import numpy as np

import closedloop as cl

robot = cl.load_model(cl.data.path("rrr3.xml"))
q = cl.assemble(robot, None, robot.reference_configuration()).q
res = cl.compliance(robot, q, "platform")
print("rank", res.rank)

Cxy = res.C[:2, :2]
w, V = np.linalg.eigh(Cxy)
t = np.linspace(0, 2 * np.pi, 200)
ellipse = V @ (np.sqrt(w)[:, None] * np.vstack([np.cos(t), np.sin(t)]))
fig, ax = plt.subplots(figsize=(4.5, 4.5))
ax.plot(ellipse[0], ellipse[1])
ax.set_aspect("equal")
ax.set_xlabel("dx / sqrt(N) [m/sqrt(N)]")
ax.set_ylabel("dy / sqrt(N) [m/sqrt(N)]")
ax.set_title("3-RRR: in-plane compliance ellipse")
fig.tight_layout()
