"""Regenerate urdf/cahyman.urdf and urdf/cahyman.yaml from the default CaHyMan parameters."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cahyman_pin.params import DEFAULT_PARAMS
from cahyman_pin.urdf_builder import build_closure_yaml, build_urdf

URDF_DIR = Path(__file__).resolve().parent.parent / "urdf"


def generated_files() -> dict[Path, str]:
    """Path -> text of every generated model file (default parameters)."""
    return {
        URDF_DIR / "cahyman.urdf": build_urdf(DEFAULT_PARAMS),
        URDF_DIR / "cahyman.yaml": build_closure_yaml(DEFAULT_PARAMS),
    }


def main(argv: list[str] | None = None) -> int:
    """Write the files, or with --check only report whether they are up to date."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--check", action="store_true", help="exit 1 if a file is stale")
    args = parser.parse_args(argv)
    stale = []
    for path, text in generated_files().items():
        if path.is_file() and path.read_text() == text:
            continue
        stale.append(path)
        if not args.check:
            path.write_text(text)
            print(f"wrote {path}")
    if args.check and stale:
        print("stale: " + ", ".join(str(p) for p in stale), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
