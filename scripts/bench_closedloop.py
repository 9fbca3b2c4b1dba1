"""Time a stiffness query (compliance, K) on the UR5 and four-bar against computeJointJacobians."""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pinocchio as pin

from closedloop.assembly import assemble
from closedloop.compliance import compliance
from closedloop.io import load_urdf, robot_data_dir

ROOT = Path(__file__).resolve().parent.parent
BATCHES = 7


def median_time(call: Callable[[], object], calls: int) -> float:
    """Median over BATCHES batches of the mean time of one call [s]."""
    call()  # warm-up
    times = []
    for _ in range(BATCHES):
        start = time.perf_counter()
        for _ in range(calls):
            call()
        times.append((time.perf_counter() - start) / calls)
    return statistics.median(times)


def stiffness_query(clm, q, frame):
    """compliance(), then K; a rank-deficient C (the planar four-bar: rank 3) has no K."""
    result = compliance(clm, q, frame)
    return result.K if result.is_full_rank else result.C


def bench(name, clm, q, frame, calls):
    data = clm.model.createData()
    query = median_time(lambda: stiffness_query(clm, q, frame), calls)
    jacobians = median_time(lambda: pin.computeJointJacobians(clm.model, data, q), 20 * calls)
    print(
        f"{name:9s} nv={clm.model.nv}  closures={len(clm.closures)}  "
        f"query {query * 1e6:8.1f} us  computeJointJacobians {jacobians * 1e6:6.2f} us  "
        f"ratio {query / jacobians:6.0f}"
    )


def main() -> None:
    ur5_path = robot_data_dir() / "ur_description/urdf/ur5_robot.urdf"
    names = list(pin.buildModelFromUrdf(str(ur5_path)).names)[1:]
    ur5 = load_urdf(ur5_path, springs={n: 1e4 for n in names})
    fourbar = load_urdf(ROOT / "urdf/fourbar.urdf", ROOT / "urdf/fourbar.yaml")
    print(f"median of {BATCHES} batches; query = compliance(...) then .K (four-bar: rank 3, no K)")
    bench("UR5", ur5, np.array([0.3, -1.2, 1.4, -0.6, 1.1, 0.2]), "tool0", 2000)
    bench("four-bar", fourbar, assemble(fourbar, [0.4]).q, "P", 2000)


if __name__ == "__main__":
    main()
