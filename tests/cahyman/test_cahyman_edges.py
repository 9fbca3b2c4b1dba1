"""CaHyMan at the edges of its parameters: links as beams with the closed forms, motors
made rigid by huge springs, a machine far stiffer than the paper's tables."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cahyman_pin.api import stiffness
from cahyman_pin.cli import main
from cahyman_pin.params import DEFAULT_PARAMS
from cahyman_pin.sweep import grid, sweep
from closedloop.exceptions import InvalidInputError, SingularConfigurationError

ALPHA = np.deg2rad([45.0, 60.0, 75.0])
#: The consistent closed form and the generic model: the same machine through different
#: algebra; with springs 1e14 apart the condition number is ~1e18, and C (a sum of the
#: springs' compliances) keeps about 1e-13 of its largest entry.
RTOL_BACKENDS = 1e-12
SPRINGS = ("K_T", "K_b", "K_d", "K_T4", "K_s", "K_4")


@pytest.mark.parametrize("backend", ["consistent", "published"])
def test_links_as_beams_are_refused_by_the_closed_forms(backend):
    """The closed forms have lumped springs: they answered for another machine."""
    beams = DEFAULT_PARAMS.replace(links_as_beams=True)
    with pytest.raises(InvalidInputError, match=f"links_as_beams needs the generic.*{backend}"):
        stiffness(ALPHA, 0.7, 0.02, params=beams, backend=backend)
    with pytest.raises(InvalidInputError, match="links_as_beams"):
        sweep(grid({"alpha4": np.deg2rad([30.0, 60.0])}, alpha=ALPHA, s4=0.02, params=beams),
              backend=backend, executor="serial")  # fmt: skip


def test_the_report_refuses_links_as_beams_in_one_line(tmp_path, capsys):
    path = tmp_path / "beams.yaml"
    path.write_text("links_as_beams: true\n")
    code = main(["report", "--params", str(path), "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Lumped springs vs beam links" in err
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("K_T", [1e18, 1e24])
def test_a_motor_made_rigid_by_a_huge_spring_is_the_closed_form(K_T):
    """Leg motors of 1e18 N m/rad beside the default springs (1e4 to 1e6): the generic
    backend answers as the consistent closed form (it refused a spring 1e14 times softer
    than the stiffest as none, advising to add springs)."""
    params = DEFAULT_PARAMS.replace(K_T=K_T)
    generic = stiffness(ALPHA, 0.7, 0.02, params=params)
    closed = stiffness(ALPHA, 0.7, 0.02, params=params, backend="consistent")
    scale = np.abs(closed.C).max()
    np.testing.assert_allclose(generic.C, closed.C, rtol=0, atol=RTOL_BACKENDS * scale)


def test_a_machine_far_stiffer_than_the_tables_gets_its_report(tmp_path, capsys):
    """Every spring 1e14 times the paper's: the cells are ~1e-14 of the published ones,
    no fitted value changes any of them (the fit has nothing to fit) and the repaired arm
    model is singular at every pose; the report says so instead of a traceback."""
    path = tmp_path / "rigid.yaml"
    path.write_text("".join(f"{n}: {getattr(DEFAULT_PARAMS, n) * 1e14:g}\n" for n in SPRINGS))
    assert main(["report", "--params", str(path), "--out", str(tmp_path / "r")]) == 0
    text = (tmp_path / "r" / "report.md").read_text()
    assert "singular at every pose of the tables" in text


@pytest.mark.parametrize("backend", ["generic", "consistent", "published"])
@pytest.mark.parametrize("factor", [1e50, 1e-60])
def test_a_determinant_beyond_the_float_range_is_an_error_not_inf_or_zero(backend, factor):
    """Every spring times 1e50 (1e-60): det K ~ 1e330 (1e-330), which was inf (0.0 for a
    full-rank K); the JSON summary keeps K and C and says why det_K is missing."""
    params = DEFAULT_PARAMS.replace(**{n: getattr(DEFAULT_PARAMS, n) * factor for n in SPRINGS})
    r = stiffness(ALPHA, 0.7, 0.02, params=params, backend=backend)
    with pytest.raises(SingularConfigurationError, match="beyond the floating point range"):
        _ = r.det_K
    doc = r.to_dict()
    json.dumps(doc, allow_nan=False)
    assert doc["det_K"] is None and doc["K"] is not None
    # det K scales as factor^6 (six directions, each a spring's): its size from the default
    size = float(doc["missing"]["det_K"].split("= 1e")[1].split()[0])
    expected = np.log10(abs(stiffness(ALPHA, 0.7, 0.02, backend=backend).det_K))
    np.testing.assert_allclose(size, expected + 6 * np.log10(factor), atol=0.05)  # 1 decimal


#: The general path against the closed form with leg motors K_T up to 1e20 (a scaled
#: spread of 1.1e17): the soft springs beside the stiff ones keep their digits
#: (closedloop.elastostatics.springs.spring_split; 1e-16 measured at 1e20, 1.2e-11 before its graded
#: QR); 1e-13 leaves rounding of the two backends' C a margin.
RTOL_GENERAL_PATH = 1e-13


def test_the_general_path_resolves_springs_up_to_its_spread_and_refuses_beyond():
    from cahyman_pin.model import cahyman_model
    from cahyman_pin.urdf_builder import FRAME_M
    from closedloop import compliance

    for K_T in (1e12, 1e16, 1e20):
        params = DEFAULT_PARAMS.replace(K_T=K_T)
        model = cahyman_model(params)
        q = model.assemble(ALPHA, 0.7, 0.02)
        closed = stiffness(ALPHA, 0.7, 0.02, params=params, backend="consistent").C
        general = compliance(model.clm, q, FRAME_M, path="null-space").C
        scale = np.abs(closed).max()
        np.testing.assert_allclose(general, closed, rtol=0, atol=RTOL_GENERAL_PATH * scale)
    params = DEFAULT_PARAMS.replace(K_T=1e30)
    model = cahyman_model(params)
    q = model.assemble(ALPHA, 0.7, 0.02)
    with pytest.raises(SingularConfigurationError, match="beyond the 1e\\+20 that the general"):
        compliance(model.clm, q, FRAME_M, path="null-space")
    closed = stiffness(ALPHA, 0.7, 0.02, params=params, backend="consistent").C
    fast = compliance(model.clm, q, FRAME_M)  # the partitioned path: exact at any spread
    assert fast.path == "partitioned"
    np.testing.assert_allclose(fast.C, closed, rtol=0, atol=RTOL_BACKENDS * np.abs(closed).max())
