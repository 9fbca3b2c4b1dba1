"""
Panda: a redundant arm
======================

The Franka Panda has seven joints for six twist components, and its gripper fingers (one of
them a URDF ``<mimic>`` joint that follows the other) are locked. The bars show the
compliance of the hand in its six directions.
"""

import matplotlib.pyplot as plt
import numpy as np

import closedloop as cl

panda = cl.load_model(cl.data.robot_file("panda"), joint_stiffness=1e4)
q = np.array([0, -0.5, 0, -2, 0, 1.5, 0.8, 0])  # nq = 8: the seven joints and one finger
res = cl.compliance(panda, q, "panda_hand")
print("rank", res.rank, " ill-conditioned:", res.ill_conditioned)

labels = ["dx", "dy", "dz", "rx", "ry", "rz"]
fig, ax = plt.subplots(figsize=(6, 3.5))
ax.bar(labels, np.diag(res.C))
ax.set_yscale("log")
ax.set_ylabel("diagonal of C [m/N, rad/(N m)]")
ax.set_title("Panda: compliance of the hand, world axes")
fig.tight_layout()
