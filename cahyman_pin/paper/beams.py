"""The report's section "lumped springs vs beam links"
(:func:`~cahyman_pin.paper.beams.beams_section`).

At the three table poses, the compliance at M (world axes; the Pinocchio model, generic
backend) of the paper's model, whose links are rigid but for the lumped axial springs
K_b, K_d, K_4, against CaHyMan with its links as beams (``links_as_beams``: tubes of
the assumed sizes and material of :class:`cahyman_pin.params.CaHyManParams`,
:mod:`cahyman_pin.urdf_builder`); both keep the motors' K_T, K_T4, K_s. For each: the
diagonal of C and the shares of the deflection energy under the vertical force
:data:`SHARE_LOAD` at M held by the motors, the legs' links and the arm's links
(:func:`closedloop.elastostatics.compliance.energy_shares`).
"""

from __future__ import annotations

import numpy as np

from cahyman_pin.model import cahyman_model
from cahyman_pin.paper.data import TABLE_POSES
from cahyman_pin.paper.document import Document, Heading, Paragraph, Table
from cahyman_pin.params import CaHyManParams
from cahyman_pin.urdf_builder import ACTUATED, FRAME_M
from closedloop.elastostatics.compliance import compliance, energy_shares

#: The load of the energy shares: a vertical force at M (f [N], n [N m], world axes).
SHARE_LOAD = np.array([0.0, 0.0, -1.0, 0.0, 0.0, 0.0])
#: Element groups of the energy shares.
GROUPS = ("motors", "legs' links", "arm's links")
MODELS = {False: "lumped springs (paper)", True: "beam links"}


def _group(name: str) -> str:
    if name in ACTUATED:
        return GROUPS[0]
    return GROUPS[2] if name.startswith(("arm", "telescope")) else GROUPS[1]


def beam_rows(params: CaHyManParams) -> list[tuple[str, bool, np.ndarray, dict[str, float]]]:
    """Per table pose and model (links_as_beams False, True): (pose label, links as beams,
    diagonal of C (6,) [m/N, rad/(N m)] at M in world axes, group -> energy share under
    :data:`SHARE_LOAD`)."""
    out = []
    for pose in TABLE_POSES:
        for as_beams in (False, True):
            model = cahyman_model(params.replace(links_as_beams=as_beams))
            q = model.assemble(*pose.si)
            res = compliance(model.clm, q, FRAME_M)
            shares = dict.fromkeys(GROUPS, 0.0)
            for name, share in energy_shares(model.clm, res, SHARE_LOAD).items():
                shares[_group(name)] += share
            out.append((pose.label, as_beams, np.diag(res.C).copy(), shares))
    return out


def beams_section(doc: Document, params: CaHyManParams) -> None:
    """Add the section "lumped springs vs beam links" to ``doc``."""
    rows = beam_rows(params)
    table = tuple(
        (label, MODELS[as_beams], *(f"{1e6 * c:.4g}" for c in diag[:3]),
         *(f"{np.rad2deg(c):.4g}" for c in diag[3:]),
         *(f"{100 * shares[g]:.1f}" for g in GROUPS))
        for label, as_beams, diag, shares in rows
    )  # fmt: skip
    header = ("pose", "links", "dx/Fx [um/N]", "dy/Fy [um/N]", "dz/Fz [um/N]",
              "rx/Nx [deg/(N m)]", "ry/Ny [deg/(N m)]", "rz/Nz [deg/(N m)]",
              *(f"{g} [%]" for g in GROUPS))  # fmt: skip
    ratios = np.array([rows[i + 1][2] / rows[i][2] for i in range(0, len(rows), 2)])
    k, d = np.unravel_index(np.argmax(ratios), ratios.shape)
    doc.add(
        Heading("Lumped springs vs beam links"),
        Paragraph(
            "The paper lumps the links' compliance into three axial springs (K_b, K_d along "
            "the cranks, K_4 along the arm) and takes everything else as rigid (it names "
            "K_ck and K_hk for the couplers and the connecting bars but gives them no value). "
            "With links_as_beams each leg's cranks b and d, its coupler c (two tubes of "
            "length a/2 meeting at the slider, so that the connecting bar's load bends a "
            "coupler held at both ends) and its connecting bar h, the arm QM2 and the "
            "sliding tube MM2 are instead clamped tubes (closedloop.model.beams: axial, bending "
            "and torsion from beam theory) of the sizes and material of the parameters, "
            "assumed (the paper gives no sections): "
            f"E = {params.E_beam / 1e9:g} GPa, G = {params.G_beam / 1e9:g} GPa, legs' tubes "
            f"{1e3 * params.d_leg:g} x {1e3 * params.t_leg:g} mm (diameter x wall), arm "
            f"{1e3 * params.d_arm:g} x {1e3 * params.t_arm:g} mm, MM2 {1e3 * params.d_MM2:g} "
            f"x {1e3 * params.t_MM2:g} mm over {1e3 * params.L_MM2:g} mm; the motors' "
            "springs K_T, K_T4 and K_s stay (the paper's K_s is that of the linear motor and "
            "link MM2 together, so MM2 counts twice there). Below: the diagonal of the "
            "compliance at M (world axes, generic backend) and the shares of the deflection "
            "energy under a vertical force at M. "
            f"The beam links multiply the diagonal compliances by {ratios.min():.3g} to "
            f"{ratios.max():.3g} (the largest: {header[2 + d].split(' ')[0]} at "
            f"{TABLE_POSES[k].label})."
        ),
        Table(header, table, caption="Compliance at M and energy shares under Fz = -1 N"),
    )
