"""Write the gallery into urdf/: each machine as a URDF tree + closure file and as an MJCF
file written the MuJoCo way (every leg, and a free-jointed platform, directly under
<worldbody>): stewart, delta (geometry in gallery_spatial.py), fivebar5, rrr3
(gallery_planar.py), each as .urdf + .yaml and .xml.

    python scripts/generate_gallery.py          # (re)write the files
    python scripts/generate_gallery.py --check  # exit 1 if a file is stale
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from gallery_planar import fivebar_mjcf, fivebar_urdf, rrr3_mjcf, rrr3_urdf
from gallery_spatial import delta_mjcf, delta_urdf, stewart_mjcf, stewart_urdf

URDF_DIR = Path(__file__).resolve().parent.parent / "urdf"


def generated_files() -> dict[Path, str]:
    """Path -> text of every gallery file."""
    urdf, closures = stewart_urdf()
    fivebar, rrr3, delta = fivebar_urdf(), rrr3_urdf(), delta_urdf()
    return {
        URDF_DIR / "stewart.urdf": urdf,
        URDF_DIR / "stewart.yaml": closures,
        URDF_DIR / "stewart.xml": stewart_mjcf(),
        URDF_DIR / "fivebar5.urdf": fivebar[0],
        URDF_DIR / "fivebar5.yaml": fivebar[1],
        URDF_DIR / "fivebar5.xml": fivebar_mjcf(),
        URDF_DIR / "rrr3.urdf": rrr3[0],
        URDF_DIR / "rrr3.yaml": rrr3[1],
        URDF_DIR / "rrr3.xml": rrr3_mjcf(),
        URDF_DIR / "delta.urdf": delta[0],
        URDF_DIR / "delta.yaml": delta[1],
        URDF_DIR / "delta.xml": delta_mjcf(),
    }


def main(argv: list[str] | None = None) -> int:
    """Write the files, or with --check only report whether they are up to date."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if a file is stale")
    args = parser.parse_args(argv)
    stale = [path for path, text in generated_files().items() if not _current(path, text)]
    if args.check:
        if stale:
            print("stale: " + ", ".join(str(p) for p in stale), file=sys.stderr)
        return 1 if stale else 0
    for path in stale:
        path.write_text(generated_files()[path])
        print(f"wrote {path}")
    return 0


def _current(path: Path, text: str) -> bool:
    return path.is_file() and path.read_text() == text


if __name__ == "__main__":
    sys.exit(main())
