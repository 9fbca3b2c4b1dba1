"""Benchmark closedloop: the UR5 query (plain and prepared) against its floor, growth of the
query with nv, UR5 with its links as beams, CaHyMan's natural frequencies, paths under a
load, the design optimiser, the start-up of the command line."""

from __future__ import annotations

import sys
from functools import partial

import numpy as np
import pinocchio as pin
from benchtools import (
    START_MODES,
    Mode,
    Table,
    fmt_time,
    growth_exponent,
    interleaved,
    parse_mode,
    wall_ratio,
)

from closedloop.analysis.vibration import batch_modes, modes
from closedloop.common import lapack
from closedloop.elastostatics.batch import compliances
from closedloop.elastostatics.compliance import compliance
from closedloop.elastostatics.query import ComplianceQuery
from closedloop.io.loader import load_urdf, robot_data_dir
from closedloop.model.closed_loop import ClosedLoopModel

#: UR5 pose of the serial query [rad].
UR5_Q = np.array([0.3, -1.2, 1.4, -0.6, 1.1, 0.2])
#: Four-bars in series (nv = 3 per loop) and serial chains (nv = n) of the growth rows.
LOOPS = {"smoke": (4, 8, 16), "quick": (4, 16, 33, 66, 133),
         "full": (4, 8, 16, 25, 33, 50, 66, 100, 133)}  # fmt: skip
JOINTS = {"smoke": (10, 25, 50), "quick": (10, 50, 100, 200, 400),
          "full": (10, 25, 50, 75, 100, 150, 200, 300, 400)}  # fmt: skip
CRANK, GROUND, SPRING = 0.3, 0.2, 1e3  # [m], [m], [N m/rad]
#: The UR5's links as aluminium tubes (d 60 mm, wall 4 mm): link -> the joint its beam ends at.
UR5_BEAMS = {"shoulder_link": "shoulder_lift_joint", "upper_arm_link": "elbow_joint",
             "forearm_link": "wrist_1_joint", "wrist_1_link": "wrist_2_joint",
             "wrist_2_link": "wrist_3_joint", "wrist_3_link": "ee_fixed_joint"}  # fmt: skip
TUBE = {"E": 7.0e10, "G": 2.6e10, "section": {"shape": "tube", "d": 0.06, "t": 0.004}}


def _placement(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> pin.SE3:
    return pin.SE3(np.eye(3), np.array([x, y, z]))


def fourbar_chain(n: int) -> tuple[ClosedLoopModel, np.ndarray, str]:
    """n planar parallelogram four-bars in series, each standing on the previous rocker.

    Loop i: crank at A = (0, 0), rocker at D = (GROUND, 0) of its base body (the world,
    then the previous rocker), coupler on the crank tip; a point closure joins the coupler
    tip to the rocker tip. Springs on the cranks; coupler and rocker passive. At crank
    angle t (coupler -t, rocker t) every loop closes exactly.
    """
    model, closures, q = pin.Model(), [], []
    base = 0
    for i in range(n):
        t = 0.8 if i % 2 == 0 else -0.8
        crank = model.addJoint(base, pin.JointModelRZ(), _placement(), f"crank{i}")
        coupler = model.addJoint(crank, pin.JointModelRZ(), _placement(CRANK), f"coupler{i}")
        rocker = model.addJoint(base, pin.JointModelRZ(), _placement(GROUND), f"rocker{i}")
        closures.append(pin.PointAnchorConstraintModel(
            model, coupler, _placement(GROUND), rocker, _placement(CRANK)))  # fmt: skip
        q += [t, -t, t]
        base = rocker
    model.addFrame(pin.Frame("tip", base, _placement(CRANK), pin.FrameType.OP_FRAME))
    cranks = [f"crank{i}" for i in range(n)]
    clm = ClosedLoopModel(model, closures, cranks, {c: SPRING for c in cranks}, name=f"4bar{n}")
    return clm, np.array(q), "tip"


def serial_chain(n: int) -> tuple[ClosedLoopModel, np.ndarray, str]:
    """n revolute joints (axes z, y, x in turn, 0.1 m apart), a spring on each."""
    model = pin.Model()
    joints = (pin.JointModelRZ, pin.JointModelRY, pin.JointModelRX)
    parent = 0
    for i in range(n):
        parent = model.addJoint(parent, joints[i % 3](), _placement(0.1 if i else 0.0), f"j{i}")
    model.addFrame(pin.Frame("tip", parent, _placement(0.1), pin.FrameType.OP_FRAME))
    q = 0.3 * np.sin(np.arange(n) + 1.0)
    springs = {f"j{i}": SPRING for i in range(n)}
    return ClosedLoopModel(model, springs=springs, name=f"serial{n}"), q, "tip"


def unit_of(clm: ClosedLoopModel, q: np.ndarray):
    """One computeJointJacobians call on the model (the unit), on a Data of the model's
    pool: the unit and the query never run at once, and a Data of a 400-joint chain
    costs seconds to create."""
    workspace = clm.acquire_workspace()
    clm.release_workspace(workspace)
    return partial(pin.computeJointJacobians, clm.model, workspace[0], q)


def ur5_floor(model, data, q, fid, root_compliance):
    """The least a serial query with the rank rule computes: Pinocchio's frame Jacobian J,
    B = J K^-1/2, C = B B^T and the SVD of B (LAPACK, no check, no scaling, no result)."""
    J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
    B = J * root_compliance
    return B @ B.T, lapack.dgesdd(B)


def bench_ur5(table: Table, mode: Mode) -> None:
    path = robot_data_dir() / "ur_description/urdf/ur5_robot.urdf"
    ur5 = load_urdf(path, joint_stiffness=1e4, geometry=False)
    unit = unit_of(ur5, UR5_Q)
    floor = partial(ur5_floor, ur5.model, ur5.model.createData(), UR5_Q,
                    ur5.model.getFrameId("tool0"), 1.0 / np.sqrt(ur5.stiffness))  # fmt: skip
    t_floor = interleaved(floor, unit, mode)
    table.units("2f", "UR5 floor: its numbers written out without any check (scripts/"
                "bench_closedloop.py ur5_floor: the frame Jacobian, C = J K^-1 J^T, the SVD of "
                "the rank rule)", "-", t_floor)  # fmt: skip
    query = ComplianceQuery(ur5, "tool0")
    rows = (
        ("2", "plain `compliance(model, q, 'tool0')`", "<= 3x floor",
         lambda: compliance(ur5, UR5_Q, "tool0")),
        ("2p", "prepared `ComplianceQuery(model, 'tool0')(q)`", "<= 1.5x floor",
         lambda: query(UR5_Q)),
    )  # fmt: skip
    for key, what, target, func in rows:
        t = interleaved(func, floor, mode)  # against the floor itself, batch by batch
        table.against_floor(key, f"UR5 (serial) query, {what} -> {func().path}", target,
                            t_floor, t)  # fmt: skip
    t = interleaved(lambda: compliance(ur5, UR5_Q, "tool0", path="null-space"), unit, mode)
    table.units("2b", "UR5 (serial) query, `compliance(..., path='null-space')` -> null-space",
                "-", t)  # fmt: skip
    Q = np.random.default_rng(0).uniform(-2.5, 2.5, (100, 6))
    t = interleaved(lambda: compliances(ur5, Q, "tool0"), unit, mode, per=len(Q))
    table.units("2c", f"UR5 `closedloop.compliances`, {len(Q)} poses at once (C, G, rank)", "-",
                t, " per pose")  # fmt: skip


def bench_ur5_beams(table: Table, mode: Mode) -> None:
    path = robot_data_dir() / "ur_description/urdf/ur5_robot.urdf"
    ur5 = load_urdf(path, joint_stiffness=1e4, geometry=False)
    beams = ur5.with_beams({link: {**TUBE, "end": end} for link, end in UR5_BEAMS.items()})
    q = pin.neutral(beams.model)  # the beams' virtual joints at rest, the arm at UR5_Q
    for j, value in zip(range(1, ur5.model.njoints), UR5_Q, strict=True):
        q[beams.model.joints[beams.model.getJointId(ur5.model.names[j])].idx_q] = value
    t = interleaved(lambda: compliance(beams, q, "tool0"), unit_of(beams, q), mode)
    taken = compliance(beams, q, "tool0").path
    table.units("8", f"UR5 with its 6 links as beams (nv = {beams.model.nv}), `compliance` -> "
                f"{taken}", "<= 100 units", t)  # fmt: skip


def bench_growth(table: Table, mode: Mode) -> None:
    families = (
        ("6a", "6c", "chains of four-bars", fourbar_chain, LOOPS[mode.name]),
        ("6b", "6d", "serial chains", serial_chain, JOINTS[mode.name]),
    )
    for key_auto, key_ns, label, build, sizes in families:
        models = [build(n) for n in sizes]
        nv = [clm.model.nv for clm, _, _ in models]
        for key, p in ((key_auto, "auto"), (key_ns, "null-space")):
            seconds, details = [], []
            for clm, q, frame in models:
                t = interleaved(lambda c=clm, q=q, f=frame, p=p: compliance(c, q, f, path=p),
                                unit_of(clm, q), mode)  # fmt: skip
                seconds.append(t.seconds)
                taken = compliance(clm, q, frame, path=p).path
                details.append(f"nv={clm.model.nv}: {fmt_time(t.seconds)} = {t.ratio:.0f} "
                               f"units ({taken})")  # fmt: skip
            exponent = growth_exponent(nv, seconds)
            upper = sorted(nv)[len(nv) // 2 :]
            table.row(
                key,
                f"growth of the query with nv, {label}, path={p!r} (fit on nv {upper[0]}-"
                f"{upper[-1]})",
                "<= 1.2 up to nv = 400" if p == "auto" else "-",
                f"exponent {exponent:.2f}",
                f"nv {nv[0]}: {fmt_time(seconds[0])}, nv {nv[-1]}: {fmt_time(seconds[-1])}",
            )
            table.note(f"{key} ({label}, {p}): " + "; ".join(details))


#: CaHyMan's masses for its modes [kg] (its defaults are 0): plate, arm, motor, leg links.
CAHYMAN_MASSES = {"m_HQ": 2.0, "m_QM": 1.0, "m_MM2": 0.5, "m_M4": 1.5, "m_M5": 0.5,
                  "m_b": 0.3, "m_c": 0.2, "m_d": 0.3, "m_h": 0.1}  # fmt: skip


def bench_modes(table: Table, mode: Mode) -> None:
    from cahyman_pin.model import cahyman_model
    from cahyman_pin.params import DEFAULT_PARAMS

    machine = cahyman_model(DEFAULT_PARAMS.replace(**CAHYMAN_MASSES))
    clm = machine.clm
    q = machine.assemble(np.deg2rad([45.0, 60.0, 75.0]), np.deg2rad(45.0), 0.01)
    query = partial(compliance, clm, q, "M")  # the unit: one compliance query, this run
    t = interleaved(lambda: modes(clm, q, n=10, frame="M"), query, mode)
    table.row("9", "CaHyMan, lowest 10 modes at one pose (`modes(..., n=10, frame='M')`), in "
              "units of one compliance query at M", "<= 3 queries",
              f"{t.ratio:.2f} queries",
              f"{fmt_time(t.seconds)}; query {fmt_time(t.unit)}")  # fmt: skip
    rng = np.random.default_rng(0)
    poses = [machine.assemble(np.deg2rad(rng.uniform(50.0, 80.0, 3)),
                              np.deg2rad(rng.uniform(30.0, 60.0)), rng.uniform(0.0, 0.04))
             for _ in range(20)]  # fmt: skip
    Q = np.array(poses)
    t = interleaved(lambda: batch_modes(clm, Q, n=10), query, mode, per=len(Q))
    table.row("9b", f"CaHyMan, lowest 10 modes, `batch_modes` over {len(Q)} poses, per pose",
              "-", f"{t.ratio:.2f} queries", f"{fmt_time(t.seconds)} per pose")  # fmt: skip


#: Designs evaluated by row 14 (the optimiser on the four-bar with tube links).
DESIGN_BUDGET = {"smoke": 8, "quick": 40, "full": 150}


def bench_design(table: Table, mode: Mode) -> None:
    """Rows 14, 14b: ``optimize_design`` of the bundled fourbar_design.yaml (the four-bar with
    its three bars as tubes, 25 workspace points, two diameters) on two processes: designs
    evaluated per second, and the optimiser's own time against the evaluations'."""
    from closedloop.analysis.design_optimizer import optimize_design
    from closedloop.io.data import path

    problem = path("fourbar_design.yaml")
    optimize_design(problem, seed=0, budget=2)  # imports and caches, before the clock
    result = optimize_design(problem, workers=2, seed=0, budget=DESIGN_BUDGET[mode.name])
    t, n = result.timing, len(result.evaluations)
    share = t["kernels"] / (2 * t["evaluations"])  # of the two processes' time, evaluating
    table.row("14", "four-bar with 3 tube links over 25 workspace points, `optimize_design` "
              "on 2 processes: designs evaluated per second", "-", f"{n / t['total']:.3g} "
              f"designs/s", f"{n} designs in {fmt_time(t['total'])}; one design "
              f"{fmt_time(t['kernels'] / n)} in its process; processes busy {share:.0%} "
              "of the evaluations' time")  # fmt: skip
    table.row("14b", "the design optimiser's own time (differential evolution, SLSQP, "
              "bookkeeping), share of the evaluations' time", "< 10 %",
              f"{100 * t['optimizer'] / t['evaluations']:.2g} %",
              f"{fmt_time(t['optimizer'])} of {fmt_time(t['total'])}")  # fmt: skip


def bench_paths(table: Table, mode: Mode) -> None:
    """Issue 42: a path point's exact compensation warm-started from the last point, in
    units of one compliance query at the point (UR5, CaHyMan); a long UR5 path on two
    processes."""
    import time

    from cahyman_pin.model import cahyman_model
    from cahyman_pin.params import DEFAULT_PARAMS
    from closedloop.analysis.model_source import ModelSource
    from closedloop.analysis.path_points import placement
    from closedloop.analysis.paths import follow_path
    from closedloop.elastostatics.compensation import compensate, extrapolated
    from closedloop.kinematics.frame_task import FrameTask, xyzquat
    from closedloop.model.gravity import Load

    path = robot_data_dir() / "ur_description/urdf/ur5_robot.urdf"
    ur5 = load_urdf(path, joint_stiffness=1e4, geometry=False)
    machine = cahyman_model(DEFAULT_PARAMS)
    q_cahyman = machine.assemble(np.deg2rad([60.0, 60.0, 60.0]), np.deg2rad(45.0), 0.025)
    cases = (("11", "UR5, pose task, tool0", ur5, UR5_Q, "tool0", "pose"),
             ("11b", "CaHyMan, tool-axis task, tool", machine.clm, q_cahyman, "tool",
              "tool-axis"))  # fmt: skip
    for key, label, clm, q, frame, task in cases:
        M = placement(clm, q, frame)
        targets = [xyzquat(pin.SE3(M.rotation, M.translation + np.array([0.0, 1e-3 * k, 0.0])))
                   for k in range(3)]  # fmt: skip
        w = np.r_[-50.0 * M.rotation[:, 2], 0.0, 0.0, 0.0]
        r = follow_path(clm, frame, targets, wrench=w, task=task, q0=q)
        q2 = np.array(r.q_target[2])
        held = FrameTask(r.held, placement(clm, q2, frame))
        guess = extrapolated(clm, q2, [(r.q_target[k], r.q_compensated[k]) for k in range(2)])
        t = interleaved(lambda c=clm, f=frame, h=held, q2=q2, g=guess, w=w:
                        compensate(c, f, h, q2, Load(w), g),
                        partial(compliance, clm, q2, frame), mode)  # fmt: skip
        table.row(key, f"{label}: a path point's exact compensation warm-started from the "
                  "last two points (`compensate`), in units of one compliance query there",
                  "<= ~5 queries", f"{t.ratio:.2f} queries",
                  f"{fmt_time(t.seconds)}; query {fmt_time(t.unit)}")  # fmt: skip
    n = 40 if mode.smoke else 1000
    angles = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    M = placement(ur5, UR5_Q, "tool0")
    targets = [xyzquat(pin.SE3(M.rotation, M.translation + 0.05 * np.array([np.cos(a) - 1,
                                                                             np.sin(a), 0.0])))
               for a in angles]  # fmt: skip
    source = ModelSource(str(path), None, (), 1e4)
    start = time.perf_counter()
    follow_path(source, "tool0", targets, wrench=[0.0, 0.0, -50.0, 0.0, 0.0, 0.0], q0=UR5_Q,
                workers=2, chunk=-(-n // 2))  # fmt: skip
    wall = time.perf_counter() - start
    table.row("11c", f"UR5, a {n}-point circle under 50 N on 2 processes (`follow_path(..., "
              "workers=2)`: inverse kinematics, loaded equilibrium, exact and first-order "
              "compensation)", "well under 10 s for 1000 points", f"{wall:.3g} s",
              f"{fmt_time(wall / n)} a point")  # fmt: skip


#: The command lines timed against ``python -c "import pinocchio"``: id, command, target.
COMMANDS = (
    ("10a", ["stiffness", "ur5", "--frame", "tool0", "--q", "0", "-1.0", "1.5", "-0.5", "1.2",
             "0.3", "--joint-stiffness", "1e4"], "<= 1.5x"),
    ("10b", ["info", "ur5"], "-"),
)  # fmt: skip


def bench_cli(table: Table, mode: Mode) -> None:
    """The start-up of ``closedloop`` commands (``python -m closedloop``) against
    ``python -c "import pinocchio"``, their bytecode cached and compiled from source."""
    reference = [sys.executable, "-c", "import pinocchio"]
    for key, words, target in COMMANDS:
        for start, suffix in zip(START_MODES, ("", "s"), strict=True):
            t = wall_ratio([sys.executable, "-m", "closedloop", *words], reference, mode, start)
            name = f"`closedloop {' '.join(words)}` wall vs `python -c 'import pinocchio'`"
            table.command(f"{key}{suffix}", name, target, t, start)


def main() -> None:
    mode = parse_mode(__doc__)
    table = Table("closedloop benchmarks", mode)
    bench_ur5(table, mode)
    bench_ur5_beams(table, mode)
    bench_growth(table, mode)
    bench_modes(table, mode)
    bench_design(table, mode)
    bench_paths(table, mode)
    bench_cli(table, mode)
    table.close()


if __name__ == "__main__":
    main()
