"""
Validation: two implementations of CaHyMan agree
================================================

The ``generic`` backend analyses the Pinocchio model of CaHyMan with ``closedloop``; the
``consistent`` backend is the paper's closed form with its damaged places resolved. They
share no code, so their agreement checks both. At 100 random poses (the sampling of the
test suite's ``tests/cahyman/test_backends_agree.py``, which requires 1e-8 entry by entry), the
figure shows the Frobenius norm of the difference of their compliances relative to that of
the generic one.
"""

import matplotlib.pyplot as plt
import numpy as np

from cahyman_pin.api import stiffness
from cahyman_pin.params import DEFAULT_PARAMS

rng = np.random.default_rng(20261122)
n = 100
alpha = np.deg2rad(rng.uniform(30.0, 90.0, (n, 3)))  # rad
alpha4 = np.deg2rad(rng.uniform(0.0, 90.0, n))  # rad
s4 = rng.uniform(0.0, DEFAULT_PARAMS.s4_max, n)  # m
gaps = []
for i in range(n):
    generic = stiffness(alpha[i], alpha4[i], s4[i]).C
    consistent = stiffness(alpha[i], alpha4[i], s4[i], backend="consistent").C
    gaps.append(np.linalg.norm(generic - consistent) / np.linalg.norm(generic))
gaps = np.array(gaps)
print(f"largest relative difference over {n} poses: {gaps.max():.2e}")

fig, ax = plt.subplots(figsize=(6, 3.5))
ax.hist(np.log10(np.maximum(gaps, 1e-18)), bins=20)
ax.axvline(-8, color="red", label="required by the tests (1e-8)")
ax.set_xlabel("log10 |C_generic - C_consistent| / |C_generic|")
ax.set_ylabel("poses")
ax.set_title("CaHyMan: generic Pinocchio model vs consistent closed form")
ax.legend()
fig.tight_layout()
