"""
Gough-Stewart platform (6-UPS)
==============================

The bundled Stewart platform (``urdf/stewart.xml``, written the MuJoCo way: six legs and a
free-jointed platform under ``<worldbody>``) has a prismatic actuator with a spring in each
leg. Its stiffness at the platform is the closed form K = J^T diag(k) J (the tests check it
to 1e-9); here we show K's diagonal and its eigenvalues.
"""

import matplotlib.pyplot as plt
import numpy as np

import closedloop as cl

robot = cl.load_model(cl.data.path("stewart.xml"))
q = cl.assemble(robot, None, robot.reference_configuration()).q  # the file's own pose
res = cl.compliance(robot, q, "platform")
print("diagonal of K:", np.array2string(np.diag(res.K), precision=3))
print(f"scaled condition number: {res.condition_number:.3g}")

fig, ax = plt.subplots(figsize=(6, 3.5))
ax.bar(["x", "y", "z", "rx", "ry", "rz"], np.diag(res.K))
ax.set_yscale("log")
ax.set_ylabel("diagonal of K [N/m, N m/rad]")
ax.set_title("Stewart platform: stiffness at the platform origin")
fig.tight_layout()
