"""
Five-bar with two motors
========================

The planar five-bar (``urdf/fivebar5.xml``) positions its end point E with two motors:
rank 2 of the 6x6 compliance (dx, dy, rz move together, driven by two motors). The figure
shows the compliance ellipse of E in the plane at the file's configuration.
"""

import matplotlib.pyplot as plt
import numpy as np

import closedloop as cl

robot = cl.load_model(cl.data.path("fivebar5.xml"))
q0 = cl.assemble(robot, None, robot.reference_configuration()).q
res = cl.compliance(robot, q0, "E")
print("rank", res.rank)

act = res.C[:2, :2]
w, V = np.linalg.eigh(act)
t = np.linspace(0, 2 * np.pi, 200)
ellipse = V @ (np.sqrt(w)[:, None] * np.vstack([np.cos(t), np.sin(t)]))
fig, ax = plt.subplots(figsize=(4.5, 4.5))
ax.plot(ellipse[0], ellipse[1])
ax.set_aspect("equal")
ax.set_xlabel("dx [m/sqrt(N)]")
ax.set_ylabel("dy [m/sqrt(N)]")
ax.set_title("Five-bar: compliance ellipse of E")
fig.tight_layout()
