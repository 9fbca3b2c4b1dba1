"""
Gravity sag and payloads
========================

Give the gravity and the configuration becomes the springs' rest configuration: the robot
settles under the weight of its links (and point-mass payloads), and the result is the
tangent compliance there. The figure shows the sag of the UR5's tool against the payload.
"""

import matplotlib.pyplot as plt
import numpy as np

import closedloop as cl

ur5 = cl.load_model(cl.data.robot_file("ur5"), joint_stiffness=1e3)  # N m/rad
q = [0, -1.0, 1.5, -0.5, 1.2, 0.3]
masses = np.linspace(0.0, 5.0, 6)  # kg
sag = []
for m in masses:
    payloads = [cl.Payload(m, "tool0", [0, 0, 0.05])] if m > 0 else []
    res = cl.compliance(ur5, q, "tool0", gravity=(0, 0, -9.81), payloads=payloads)
    sag.append(res.sag)
sag = np.array(sag)
print("sag at 5 kg [m, rad]:", np.array2string(sag[-1], precision=4))

fig, ax = plt.subplots(figsize=(6, 3.5))
ax.plot(masses, 1e3 * np.linalg.norm(sag[:, :3], axis=1), "o-")
ax.set_xlabel("payload at tool0 [kg]")
ax.set_ylabel("sag of tool0 [mm]")
ax.set_title("UR5 (springs of 1e3 N m/rad) under its own weight and a payload")
fig.tight_layout()
