"""CaHyMan over many poses and designs, on the project's one sweep engine
(:mod:`closedloop.analysis.maps`): points (:mod:`.points`), the kernel of a chunk for each backend
(:mod:`.execution`), and the driver with its result and files (:mod:`.engine`)."""

from cahyman_pin.sweep.engine import INDEX_UNITS, SweepResult, sweep
from cahyman_pin.sweep.points import grid, pose_list

__all__ = ["INDEX_UNITS", "SweepResult", "grid", "pose_list", "sweep"]
