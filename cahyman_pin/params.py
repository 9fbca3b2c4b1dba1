"""CaHyMan parameters: every dimension, spring and mass of the reference model.

The defaults are those of the project's reference reading of the mechanism (the paper
gives the springs, not the dimensions; :data:`SOURCES` says where each default comes from).
All values are SI: metres, radians, newtons, N/m for axial springs, N m/rad for torsional
springs, kilograms. :func:`read_params_file` reads any of them from a YAML file.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

from closedloop.exceptions import InvalidInputError, ModelFileError

#: K_s as printed in the paper [N/m]. It gives 1.4 m of deflection per newton.
K_S_PRINTED = 0.697
#: K_s assumed by the reference model [N/m] (the printed value times 1e6).
K_S_ASSUMED = 0.697e6

_KS_PRESETS = {"assumed": K_S_ASSUMED, "printed": K_S_PRINTED}

_LENGTHS = ("a", "b", "h", "r_e", "r_p", "HQ", "L")
#: The lumped springs [N/m or N m/rad].
SPRING_FIELDS = ("K_T", "K_b", "K_d", "K_T4", "K_s", "K_4")
_MASSES = ("m_HQ", "m_QM", "m_MM2", "m_M4", "m_M5")
#: Masses of each leg's links (the same in the three legs); the paper names none.
LEG_MASSES = ("m_b", "m_c", "m_d", "m_h")
#: Fields that only the weight reads (``weight=True``, ``--gravity``): masses [kg] and g [m/s^2].
WEIGHT_FIELDS = (*_MASSES, *LEG_MASSES, "gravity")
#: Material [Pa] and tube sizes [m] of the links as beams (``links_as_beams``).
BEAM_FIELDS = ("E_beam", "G_beam", "d_leg", "t_leg", "d_arm", "t_arm", "d_MM2", "t_MM2", "L_MM2")


#: Magnitudes of a non-zero parameter (SI) accepted: the backends multiply several of
#: them (stiffness x length^2, mass x gravity x length), and squares of squares stay finite.
PARAM_RANGE = (1e-60, 1e60)


@dataclass(frozen=True)
class CaHyManParams:
    """Dimensions [m], springs [N/m or N m/rad] and masses [kg] of CaHyMan.

    Attributes:
        a: frame link and coupler length a_k = c_k of each parallelogram [m].
        b: crank length b_k = d_k [m].
        h: connecting-bar length h_k [m].
        r_e: radius of the leg bases on the fixed plate [m].
        r_p: radius of the ball joints on the mobile plate [m].
        HQ: offset of the arm's revolute joint Q from H along the plate normal [m].
        L: arm length from Q to M at s_4 = 0 [m].
        K_T: torsional stiffness of each leg motor at alpha_k [N m/rad].
        K_b: axial stiffness of each input crank b_k [N/m].
        K_d: axial stiffness of each follower crank d_k [N/m].
        K_T4: torsional stiffness of the arm motor at alpha_4 [N m/rad].
        K_s: axial stiffness of the linear motor and link MM2 (joint s_4) [N/m].
        K_4: axial stiffness of link QM2, in series with K_s [N/m].
        m_HQ, m_QM, m_MM2, m_M4, m_M5: masses named by the paper [kg] (0: no gravity).
        m_b, m_c, m_d, m_h: mass of each leg's input crank, coupler, follower crank and
            connecting bar [kg], at the middle of the link (0 by default).
        gravity: gravitational acceleration [m/s^2], acting along -z.
        s4_max: stroke of the linear motor, s_4 in [0, s4_max] [m].
        links_as_beams: model each leg's links (b, c, d, h) and the arm's links (QM2,
            MM2) as beams (:mod:`closedloop.model.beams`, :func:`cahyman_pin.urdf_builder.beams`)
            instead of the paper's lumped axial springs K_b, K_d, K_4 (default False: the
            paper's model). The motor springs K_T, K_T4, K_s stay.
        E_beam, G_beam: Young's and shear moduli of the links as beams [Pa] (assumed:
            aluminium alloy).
        d_leg, t_leg: outer diameter and wall of the tube of each leg link [m] (assumed).
        d_arm, t_arm: outer diameter and wall of the arm tube QM2 [m] (assumed).
        d_MM2, t_MM2, L_MM2: outer diameter, wall and length of the sliding tube MM2 [m]
            (assumed; a beam of constant length clamped at its driven end).
    """

    a: float = 0.200
    b: float = 0.080
    h: float = 0.050
    r_e: float = 0.100
    r_p: float = 0.100
    HQ: float = 0.050
    L: float = 0.150
    K_T: float = 4.672e3
    K_b: float = 2.625e6
    K_d: float = 2.625e6
    K_T4: float = 0.876e3
    K_s: float = K_S_ASSUMED
    K_4: float = 2.625e6
    m_HQ: float = 0.0
    m_QM: float = 0.0
    m_MM2: float = 0.0
    m_M4: float = 0.0
    m_M5: float = 0.0
    m_b: float = 0.0
    m_c: float = 0.0
    m_d: float = 0.0
    m_h: float = 0.0
    gravity: float = 9.81
    s4_max: float = 0.050
    links_as_beams: bool = False
    E_beam: float = 7.0e10
    G_beam: float = 2.6e10
    d_leg: float = 0.012
    t_leg: float = 0.002
    d_arm: float = 0.020
    t_arm: float = 0.002
    d_MM2: float = 0.014
    t_MM2: float = 0.002
    L_MM2: float = 0.060

    def __post_init__(self) -> None:
        if not isinstance(self.links_as_beams, bool):
            raise InvalidInputError(
                f"CaHyMan parameter links_as_beams={self.links_as_beams!r} must be true or false"
            )
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "links_as_beams":
                continue
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise InvalidInputError(
                    f"CaHyMan parameter {f.name}={value!r} must be a real number"
                )
            if not math.isfinite(value):
                raise InvalidInputError(f"CaHyMan parameter {f.name}={value!r} must be finite")
            if value and not PARAM_RANGE[0] <= abs(value) <= PARAM_RANGE[1]:
                raise InvalidInputError(
                    f"CaHyMan parameter {f.name}={value!r} is outside the range "
                    f"{PARAM_RANGE[0]:g}..{PARAM_RANGE[1]:g} (SI) in which the closed forms and "
                    "the model stay within the floating point range"
                )
        for name in (*_LENGTHS, *SPRING_FIELDS, "s4_max", *BEAM_FIELDS):
            if getattr(self, name) <= 0.0:
                raise InvalidInputError(
                    f"CaHyMan parameter {name}={getattr(self, name)!r} must be > 0"
                )
        for d, t in (("d_leg", "t_leg"), ("d_arm", "t_arm"), ("d_MM2", "t_MM2")):
            if getattr(self, t) > getattr(self, d) / 2:
                raise InvalidInputError(
                    f"CaHyMan parameter {t}={getattr(self, t)!r} must be at most {d}/2 = "
                    f"{getattr(self, d) / 2!r} (a tube's wall is at most its radius)"
                )
        for name in WEIGHT_FIELDS:
            if getattr(self, name) < 0.0:
                raise InvalidInputError(
                    f"CaHyMan parameter {name}={getattr(self, name)!r} must be >= 0"
                )

    @property
    def length(self) -> float:
        """Characteristic length of the machine [m], the scale of the unit-free rank rule
        (:mod:`closedloop.common.conditioning`) for every backend: base diameter plus the heights
        of a leg and of the arm, 2 r_e + a + b + h + HQ + L + s4_max."""
        return 2 * self.r_e + self.a + self.b + self.h + self.HQ + self.L + self.s4_max

    def replace(self, **changes: float) -> CaHyManParams:
        """Copy with some fields changed (validated); unknown names raise."""
        unknown = sorted(set(changes) - set(self.field_names()))
        if unknown:
            raise InvalidInputError(
                f"unknown CaHyMan parameter(s) {unknown}; expected some of {self.field_names()}"
            )
        return dataclasses.replace(self, **changes)

    def with_ks(self, preset: str) -> CaHyManParams:
        """Copy with K_s set by name: ``"assumed"`` (0.697e6 N/m) or ``"printed"`` (0.697 N/m)."""
        if preset not in _KS_PRESETS:
            raise InvalidInputError(
                f"unknown K_s preset {preset!r}; expected one of {sorted(_KS_PRESETS)}"
            )
        return self.replace(K_s=_KS_PRESETS[preset])

    @property
    def total_arm_mass(self) -> float:
        """Sum of the five masses carried by the plate [kg]."""
        return sum(getattr(self, n) for n in _MASSES)

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        """Names of every parameter, in declaration order."""
        return tuple(f.name for f in dataclasses.fields(cls))


DEFAULT_PARAMS = CaHyManParams()

_DIMENSION = "assumed: the paper gives no dimensions"
#: Where each default comes from: ``"paper"`` (printed in the stiffness paper), or
#: ``"assumed: ..."`` with the reason (project reference model, ``cahyman-model.md``).
SOURCES: dict[str, str] = {
    **dict.fromkeys(_LENGTHS, _DIMENSION),
    **dict.fromkeys(("K_T", "K_b", "K_d", "K_T4", "K_4"), "paper"),
    "K_s": "assumed: 0.697e6 N/m, the printed 0.697 N/m times 1e6 (the printed value gives "
    "1.4 m of deflection per newton, which no table shows)",
    **dict.fromkeys(_MASSES, "assumed: 0 (the paper names the masses without values)"),
    **dict.fromkeys(LEG_MASSES, "assumed: 0 (the paper names no mass for the legs)"),
    "gravity": "standard gravity (acts only through the masses)",
    "s4_max": "from the paper's cases (s_4 = 0, 25, 50 mm)",
    "links_as_beams": "the paper's model: lumped axial springs K_b, K_d, K_4",
    **dict.fromkeys(("E_beam", "G_beam"), "assumed: aluminium alloy (used with links_as_beams)"),
    **dict.fromkeys(
        BEAM_FIELDS[2:], "assumed: the paper gives no sections (used with links_as_beams)"
    ),
}


def source(params: CaHyManParams, name: str, given: frozenset[str] = frozenset()) -> str:
    """Where the value of field ``name`` of ``params`` comes from: ``"given"`` for a field
    of ``given`` (those of a parameter file, :func:`params_file_fields`) or a value that
    differs from the default (``"given (the paper's printed value)"`` for K_s = 0.697
    N/m), else :data:`SOURCES`."""
    value = getattr(params, name)
    if name not in given and value == getattr(DEFAULT_PARAMS, name):
        return SOURCES[name]
    if name == "K_s" and value == K_S_PRINTED:
        return "given (the paper's printed value)"
    return "given"


def read_params_file(path: str | Path, base: CaHyManParams = DEFAULT_PARAMS) -> CaHyManParams:
    """Parameters from a YAML mapping ``{field: value}`` of any :class:`CaHyManParams` fields
    (SI); the others keep their value in ``base``. Example: ``K_s: 0.697`` or ``b: 0.09``.

    Raises:
        ModelFileError: a missing or unreadable file, invalid YAML, not a mapping.
        InvalidInputError: an unknown field or a value that is not a valid number (the
            message names the file, the field and the value).
    """
    try:
        return base.replace(**_params_file_values(path))
    except InvalidInputError as e:
        raise InvalidInputError(f"parameter file {str(path)!r}: {e}") from None


def params_file_fields(path: str | Path) -> frozenset[str]:
    """The fields a parameter file sets (raises as :func:`read_params_file`)."""
    return frozenset(_params_file_values(path))


def _params_file_values(path: str | Path) -> dict:
    """field -> value of a parameter file, numbers written as YAML 1.1 strings converted."""
    import yaml  # only when a file is read

    from closedloop.common.arrays import decimal
    from closedloop.common.input_files import read_text
    from closedloop.io import strict_yaml

    path = Path(path)
    text = read_text(path, f"parameter file {str(path)!r}", "YAML")
    try:
        doc = strict_yaml.load(text)
    except yaml.YAMLError as e:
        msg = " ".join(str(e).split())
        raise ModelFileError(f"parameter file {str(path)!r} is not valid YAML: {msg}") from None
    if doc is None:
        doc = {}
    if not isinstance(doc, dict):
        raise ModelFileError(
            f"parameter file {str(path)!r}: expected a mapping field -> value, got "
            f"{type(doc).__name__}"
        )
    values = {}
    for name, value in doc.items():
        if isinstance(value, str):  # YAML 1.1 reads 1e5 as a string
            try:
                value = decimal(value.strip())
            except ValueError:
                pass  # refused as a string by the field's check
        values[str(name)] = value
    return values
