"""
CaHyMan drills along a line: the deflection and its compensation
================================================================

CaHyMan's five inputs fix the position of its tool and the direction of its axis, which a
5-axis task asks for (``task="tool-axis"``; the ``tool`` frame at the arm's extremity M has
its z axis along the telescope). Here the tool moves 40 mm along a straight line, its axis
held, against a constant thrust of 50 N along the axis. ``closedloop.follow_path`` gives at
every point the unloaded configuration (the inverse kinematics, continued from point to
point), the error under the load with the unloaded commands, and two compensations: the
first-order one (the target moved back by the linear deflection C w) and the exact one
(Newton on the actuated values with the tangent stiffness), which meets the position and
the axis to the statics' tolerance. The rotation about the tool axis is not compensated: a
5-axis machine does not control it.
"""

import matplotlib.pyplot as plt
import numpy as np
import pinocchio as pin

import closedloop as cl
from cahyman_pin.model import cahyman_model

machine = cahyman_model()
robot = machine.clm
q0 = machine.assemble(np.deg2rad([60.0, 60.0, 60.0]), np.deg2rad(45.0), 0.025)
start = cl.Configuration(robot, q0).frame_placement("tool")
line = [start.translation + np.array([0.0, s, 0.0]) for s in np.linspace(-0.02, 0.02, 21)]
path = [pin.SE3ToXYZQUAT(pin.SE3(start.rotation, p)) for p in line]  # (x, y, z, qx, qy, qz, qw)
thrust = np.r_[-50.0 * start.rotation[:, 2], 0.0, 0.0, 0.0]  # the workpiece pushes back [N]

result = cl.follow_path(robot, "tool", path, wrench=thrust, task="tool-axis", q0=q0)
summary = result.summary()
for key in ("error", "residual_first_order", "residual"):
    print(f"{key:>22}: largest {1e3 * summary[key]['translation_m']:.3g} mm, "
          f"tool axis tilted {1e3 * summary[key]['rotation_rad']:.3g} mrad")  # fmt: skip

# %%
# The error along the line: without compensation (tenths of a millimetre), with the
# first-order compensation (its second-order remainder) and with the exact one (rounding).
# The commands that cancel the deflection are ``result.commands``, in the order of
# ``result.joints``.
x = 1e3 * (np.array(line)[:, 1] - line[0][1])
fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(6.4, 5))
for name, error, style in (("without compensation", result.error, "-"),
                           ("first-order (C w)", result.residual_first_order, "--"),
                           ("exact", result.residual, ":")):  # fmt: skip
    top.semilogy(x, np.maximum(1e3 * np.linalg.norm(error[:, :3], axis=1), 1e-12), style,
                 label=name)  # fmt: skip
    tilt = np.maximum(1e3 * result.held_rotation(error[:, 3:]), 1e-12)
    bottom.semilogy(x, tilt, style, label=name)
top.set_ylabel("position error [mm]")
bottom.set_ylabel("tool axis tilt [mrad]")
bottom.set_xlabel("position along the line [mm]")
top.legend(fontsize=8)
top.set_title("CaHyMan, 50 N of thrust along the tool axis")
fig.tight_layout()

# %%
# The commands at the middle of the line, against their unloaded values: the angles move by
# fractions of a milliradian, the stroke s_4 by about a tenth of a millimetre (the thrust
# pushes along the telescope).
middle = len(path) // 2
shift = result.commands[middle] - robot.actuated_values(result.q_target[middle])
angles = [u == "rad" for u in result.joint_units]
fig, (left, right) = plt.subplots(1, 2, figsize=(6.4, 3.0), width_ratios=(4, 1))
left.bar(np.array(result.joints)[angles], 1e3 * shift[angles])
left.set_ylabel("command - unloaded value [mrad]")
right.bar(np.array(result.joints)[~np.array(angles)], 1e6 * shift[~np.array(angles)],
          color="tab:purple")  # fmt: skip
right.set_ylabel("[um]")
fig.suptitle("The compensating change of each input, mid-line")
fig.tight_layout()
