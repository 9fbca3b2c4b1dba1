"""
A stiffness map over two actuated joints
========================================

:func:`closedloop.analysis.maps.stiffness_map` computes stiffness indices at every point of a grid
of actuated values, closing the loops from the previous point. Here the five-bar's two
motors are swept, and the smallest translational stiffness of its end point is drawn.
A point that fails (a singular pose, loops that do not close) is recorded with its status,
never the whole map lost.
"""

import matplotlib.pyplot as plt
import numpy as np

import closedloop as cl
from closedloop.analysis.maps import stiffness_map

robot = cl.load_model(cl.data.path("fivebar5.xml"))
legs = {"leg0": np.linspace(-0.5, 0.5, 21), "leg1": np.linspace(-0.5, 0.5, 21)}  # rad
smap = stiffness_map(robot, "E", sweeps=legs)
k = smap.indices["min_translational"].reshape(smap.shape)  # N/m, NaN where a point failed
print(f"{np.isfinite(k).sum()} of {k.size} points; smallest stiffness {np.nanmin(k):.4g} N/m")

fig, ax = plt.subplots(figsize=(5.5, 4.5))
mesh = ax.pcolormesh(legs["leg1"], legs["leg0"], k, shading="auto", cmap="viridis")
fig.colorbar(mesh, ax=ax, label="smallest translational stiffness at E [N/m]")
ax.set_xlabel("leg1 [rad]")
ax.set_ylabel("leg0 [rad]")
ax.set_title("Five-bar: stiffness map over the two motors")
fig.tight_layout()
