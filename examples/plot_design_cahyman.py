"""
Designing for stiffness: CaHyMan's arm tubes under a mass budget
================================================================

Which tubes make CaHyMan's arm stiffest at its extremity M, everywhere in the paper's
workspace, without weighing more than a budget? The arm QM2 and the sliding tube MM2 become
aluminium beams whose outer diameters ``d_arm`` and ``d_slide`` (walls a tenth of them) are
``${...}`` placeholders of the closure file; the legs keep the paper's lumped springs. A
design problem asks for the largest worst-case translational stiffness at M over the
paper's three configurations (Tables 1-3) and the smallest mass (the tubes' own: the paper
gives no masses), the mass at most 50 g, and
:func:`~closedloop.analysis.design_optimizer.optimize_design` finds the Pareto front.
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import yaml

import closedloop as cl
from cahyman_pin.paper.data import TABLE_POSES
from cahyman_pin.params import DEFAULT_PARAMS
from cahyman_pin.urdf_builder import build_urdf, closure_spec, springs
from closedloop.analysis.design_evaluation import evaluate_design

p = DEFAULT_PARAMS.replace(links_as_beams=True)  # its URDF has the sliding tube's link
spec = closure_spec(p)


def tube(end: str, d: str) -> dict:
    """An aluminium tube whose outer diameter is the argument ``d`` [m]."""
    section = {"shape": "tube", "d": f"${{{d}}}", "t": f"${{{d} / 10}}"}
    return {"end": end, "E": p.E_beam, "G": p.G_beam, "density": 2700.0, "section": section}


closures = {
    "closed_loop": [list(pair) for pair in spec.pairs], "type": list(spec.types),
    "name_mot": list(spec.actuated),
    "springs": {n: k for n, k in springs(p).items() if n != "arm_axial"},  # the paper's
    "locked": ["arm_axial"],  # the arm tube carries its axial stiffness
    "beams": {"arm": tube("arm_axial", "d_arm"),
              "telescope_root": tube("telescope_fixed", "d_slide")},
}  # fmt: skip
poses = [TABLE_POSES[1], TABLE_POSES[2], TABLE_POSES[0]]  # a short path through them
workspace = [[*np.deg2rad(x.alpha_deg), np.deg2rad(x.alpha4_deg), 1e-3 * x.s4_mm] for x in poses]

with tempfile.TemporaryDirectory() as folder:  # the model's files, for this run
    (Path(folder) / "cahyman.urdf").write_text(build_urdf(p))
    text = yaml.safe_dump(closures, sort_keys=False).replace("'", "")  # ${...} unquoted
    (Path(folder) / "cahyman.yaml").write_text(text)
    problem = {
        "model": f"{folder}/cahyman.urdf", "closures": f"{folder}/cahyman.yaml",
        "frame": "M", "parameters": {"d_arm": [0.006, 0.03], "d_slide": [0.006, 0.03]},
        "workspace": {"points": workspace},
        "objectives": [{"index": "mass", "goal": "minimize"},
                       {"index": "min_translational", "goal": "maximize"}],
        "constraints": [{"index": "mass", "max": 0.05}],
    }  # fmt: skip
    result = cl.optimize_design(problem, seed=0, budget=60)
    # the same machine with tubes of 20 cm: as if rigid, its springs alone
    rigid = evaluate_design(cl.design_problem(problem), {"d_arm": 0.2, "d_slide": 0.2})
print("\n".join(result.summary()))
stiffest = result.pareto[-1].values["min_translational"]
limit = rigid.values["min_translational"]
print(f"stiffest within the budget: {stiffest:.4g} N/m, {stiffest / limit:.0%} of {limit:.4g} N/m")

# %%
# Along the front the stiffness at M rises with the tubes' mass, ever more slowly, toward
# that of the same machine with rigid tubes (dotted): its motors' and legs' springs alone.
# Within the budget the stiffest design, the front's last point, reaches about 80 % of it.
# The star is the design the result calls best, the compromise nearest to both ends.
front = np.array([[e.values["mass"], e.values["min_translational"]] for e in result.pareto])
feasible = np.array([[e.values["mass"], e.values["min_translational"]]
                     for e in result.evaluations if e.feasible])  # fmt: skip
fig, ax = plt.subplots(figsize=(6, 4))
ax.plot(1e3 * feasible[:, 0], 1e-3 * feasible[:, 1], ".", color="0.7", label="designs evaluated")
ax.plot(1e3 * front[:, 0], 1e-3 * front[:, 1], "o-", ms=4, label="Pareto front")
best = result.best.values
ax.plot(1e3 * best["mass"], 1e-3 * best["min_translational"], "*", ms=14, label="best")
ax.axvline(50, color="C3", ls="--", label="mass budget")
ax.axhline(1e-3 * limit, color="0.3", ls=":", label="rigid tubes")
ax.set_xlabel("mass of the two tubes [g]")
ax.set_ylabel("worst min. translational stiffness at M [kN/m]")
ax.set_title("CaHyMan: stiffness at M against the tubes' mass")
ax.legend(loc="lower right", fontsize=8)
fig.tight_layout()
