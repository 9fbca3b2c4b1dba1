"""Generate the CaHyMan URDF tree and its closure file from a :class:`~cahyman_pin.CaHyManParams`.

Tree (every pose in metres and radians, world frame at the centre of the fixed plate's
top face, z up, x towards leg 1):

* ``fixed_plate`` is the root link (fixed to the world).
* Leg k = 1, 2, 3, in a leg frame rotated by delta_k about z (axes u_k, t_k, z):

  - ``alpha_k`` (revolute, actuated, spring K_T) at B0_k = O_k - (a/2) t_k, axis u_k; at
    zero the input crank ``crank_b_k`` points along t_k, a positive angle turns it
    towards z;
  - ``b_k_axial`` (prismatic, spring K_b) along the crank, at its tip B_k;
  - ``c_k`` (revolute, passive) at B_k, axis u_k: the coupler ``coupler_k`` (length a,
    along its local y); undeformed it stays parallel to t_k, so c_k = -alpha_k;
  - ``s_k`` (prismatic, passive) at the coupler midpoint C_k (frame ``coupler_k_mid``)
    along u_k: the slider and connecting bar ``bar_k`` (length h, along the coupler
    normal) ending at ``H_k``;
  - ``d_k`` (revolute, passive) at O_k + (a/2) t_k, axis u_k: the follower crank
    ``crank_d_k``; ``d_k_axial`` (prismatic, spring K_d) to its tip ``crank_d_k_tip``,
    closed to the coupler's far end ``coupler_k_end`` by a 3D point closure.

* ``plate`` (floating: free flyer, passive) carries ``mobile_plate``; frame ``H`` at its
  centre (the centroid of the ball centres) and ``ball_k`` at p_k = r_p u_k (plate
  frame), each closed to ``H_k`` by a 3D point closure (a spherical joint leaves all
  three relative rotations free, which is exactly what a point closure does).
* Arm: frame ``Q`` at H + HQ z_p; ``alpha_4`` (revolute, actuated, spring K_T4) at Q with
  URDF axis -y_p, so that a positive alpha_4 turns the arm from x_p towards z_p; link
  ``arm`` (QM2, along its local x); ``arm_axial`` (prismatic, spring K_4) at distance L
  from Q, to ``M2``; ``s_4`` (prismatic, actuated, spring K_s) along the arm, to the
  sliding link ``telescope``; frame ``M`` at its tip, x axis along the arm direction w:
  M = Q + (L + s_4) w at rest; frame ``tool`` at M, its z axis along w (the axis of a
  tool carried by the telescope, :data:`FRAME_TOOL`).

Masses (``CaHyManParams.m_*``, default 0: no ``<inertial>`` is written), placed where the
lever arms of the paper's eq. (11) put them (an interpretation: the paper gives the arms,
not the bodies): m_HQ at the middle of HQ (on the plate), m_QM at Q and m_M4 (the motor
of alpha_4) at L / 2 on ``arm``, m_MM2 at M2, and the linear motor m_M5 half at M2 and
half at M, so that its centre is at L + s_4 / 2 from Q, as eq. (11) has it. Each leg's
links carry m_b, m_c, m_d, m_h at their middles (the paper names no leg masses).

Links as beams (``CaHyManParams.links_as_beams``, :func:`beams`): each leg's input crank
``crank_b_k`` (to ``b_k_axial``, length b), coupler as two beams of length a / 2 meeting
at the slider's C_k (``coupler_k`` from B_k to ``coupler_k_mid``, ``coupler_k_mid`` to the
far end: the load of the connecting bar bends a coupler held at both ends), follower
crank ``crank_d_k`` (to
``d_k_axial``, length b) and connecting bar ``bar_k`` (to H_k, length h) are tubes
(d_leg, t_leg), the arm ``arm`` (QM2, to ``arm_axial``, length L) a tube (d_arm, t_arm),
of material E_beam, G_beam, each a cantilever from its link frame (Euler-Bernoulli,
:mod:`closedloop.model.beams`). The sliding tube MM2 is a tube (d_MM2, t_MM2) of constant length
L_MM2 clamped at its driven end: ``s_4`` then moves a link ``telescope_root`` at
M - L_MM2 w (the s_4 joint's origin moves back by L_MM2 along the arm, M stays at
Q + (L + s_4) w) carrying the telescope on the fixed joint ``telescope_fixed``. The
virtual joints of K_b, K_d and K_4 are locked (the beams carry the links' axial
stiffness); the motors' K_T, K_T4, K_s stay.

Closure file: the "Extended URDF" keys ``closed_loop``, ``type``, ``name_mot`` plus the
``springs`` extension read by :func:`closedloop.io.closure_file.read_closure_file` (and ``locked``,
``beams`` with links as beams).
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from cahyman_pin.geometry import DELTA, T, U, plate_pose
from cahyman_pin.params import DEFAULT_PARAMS, CaHyManParams
from closedloop.io.closure_file import ClosureSpec

LEGS = (1, 2, 3)
#: Actuated joints, in the order of the inputs (alpha_1, alpha_2, alpha_3, alpha_4, s_4).
ACTUATED = ("alpha_1", "alpha_2", "alpha_3", "alpha_4", "s_4")
#: Name of the frame at the arm extremity M and at the plate centre H.
FRAME_M, FRAME_H = "M", "H"
#: Name of the tool frame at M whose z axis is the arm's direction w (M's x axis): the
#: axis of a drill or a spindle carried by the telescope, which a 5-axis task fixes.
FRAME_TOOL = "tool"
#: Virtual joints standing for link compliance (rest value 0).
VIRTUAL_JOINTS = (*(f"{c}_{k}_axial" for c in "bd" for k in LEGS), "arm_axial")
#: Free-flyer joint of the mobile plate.
PLATE_JOINT = "plate"
#: The pose of the closure file's ``start:``: alpha_1..3 [rad], alpha_4 [rad], s_4 [m], that
#: of the paper's Table 1 (``cahyman_pin.paper.data.TABLE_POSES[0]``), the cahyman
#: command's default.
START_POSE = (np.radians([90.0, 90.0, 90.0]), math.radians(90.0), 0.05)

_MATERIALS = {
    "grey": "0.55 0.55 0.6 1",
    "blue": "0.2 0.4 0.8 1",
    "orange": "0.9 0.5 0.1 1",
    "green": "0.2 0.7 0.3 1",
    "red": "0.8 0.2 0.2 1",
    "dark": "0.25 0.25 0.3 1",
}
_ROD_ALONG_Y = (math.pi / 2, 0.0, 0.0)  # turns a URDF cylinder (local z) onto local y
_ROD_ALONG_X = (0.0, math.pi / 2, 0.0)  # turns a URDF cylinder (local z) onto local x


def closure_pairs() -> tuple[tuple[str, str], ...]:
    """Frame pairs closed by 3D point closures: 3 parallelograms, then 3 ball joints."""
    return tuple((f"coupler_{k}_end", f"crank_d_{k}_tip") for k in LEGS) + tuple(
        (f"H_{k}", f"ball_{k}") for k in LEGS
    )


def springs(p: CaHyManParams) -> dict[str, float]:
    """Joint name -> stiffness [N m/rad or N/m]; every joint not listed is passive."""
    out: dict[str, float] = {}
    for k in LEGS:
        out[f"alpha_{k}"] = p.K_T
        out[f"b_{k}_axial"] = p.K_b
        out[f"d_{k}_axial"] = p.K_d
    out.update({"alpha_4": p.K_T4, "s_4": p.K_s, "arm_axial": p.K_4})
    return {name: float(value) for name, value in out.items()}


def closed_form_values(alpha, alpha4, s4, p: CaHyManParams) -> dict[str, np.ndarray]:
    """Joint name -> (n, nq_j) values of the closed-form geometry at n poses: the cranks
    alpha_k, the parallelograms' c_k = -alpha_k and d_k = alpha_k, the legs' s_k, the
    plate's free flyer (x y z [m], qx qy qz qw), alpha_4 and s_4 (the joints not listed,
    the virtual springs, at rest: 0).

    Args:
        alpha: (n, 3) crank angles [rad]; alpha4: (n,) arm angles [rad]; s4: (n,) strokes
            [m]; checked by the caller (see :func:`cahyman_pin.model.check_inputs`).

    Raises:
        AssemblyError: the legs cannot carry the plate at some pose.
    """
    alpha = np.asarray(alpha, dtype=float)
    pose = plate_pose(alpha, p)
    out = {}
    for k, leg in enumerate(LEGS):
        a = alpha[:, k : k + 1]
        out[f"alpha_{leg}"], out[f"c_{leg}"], out[f"d_{leg}"] = a, -a, a
        out[f"s_{leg}"] = pose.s[:, k : k + 1]
    out[PLATE_JOINT] = np.hstack([pose.H, [pin.Quaternion(R).coeffs() for R in pose.R]])
    out["alpha_4"], out["s_4"] = np.reshape(alpha4, (-1, 1)), np.reshape(s4, (-1, 1))
    return out


def beams(p: CaHyManParams) -> dict[str, dict]:
    """Link name -> beam (:mod:`closedloop.model.beams`) of the links as beams (module docstring);
    empty unless ``p.links_as_beams``."""
    if not p.links_as_beams:
        return {}

    def tube(end: str, d: float, t: float) -> dict:
        section = {"shape": "tube", "d": float(d), "t": float(t)}
        return {"end": end, "E": float(p.E_beam), "G": float(p.G_beam), "section": section}

    out = {}
    for k in LEGS:
        out[f"crank_b_{k}"] = tube(f"b_{k}_axial", p.d_leg, p.t_leg)
        out[f"coupler_{k}"] = tube(f"coupler_{k}_mid_fixed", p.d_leg, p.t_leg)
        out[f"coupler_{k}_mid"] = tube(f"coupler_{k}_end_fixed", p.d_leg, p.t_leg)
        out[f"crank_d_{k}"] = tube(f"d_{k}_axial", p.d_leg, p.t_leg)
        out[f"bar_{k}"] = tube(f"H_{k}_fixed", p.d_leg, p.t_leg)
    out["arm"] = tube("arm_axial", p.d_arm, p.t_arm)
    out["telescope_root"] = tube("telescope_fixed", p.d_MM2, p.t_MM2)
    return out


def closure_spec(p: CaHyManParams = DEFAULT_PARAMS) -> ClosureSpec:
    """Closures, actuated joints, springs (and, with links as beams, the locked virtual
    joints and the beams) of the CaHyMan model (the closure file's data)."""
    pairs = closure_pairs()
    types = ("3d",) * len(pairs)
    if not p.links_as_beams:
        return ClosureSpec(pairs, types, ACTUATED, springs(p), ())
    motors = {n: k for n, k in springs(p).items() if n not in VIRTUAL_JOINTS}
    return ClosureSpec(pairs, types, ACTUATED, motors, VIRTUAL_JOINTS, beams(p))


# ---------------------------------------------------------------------- XML helpers
def _num(x: float) -> str:
    """Exact (round-trip) decimal text of a kinematic value."""
    x = float(x)
    return "0" if x == 0.0 else (str(int(x)) if x.is_integer() and abs(x) < 1e15 else repr(x))


def _short(x: float) -> str:
    """Six-digit text of a display-only size."""
    return f"{float(x) + 0.0:.6g}"


def _vec(v, fmt=_num) -> str:
    return " ".join(fmt(x) for x in v)


def _origin(xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0)) -> str:
    return f'<origin xyz="{_vec(xyz)}" rpy="{_vec(rpy)}"/>'


def _visual(geometry: str, material: str, xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0)) -> str:
    origin = f'<origin xyz="{_vec(xyz, _short)}" rpy="{_vec(rpy, _short)}"/>'
    return f'<visual>{origin}<geometry>{geometry}</geometry><material name="{material}"/></visual>'


def _cylinder(radius: float, length: float) -> str:
    return f'<cylinder radius="{_short(radius)}" length="{_short(length)}"/>'


def _sphere(radius: float) -> str:
    return f'<sphere radius="{_short(radius)}"/>'


def _box(size) -> str:
    return f'<box size="{_vec(size, _short)}"/>'


def _link(name: str, *visuals: str, masses=()) -> str:
    """A link with its visuals and, when their total is > 0, the inertial of point masses
    ``masses``: (mass [kg], (x, y, z) [m] in the link frame) pairs."""
    inertial = _inertial(masses)
    if not visuals and not inertial:
        return f'  <link name="{name}"/>'
    body = "".join(f"\n    {v}" for v in (*visuals, *inertial))
    return f'  <link name="{name}">{body}\n  </link>'


def _inertial(masses) -> list[str]:
    """URDF inertial of point masses: total mass, centre of mass, inertia about it."""
    m = sum(mass for mass, _ in masses)
    if m <= 0.0:
        return []
    com = sum(mass * np.asarray(at, float) for mass, at in masses) / m
    inertia = np.zeros((3, 3))
    for mass, at in masses:
        r = np.asarray(at, float) - com
        inertia += mass * (r @ r * np.eye(3) - np.outer(r, r))
    (ixx, ixy, ixz), (_, iyy, iyz), (_, _, izz) = inertia
    return [
        f'<inertial>{_origin(com)}<mass value="{_num(m)}"/>'
        f'<inertia ixx="{_num(ixx)}" ixy="{_num(ixy)}" ixz="{_num(ixz)}" iyy="{_num(iyy)}" '
        f'iyz="{_num(iyz)}" izz="{_num(izz)}"/></inertial>'
    ]


def _joint(name, kind, parent, child, xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0), axis=None,
           limits=None) -> str:  # fmt: skip
    parts = [f'<parent link="{parent}"/><child link="{child}"/>', _origin(xyz, rpy)]
    if axis is not None:
        parts.append(f'<axis xyz="{_vec(axis)}"/>')
    if limits is not None:
        lo, hi, effort = limits
        parts.append(
            f'<limit lower="{_num(lo)}" upper="{_num(hi)}" effort="{_num(effort)}" velocity="1"/>'
        )
    return f'  <joint name="{name}" type="{kind}">\n    {"".join(parts)}\n  </joint>'


def _fixed_frame(name: str, parent: str, xyz=(0.0, 0.0, 0.0), *visuals: str) -> list[str]:
    """A frame ``name`` (a link on a fixed joint ``name_fixed``) on ``parent``."""
    return [_joint(f"{name}_fixed", "fixed", parent, name, xyz), _link(name, *visuals)]


class _Sizes:
    """Visual sizes [m] derived from the dimensions (display only, no mechanical role)."""

    def __init__(self, p: CaHyManParams):
        self.rod = 0.025 * p.a
        self.ball = 2.0 * self.rod
        self.plate = 2.0 * self.rod
        self.fixed_radius = math.hypot(p.r_e, p.a / 2) + 2.0 * self.ball
        self.mobile_radius = p.r_p + 2.0 * self.ball


#: Position limit [rad] of the revolute joints (cranks, arm): one turn either way.
REVOLUTE_LIMIT = 2 * math.pi
_REVOLUTE = (-REVOLUTE_LIMIT, REVOLUTE_LIMIT, 1e3)
_VIRTUAL = (-0.01, 0.01, 1e4)


def _leg(k: int, p: CaHyManParams, z: _Sizes) -> list[str]:
    """Elements of leg k: parallelogram, slider and connecting bar (see module docstring)."""
    i, rpy = k - 1, (0.0, 0.0, float(DELTA[k - 1]))
    b0 = p.r_e * U[i] - 0.5 * p.a * T[i]
    d0 = p.r_e * U[i] + 0.5 * p.a * T[i]
    crank = _visual(_cylinder(z.rod, p.b), "blue", (0, p.b / 2, 0), _ROD_ALONG_Y)
    hinge = _visual(_sphere(1.3 * z.rod), "dark")
    out = [f"  <!-- leg {k}: delta = {math.degrees(DELTA[i]):g} deg -->"]
    out += [
        _joint(f"alpha_{k}", "revolute", "fixed_plate", f"crank_b_{k}", b0, rpy, (1, 0, 0),
               _REVOLUTE),
        _link(f"crank_b_{k}", crank, hinge, masses=[(p.m_b, (0, p.b / 2, 0))]),
        _joint(f"b_{k}_axial", "prismatic", f"crank_b_{k}", f"crank_b_{k}_tip", (0, p.b, 0),
               axis=(0, 1, 0), limits=_VIRTUAL),
        _link(f"crank_b_{k}_tip", hinge),
        _joint(f"c_{k}", "revolute", f"crank_b_{k}_tip", f"coupler_{k}", axis=(1, 0, 0),
               limits=_REVOLUTE),
        _link(f"coupler_{k}",
              _visual(_cylinder(z.rod, p.a), "orange", (0, p.a / 2, 0), _ROD_ALONG_Y),
              masses=[(p.m_c, (0, p.a / 2, 0))]),
        *_fixed_frame(f"coupler_{k}_mid", f"coupler_{k}", (0, p.a / 2, 0)),
        *_fixed_frame(f"coupler_{k}_end", f"coupler_{k}_mid", (0, p.a / 2, 0), hinge),
        _joint(f"s_{k}", "prismatic", f"coupler_{k}_mid", f"bar_{k}", axis=(1, 0, 0),
               limits=(-p.r_e - p.r_p, p.r_e + p.r_p, 1e3)),
        _link(f"bar_{k}", _visual(_box((4 * z.rod, 3 * z.rod, 3 * z.rod)), "grey"),
              _visual(_cylinder(z.rod, p.h), "green", (0, 0, p.h / 2)),
              masses=[(p.m_h, (0, 0, p.h / 2))]),
        *_fixed_frame(f"H_{k}", f"bar_{k}", (0, 0, p.h), _visual(_sphere(z.ball), "red")),
        _joint(f"d_{k}", "revolute", "fixed_plate", f"crank_d_{k}", d0, rpy, (1, 0, 0),
               _REVOLUTE),
        _link(f"crank_d_{k}", crank, hinge, masses=[(p.m_d, (0, p.b / 2, 0))]),
        _joint(f"d_{k}_axial", "prismatic", f"crank_d_{k}", f"crank_d_{k}_tip", (0, p.b, 0),
               axis=(0, 1, 0), limits=_VIRTUAL),
        _link(f"crank_d_{k}_tip"),
    ]  # fmt: skip
    return out


def _plate_and_arm(p: CaHyManParams, z: _Sizes) -> list[str]:
    """Elements of the mobile plate and of the telescopic arm."""
    out = ["  <!-- mobile plate: free flyer closed to the legs at the ball joints -->"]
    out += [
        _joint(PLATE_JOINT, "floating", "fixed_plate", "mobile_plate"),
        _link("mobile_plate", _visual(_cylinder(z.mobile_radius, z.plate), "grey"),
              _visual(_cylinder(z.rod, p.HQ), "dark", (0, 0, p.HQ / 2)),
              masses=[(p.m_HQ, (0, 0, p.HQ / 2))]),
        *_fixed_frame(FRAME_H, "mobile_plate"),
    ]  # fmt: skip
    for k in LEGS:
        out += _fixed_frame(f"ball_{k}", "mobile_plate", p.r_p * U[k - 1])
    tele = 1.2 * p.s4_max
    telescope = _link(
        "telescope",
        _visual(_cylinder(z.rod, tele), "orange", (-tele / 2, 0, 0), _ROD_ALONG_X),
        masses=[(p.m_M5 / 2, (0, 0, 0))],
    )
    if p.links_as_beams:  # s_4 moves the sliding tube's driven end (module docstring)
        sliding = [
            _joint("s_4", "prismatic", "M2", "telescope_root", (-p.L_MM2, 0, 0), axis=(1, 0, 0),
                   limits=(0.0, p.s4_max, 1e3)),
            _link("telescope_root"),
            _joint("telescope_fixed", "fixed", "telescope_root", "telescope", (p.L_MM2, 0, 0)),
        ]  # fmt: skip
    else:
        sliding = [
            _joint("s_4", "prismatic", "M2", "telescope", axis=(1, 0, 0),
                   limits=(0.0, p.s4_max, 1e3)),
        ]  # fmt: skip
    out += [
        "  <!-- telescopic arm: Q = H + HQ z_p, w = cos(alpha_4) x_p + sin(alpha_4) z_p -->",
        *_fixed_frame("Q", "mobile_plate", (0, 0, p.HQ), _visual(_sphere(1.5 * z.rod), "dark")),
        _joint("alpha_4", "revolute", "Q", "arm", axis=(0, -1, 0), limits=_REVOLUTE),
        _link("arm", _visual(_cylinder(1.5 * z.rod, p.L), "blue", (p.L / 2, 0, 0), _ROD_ALONG_X),
              masses=[(p.m_QM, (0, 0, 0)), (p.m_M4, (p.L / 2, 0, 0))]),
        _joint("arm_axial", "prismatic", "arm", "M2", (p.L, 0, 0), axis=(1, 0, 0),
               limits=_VIRTUAL),
        _link("M2", masses=[(p.m_MM2, (0, 0, 0)), (p.m_M5 / 2, (0, 0, 0))]),
        *sliding,
        telescope,
        *_fixed_frame(FRAME_M, "telescope", (0, 0, 0), _visual(_sphere(z.ball), "red")),
        _joint(f"{FRAME_TOOL}_fixed", "fixed", FRAME_M, FRAME_TOOL, rpy=_ROD_ALONG_X),
        _link(FRAME_TOOL),
    ]  # fmt: skip
    return out


def build_urdf(p: CaHyManParams = DEFAULT_PARAMS) -> str:
    """URDF text of the CaHyMan tree for parameters ``p`` (see the module docstring)."""
    z = _Sizes(p)
    dims = ", ".join(f"{n}={getattr(p, n)!r}" for n in ("a", "b", "h", "r_e", "r_p", "HQ", "L"))
    frame_links = "".join(
        _visual(_box((2 * z.rod, p.a, 2 * z.rod)), "dark", p.r_e * U[i] - (0, 0, z.rod),
                (0, 0, float(DELTA[i])))
        for i in range(3)
    )  # fmt: skip
    lines = [
        '<?xml version="1.0"?>',
        "<!-- CaHyMan (Cassino Hybrid Manipulator), generated by cahyman_pin.urdf_builder;",
        "     do not edit: run scripts/generate_cahyman_urdf.py. Loop closures, actuated",
        "     joints and springs are in cahyman.yaml.",
        f"     Dimensions [m]: {dims}. -->",
        '<robot name="cahyman">',
        *(f'  <material name="{n}"><color rgba="{c}"/></material>' for n, c in _MATERIALS.items()),
        _link("fixed_plate",
              _visual(_cylinder(z.fixed_radius, z.plate), "grey", (0, 0, -z.plate / 2 - 2 * z.rod))
              + frame_links),
    ]  # fmt: skip
    for k in LEGS:
        lines += _leg(k, p, z)
    lines += _plate_and_arm(p, z)
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def build_closure_yaml(p: CaHyManParams = DEFAULT_PARAMS) -> str:
    """Closure-file text (YAML) matching :func:`build_urdf` for parameters ``p``."""
    import yaml  # on demand: the model is built without the file

    spec = closure_spec(p)
    body = yaml.safe_dump(
        {
            "closed_loop": [list(pair) for pair in spec.pairs],
            "type": list(spec.types),
            "name_mot": list(spec.actuated),
        },
        sort_keys=False,
        default_flow_style=None,
    )
    springs_text = yaml.safe_dump({"springs": spec.springs}, sort_keys=False)
    beams_text = ""
    if spec.beams:
        beams_text = (
            "# Links as beams (closedloop.model.beams), their lumped axial springs locked.\n"
        )
        beams_text += yaml.safe_dump({"beams": spec.beams}, sort_keys=False)
    locked = yaml.safe_dump({"locked": list(spec.locked)}, default_flow_style=None)
    alpha, alpha4, s4 = START_POSE
    values = closed_form_values([alpha], [alpha4], [s4], p)
    # the passive values rounded to 1e-12 (far below a mode), so that the rounding of the
    # trigonometry leaves the text the same on any machine; the inputs as given
    rounded = {n: [round(float(x), 12) + 0.0 for x in v[0]] for n, v in values.items()}
    rounded.update({n: [float(x)] for n, x in zip(ACTUATED, [*alpha, alpha4, s4], strict=True)})
    start = {n: v[0] if len(v) == 1 else v for n, v in rounded.items()}
    start_text = (
        "# The start of the assembly, which picks its mode (the working one): the closed-form\n"
        "# pose of the paper's Table 1, the cahyman command's default pose [rad, m].\n"
        + yaml.safe_dump({"start": start}, sort_keys=False, default_flow_style=None)
    )
    return (
        '# Loop closures of cahyman.urdf ("Extended URDF" convention, with springs),\n'
        "# generated by cahyman_pin.urdf_builder; do not edit: run\n"
        "# scripts/generate_cahyman_urdf.py.\n"
        "# Parallelograms: coupler end <-> follower-crank tip; ball joints: H_k <-> ball_k.\n"
        + body
        + "# Joint stiffness [N m/rad for revolute, N/m for prismatic joints]; joints not\n"
        "# listed are passive.\n" + springs_text + locked + beams_text + start_text
    )
