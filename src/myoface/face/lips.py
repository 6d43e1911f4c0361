"""The lips at rest: how far apart the inner lip margins are along the mouth.

A relaxed face rests with its lips together; a face that rests with them apart shows the
inside of its mouth (and the teeth) in every neutral render and in every expression that starts
from it. :func:`rest_lip_gap` measures it on any face with a mouth opening: the default face and
the faces in its topology (the personal faces from a photo or a scan) by their landmark groups
``lip_upper_inner`` / ``lip_lower_inner``, any other face (Waters' geoface) by its mouth's
boundary loop (:func:`inner_lip_margins`).

The gap at a point of one lip's inner margin is its 3-D distance from the other lip's inner
margin (the polyline through its vertices, corner to corner); it is measured at every margin
vertex but the two corners (which both lips share, or nearly), on both lips. Millimetres, head
frame (+x the subject's left, +y up, +z forward).

Example
-------
>>> from myoface.face import load_default_face
>>> from myoface.face.lips import rest_lip_gap
>>> gap = rest_lip_gap(load_default_face())
>>> gap.max_mm <= 1.0
True
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from myoface.errors import MyofaceValueError

#: landmark groups of the inner lip margins (corner to corner, corners shared)
MARGIN_GROUPS = ("lip_upper_inner", "lip_lower_inner")
#: a boundary loop needs this many vertices to be taken for a mouth (a slit with at least two
#: vertices on each lip between the corners); smaller loops are holes in a mesh
MIN_MOUTH_LOOP = 6
#: a mouth's loop lies on the face's midline: its centre within this fraction of the face's
#: width of the face's centre in x (the eyes' loops lie a quarter of the width out)
MIDLINE_FRACTION = 0.05
#: a relaxed, closed mouth: the inner lips at most this far apart along the whole mouth (mm);
#: the personal faces made from a photo or a scan rest at 0-0.5 mm
CLOSED_MAX_MM = 1.0


@dataclass(frozen=True)
class LipGap:
    """The inner lips' distance along the mouth.

    Attributes
    ----------
    gaps_mm : (K,) float ndarray — at each measured margin vertex (upper lip's first), mm.
    x_mm : (K,) float ndarray — the measured vertices' x (mm), where along the mouth.
    vertices : (K,) int ndarray — the measured vertices.
    source : str — where the margins came from: ``"landmarks"`` or ``"mouth loop"``.
    """

    gaps_mm: np.ndarray
    x_mm: np.ndarray
    vertices: np.ndarray
    source: str

    @property
    def min_mm(self) -> float:
        return float(self.gaps_mm.min())

    @property
    def median_mm(self) -> float:
        return float(np.median(self.gaps_mm))

    @property
    def max_mm(self) -> float:
        return float(self.gaps_mm.max())

    @property
    def closed(self) -> bool:
        """The lips together along the whole mouth (every gap at most :data:`CLOSED_MAX_MM`)."""
        return self.max_mm <= CLOSED_MAX_MM

    def text(self) -> str:
        """E.g. ``"min 0.00 / median 0.20 / max 0.31 mm (closed; landmarks)"``."""
        state = "closed" if self.closed else "apart"
        return (
            f"min {self.min_mm:.2f} / median {self.median_mm:.2f} / max {self.max_mm:.2f} mm "
            f"({state}; {self.source})"
        )


def distance_to_polyline(points: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Distance (N,) mm of points (N, 3) from the polyline through ``line`` (K, 3), K >= 2."""
    p = np.asarray(points, dtype=np.float64)
    q = np.asarray(line, dtype=np.float64)
    a, ab = q[:-1], q[1:] - q[:-1]
    den = np.maximum(np.einsum("kj,kj->k", ab, ab), 1e-300)
    t = np.clip(np.einsum("nkj,kj->nk", p[:, None, :] - a[None], ab) / den, 0.0, 1.0)
    return np.linalg.norm(a[None] + t[..., None] * ab[None] - p[:, None, :], axis=2).min(axis=1)


def _mouth_loop(face) -> np.ndarray | None:
    """The boundary loop of ``face`` that is its mouth: not the outer rim (the longest loop),
    at least :data:`MIN_MOUTH_LOOP` vertices, centred on the face's midline, the lowest such."""
    loops = sorted(face.boundary_loops, key=len, reverse=True)[1:]
    v = np.asarray(face.vertices, dtype=np.float64)
    cx = 0.5 * (v[:, 0].min() + v[:, 0].max())
    width = float(np.ptp(v[:, 0]))
    cand = [
        b
        for b in loops
        if len(b) >= MIN_MOUTH_LOOP and abs(v[b, 0].mean() - cx) <= MIDLINE_FRACTION * width
    ]
    if not cand:
        return None
    return min(cand, key=lambda b: float(v[b, 1].mean()))


def _split_loop(v: np.ndarray, loop: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A mouth's loop cut at its corners (its extremes in x) into the upper and lower margins,
    each from the corner at lower x to the other, corners in both."""
    loop = np.asarray(loop, dtype=np.int64)
    i0, i1 = int(np.argmin(v[loop, 0])), int(np.argmax(v[loop, 0]))
    rolled = np.roll(loop, -i0)
    k = (i1 - i0) % len(loop)
    a = rolled[: k + 1]
    b = np.r_[rolled[k:], rolled[:1]][::-1]
    if v[a, 1].mean() >= v[b, 1].mean():
        return a, b
    return b, a


def inner_lip_margins(face) -> tuple[np.ndarray, np.ndarray, str] | None:
    """The inner margins of the upper and lower lip of ``face`` (a FaceMesh): vertex indices
    from one corner to the other, and where they came from (``"landmarks"``: the groups
    :data:`MARGIN_GROUPS`; ``"mouth loop"``: the mouth's boundary loop cut at its corners).
    None when the face has neither."""
    lm = face.landmarks
    if all(k in lm and len(lm[k]) >= 3 for k in MARGIN_GROUPS):
        return (
            np.asarray(lm[MARGIN_GROUPS[0]], dtype=np.int64),
            np.asarray(lm[MARGIN_GROUPS[1]], dtype=np.int64),
            "landmarks",
        )
    loop = _mouth_loop(face)
    if loop is None:
        return None
    up, lo = _split_loop(np.asarray(face.vertices, dtype=np.float64), loop)
    if min(len(up), len(lo)) < 3:  # not a slit between two lips
        return None
    return up, lo, "mouth loop"


def lip_gap(vertices: np.ndarray, upper, lower, source: str = "") -> LipGap:
    """The inner lips' gap along the mouth for skin ``vertices`` (V, 3) mm.

    Parameters
    ----------
    vertices : (V, 3) float ndarray — mm.
    upper, lower : (K,), (L,) int — the lips' inner margins, corner to corner (at least 3
        vertices each).
    source : str — recorded in the result.

    Returns
    -------
    LipGap
        At each margin vertex but the first and last of each margin: its distance from the
        other margin's polyline (mm).
    """
    v = np.asarray(vertices, dtype=np.float64)
    up, lo = np.asarray(upper, dtype=np.int64), np.asarray(lower, dtype=np.int64)
    if len(up) < 3 or len(lo) < 3:
        raise MyofaceValueError(
            f"each inner lip margin needs at least 3 vertices; got {len(up)} and {len(lo)}"
        )
    gaps = np.r_[distance_to_polyline(v[up[1:-1]], v[lo]), distance_to_polyline(v[lo[1:-1]], v[up])]
    idx = np.r_[up[1:-1], lo[1:-1]]
    return LipGap(gaps, v[idx, 0].copy(), idx, source)


def rest_lip_gap(face) -> LipGap | None:
    """The inner lips' gap of ``face`` (a FaceMesh) at rest, or None when it has no mouth
    (neither lip landmark groups nor a mouth opening). See :func:`lip_gap`."""
    m = inner_lip_margins(face)
    if m is None:
        return None
    up, lo, source = m
    return lip_gap(face.vertices, up, lo, source)
