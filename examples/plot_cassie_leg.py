"""
Cassie's leg from its SDF file
==============================

example-robot-data ships the Cassie biped as SDF. Each leg is closed by two ball joints
(the achilles rod and the plantar rod) and carries two springs written in the file (the
shin flex and the heel spring). An SDF names no actuators, so the five motors of the left
leg get springs of 1e4 N m/rad; with the pelvis fixed, every other joint is passive.
"""

import matplotlib.pyplot as plt
import numpy as np

import closedloop as cl
from closedloop.elastostatics.compliance import energy_shares

sdf = cl.robot_data_dir() / "cassie_description/robots/cassie_v2.sdf"
motors = ["left-roll-op", "left-yaw-op", "left-pitch-op", "left-knee-op", "left-foot-op"]
leg = cl.load_model(sdf, springs=dict.fromkeys(motors, 1.0e4))
q = cl.assemble(leg, None, leg.reference_configuration()).q  # the pose drawn in the file
# the file draws two joints of each leg at 0, outside their limits: taken as drawn
res = cl.compliance(leg, q, "left-foot", check_limits=False)
print("diagonal of C:", ", ".join(f"{c:.3g}" for c in np.diag(res.C)))
print(f"scaled condition number {res.condition_number:.2g}, ill-conditioned: {res.ill_conditioned}")

# %%
# Which spring takes the energy of a vertical force at the foot?
shares = energy_shares(leg, res, [0, 0, -1.0, 0, 0, 0])
named = {k: v for k, v in shares.items() if v > 0.01}
fig, ax = plt.subplots(figsize=(6, 3.5))
ax.barh(list(named), [100 * v for v in named.values()])
ax.set_xlabel("share of the deflection energy [%]")
ax.set_title("Cassie's left leg under a vertical force at the foot")
fig.tight_layout()
