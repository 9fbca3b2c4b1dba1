"""CaHyMan over many poses and designs: points (:mod:`.points`), chunked execution on any
``concurrent.futures`` executor (:mod:`.execution`), the indices and status per point
(:mod:`.indices`), and the driver with its result and files (:mod:`.engine`)."""

from cahyman_pin.sweep.engine import INDEX_UNITS, SweepResult, sweep
from cahyman_pin.sweep.points import grid, pose_list

__all__ = ["INDEX_UNITS", "SweepResult", "grid", "pose_list", "sweep"]
