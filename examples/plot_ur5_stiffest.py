"""
UR5: the stiffest rotation about the tool axis along a circle
=============================================================

A milling spindle on a UR5, its axis parallel to the flange's but 20 cm off it, cuts a
circle with its axis vertical. A 5-axis task leaves the rotation about the tool axis free;
offline programming tools choose it for reach and joint limits. Here
``follow_path(..., stiffest=True)`` chooses it for the least deflection under the cutting
force (80 N along the direction of travel): dynamic programming over the whole turn at
every point, the rotation changing by at most ``max_change`` (0.1 rad) between neighbouring
points, compared with the default path (the rotation continued from point to point).
"""

import matplotlib.pyplot as plt
import numpy as np
import pinocchio as pin

import closedloop as cl

joints = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint",
          "wrist_2_joint", "wrist_3_joint")  # fmt: skip
springs = dict(zip(joints, (4e4, 4e4, 2e4, 6e3, 6e3, 6e3), strict=True))  # N m/rad
ur5 = cl.load_model(cl.data.robot_file("ur5"), springs=springs)
model = pin.Model(ur5.model)  # the UR5 with a frame at the spindle's tip
flange = model.frames[model.getFrameId("tool0")]
tip = flange.placement * pin.SE3(np.eye(3), np.array([0.2, 0.0, 0.1]))
model.addFrame(pin.Frame("spindle", flange.parentJoint, flange.parentFrame, tip, pin.OP_FRAME))
robot = cl.ClosedLoopModel(model, actuated=ur5.actuated, springs=springs, name="UR5 + spindle")

down = pin.utils.rotate("x", np.pi)  # the tool axis vertical, pointing down
angles = np.linspace(0.0, 2 * np.pi, 36, endpoint=False)
centre = np.array([0.45, 0.15, 0.15])
path = [pin.SE3ToXYZQUAT(pin.SE3(down, centre + 0.08 * np.array([np.cos(a), np.sin(a), 0.0])))
        for a in angles]  # fmt: skip
force = np.array([[-80.0 * np.sin(a), 80.0 * np.cos(a), 0, 0, 0, 0] for a in angles])
q0 = np.array([0.3, -1.4, 1.8, -1.9, -1.57, 0.2])
result = cl.follow_path(robot, "spindle", path, wrench=force, task="tool-axis",
                        stiffest=True, q0=q0)  # fmt: skip
choice = result.stiffest
print(f"largest deflection: {1e3 * choice.deflection.max():.3g} mm (stiffest) vs "
      f"{1e3 * choice.default_deflection.max():.3g} mm (default); median gain "
      f"{np.median(choice.gain):.3g}")  # fmt: skip

# %%
# The deflection of the linear model at each point, with the default rotation and with the
# stiffest one, and the rotation chosen (from the default one). The choice weighs the
# whole path: a point may deflect a little more than by default where that lets its
# neighbours deflect much less.
deg = np.rad2deg(angles)
fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(6.4, 5))
top.plot(deg, 1e3 * choice.default_deflection, label="default rotation")
top.plot(deg, 1e3 * choice.deflection, label="stiffest rotation")
top.set_ylabel("deflection [mm]")
top.legend(fontsize=8)
bottom.plot(deg, np.rad2deg(choice.free[:, 0]))
bottom.set_ylabel("rotation about the tool\naxis from the default [deg]")
bottom.set_xlabel("position on the circle [deg]")
top.set_title("UR5 milling a circle: the stiffest rotation about the tool axis")
fig.tight_layout()
