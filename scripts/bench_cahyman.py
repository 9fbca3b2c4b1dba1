"""Time CaHyMan stiffness queries, sweeps and a 1e5-pose map against computeJointJacobians."""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import numpy as np
import pinocchio as pin

from cahyman_pin.api import stiffness
from cahyman_pin.backend_consistent import consistent_compliance
from cahyman_pin.model import CaHyManModel
from cahyman_pin.sweep import grid, sweep
from cahyman_pin.sweep_exec import default_workers
from cahyman_pin.sweep_indices import stiffness_indices
from cahyman_pin.urdf_builder import FRAME_M
from closedloop.compliance import compliance

#: Table 3's pose [rad, rad, m], where single queries are timed.
POSE = (np.deg2rad([45.0, 60.0, 75.0]), np.deg2rad(45.0), 0.0)
#: Leg-input range of the maps [deg]; the arm is fixed at alpha_4 = 45 deg, s_4 = 25 mm.
RANGE_DEG = (40.0, 80.0)
TARGETS_US = {
    "generic query": 100.0,
    "warm assembly + query": 150.0,
    "closed-form start + query": 150.0,
    "closed form, batch": 5.0,
}
TARGET_MAP_S = 15.0


def median_time(call: Callable[[], object], calls: int, repeats: int) -> float:
    """Median over ``repeats`` batches of the mean time of one call [s]."""
    call()  # warm-up
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(calls):
            call()
        times.append((time.perf_counter() - start) / calls)
    return statistics.median(times)


def leg_grid(n_side: int):
    """n_side x n_side grid of alpha_1, alpha_2 over RANGE_DEG, alpha_3 = 60 deg [SI]."""
    a = np.deg2rad(np.linspace(*RANGE_DEG, n_side))
    return grid(
        {"alpha1": a, "alpha2": a},
        alpha=np.deg2rad([60.0, 60.0, 60.0]),
        alpha4=POSE[1],
        s4=0.025,
    )


def median_sweep(points, repeats: int, **kw) -> tuple[float, object]:
    """Median wall time [s] of ``sweep(points, **kw)`` and the last result."""
    times, result = [], None
    for _ in range(repeats):
        result = sweep(points, **kw)
        times.append(result.seconds)
    return statistics.median(times), result


def iteration_counts(result) -> dict[int, int]:
    """Number of generic assemblies per Gauss-Newton iteration count."""
    counts = np.bincount(result.iterations[result.iterations >= 0])
    return {i: c for i, c in enumerate(counts.tolist()) if c}


def row(name: str, seconds: float, unit: float, per: str = "per pose") -> None:
    target = TARGETS_US.get(name)
    verdict = (
        ""
        if target is None
        else f"target <= {target:g} us: " + ("met" if seconds * 1e6 <= target else "NOT met")
    )
    print(f"{name:34s} {seconds * 1e6:10.1f} us {per:9s} {seconds / unit:8.0f} x unit  {verdict}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true",
                        help="fewer repeats and a 1e4-pose map instead of 1e5")  # fmt: skip
    args = parser.parse_args()
    repeats = 3 if args.quick else 7
    calls = 200 if args.quick else 1000
    workers = default_workers()

    model = CaHyManModel()
    clm = model.clm
    q = model.assemble(*POSE)
    data = clm.model.createData()
    unit = median_time(lambda: pin.computeJointJacobians(clm.model, data, q), 20 * calls, repeats)
    print(f"CaHyMan nq={clm.model.nq} nv={clm.model.nv} closures={len(clm.closures)}; "
          f"medians of {repeats} runs; {workers} cores")  # fmt: skip
    row("unit: computeJointJacobians", unit, unit, "per call")

    query = median_time(lambda: compliance(clm, q, FRAME_M, "world"), calls, repeats)
    row("generic query", query, unit)
    api_call = median_time(lambda: stiffness(*POSE), calls // 4, repeats)
    row("api.stiffness (cold, one call)", api_call, unit)

    points = leg_grid(21 if args.quick else 41)
    n = len(points)
    step = (RANGE_DEG[1] - RANGE_DEG[0]) / (points.shape[0] - 1)
    print(f"{'':34s} sweeps: {n} poses, alpha_1 x alpha_2 in {step:g} deg steps, serial, "
          "indices included")  # fmt: skip
    for name, start in (("warm assembly + query", "neighbour"),
                        ("closed-form start + query", "closed_form")):  # fmt: skip
        seconds, result = median_sweep(
            points, repeats, executor="serial", chunk_size=n, start=start
        )
        row(name, seconds / n, unit)
        print(f"{'':34s} (Gauss-Newton iterations: {iteration_counts(result)})")

    def cold_pass() -> None:
        for i in range(n):
            qi = model.assemble(points.alpha[i], points.alpha4[i], points.s4[i])
            compliance(clm, qi, FRAME_M, "world")

    row("cold assembly + query", median_time(cold_pass, 1, repeats) / n, unit)

    one = median_time(lambda: consistent_compliance(*POSE), calls, repeats)
    row("closed form, one pose", one, unit)
    rng = np.random.default_rng(0)
    batch = 10_000
    alpha = np.deg2rad(rng.uniform(*RANGE_DEG, (batch, 3)))
    alpha4, s4 = np.deg2rad(rng.uniform(0.0, 90.0, batch)), rng.uniform(0.0, 0.05, batch)
    per = median_time(lambda: consistent_compliance(alpha, alpha4, s4), 1, repeats) / batch
    row("closed form, batch", per, unit)
    C = consistent_compliance(alpha, alpha4, s4)
    ok = np.ones(batch, dtype=bool)
    indices = median_time(lambda: stiffness_indices(C, ok, ok, None), 1, repeats) / batch
    row("indices, batch (any backend)", indices, unit)

    side = 100 if args.quick else 316
    big = leg_grid(side)
    for start in ("neighbour", "closed_form"):
        res = sweep(big, start=start, workers=workers, show_progress=True)
        verdict = "met" if res.seconds <= TARGET_MAP_S else "NOT met"
        print(f"{len(big)}-pose generic map, start={start}, {workers} processes: "
              f"{res.seconds:.2f} s wall ({res.seconds / len(big) * 1e6 * workers:.0f} us per "
              f"pose per core; iterations {iteration_counts(res)}; {res.summary()})"
              + ("" if args.quick else f"; target <= {TARGET_MAP_S:g} s: {verdict}"))  # fmt: skip


if __name__ == "__main__":
    main()
