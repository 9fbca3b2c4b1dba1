"""
CaHyMan: the Cassino Hybrid Manipulator
=======================================

CaHyMan is a 3-dof parallel base (CaPaMan) carrying a 2-dof telescopic arm. Its package
``cahyman_pin`` gives the stiffness at the arm's extremity M from three backends: the
Pinocchio model (``generic``) and the paper's closed form, resolved (``consistent``) or as
printed (``published``). The two independent implementations agree to rounding.
"""

import matplotlib.pyplot as plt
import numpy as np

from cahyman_pin.api import stiffness

alpha, alpha4, s4 = np.deg2rad([45, 60, 75]), np.deg2rad(45), 0.0  # inputs [rad, m]
generic = stiffness(alpha, alpha4, s4)
consistent = stiffness(alpha, alpha4, s4, backend="consistent")
gap = np.abs(generic.C - consistent.C).max() / np.abs(generic.C).max()
print(f"det K = {generic.det_K:.4g}; generic vs consistent: {gap:.1e} of the largest entry")

# %%
# The translational compliance of M as the first leg's crank turns.
angles = np.deg2rad(np.linspace(40, 110, 29))
Czz = [stiffness([a, alpha[1], alpha[2]], alpha4, s4).C[2, 2] for a in angles]
fig, ax = plt.subplots(figsize=(6, 3.5))
ax.plot(np.rad2deg(angles), np.array(Czz) * 1e6)
ax.set_xlabel("alpha_1 [deg]")
ax.set_ylabel("C_zz at M [um/N]")
ax.set_title("CaHyMan: vertical compliance of M against the first crank")
fig.tight_layout()
