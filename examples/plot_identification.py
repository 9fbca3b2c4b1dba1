"""
Identifying springs from noisy measurements
===========================================

Which spring values explain measured deflections? We synthesise measurements of the
four-bar (three crank angles, three random wrenches each, 0.1 um of noise), start from a
wrong guess and fit the three springs by weighted least squares in log space. The fit
returns estimates with standard errors.
"""

import matplotlib.pyplot as plt
import numpy as np

import closedloop as cl
from closedloop.analysis.identification import Measurement, identify

robot = cl.load_model(cl.data.path("fourbar.urdf"), cl.data.path("fourbar.yaml"))
names = ["crank", "crank_axial", "rocker_axial"]
rng = np.random.default_rng(0)
data = []
for crank in (0.2, 0.6, 1.0):
    q = cl.assemble(robot, actuated=[crank]).q
    C = cl.compliance(robot, q, "P").C
    for w in 10.0 * rng.normal(size=(3, 6)):
        measured = C @ w + 1e-7 * rng.normal(size=6)
        data.append(Measurement.of(q=q, wrench=w, twist=measured, sd=1e-7))
guess = robot.with_springs({"crank": 20.0, "crank_axial": 4e5, "rocker_axial": 5e4})
fit = identify(guess, data, "P", names)
for n in names:
    print(f"{n}: {fit.estimates[n]:.4g} +- {fit.std_errors[n]:.2g} (true {robot.springs[n]:.4g})")

# %%
# Estimates relative to the file's values, with two standard errors.
true = np.array([robot.springs[n] for n in names])
est = np.array([fit.estimates[n] for n in names])
err = np.array([fit.std_errors[n] for n in names])
fig, ax = plt.subplots(figsize=(6, 3.5))
ax.errorbar(range(3), est / true, yerr=2 * err / true, fmt="o", capsize=4)
ax.axhline(1.0, color="grey", lw=0.8)
ax.set_xticks(range(3), names)
ax.set_ylabel("estimate / true value")
ax.set_title("Four-bar: springs fitted to noisy deflections")
fig.tight_layout()
