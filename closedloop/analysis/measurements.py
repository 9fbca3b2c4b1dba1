"""Measured deflections for the identification of springs
(:mod:`closedloop.analysis.identification`): one
:class:`~closedloop.analysis.measurements.Measurement` (configuration, wrench, twist and its
standard deviation) each, given in Python or read from a YAML or CSV file
(:func:`~closedloop.analysis.measurements.read_measurements`).
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from closedloop.common.arrays import check_wrench, readonly, real_array, real_number
from closedloop.common.input_files import read_text
from closedloop.exceptions import (
    InvalidInputError,
    ModelFileError,
)
from closedloop.io import strict_yaml


@dataclass(frozen=True)
class Measurement:
    """One measured deflection (arrays read-only, SI).

    Attributes:
        q: (nq,) configuration [rad, m]: the one the deflection is computed at; with
            ``actuated``, the configuration the robot was in, only to check the assembly
            mode of the actuated values (its branch; see
            :mod:`closedloop.analysis.misfit`); or None.
        actuated: (n_act,) actuated joint values [rad, m] to assemble (driven from the
            model file's configuration, as the command line does), or None.
        wrench: (6,) applied wrench (fx, fy, fz [N], nx, ny, nz [N m]), world axes.
        twist: (6,) measured twist (dx, dy, dz [m], rx, ry, rz [rad]), world axes.
        sd: (6,) standard deviation of the twist, > 0 (same units); inf for a component
            not measured (its twist is then 0 here, whatever was given: NaN or a value).
    """

    q: np.ndarray | None
    actuated: np.ndarray | None
    wrench: np.ndarray
    twist: np.ndarray
    sd: np.ndarray

    @classmethod
    def of(cls, *, wrench, twist, sd, q=None, actuated=None) -> Measurement:
        """A validated measurement (see the attributes).

        Raises:
            InvalidInputError: wrong shapes, a NaN or inf (in any array), sd <= 0, neither
                q nor actuated.
        """
        if q is None and actuated is None:
            raise InvalidInputError("a measurement needs q or actuated (or both)")
        given = real_array(sd, "sd")
        sd_ = np.full(6, float(given)) if given.ndim == 0 else given.reshape(-1)
        if sd_.shape != (6,) or np.any(np.isnan(sd_)) or np.any(sd_ <= 0.0):
            raise InvalidInputError(
                f"sd must be one or 6 values > 0 (units of the twist; inf for a component not "
                f"measured), got {given.tolist()}"
            )
        measured = np.isfinite(sd_)
        if not measured.any():
            raise InvalidInputError("sd is inf for every component: nothing is measured")
        twist_ = real_array(twist, "measured twist").reshape(-1)
        if twist_.shape != (6,) or not np.all(np.isfinite(twist_[measured])):
            raise InvalidInputError(
                f"measured twist must be 6 values (dx dy dz [m], rx ry rz [rad]), finite where "
                f"sd is, got {twist_.tolist()}"
            )
        twist_ = np.where(measured, twist_, 0.0)
        vector, act = (None if v is None else _finite(v, name)
                       for v, name in ((q, "q"), (actuated, "actuated")))  # fmt: skip
        return cls(vector, act, readonly(check_wrench(wrench)), readonly(twist_), readonly(sd_))


def _finite(value, name: str) -> np.ndarray:
    """(k,) read-only finite values of ``name``."""
    values = real_array(value, name).reshape(-1)
    if not np.all(np.isfinite(values)):
        raise InvalidInputError(f"{name} must be finite values, got {values.tolist()}")
    return readonly(values)


#: Columns of a measurement CSV file (besides ``frame`` and q_i or actuated_i): the wrench
#: [N, N m], the twist [m, rad] and, optional, the twist's standard deviations.
CSV_WRENCH = ("fx", "fy", "fz", "nx", "ny", "nz")
#: The twist's columns (see :data:`CSV_WRENCH`).
CSV_TWIST = ("dx", "dy", "dz", "rx", "ry", "rz")
#: The standard deviations' columns (see :data:`CSV_WRENCH`).
CSV_SD = tuple(f"sd_{c}" for c in CSV_TWIST)
_KEYS = ("q", "actuated", "wrench", "twist", "sd")


def read_measurements(path: str | Path) -> tuple[str, list[Measurement]]:
    """(frame, measurements) from a YAML or CSV file, every value in SI units (q and
    actuated in rad and m, wrench in N and N m, twist and sd in m and rad): nothing is
    converted, so mm or deg must be converted before (a twist in mm fits springs 1000
    times too soft, or does not fit at all).

    YAML (module docstring): keys ``frame`` and ``measurements``, each a mapping with
    ``q`` or ``actuated`` (or both: q is then the configuration the robot was in, which
    checks the actuated values' assembly mode; :class:`Measurement`), ``wrench``,
    ``twist`` and ``sd``. CSV (``.csv``): a header, one measurement per row, the columns
    ``frame`` (the same in every row), ``q_0`` .. ``q_{nq-1}`` or ``actuated_0`` .. (or
    both), :data:`CSV_WRENCH`, :data:`CSV_TWIST`, and ``sd`` or :data:`CSV_SD`.

    Raises:
        ModelFileError: missing or unreadable file, wrong structure (a missing column or
            key, several frames).
        InvalidInputError: a bad measurement (its index is named).
    """
    kind = "CSV" if Path(path).suffix.lower() == ".csv" else "YAML"
    text = read_text(path, f"measurement file {str(path)!r}", kind)  # a BOM dropped
    try:
        if kind == "CSV":
            frame, items = _csv_items(str(path), text)
        else:
            frame, items = _yaml_items(str(path), strict_yaml.load(text))
    except (yaml.YAMLError, csv.Error) as e:
        msg = " ".join(str(e).split())
        raise ModelFileError(f"cannot read measurement file {str(path)!r}: {msg}") from None
    out = []
    for i, item in enumerate(items):
        missing = [k for k in ("wrench", "twist", "sd") if k not in item]
        if missing or not set(item) <= set(_KEYS):
            raise ModelFileError(
                f"{str(path)!r}: measurement {i} has {sorted(map(str, item))}; expected q or "
                "actuated (or both), wrench, twist, sd"
            )
        try:
            out.append(Measurement.of(**{k: _number(v) for k, v in item.items()}))
        except (InvalidInputError, TypeError, ValueError) as e:
            raise InvalidInputError(f"measurement {i} of {str(path)!r}: {e}") from None
    return frame, out


def _yaml_items(path: str, doc) -> tuple[str, list[dict]]:
    if not isinstance(doc, dict) or not isinstance(doc.get("frame"), str):
        raise ModelFileError(f"{path!r}: expected a mapping with 'frame' and 'measurements'")
    items = doc.get("measurements")
    if not isinstance(items, list) or not items:
        raise ModelFileError(f"{path!r}: 'measurements' must be a non-empty list")
    for i, item in enumerate(items):
        if not isinstance(item, dict):
            raise ModelFileError(f"{path!r}: measurement {i} must be a mapping of {_KEYS}")
    return doc["frame"], items


def _csv_items(path: str, text: str) -> tuple[str, list[dict]]:
    reader = csv.DictReader(io.StringIO(text), skipinitialspace=True)
    # columns aligned by hand: names and the frame may carry spaces on either side
    reader.fieldnames = header = [c.strip() for c in reader.fieldnames or []]
    rows = list(reader)
    repeated = sorted({c for c in header if header.count(c) > 1})
    if repeated:
        raise ModelFileError(f"{path!r}: column(s) {repeated} given twice; expected each once")
    for i, row in enumerate(rows):
        if None in row or None in row.values():
            raise ModelFileError(f"{path!r}: row {i} has not one value per column")
        empty = [c for c, v in row.items() if not v.strip()]
        if empty:
            raise ModelFileError(f"{path!r}: row {i} has no value in column(s) {empty}")
    sd = ["sd"] if "sd" in header else list(CSV_SD)
    config = {kind: [f"{kind}_{i}" for i in range(sum(c.startswith(f"{kind}_") for c in header))]
              for kind in ("q", "actuated")}  # fmt: skip
    config = {kind: columns for kind, columns in config.items() if columns}
    wanted = ("frame", *(c for columns in config.values() for c in columns), *CSV_WRENCH,
              *CSV_TWIST, *sd)  # fmt: skip
    missing, unknown = [c for c in wanted if c not in header], sorted(set(header) - set(wanted))
    if missing or unknown or not config:
        raise ModelFileError(
            f"{path!r}: expected a header and rows with frame, q_0.. or actuated_0.., "
            f"{', '.join(CSV_WRENCH + CSV_TWIST)}, sd or sd_dx..sd_rz (missing {missing}, "
            f"unknown {unknown})"
        )
    if not rows:
        raise ModelFileError(f"{path!r} has a header and no measurement rows; expected one "
                             "row a measurement")  # fmt: skip
    frames = sorted({row["frame"].strip() for row in rows})
    if len(frames) != 1:
        raise ModelFileError(f"{path!r}: one frame expected in every row, got {frames}")
    items = [
        {**{kind: [row[c] for c in columns] for kind, columns in config.items()},
         "wrench": [row[c] for c in CSV_WRENCH],
         "twist": [row[c] for c in CSV_TWIST],
         "sd": [row[c] for c in sd] if len(sd) > 1 else row["sd"]}
        for row in rows
    ]  # fmt: skip
    return frames[0], items


def _number(value, depth: int = 0):
    """YAML 1.1 reads 1e-6 as a string, CSV gives strings: numbers, and lists of them, as
    floats (:func:`closedloop.common.arrays.real_number`: a string in ASCII decimal
    notation, with the spaces of an aligned column around it).

    Raises:
        ValueError: a boolean (YAML's true/false), a string that is not such a number
            (``1e999`` neither), or a list inside a list.
    """
    if isinstance(value, list):
        if depth:
            raise ValueError(f"{value!r} is a list inside a list; expected numbers")
        return [_number(v, 1) for v in value]
    try:
        return real_number(value)
    except TypeError:
        raise ValueError(f"{value!r} is not a number") from None
