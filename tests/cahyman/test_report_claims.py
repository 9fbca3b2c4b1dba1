"""Sentences of the report checked against an independent computation.

Each test recomputes what a sentence of the report claims (from the backends' matrices,
the Pinocchio model or the paper's eq. (19)) and checks that the report says it.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from cahyman_pin.api import stiffness
from cahyman_pin.backends.published import PublishedOptions, a_d_printed, published_stiffness
from cahyman_pin.geometry import plate_pose
from cahyman_pin.model import cahyman_model
from cahyman_pin.paper import beams as beams_module
from cahyman_pin.paper.cells import model_values
from cahyman_pin.paper.compare import table_values
from cahyman_pin.paper.data import LOADS, TABLE_POSES
from cahyman_pin.paper.document import Document, Paragraph
from cahyman_pin.paper.effects import EFFECTS
from cahyman_pin.paper.parameters import conventions_section, parameters_section
from cahyman_pin.params import DEFAULT_PARAMS
from cahyman_pin.urdf_builder import beams, springs
from closedloop.exceptions import SingularConfigurationError

#: Masses [kg] given to every mass field (none is in the paper).
MASSES = {"m_HQ": 0.2, "m_QM": 0.3, "m_MM2": 0.1, "m_M4": 0.5, "m_M5": 0.4,
          "m_b": 0.1, "m_c": 0.2, "m_d": 0.1, "m_h": 0.05}  # fmt: skip
#: The tables print 0.01 mm or deg: half of it is the rounding of a printed cell.
HALF_PRINTED = 0.005


def _text(doc: Document) -> str:
    return " ".join(b.text for b in doc.blocks if isinstance(b, Paragraph))


def _intro_text(params=DEFAULT_PARAMS) -> str:
    """The text of the section 'Parameters and conventions' on the parameters."""
    doc = Document("t")
    parameters_section(doc, params)
    return _text(doc)


def test_masses_act_only_through_the_weight():
    """The parameters paragraph: the masses shape only the weight terms (the published
    column) and the weight sections, not the consistent or generic columns or the fits."""
    heavy = DEFAULT_PARAMS.replace(**MASSES)
    for pose in TABLE_POSES:
        light, loaded = table_values(pose, DEFAULT_PARAMS), table_values(pose, heavy)
        for b in ("consistent", "generic"):  # exactly: no mass enters a linear answer
            np.testing.assert_array_equal(loaded.values[b], light.values[b], err_msg=b)
        # the published column's weight terms move it by more than the printed rounding
        assert (
            np.max(np.abs(loaded.values["published"] - light.values["published"]))
            > (HALF_PRINTED) / 5
        )
    np.testing.assert_array_equal(model_values(heavy), model_values(DEFAULT_PARAMS))  # fits
    text = _intro_text()
    assert "they shape every number of this report, except the beam fields" in text
    assert "and the masses (m_HQ, m_QM, m_MM2, m_M4, m_M5, m_b, m_c, m_d, m_h), " in text
    assert "the consistent and generic columns and the fits do not depend on them" in text


def test_the_published_column_takes_the_printed_k_s_unlike_the_api_backend():
    """The report's published column takes K_s as printed; the API's backend 'published'
    takes the parameters' K_s: at Table 1 (arm vertical) they differ in dz."""
    pose = TABLE_POSES[0]
    column = table_values(pose, DEFAULT_PARAMS).values["published"][2, 0]  # dz, load F
    api = 1e3 * (stiffness(*pose.si, backend="published").C @ LOADS[0])[2]
    printed = 1e3 * (stiffness(*pose.si, params=DEFAULT_PARAMS.with_ks("printed"),
                               backend="published").C @ LOADS[0])[2]  # fmt: skip
    assert column == pytest.approx(printed, rel=1e-12)
    assert abs(api - column) > 1e-4  # mm: the 'K_s value' effect, 0.00016 mm
    text = _intro_text()
    assert "The published backend always takes K_s" not in text
    assert "The published column always takes K_s = 0.697 N/m as printed" in text
    assert (
        "the backend 'published' of the API and of 'cahyman stiffness' takes the "
        "parameters' K_s instead" in text
    )


def test_the_published_column_is_not_a_twist_at_M():
    """Conventions: the published column is H's translation plus the arm's deflection in
    plate axes (no lever arm), not the displacement of M: with the lever arm and world
    axes (the two repairs that make it one) it changes by far more than round-off."""
    pose = TABLE_POSES[2]  # a tilted plate: plate axes are not world axes
    r = published_stiffness(*pose.si, DEFAULT_PARAMS)
    at_m = published_stiffness(*pose.si, DEFAULT_PARAMS,
                               PublishedOptions(lever_arm=True, serial_frame="world"))  # fmt: skip
    column = table_values(pose, DEFAULT_PARAMS).values["published"][:3]
    for j, load in enumerate(LOADS):
        parts = 1e3 * (r.C_PAR[:3] + r.C_SER[:3]) @ load
        np.testing.assert_allclose(column[:, j], parts, rtol=1e-12, atol=1e-15)
        moved = 1e3 * at_m.C[:3] @ load
        assert np.linalg.norm(moved - parts) > 0.1 * np.linalg.norm(parts), j
    doc = Document("t")
    tables = [table_values(p, DEFAULT_PARAMS) for p in TABLE_POSES]
    conventions_section(doc, DEFAULT_PARAMS, tables)
    text = _text(doc)
    assert (
        "not a twist at M: translations of H (the plate, eq. 9) plus the arm's "
        "deflection in plate axes" in text
    )
    assert "with no lever arm (eq. 3)" in text


def test_printed_a_d_is_singular_where_y2_vanishes():
    """Eq. (19) divides by Delta y_2 (C_y) as well as by Delta y_1 and C_psi: at alpha_2 =
    90 deg alone the printed A_d is singular, and the effect's note says so."""
    p = DEFAULT_PARAMS
    alpha = np.deg2rad([45.0, 90.0, 75.0])
    y, z = p.b * np.cos(alpha), p.b * np.sin(alpha) + p.h  # model document
    assert abs(y[0]) > 0.05 and abs(2 * z[0] - z[1] - z[2]) > 0.01 and abs(y[1]) < 1e-15
    with pytest.raises(SingularConfigurationError, match="Delta y_2"):
        a_d_printed(alpha, plate_pose(alpha, p), p)
    note = next(e for e in EFFECTS if e.name.startswith("A_d")).text(p)
    assert "singular where y_1, y_2 or C_psi = 2 z_1 - z_2 - z_3 is 0" in note


def test_beams_text_coupler_as_two_tubes(monkeypatch):
    """The beams section: each coupler is two tubes of length a/2 meeting at the slider
    (frames of the Pinocchio model), and K_s stays beside the MM2 tube."""
    p = DEFAULT_PARAMS.replace(links_as_beams=True)
    tubes = beams(p)
    model = cahyman_model(p)
    q = model.assemble(*TABLE_POSES[2].si)
    m = model.clm.model
    data = m.createData()
    pin.framesForwardKinematics(m, data, q)

    def at(name):
        return data.oMf[m.getFrameId(name)].translation

    for k in (1, 2, 3):
        first, second = tubes[f"coupler_{k}"], tubes[f"coupler_{k}_mid"]
        for start, tube in ((f"coupler_{k}", first), (f"coupler_{k}_mid", second)):
            length = np.linalg.norm(at(tube["end"]) - at(start))
            assert length == pytest.approx(p.a / 2, rel=1e-9), start
        # they meet at the slider: the s_k joint hangs from the second tube's start
        j = m.getJointId(f"s_{k}")
        origin = (data.oMi[m.parents[j]] * m.jointPlacements[j]).translation  # q_s = 0
        np.testing.assert_allclose(origin, at(f"coupler_{k}_mid"), atol=1e-12)
    assert "telescope_root" in tubes and springs(p)["s_4"] == p.K_s
    fake = [(pose.label, b, np.ones(6), dict.fromkeys(beams_module.GROUPS, 1 / 3))
            for pose in TABLE_POSES for b in (False, True)]  # fmt: skip
    monkeypatch.setattr(beams_module, "beam_rows", lambda params: fake)
    doc = Document("t")
    beams_module.beams_section(doc, DEFAULT_PARAMS)
    text = _text(doc)
    assert "its coupler c (two tubes of length a/2 meeting at the slider" in text
    assert "springs K_T, K_T4 and K_s stay" in text
    assert "K_ck and K_hk" in text
