"""One convention for both command lines (closedloop.cli.common): usage errors, finite
numbers, the JSON writer, exit statuses, closed pipes."""

from __future__ import annotations

import argparse
import json
import math
import re

import pytest
from helpers import closed_pipe_run

from cahyman_pin.cli import main as cahyman_main
from closedloop.cli.app import main as closedloop_main
from closedloop.cli.common import run_command
from closedloop.cli.map_options import SpecError, parse_values
from closedloop.cli.outputs import EXIT_PIPE, print_json
from closedloop.cli.parser import UsageError, finite_float, positive_int
from closedloop.exceptions import EXIT_BAD_INPUT, EXIT_FAILED, NumericalError

MAINS = {"closedloop": closedloop_main, "cahyman": cahyman_main}
#: A valid command of each, before the option under test.
COMMANDS = {
    "closedloop": ["stiffness", "fourbar", "--frame", "P", "--actuated", "0.3"],
    "cahyman": ["deflect"],
}


def run(capsys, prog: str, *argv: str) -> tuple[int, str, str]:
    code = MAINS[prog](list(argv))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.mark.parametrize("prog", MAINS)
@pytest.mark.parametrize(
    ("extra", "match"),
    [
        (["--no-such-option"], "unrecognized arguments: --no-such-option"),
        (["--force", "0", "nan", "0"], "argument --force: 'nan' is not a finite number"),
        (["--force", "0", "1e999", "0"], "'1e999' is beyond the floating point range"),
        (["--force", "0", "x", "0"], "argument --force: 'x' is not a number"),
        # Python's float() reads 0_3 as 3.0 and other scripts' digits as digits
        (["--force", "0", "0_3", "0"], "argument --force: '0_3' is not a number"),
        (["--force", "0", "\u0663", "0"], "argument --force: '\u0663' is not a number"),
    ],
)
def test_usage_errors_are_one_line_and_exit_2(capsys, prog, extra, match):
    command = COMMANDS[prog] if "--force" not in extra or prog == "cahyman" else ["view",
              "fourbar", "--frame", "P", "--html", "unused.html"]  # fmt: skip
    code, out, err = run(capsys, prog, *command, *extra)
    assert (code, out) == (EXIT_BAD_INPUT, "")
    assert err.startswith(f"{prog}: error: ") and err.count("\n") == 1, err
    assert match in err


@pytest.mark.parametrize("prog", MAINS)
def test_unknown_command_is_one_line(capsys, prog):
    code, out, err = run(capsys, prog, "stiffnes")
    assert (code, out) == (EXIT_BAD_INPUT, "")
    assert err.startswith(f"{prog}: error: argument COMMAND: invalid choice: 'stiffnes'")
    assert err.count("\n") == 1


@pytest.mark.parametrize("prog", MAINS)
def test_help_states_the_same_exit_statuses(capsys, prog):
    code, out, _ = run(capsys, prog, "--help")
    flat = " ".join(out.split())
    assert code == 0
    assert "Exit status: 0 ok; 1 rank deficient (K does not exist); 2 bad input; 3 " in flat
    assert f"{EXIT_PIPE} output closed early" in flat


@pytest.mark.parametrize(("module", "argv"), [("closedloop", ["--help"]),
                                              ("cahyman_pin", ["--help"])])  # fmt: skip
def test_help_into_a_closed_pipe_ends_quietly(module, argv):
    done = closed_pipe_run(module, *argv)
    # argparse ignores the failed write of its help: 0; a later flush would give 141
    assert done.returncode in (0, EXIT_PIPE) and done.stderr == ""


@pytest.mark.parametrize(
    ("text", "value"), [("-1e5", -1e5), ("-.5", -0.5), ("2E-1", 0.2), ("0", 0.0), ("1e308", 1e308)]
)
def test_finite_float_reads_numbers(text, value):
    assert finite_float(text) == value


@pytest.mark.parametrize(
    "text",
    ["nan", "-inf", "inf", "1e309", "", "1,5", "0x10", "0_3", "1_000.5", " 1", "1 ",
     "\u0663", "\uff11", "\u0661.5", "1e\u0663", "True"],  # Arabic-Indic, full-width digits
)  # fmt: skip
def test_finite_float_refuses_the_rest(text):
    with pytest.raises(argparse.ArgumentTypeError, match=repr(text)):
        finite_float(text)


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--q", "0", "-1", "1.5", "-0.5", "1.2", "0_3"], "argument --q: '0_3' is not a number"),
        (["--actuated", "\u0660.3"], "argument --actuated: '\u0660.3' is not a number"),
        (["--actuated", "0.3", "--joint-stiffness", "1_0"],
         "argument --joint-stiffness: '1_0' is not a number"),
    ],
)  # fmt: skip
def test_the_command_line_reads_ascii_decimal_numbers_only(capsys, argv, match):
    code, out, err = run(capsys, "closedloop", "stiffness", "fourbar", "--frame", "P", *argv)
    assert (code, out) == (EXIT_BAD_INPUT, "")
    assert err == f"closedloop: error: {match}; expected ASCII decimal notation (e.g. -1.5e3)\n"


def test_a_locked_joint_s_inf_and_negative_e_notation_stay_numbers(capsys):
    code, out, _ = run(capsys, "closedloop", "stiffness", "fourbar", "--frame", "P",
                       "--actuated", "-3E-1", "--joint-stiffness", "inf", "--json")  # fmt: skip
    assert code in (0, 1)  # the crank locked: K or rank deficient, either way an answer
    assert json.loads(out)["q"][0] == -0.3


@pytest.mark.parametrize("text", ["1_0", "\u0663", "1.0", " 2"])
def test_counts_are_ascii_integers(text):
    with pytest.raises(argparse.ArgumentTypeError, match="is not an integer"):
        positive_int(text)


def test_print_json_writes_strict_indented_json(capsys):
    doc = {"K": None, "C": [[1.0, -2.5e-7], [0.0, 3.0]], "rank": 6, "name": "P"}
    print_json(doc)
    text = capsys.readouterr().out
    assert json.loads(text) == doc and text.startswith('{\n  "K": null,')


@pytest.mark.parametrize(
    ("doc", "where"),
    [
        ({"C": [[1.0, 2.0], [3.0, math.nan]]}, "C[1][1]"),
        ({"pose": {"M": [0.0, math.inf, 0.0]}}, "pose.M[1]"),
        ([1.0, -math.inf], "[1]"),
    ],
)
def test_print_json_never_writes_a_nan(capsys, doc, where):
    with pytest.raises(NumericalError, match=rf"not finite at {re.escape(where)};"):
        print_json(doc)
    assert capsys.readouterr().out == ""


@pytest.mark.parametrize("prog", MAINS)
def test_a_nan_result_exits_3_with_one_line(capsys, prog):
    args = argparse.Namespace(func=lambda _: print_json({"C": [math.nan]}))
    assert run_command(prog, args) == EXIT_FAILED
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err == f"{prog}: error: the result is not finite at C[0]; nothing written\n"


def test_usage_error_is_bad_input():
    from closedloop.exceptions import InvalidInputError, exit_status

    assert issubclass(UsageError, InvalidInputError)
    assert exit_status(UsageError("x")) == EXIT_BAD_INPUT


@pytest.mark.parametrize(
    ("prog", "argv", "match"),
    [
        ("cahyman", ["map", "--alpha4", "0:90:100000000000"], r"NUM must be from 1 to 2000000"),
        (
            "closedloop",
            ["map", "fourbar", "--frame", "P", "--sweep", "crank=0:1:100000000000"],
            r"NUM must be from 1 to 2000000",
        ),
        ("cahyman", ["map", "--alpha4", "0:inf:3"], r"'0:inf:3' has non-finite values"),
        (
            "cahyman",
            ["map", "--alpha4", "0:90:2000", "--s4", "0:50:2000"],
            r"4000000 points is more than the 2000000 a map may have",
        ),
    ],
)
def test_a_sweep_too_long_or_not_finite_is_refused_before_any_array(capsys, tmp_path, prog,
                                                                    argv, match):  # fmt: skip
    """NUM = 1e11 built the array first (a numpy MemoryError traceback, exit 1); an inf
    bound printed numpy's warning before the error. One line, exit 2, nothing written."""
    code, _out, err = run(capsys, prog, *argv, "--out", str(tmp_path / "m"))
    assert code == EXIT_BAD_INPUT
    assert len(err.strip().splitlines()) == 1 and re.search(match, err)
    assert not (tmp_path / "m").exists()


def test_sweep_specifications_may_start_with_a_negative_number(capsys, tmp_path):
    """``--alpha4 -90:90:3`` and ``-90,0,90`` (the README: numbers may be negative in any
    notation) were taken for options by argparse."""
    for spec in ("-90:90:3", "-90,0,90"):
        code, _out, err = run(capsys, "cahyman", "map", "--alpha4", spec, "--out",
                             str(tmp_path / spec))  # fmt: skip
        assert code == 0, err
        assert (tmp_path / spec / "map.npz").exists()


@pytest.mark.parametrize(
    ("prog", "argv"),
    [
        ("closedloop", ["stiffness", "ur5", "--frame", "tool0", "--springs", ""]),
        ("closedloop", ["stiffness", "fourbar", "--frame", "P", "--closures", " "]),
        ("closedloop", ["stiffness", "", "--frame", "P"]),
        ("closedloop", ["view", "fourbar", "--frame", "P", "--html", ""]),
        ("closedloop", ["map", "fourbar", "--frame", "P", "--sweep", "crank=0:1:3", "--out", ""]),
        ("closedloop", ["identify", "fourbar", "--measurements", "", "--fit", "crank"]),
        ("cahyman", ["map", "--alpha", "60,70", "--out", ""]),
        ("cahyman", ["report", "--out", ""]),
        ("cahyman", ["report", "--params", ""]),
    ],
)
def test_an_empty_path_is_refused(capsys, tmp_path, monkeypatch, prog, argv):
    """An empty path named the current folder (--out: a map written into it) or no file
    (``--springs ''``: the UR5 without springs, a rank-0 answer with exit 1)."""
    monkeypatch.chdir(tmp_path)
    code, out, err = run(capsys, prog, *argv)
    assert (code, out) == (EXIT_BAD_INPUT, "")
    assert err.count("\n") == 1 and "is an empty path; expected a file or folder" in err, err
    assert not list(tmp_path.iterdir())


def test_a_worker_timeout_without_a_scheduler_is_refused(capsys, tmp_path):
    argv = ["map", "fourbar", "--frame", "P", "--sweep", "crank=0:1:3", "--worker-timeout", "5"]
    code, out, err = run(capsys, "closedloop", *argv, "--out", str(tmp_path / "m"))
    assert (code, out) == (EXIT_BAD_INPUT, "")
    assert "--worker-timeout 5 bounds a Dask run only; give --scheduler ADDRESS too" in err
    assert not (tmp_path / "m").exists()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("1,2,x", "'1,2,x': 'x' is not a number; expected a value, START:STOP:NUM or V1,V2,..."),
        ("a:1:3", "'a:1:3': 'a' is not a number"),
        ("0:1", "'0:1' is not START:STOP:NUM (numbers, NUM an integer)"),
        ("0:1:2.5", "'0:1:2.5' is not START:STOP:NUM"),
        ("z", "'z' is not a number"),
        ("0_3,1", "'0_3,1': '0_3' is not a number"),
        ("0:1:1_0", "'0:1:1_0' is not START:STOP:NUM"),
        ("0:\u0661:3", "'0:\u0661:3': '\u0661' is not a number"),
    ],
)
def test_a_malformed_specification_names_its_bad_value(text, message):
    with pytest.raises(SpecError) as info:
        parse_values(text)
    assert str(info.value) == message or str(info.value).startswith(message)


def test_a_long_malformed_list_is_cut_in_the_message(capsys, tmp_path):
    """A 20,000-value list with one bad value was echoed whole (40 kB on one line)."""
    text = ",".join(["1"] * 20_000 + ["q"])
    code, out, err = run(capsys, "cahyman", "map", "--alpha4", text, "--out", str(tmp_path / "m"))
    assert (code, out) == (EXIT_BAD_INPUT, "")
    assert len(err) < 300 and err.count("\n") == 1, err
    assert f"... ({len(text)} characters): 'q' is not a number" in err


def test_an_option_given_twice_is_refused(capsys):
    """argparse keeps the last value: `--force 1 0 0 --force 0 0 1` loaded one force and
    `--payload 2 --payload 3` one payload. Options that collect (--mass, --sweep) may
    repeat."""
    from cahyman_pin.cli import main as cahyman_main
    from closedloop.cli.app import main as closedloop_main

    cases = [
        (cahyman_main, ["deflect", "--force", "1", "0", "0", "--force", "0", "0", "1"],
         "cahyman: error: --force given twice; expected it once"),
        (closedloop_main, ["stiffness", "ur5", "--frame", "tool0", "--joint-stiffness", "1e4",
                           "--gravity", "--payload", "2", "--payload", "3"],
         "closedloop: error: --payload given twice; expected it once"),
        (cahyman_main, ["stiffness", "--json", "--json"], "--json given twice"),
        (cahyman_main, ["deflect", "--force", "0", "0", "-10", "--forc", "0", "0", "-9"],
         "unrecognized arguments: --forc"),  # an abbreviation escaped the check
    ]  # fmt: skip
    for main, argv, message in cases:
        assert main(argv) == 2
        assert message in capsys.readouterr().err
    argv = ["stiffness", "--gravity", "--mass", "m_M4=1", "--mass", "m_M5=2", "--json"]
    assert cahyman_main(argv) == 0  # an option that collects


def test_warnings_of_one_place_are_counted_beyond_three(capsys):
    """A nonlinear view warned once per load step (24 lines): the first three of one place
    are printed, the others counted; a repeated message is printed once (Python's rule)."""
    import warnings

    from closedloop.cli.common import one_line_warnings

    with one_line_warnings("prog"):
        for step in range(6):
            warnings.warn(f"step {step} is outside the limits", stacklevel=1)
        for _ in range(2):
            warnings.warn("the same message", stacklevel=1)
    lines = capsys.readouterr().err.splitlines()
    assert lines == [*(f"prog: warning: step {s} is outside the limits" for s in range(3)),
                     "prog: warning: the same message",
                     "prog: warning: 3 more warnings like those above"]  # fmt: skip


@pytest.mark.parametrize("prog", MAINS)
def test_the_reference_parser_builds_every_subcommand_in_full(prog):
    """The command-line reference's parser holds each subcommand with its options, where
    the command's own parser holds the others' help lines only."""
    from cahyman_pin.cli import build_parser as cahyman_parser
    from cahyman_pin.cli import reference_parser as cahyman_reference
    from closedloop.cli.app import build_parser as closedloop_parser
    from closedloop.cli.app import reference_parser as closedloop_reference

    build, reference = {
        "closedloop": (closedloop_parser, closedloop_reference),
        "cahyman": (cahyman_parser, cahyman_reference),
    }[prog]
    full, lazy = subcommands(reference()), subcommands(build(None))
    assert full.keys() == lazy.keys()
    placeholders = [n for n, p in lazy.items() if "-h" not in p._option_string_actions]
    assert "map" in placeholders  # a subcommand of a module of its own: its help line only
    for name, parser in full.items():
        assert "-h" in parser._option_string_actions, name  # built, not a placeholder
    options = {"closedloop": ("stiffness", "--frame"), "cahyman": ("map", "--param")}[prog]
    assert options[1] in full[options[0]]._option_string_actions


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """Name -> parser of each subcommand of ``parser``."""
    (action,) = (a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)
