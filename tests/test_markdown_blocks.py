"""The code of the README and of the documentation's Markdown pages, run as a newcomer would.

Every ```python block runs (exit 0) from an empty folder. Every command of the ```bash
blocks runs in one empty folder per document, in order (one shell per block, so that a
variable set by a line is seen by the next), and exits with status 0, or with the status
``N`` its trailing comment announces as ``# exit N`` (the page documents the status there).
Every ```yaml block parses. The commands that install software, take minutes or need a
Dask cluster are not run here: they are listed, with the reason, in :data:`NOT_RUN_HERE`;
a listed command that no document has any more fails the test, so that the list cannot
hide a command. The gallery's scripts (``examples/``) run when the documentation is built.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from helpers import REPO

#: The documents whose blocks run: the README and every Markdown page of the docs.
DOCUMENTS = [REPO / "README.md", *sorted((REPO / "docs").glob("**/*.md"))]
DOCUMENTS = [d for d in DOCUMENTS if "_build" not in d.parts]
#: Commands not run by this test, and why (they are the CI's: .ci/run).
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
    "python3 -m venv .venv && . .venv/bin/activate && pip install .": (
        "creates a virtual environment and installs from the network; .ci/run installs"
    ),
    'pip install ".[docs]" && python -m sphinx -n -W --keep-going -b html docs docs/_build/html': (
        "installs from the network and builds the site (minutes); .ci/run builds it"
    ),
    "cahyman report --out my-report": (
        "the default report (seconds of fits and figures), given in the CaHyMan guide and the "
        "task index; tests/cahyman/test_report.py builds it and reads every section, and the "
        "guide's `cahyman report --params ...` runs here"
    ),
    "python scripts/bench_closedloop.py": (
        "takes minutes and needs the repository's scripts/; tests/test_bench_scripts.py "
        "runs its --smoke mode"
    ),
    "closedloop map fivebar5 --frame E --sweep leg0=-0.5:0.5:101 --sweep leg1=-0.5:0.5:101 "
    "--scheduler tcp://HOST:8786 --out fivebar-map": (
        "needs a Dask cluster at HOST; the task index's Python block runs a map on a local "
        "cluster, and tests/cli/test_cli_map.py runs --scheduler against one"
    ),
}
EXIT_COMMENT = re.compile(r"#\s*exit\s+(\d+)\b")


def name(document: Path) -> str:
    return str(document.relative_to(REPO))


def blocks(document: Path, language: str) -> list[str]:
    """The document's fenced blocks of ``language``, in order."""
    text = document.read_text()
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


def bash_commands(document: Path) -> list[tuple[str, int]]:
    return [c for block in blocks(document, "bash") for c in commands(block)]


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
    found = [c for d in DOCUMENTS for c, _ in bash_commands(d)]
    assert len(found) >= 20 and any(c.startswith("closedloop stiffness") for c in found)
    missing = sorted(set(NOT_RUN_HERE) - set(found))
    assert not missing, f"NOT_RUN_HERE lists commands no document has any more: {missing}"
    assert not any(c.endswith("\\") for c in found)  # continuation lines were joined


def test_the_readme_keeps_its_two_commands_and_fits_on_a_few_screens():
    readme = REPO / "README.md"
    found = [c for c, _ in bash_commands(readme)]
    assert set(list(NOT_RUN_HERE)[:2]) <= set(found)  # the two commands, exactly
    assert len(readme.read_text().splitlines()) <= 250


@pytest.mark.parametrize("document", DOCUMENTS, ids=name)
def test_bash_commands_run_from_an_empty_folder(tmp_path, document):
    for text in blocks(document, "bash"):
        block = [(c, s) for c, s in commands(text) if c not in NOT_RUN_HERE]
        if not block:
            continue
        statuses, stderr = run_block(block, tmp_path)
        for (command, expected), status in zip(block, statuses, strict=False):
            assert status == expected, (command, status, stderr[-2000:])
        assert len(statuses) == len(block), stderr[-2000:]
        assert "Traceback" not in stderr, stderr[-2000:]


PYTHON_BLOCKS = [(d, i) for d in DOCUMENTS for i in range(len(blocks(d, "python")))]


@pytest.mark.parametrize(
    ("document", "index"), PYTHON_BLOCKS, ids=[f"{name(d)}-{i}" for d, i in PYTHON_BLOCKS]
)
def test_python_blocks_run_from_an_empty_folder(tmp_path, document, index):
    block = blocks(document, "python")[index]
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


@pytest.mark.parametrize("document", DOCUMENTS, ids=name)
def test_yaml_blocks_parse(document):
    for text in blocks(document, "yaml"):
        assert isinstance(yaml.safe_load(text), dict), text


def test_python_blocks_exist():
    assert len(PYTHON_BLOCKS) >= 15
