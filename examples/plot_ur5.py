"""
UR5: a serial arm from its URDF
===============================

Any URDF without a closure file is a serial robot: its main chain is actuated. Here every
joint of the UR5 (from example-robot-data) gets a spring of 1e4 N m/rad; the compliance at
the tool is J K_q^-1 J^T, and the stiffness indices give the principal stiffnesses.
"""

import matplotlib.pyplot as plt
import numpy as np

import closedloop as cl

ur5 = cl.load_model(cl.data.robot_file("ur5"), joint_stiffness=1e4)  # N m/rad
q = np.array([0.0, -1.0, 1.5, -0.5, 1.2, 0.3])
res = cl.compliance(ur5, q, "tool0")
ind = cl.StiffnessIndices.from_result(res)
print("K exists:", res.K is not None, " condition number (scaled):", f"{res.condition_number:.3g}")
print("weakest translational direction:", ind.min_translational_stiffness)

# %%
# The translational stiffness along the tool's vertical axis as the elbow opens.
elbows = np.linspace(0.3, 2.8, 40)
Q = np.tile(q, (len(elbows), 1))
Q[:, 2] = elbows
C = cl.compliances(ur5, Q, "tool0").C
fig, ax = plt.subplots(figsize=(6, 3.5))
ax.semilogy(elbows, 1.0 / C[:, 2, 2])
ax.set_xlabel("elbow angle q3 [rad]")
ax.set_ylabel("1 / C_zz at tool0 [N/m]")
ax.set_title("UR5: vertical stiffness at the tool against the elbow angle")
fig.tight_layout()
