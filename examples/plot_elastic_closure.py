"""
A spring at a loop's cut: an elastic closure
============================================

The bundled four-bar closes its loop at the pin C with a point closure (``'3d'``): the
coupler's end and the rocker's end coincide. Here the same cut is made elastic: a bushing of
stiffness k [N/m] along each of the three translations of the coupler's end relative to the
rocker's, its rotations free, given as ``closure_springs`` (6 values, order dx dy dz rx ry
rz, in the axes of the pair's first frame; ``.inf`` rigid, 0 free). The library adds
joints at the cut that carry the spring; they are springs like any other, so the share of
the deflection energy each one stores is named.
"""

import matplotlib.pyplot as plt
import numpy as np

import closedloop as cl
from closedloop.elastostatics.unloaded import energy_shares

urdf, closures = cl.data.path("fourbar.urdf"), cl.data.path("fourbar.yaml")
rigid = cl.load_model(urdf, closures, geometry=False)
bushing = cl.load_model(urdf, closures, geometry=False, closure_springs={0: [2e5] * 3 + [0] * 3})
print("joints added at the cut:", [n for n in bushing.model.names if "<->" in n])

# %%
# The share of the deflection energy under a load at P (3 N along x, -20 N along z) in
# each spring, at crank 0.3 rad: the motor, the two links' axial springs and the bushing.
q = cl.assemble(bushing, actuated=[0.3]).q
wrench = np.array([3.0, 0.0, -20.0, 0.0, 0.0, 0.0])
for name, share in energy_shares(bushing, cl.compliance(bushing, q, "P"), wrench).items():
    print(f"{name:40s} {100 * share:5.1f} %")

# %%
# The compliance of P along z against the bushing's stiffness: soft, the bushing adds its
# own compliance in series with the loop's; stiff, the loop approaches the rigid closure
# (dashed line).
q_rigid = cl.assemble(rigid, actuated=[0.3]).q
C_rigid = cl.compliance(rigid, q_rigid, "P").C[2, 2]
ks = np.logspace(3, 9, 25)
C_zz = []
for k in ks:
    model = cl.load_model(urdf, closures, geometry=False, closure_springs={0: [k] * 3 + [0] * 3})
    C_zz.append(cl.compliance(model, cl.assemble(model, actuated=[0.3]).q, "P").C[2, 2])
fig, ax = plt.subplots(figsize=(6, 3.5))
ax.loglog(ks, C_zz, "o-", ms=3, label="elastic closure")
ax.axhline(C_rigid, ls="--", color="k", label="rigid closure")
ax.set_xlabel("bushing stiffness k [N/m]")
ax.set_ylabel("$C_{zz}$ at P [m/N]")
ax.set_title("Four-bar closed by a bushing at C")
ax.legend()
fig.tight_layout()
print(f"k = 1e9 N/m: C_zz {C_zz[-1]:.6e} m/N, rigid closure {C_rigid:.6e} m/N")
