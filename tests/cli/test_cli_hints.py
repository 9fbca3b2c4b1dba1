"""What the command lines offer for a likely slip: "degrees?" for actuated values beyond
2 pi, the close model name, the commands of a bare ``closedloop`` or ``cahyman``."""

from __future__ import annotations

import pytest
from helpers import one_error_line as one_line

from cahyman_pin.cli import SUBCOMMAND_MODULES as CAHYMAN_MODULES
from cahyman_pin.cli import main as cahyman_main
from closedloop.cli.app import SUBCOMMAND_MODULES
from closedloop.cli.app import main as closedloop_main
from closedloop.exceptions import EXIT_BAD_INPUT

MAINS = {"closedloop": closedloop_main, "cahyman": cahyman_main}


def run(capsys, prog: str, *argv) -> tuple[int, str, str]:
    code = MAINS[prog]([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize(
    ("argv", "joint"),
    [
        (["fourbar", "--frame", "P", "--actuated", "60"], "crank"),
        (["ur5", "--frame", "tool0", "--joint-stiffness", "1e4", "--actuated", "60", "0", "0",
          "0", "0", "0"], "shoulder_pan_joint"),
    ],
)  # fmt: skip
def test_actuated_values_in_degrees_get_the_degrees_hint(capsys, argv, joint):
    """--q 60 asked "degrees?"; --actuated 60 said only "outside their limits"."""
    code, _, err = run(capsys, "closedloop", "stiffness", *argv)
    line = one_line(err)
    assert code == EXIT_BAD_INPUT
    assert f"{joint} = 60 (limits" in line and f"; {joint} beyond 2 pi: degrees?" in line, line


def test_a_mistyped_model_name_is_offered_the_close_one(capsys):
    code, _, err = run(capsys, "closedloop", "stiffness", "ur55", "--frame", "tool0")
    assert code == EXIT_BAD_INPUT
    assert "(did you mean 'ur5'?)" in one_line(err)


@pytest.mark.parametrize("prog", MAINS)
def test_a_bare_command_lists_its_commands(capsys, prog):
    """``closedloop`` alone said only "the following arguments are required: COMMAND";
    it is still a usage error (exit 2, as argparse's), with the commands listed."""
    code, out, err = run(capsys, prog)
    assert (code, out) == (EXIT_BAD_INPUT, "")
    modules = SUBCOMMAND_MODULES if prog == "closedloop" else CAHYMAN_MODULES
    for name, (_, help_line) in modules.items():
        assert name in err and " ".join(help_line.split()[:3]) in " ".join(err.split()), name
    assert "stiffness" in err
    assert err.splitlines()[-1].startswith(f"{prog}: error: give a COMMAND"), err
