"""The README's examples, run as a newcomer would: from an empty folder, as written.

Every ```python block runs (exit 0). Every command of the ```bash blocks runs in one empty
folder, in order (one shell per block, so that a variable set by a line is seen by the
next), and exits with status 0, or with the status ``N`` its trailing comment announces as
``# exit N`` (the README documents the status there). The commands that
install software are not run here: they are listed, with the reason, in
:data:`NOT_RUN_HERE`; a listed command that the README no longer has fails the test, so
that the list cannot hide a command.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import REPO

README = REPO / "README.md"
#: Commands of the README not run by this test, and why (they are the CI's: .ci/run).
NOT_RUN_HERE = {
    "python3 -m venv .venv && . .venv/bin/activate && pip install . && cahyman report": (
        "creates a virtual environment and installs from the network (minutes); "
        ".ci/run does it, and `cahyman report` runs below"
    ),
    'python3 -m venv .venv && . .venv/bin/activate && pip install ".[test]" && '
    "python -m pytest -q": (
        "creates a virtual environment, installs from the network and runs this suite; "
        ".ci/run does it"
    ),
}
EXIT_COMMENT = re.compile(r"#\s*exit\s+(\d+)\b")


def blocks(language: str) -> list[str]:
    """The README's fenced blocks of ``language``, in order."""
    text = README.read_text()
    return [b.split("```", 1)[0] for b in text.split(f"```{language}\n")[1:]]


def commands(block: str) -> list[tuple[str, int]]:
    """(command, expected exit status) of a bash block: continuation lines joined, comment
    lines skipped, a trailing ``# exit N`` read and removed."""
    out, current = [], ""
    for line in block.splitlines():
        if not current and (not line.strip() or line.lstrip().startswith("#")):
            continue
        if line.rstrip().endswith("\\"):
            current += line.rstrip()[:-1].rstrip() + " "
            continue
        current += line.strip()
        match = EXIT_COMMENT.search(current)
        status = int(match.group(1)) if match else 0
        out.append((re.sub(r"\s+#.*$", "", current).strip(), status))
        current = ""
    return out


def bash_commands() -> list[tuple[str, int]]:
    return [c for block in blocks("bash") for c in commands(block)]


def run_block(block: list[tuple[str, int]], folder: Path) -> tuple[list[int], str]:
    """Run the commands of one block in one shell in ``folder``: (their exit statuses in
    order, the shell's stderr)."""
    statuses = folder / ".statuses"
    statuses.write_text("")
    lines = [f'{command}\necho "$?" >> "{statuses}"' for command, _ in block]
    done = subprocess.run(["bash", "-c", "\n".join(lines)], cwd=folder, env=newcomer_env(),
                          capture_output=True, text=True, timeout=600, check=False)  # fmt: skip
    return [int(v) for v in statuses.read_text().split()], done.stderr


def newcomer_env() -> dict[str, str]:
    """The environment of an installed package: its scripts on PATH, no PYTHONPATH."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    return env


def test_commands_are_found_and_the_not_run_list_is_current():
    found = [c for c, _ in bash_commands()]
    assert len(found) >= 8 and any(c.startswith("closedloop stiffness") for c in found)
    missing = sorted(set(NOT_RUN_HERE) - set(found))
    assert not missing, f"NOT_RUN_HERE lists commands the README no longer has: {missing}"
    assert not any(c.endswith("\\") for c in found)  # continuation lines were joined


def test_bash_commands_run_from_an_empty_folder(tmp_path):
    ran = 0
    for text in blocks("bash"):
        block = [(c, s) for c, s in commands(text) if c not in NOT_RUN_HERE]
        if not block:
            continue
        statuses, stderr = run_block(block, tmp_path)
        for (command, expected), status in zip(block, statuses, strict=False):
            assert status == expected, (command, status, stderr[-2000:])
        assert len(statuses) == len(block), stderr[-2000:]
        assert "Traceback" not in stderr, stderr[-2000:]
        ran += len(block)
    assert ran >= 6


@pytest.mark.parametrize("index", range(len(blocks("python"))))
def test_python_blocks_run_from_an_empty_folder(tmp_path, index):
    block = blocks("python")[index]
    done = subprocess.run(
        [sys.executable, "-c", block],
        cwd=tmp_path,
        env=newcomer_env(),
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-2000:]


def test_python_blocks_exist():
    assert len(blocks("python")) >= 2
