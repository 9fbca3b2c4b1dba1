"""Identification from files: the measurement YAML and CSV, and ``closedloop identify``
(exit 0 identified, 1 a parameter not identifiable, 2 bad input, one line on stderr)."""

import json

import numpy as np
import pytest
from helpers import driven

import closedloop as cl
from closedloop.analysis.identification import identify
from closedloop.analysis.measurements import CSV_SD, CSV_TWIST, CSV_WRENCH, read_measurements
from closedloop.cli.app import main

TRUE = {"crank": 50.0, "crank_axial": 1e5, "rocker_axial": 2e5}
#: Noise-free data: the fit stops at the optimiser's tolerances, far below 1e-8.
RTOL_EXACT_FIT = 1e-8


@pytest.fixture(scope="module")
def exact(fourbar_urdf, fourbar_yaml):
    """(model, [(q, actuated, wrench, twist)]): the four-bar's exact deflections."""
    clm = cl.load_model(fourbar_urdf, fourbar_yaml)
    rng = np.random.default_rng(21)
    rows = []
    cranks = (0.3, 0.8, 1.3)
    for crank, q in zip(cranks, driven(clm, cranks), strict=True):  # as the robot is driven
        C = cl.compliance(clm, q, "P").C
        rows += [(q, crank, w, C @ w) for w in 10 * rng.normal(size=(2, 6))]
    return clm, rows


def _csv(path, rows, config="q", sd_columns=False):
    head = [f"{config}_{i}" for i in range(rows[0][0].size if config == "q" else 1)]
    sd = list(CSV_SD) if sd_columns else ["sd"]
    lines = [",".join(["frame", *head, *CSV_WRENCH, *CSV_TWIST, *sd])]
    for q, crank, w, d in rows:
        values = q.tolist() if config == "q" else [crank]
        sds = [1e-7] * (6 if sd_columns else 1)
        lines.append(",".join(["P", *(repr(float(x)) for x in [*values, *w, *d, *sds])]))
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize(("config", "sd_columns"), [("q", False), ("actuated", True)])
def test_a_csv_file_gives_the_same_measurements(tmp_path, exact, config, sd_columns):
    clm, rows = exact
    frame, data = read_measurements(_csv(tmp_path / "m.csv", rows, config, sd_columns))
    assert frame == "P" and len(data) == len(rows)
    for m, (q, crank, w, d) in zip(data, rows, strict=True):
        np.testing.assert_array_equal(m.wrench, w)
        np.testing.assert_array_equal(m.twist, d)
        np.testing.assert_array_equal(m.sd, np.full(6, 1e-7))
        np.testing.assert_array_equal(m.q if config == "q" else m.actuated,
                                      q if config == "q" else [crank])  # fmt: skip
    start = clm.with_springs({"crank": 10.0, "crank_axial": 1e6, "rocker_axial": 1e4})
    fit = identify(start, data, frame, list(TRUE))
    for name, value in TRUE.items():
        np.testing.assert_allclose(fit.estimates[name], value, rtol=RTOL_EXACT_FIT)


@pytest.mark.parametrize(
    ("text", "error", "match"),
    [("frame,q_0\nP,0\n", cl.ModelFileError, r"missing \['fx'"),
     ("frame,q_0,fx,fy,fz,nx,ny,nz,dx,dy,dz,rx,ry,rz,sd,extra\n" + "P" + ",0" * 15 + "\n",
      cl.ModelFileError, r"unknown \['extra'\]"),
     ("frame,q_0,fx,fy,fz,nx,ny,nz,dx,dy,dz,rx,ry,rz,sd\nP" + ",0" * 13 + ",0\n",
      cl.InvalidInputError, r"measurement 0 of .*sd must be one or 6 values > 0"),
     ("frame,q_0,fx,fy,fz,nx,ny,nz,dx,dy,dz,rx,ry,rz,sd\nP" + ",0" * 13 + "\n",
      cl.ModelFileError, r"row 0 has not one value per column"),
     ("frame,q_0,fx,fy,fz,nx,ny,nz,dx,dy,dz,rx,ry,rz,sd\nP" + ",0" * 13 + ",nan\n",
      cl.InvalidInputError, r"sd must be one or 6 values > 0 .* got nan"),
     ("frame,q_0,fx,fy,fz,nx,ny,nz,dx,dy,dz,rx,ry,rz,sd\nP" + ",0" * 6 + ",x" + ",0" * 6
      + ",1\n", cl.InvalidInputError, r"measurement 0 of"),
     ("frame,q_0,fx,fy,fz,nx,ny,nz,dx,dy,dz,rx,ry,rz,sd\nP" + ",0" * 13 + ",1\nQ" + ",0" * 13
      + ",1\n", cl.ModelFileError, r"one frame expected in every row, got \['P', 'Q'\]")],
)  # fmt: skip
def test_bad_csv_files_are_refused(tmp_path, text, error, match):
    (tmp_path / "m.csv").write_text(text)
    with pytest.raises(error, match=match):
        read_measurements(tmp_path / "m.csv")


def test_a_yaml_measurement_without_sd_is_refused(tmp_path):
    (tmp_path / "m.yaml").write_text("frame: P\nmeasurements:\n  - {q: [0], wrench: [0, 0, 0, "
                                     "0, 0, 0], twist: [0, 0, 0, 0, 0, 0]}\n")  # fmt: skip
    with pytest.raises(cl.ModelFileError, match=r"measurement 0 has \['q', 'twist', 'wrench'\]"):
        read_measurements(tmp_path / "m.yaml")


def test_a_yaml_measurement_with_a_number_for_a_key_is_refused(tmp_path):
    """The keys are named in the message even when one is not a string (sorting them
    raised a TypeError, a traceback from the command line)."""
    (tmp_path / "m.yaml").write_text("frame: P\nmeasurements:\n  - {actuated: [0.2], wrench: "
                                     "[1, 0, 0, 0, 0, 0], twist: [0, 0, 0, 0, 0, 0], sd: 1e-7, "
                                     "1: 2}\n")  # fmt: skip
    with pytest.raises(cl.ModelFileError, match=r"measurement 0 has \['1', 'actuated', 'sd'"):
        read_measurements(tmp_path / "m.yaml")


def _yaml(path, rows, sd="1e-7"):
    lines = ["frame: P", "measurements:"]
    for q, _, w, d in rows:
        lines += [f"  - q: {q.tolist()}", f"    wrench: {w.tolist()}",
                  f"    twist: {d.tolist()}", f"    sd: {sd}"]  # fmt: skip
    path.write_text("\n".join(lines) + "\n")
    return path


def _run(capsys, *argv):
    code = main(["identify", *map(str, argv)])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_the_command_reads_a_csv_file(tmp_path, exact, fourbar_urdf, fourbar_yaml, capsys):
    _, rows = exact
    code, out, err = _run(capsys, fourbar_urdf, "--closures", fourbar_yaml, "--measurements",
                          _csv(tmp_path / "m.csv", rows), "--fit", *TRUE, "--json")  # fmt: skip
    assert code == 0, err
    doc = json.loads(out)
    assert doc["unidentifiable"] == [] and doc["n_measurements"] == len(rows)
    for name, value in TRUE.items():
        np.testing.assert_allclose(doc["estimates"][name], value, rtol=1e-6)


def test_an_unidentifiable_parameter_exits_1_without_a_value(tmp_path, fourbar_urdf,
                                                              fourbar_yaml, capsys):  # fmt: skip
    # the four-bar moves in the x-z plane: loads fy, nx, nz at P meet no spring (C w = 0)
    clm = cl.load_model(fourbar_urdf, fourbar_yaml)
    q = cl.assemble(clm, actuated=[0.5]).q
    w = np.array([0.0, 3.0, 0.0, 1.0, 0.0, -0.5])
    np.testing.assert_array_equal(cl.compliance(clm, q, "P").C @ w, 0.0)
    path = _yaml(tmp_path / "m.yaml", [(q, 0.5, w, np.zeros(6))] * 2)
    code, out, err = _run(capsys, fourbar_urdf, "--closures", fourbar_yaml, "--measurements",
                          path, "--fit", "crank", "crank_axial+rocker_axial", "--json")  # fmt: skip
    doc = json.loads(out)
    assert code == 1, err
    assert doc["unidentifiable"] == ["crank", "crank_axial+rocker_axial"]
    assert doc["estimates"] == {"crank": None, "crank_axial+rocker_axial": None}
    assert doc["std_errors"] == {"crank": None, "crank_axial+rocker_axial": None}
    code, out, _ = _run(capsys, fourbar_urdf, "--closures", fourbar_yaml, "--measurements",
                        path, "--fit", "crank")  # fmt: skip
    assert code == 1 and "crank: not identifiable from these data" in out


@pytest.mark.parametrize(
    ("fit", "sd", "match"),
    [(["nope"], "1e-7", "unknown joint 'nope'"),
     (["crank"], "0", "sd must be one or 6 values > 0"),
     (["crank"], "-1e-7", "got -1e-07"),
     (["crank"], ".nan", "got nan"),
     (["crank"], "[1e-7, 1e-7]", "got [1e-07, 1e-07]"),
     (["coupler"], "1e-7", "'coupler' needs a finite start value > 0"),
     (["crank_axial", "crank_axial+rocker_axial"], "1e-7", "a joint appears in two fitted"),
     (["crank+rocker_axial"], "1e-7", "ties springs of different units")],
)  # fmt: skip
def test_bad_input_is_one_line_and_exit_2(tmp_path, exact, fourbar_urdf, fourbar_yaml,
                                          capsys, fit, sd, match):  # fmt: skip
    path = _yaml(tmp_path / "m.yaml", exact[1], sd=sd)
    code, out, err = _run(capsys, fourbar_urdf, "--closures", fourbar_yaml, "--measurements",
                          path, "--fit", *fit)  # fmt: skip
    assert code == 2 and match in err, err
    assert err.count("\n") == 1 and "Traceback" not in err and out == ""


def test_a_missing_file_and_an_unknown_frame_exit_2(tmp_path, exact, fourbar_urdf,
                                                    fourbar_yaml, capsys):  # fmt: skip
    code, _, err = _run(capsys, fourbar_urdf, "--closures", fourbar_yaml, "--measurements",
                        tmp_path / "none.yaml", "--fit", "crank")  # fmt: skip
    assert code == 2 and "none.yaml' cannot be read: No such file" in err
    assert err.count("\n") == 1 and err.startswith("closedloop: error: measurement file ")
    path = _yaml(tmp_path / "m.yaml", exact[1])
    path.write_text(path.read_text().replace("frame: P", "frame: nowhere"))
    code, _, err = _run(capsys, fourbar_urdf, "--closures", fourbar_yaml, "--measurements",
                        path, "--fit", "crank")  # fmt: skip
    assert code == 2 and "nowhere" in err and err.count("\n") == 1


def test_a_spreadsheet_csv_with_a_bom_reads_as_without(tmp_path, exact):
    """Excel's "CSV UTF-8" starts with a byte order mark: the header was '\\ufeffframe'."""
    _, rows = exact
    plain = _csv(tmp_path / "plain.csv", rows)
    bom = tmp_path / "bom.csv"
    bom.write_bytes(b"\xef\xbb\xbf" + plain.read_bytes())
    (frame, read), (frame0, read0) = read_measurements(bom), read_measurements(plain)
    assert frame == frame0 == "P" and len(read) == len(read0)
    for a, b in zip(read, read0, strict=True):
        np.testing.assert_array_equal(a.wrench, b.wrench)
        np.testing.assert_array_equal(a.twist, b.twist)


def test_a_csv_aligned_with_spaces_reads_as_without(tmp_path, exact):
    """Columns padded to line up: the header's 'frame ' and the cell ' P ' were refused as
    an unknown column and a second frame."""
    _, rows = exact
    plain = _csv(tmp_path / "plain.csv", rows)
    aligned = tmp_path / "aligned.csv"
    lines = plain.read_text().splitlines()
    aligned.write_text("\n".join(" , ".join(f"{c:>8} " for c in line.split(",")) for line in lines))
    (frame, read), (frame0, read0) = read_measurements(aligned), read_measurements(plain)
    assert frame == frame0 == "P" and len(read) == len(read0)
    for a, b in zip(read, read0, strict=True):
        np.testing.assert_array_equal(a.wrench, b.wrench)
        np.testing.assert_array_equal(a.twist, b.twist)
        np.testing.assert_array_equal(a.q, b.q)


@pytest.mark.parametrize("cell", ["0_3", "\u0663"])
def test_a_csv_number_in_other_notation_is_refused(tmp_path, exact, cell):
    """Python's float() read 0_3 as 3.0 and Arabic-Indic digits as digits."""
    _, rows = exact
    header, first, *rest = _csv(tmp_path / "m.csv", rows).read_text().splitlines()
    cells = first.split(",")
    column = header.split(",").index("fx")
    cells[column] = cell
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join([header, ",".join(cells), *rest]) + "\n")
    with pytest.raises(cl.ClosedLoopError, match=f"'{cell}' is not a decimal number"):
        read_measurements(bad)


def test_csv_columns_given_twice_or_empty_are_named(tmp_path, exact):
    """A repeated column: csv.DictReader kept the last one. An empty cell: "could not
    convert string to float: ''", without the column."""
    _, rows = exact
    header, first, *rest = _csv(tmp_path / "m.csv", rows).read_text().splitlines()
    twice = tmp_path / "twice.csv"
    twice.write_text("\n".join([header + ",fx", *(row + ",9" for row in (first, *rest))]) + "\n")
    with pytest.raises(cl.ModelFileError, match=r"column\(s\) \['fx'\] given twice"):
        read_measurements(twice)
    cells = first.split(",")
    cells[header.split(",").index("fy")] = ""
    empty = tmp_path / "empty.csv"
    empty.write_text("\n".join([header, ",".join(cells), *rest]) + "\n")
    with pytest.raises(cl.ModelFileError, match=r"row 0 has no value in column\(s\) \['fy'\]"):
        read_measurements(empty)


@pytest.mark.parametrize(
    ("sd", "wrench", "match"),
    [("true", "[1, 0, 0, 0, 0, 0]", r"measurement 0 .*True is not a number"),
     ("1e-7", "[[1, 0, 0], [0, 0, 0]]", r"measurement 0 .*is a list inside a list")],
)  # fmt: skip
def test_a_yaml_boolean_or_nested_list_is_refused(tmp_path, sd, wrench, match):
    """sd: true was read as 1.0 and a nested wrench flattened."""
    (tmp_path / "m.yaml").write_text(
        f"frame: P\nmeasurements:\n  - {{q: [0, 0, 0, 0, 0], wrench: {wrench}, "
        f"twist: [0, 0, 0, 0, 0, 0], sd: {sd}}}\n"
    )
    with pytest.raises(cl.InvalidInputError, match=match):
        read_measurements(tmp_path / "m.yaml")


def test_a_fit_that_did_not_converge_exits_3(tmp_path, exact, fourbar_urdf, fourbar_yaml, capsys,
                                            monkeypatch):  # fmt: skip
    """The optimiser's own report of non-convergence (simulated here: the real fit, its
    success flag turned off) ended in exit 0 with the estimates printed."""
    import closedloop.analysis.identification as identification

    solve = identification._solve
    monkeypatch.setattr(identification, "_solve", lambda *a: (solve(*a)[0], False))
    code, out, err = _run(capsys, fourbar_urdf, "--closures", fourbar_yaml, "--measurements",
                          _yaml(tmp_path / "m.yaml", exact[1]), "--fit", *TRUE)  # fmt: skip
    assert code == 3 and out == "", (code, out)
    assert err.count("\n") == 1 and "the optimiser did not converge" in err
