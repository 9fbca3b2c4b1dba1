"""
Which link limits my stiffness? Links as beams
==============================================

A link can be flexible: a rigid body with a 6-dof virtual spring at its end whose 6x6
stiffness comes from beam theory. Here the six links of a UR5 become aluminium tubes
(d = 60 mm, t = 4 mm), and :func:`~closedloop.elastostatics.compliance.energy_shares` splits the
deflection energy of a load at the tool among the joint springs and the beams.
"""

import matplotlib.pyplot as plt

import closedloop as cl
from closedloop.elastostatics.compliance import energy_shares
from closedloop.model.beams import map_configuration

ur5 = cl.load_model(cl.data.robot_file("ur5"), joint_stiffness=1e4)
tube = {"E": 7.0e10, "G": 2.6e10, "section": {"shape": "tube", "d": 0.06, "t": 0.004}}
ends = {
    "shoulder_link": "shoulder_lift_joint",
    "upper_arm_link": "elbow_joint",
    "forearm_link": "wrist_1_joint",
    "wrist_1_link": "wrist_2_joint",
    "wrist_2_link": "wrist_3_joint",
    "wrist_3_link": "ee_fixed_joint",
}
flex = ur5.with_beams({link: {**tube, "end": end} for link, end in ends.items()})
q = map_configuration(ur5.model, flex.model, [0.3, -1.0, 1.5, -0.5, 1.2, 0.3])
res = cl.compliance(flex, q, "ee_link")
shares = energy_shares(flex, res, [30.0, -10.0, 20.0, 1.0, -2.0, 0.5])

fig, ax = plt.subplots(figsize=(6, 4))
names = list(shares)
ax.barh(names, [100 * shares[n] for n in names])
ax.invert_yaxis()
ax.set_xlabel("share of the deflection energy [%]")
ax.set_title("UR5 with beam links: where the energy goes")
fig.tight_layout()
