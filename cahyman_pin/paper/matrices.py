"""The report's stiffness matrices at the paper's three configurations: K of the generic
backend, and det K and the eigenvalues of K of every backend."""

from __future__ import annotations

import numpy as np

from cahyman_pin.paper.compare import BACKENDS, backend_stiffness
from cahyman_pin.paper.data import TABLE_POSES
from cahyman_pin.paper.document import Document, Heading, Paragraph, Table
from cahyman_pin.params import CaHyManParams
from closedloop.elastostatics.compliance import TWIST_LABELS
from closedloop.exceptions import ClosedLoopError


def _matrix_rows(K: np.ndarray) -> tuple[tuple[str, ...], ...]:
    """Rows of a 6x6 matrix; entries below 1e-12 of the largest are shown as 0."""
    tiny = 1e-12 * np.max(np.abs(K))
    return tuple(
        (lab, *("0" if abs(x) < tiny else f"{x:.4g}" for x in K[i]))
        for i, lab in enumerate(TWIST_LABELS)
    )


def _api_value(result, name: str):
    """``result.name`` of an API result, or the error of the API (``result`` itself when the
    call was refused)."""
    if isinstance(result, ClosedLoopError):
        return result
    try:
        return getattr(result, name)
    except ClosedLoopError as e:
        return e


def _eigenvalues_text(ev: np.ndarray) -> str:
    return ", ".join(f"{e.real:.4g}" if abs(e.imag) < 1e-9 * abs(e) else f"{e:.3g}" for e in ev)


def matrices_section(doc: Document, params: CaHyManParams) -> None:
    """Add the section (module docstring) to ``doc``, for ``params``."""
    doc.add(
        Heading("Stiffness matrices at the three configurations"),
        Paragraph(
            "The stiffness of the machine at the paper's three configurations, before any "
            "comparison with the paper: K maps a small displacement of M (translation and "
            "rotation) to the load at M (force and moment) that holds it. "
            "K at M, world axes, SI (N/m, N/rad, N m/rad), order dx dy dz rx ry rz, from the "
            "generic backend (a matrix acts on small rotation vectors rx, ry, rz about the "
            "world axes: the paper's angles, singular at the level plate, cannot be its "
            "coordinates); eigenvalues and determinant for every backend (the published "
            "K is in its own mixed coordinates, see the choices under 'Parameters and "
            "conventions'). Every number is that "
            "of cahyman_pin.api.stiffness (the consistent and generic K from a square-root "
            "factor of C, not inv(C)); 'n/a' where the API gives none, for the reason stated."
        ),
    )
    for pose in TABLE_POSES:
        results = {}
        for b in BACKENDS:
            try:
                results[b] = backend_stiffness(b, pose, params)
            except ClosedLoopError as e:
                results[b] = e
        values = {b: {name: _api_value(r, name) for name in ("K", "det_K", "eigenvalues")}
                  for b, r in results.items()}  # fmt: skip
        doc.add(Heading(pose.label, 3))
        K_generic = values["generic"]["K"]
        if not isinstance(K_generic, ClosedLoopError):
            doc.add(
                Table(
                    ("", *TWIST_LABELS),
                    _matrix_rows(K_generic),
                    caption=f"K (generic), {pose.describe()}",
                )
            )
        rows, reasons = [], {}
        for b, v in values.items():
            for e in v.values():
                if isinstance(e, ClosedLoopError):
                    reasons.setdefault(b, str(e).rstrip("."))
            det, ev = v["det_K"], v["eigenvalues"]
            rows.append((
                b,
                "n/a" if isinstance(det, ClosedLoopError) else f"{det:.4g}",
                "n/a" if isinstance(ev, ClosedLoopError) else _eigenvalues_text(ev),
            ))  # fmt: skip
        doc.add(Table(("backend", "det K", "eigenvalues of K (ascending)"), tuple(rows)))
        if reasons:
            doc.add(Paragraph("n/a: " + "; ".join(f"{b}: {e}" for b, e in reasons.items()) + "."))
        K_consistent = values["consistent"]["K"]
        if not any(isinstance(K, ClosedLoopError) for K in (K_consistent, K_generic)):
            rel = np.max(np.abs(K_consistent - K_generic)) / np.max(np.abs(K_generic))
            doc.add(
                Paragraph(
                    f"Largest difference between the consistent and generic K, relative to "
                    f"the largest entry: {rel:.2e}."
                )
            )
