"""Initial-contours files: the snakes' starting contours on the calibration frame, as JSON
(``myoface analyze --init FILE``; ``myoface demo`` writes one)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from myoface._io import atomic_output, parse_json, read_text
from myoface.analysis.sections import SECTIONS
from myoface.errors import MyofaceFileNotFoundError, MyofaceFormatError


def load_init(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read an initial-contours file: ``{"contours": {section: [[x, y], ...], ...}}`` (pixels
    of the calibration frame, (x, y) = (column, row)); see :data:`SECTIONS` for the names and
    the node order. Sections may be left out."""
    p = Path(path)
    if not p.is_file():
        raise MyofaceFileNotFoundError(f"no such contour file: {p}")
    doc = parse_json(read_text(p, "contour file (JSON)"), str(p))
    cont = doc.get("contours") if isinstance(doc, dict) else None
    if not isinstance(cont, dict) or not cont:
        raise MyofaceFormatError(f'{p}: expected {{"contours": {{section: [[x, y], ...]}}}}')
    out = {}
    for name, pts in cont.items():
        if name not in SECTIONS:
            raise MyofaceFormatError(
                f"{p}: unknown section {name!r}; sections are {', '.join(SECTIONS)}"
            )
        try:
            a = np.asarray(pts, dtype=np.float64)
        except (TypeError, ValueError, OverflowError):
            raise MyofaceFormatError(f"{p}: section {name!r} must be a list of [x, y]") from None
        if a.ndim != 2 or a.shape[1] != 2 or len(a) < 2:
            raise MyofaceFormatError(
                f"{p}: section {name!r} must be a list of at least 2 [x, y] points; got shape "
                f"{a.shape}"
            )
        if not np.isfinite(a).all():
            raise MyofaceFormatError(f"{p}: section {name!r} has NaN or infinite coordinates")
        out[name] = a
    return out


def save_init(path: str | os.PathLike, contours: dict[str, np.ndarray], note: str = "") -> None:
    doc = {
        "note": note or "initial contours, pixels (x, y) of the calibration frame",
        "contours": {k: np.round(v, 2).tolist() for k, v in contours.items()},
    }
    with atomic_output(path) as tmp:
        tmp.write_text(json.dumps(doc, indent=1))
