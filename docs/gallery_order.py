"""The order of the gallery's examples, for teaching (sphinx-gallery's
``within_subsection_order``, named in ``conf.py`` as ``gallery_order.TeachingOrder``).

First one loop (the four-bar), then serial arms from their files (UR5, the redundant
Panda), the parallel robots from the most general (Stewart) to the planar ones, a leg
from an SDF file (Cassie), the hybrid showcase (CaHyMan); then what a model can add or
answer: links as beams, a spring at a loop's cut, gravity and payloads, a map over the
workspace, a path under a process load (CaHyMan's compensated drilling, the UR5's stiffest
rotation about its tool axis), springs identified from measurements, dimensions designed for
stiffness; last, two implementations of CaHyMan that agree.
"""

from __future__ import annotations

from pathlib import Path

#: The examples' file names, in the order shown.
ORDER = (
    "plot_fourbar.py",
    "plot_ur5.py",
    "plot_panda.py",
    "plot_stewart.py",
    "plot_delta.py",
    "plot_rrr3.py",
    "plot_fivebar.py",
    "plot_cassie_leg.py",
    "plot_cahyman.py",
    "plot_beams.py",
    "plot_elastic_closure.py",
    "plot_gravity_sag.py",
    "plot_stiffness_map.py",
    "plot_cahyman_drilling.py",
    "plot_ur5_stiffest.py",
    "plot_identification.py",
    "plot_design_cahyman.py",
    "plot_validation_cahyman.py",
)


class TeachingOrder:
    """Sort key of the examples of a gallery folder: their place in :data:`ORDER`.

    Args:
        src_dir: the gallery folder (sphinx-gallery passes it; unused).
    """

    def __init__(self, src_dir) -> None:
        self.src_dir = src_dir

    def __repr__(self) -> str:
        return "<TeachingOrder>"

    def __call__(self, filename) -> int:
        """The place of ``filename`` (a name or a path) in :data:`ORDER`.

        Raises:
            ValueError: an example not in :data:`ORDER` (add it there, where it teaches).
        """
        name = Path(filename).name
        if name not in ORDER:
            raise ValueError(f"gallery example {name!r} is not in docs/gallery_order.py ORDER")
        return ORDER.index(name)
