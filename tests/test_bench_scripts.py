"""The benchmark scripts run (``--smoke``: one iteration of each row) and print every row."""

from __future__ import annotations

import math
import re
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPTS = Path(__file__).resolve().parent.parent / "scripts"
#: Row ids each script prints (b, c... are the variants; s: a command line started from
#: source).
ROWS = {
    "bench_closedloop.py": ["2", "2b", "2c", "2f", "2p", "6a", "6b", "6c", "6d", "8", "9", "9b",
                            "10a", "10as", "10b", "10bs", "11", "11b", "11c", "14", "14b"],
    "bench_cahyman.py": ["1a", "1b", "1c", "1d", "1e", "1f", "1g", "1h", "3a", "3b", "3c", "4",
                         "5", "7", "7s"],
}  # fmt: skip
NUMBER = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?|nan|inf", re.IGNORECASE)


def table_rows(text: str) -> dict[str, list[str]]:
    """id -> cells of the Markdown table rows (header and rule left out)."""
    rows = {}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("| ") and len(cells) == 5 and cells[0] not in ("id", "---"):
            rows[cells[0]] = cells
    return rows


@pytest.mark.parametrize("script", sorted(ROWS))
def test_smoke_run_prints_every_row(script):
    run = subprocess.run(
        [sys.executable, str(SCRIPTS / script), "--smoke"],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert run.returncode == 0, run.stderr
    assert "load average at start" in run.stdout and "load average at end" in run.stdout
    assert re.search(r"python \S+, pin \S+, numpy \S+", run.stdout)
    rows = table_rows(run.stdout)
    assert sorted(rows) == sorted(ROWS[script]), run.stdout
    for key, (_, name, target, measured, absolute) in rows.items():
        value = NUMBER.search(measured)
        assert value is not None, (key, measured)
        assert math.isfinite(float(value.group(0))), (key, measured)
        assert name and target and absolute, key
