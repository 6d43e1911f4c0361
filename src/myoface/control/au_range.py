"""The range of motion of each FACS action unit: the model's against published human values.

Each action unit is relaxed alone at full intensity (``au_contractions({au: 1.0})``) and the
displacement of its measured points (MediaPipe vertex indices, so any face in that topology) is
compared with the range reported for real faces in ``data/au_range.toml`` (with its sources).

The jaw's openings (AU26, AU27) are measured as the clinic measures a mouth opening: the
distance between the upper and lower central incisors' edges at the midline (quantity
``"interincisal"``; the model's teeth, :mod:`myoface.face.teeth`, the lower ones carried by the
jaw), not between the lips, which part less than the teeth (they roll over them).

Directions are in the head frame (+x the subject's left, +y up, +z forward), each point's x
mirrored so that +x is lateral (away from the midline) on both sides:
``lateral/medial``, ``up/down``, ``forward/back``.

Example
-------
>>> import myoface as mf
>>> from myoface.control.au_range import measure_au_ranges, au_range_within
>>> rows = measure_au_ranges(mf.build_face_model())
>>> au_range_within(rows)          # fraction of the AUs with a published range that lie in it
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources

import numpy as np

from myoface.control.facs import au_contractions, au_table
from myoface.errors import MyofaceValueError
from myoface.model import build_face_model

#: the signed axes a direction may name, as (component index, sign) in (lateral, up, forward)
AXES = {
    "lateral": (0, 1.0),
    "medial": (0, -1.0),
    "up": (1, 1.0),
    "down": (1, -1.0),
    "forward": (2, 1.0),
    "back": (2, -1.0),
}
QUANTITIES = ("displacement", "opening", "interincisal")
#: points within this distance (mm) of the midline have no lateral side: their x is not mirrored
MIDLINE_MM = 1.0


@dataclass(frozen=True)
class AURange:
    """One row of ``data/au_range.toml``: what is measured for an AU and the human reference.

    Attributes
    ----------
    au : int — FACS action unit number.
    points : tuple of str — names of the measured points (none for ``"interincisal"``: the
        teeth's edges are measured).
    vertices : tuple of int — their MediaPipe vertex indices.
    quantity : {"displacement", "opening", "interincisal"}
    direction : tuple of str — signed axes of the published motion (see :data:`AXES`).
    range_mm : (low, high) mm, or None when no published value was found.
    source : str — the publication of the range ("" when none).
    note : str
    """

    au: int
    points: tuple[str, ...]
    vertices: tuple[int, ...]
    quantity: str
    direction: tuple[str, ...]
    range_mm: tuple[float, float] | None
    source: str
    note: str

    @property
    def published(self) -> bool:
        return self.range_mm is not None


@dataclass(frozen=True)
class AURangeResult:
    """The model's motion for one AU beside its reference.

    Attributes
    ----------
    ref : AURange
    value_mm : float — the measured quantity (mm).
    mean_mm : (3,) float — mean displacement of the points, (lateral, up, forward) mm.
    converged : bool — whether the tissue's relax converged.
    """

    ref: AURange
    value_mm: float
    mean_mm: np.ndarray
    converged: bool

    @property
    def dominant(self) -> str:
        """The signed axis of the largest component of :attr:`mean_mm`."""
        k = int(np.argmax(np.abs(self.mean_mm)))
        sign = 1.0 if self.mean_mm[k] >= 0 else -1.0
        return next(a for a, (i, s) in AXES.items() if i == k and s == sign)

    @property
    def direction_ok(self) -> bool:
        """The dominant component is one of the reference's axes, and each of those axes has
        its sign."""
        ok_signs = all(AXES[a][1] * self.mean_mm[AXES[a][0]] > 0 for a in self.ref.direction)
        return ok_signs and self.dominant in self.ref.direction

    @property
    def within(self) -> bool | None:
        """Inside the published range (None when there is none)."""
        if self.ref.range_mm is None:
            return None
        lo, hi = self.ref.range_mm
        return bool(lo <= self.value_mm <= hi)

    def direction_text(self) -> str:
        """E.g. ``"up 9.1, lateral 3.8, back 5.2"`` (mm), largest first."""
        parts = []
        for k in np.argsort(-np.abs(self.mean_mm)):
            v = float(self.mean_mm[k])
            name = next(a for a, (i, s) in AXES.items() if i == k and s * v >= 0)
            parts.append(f"{name} {abs(v):.1f}")
        return ", ".join(parts)


def _check(au: int, cond: bool, what: str) -> None:
    if not cond:
        raise MyofaceValueError(f"au_range.toml, AU{au}: {what}")


@lru_cache(maxsize=1)
def au_ranges() -> tuple[AURange, ...]:
    """The reference table ``data/au_range.toml``, checked, in file order."""
    doc = tomllib.loads((resources.files("myoface") / "data" / "au_range.toml").read_text())
    return parse_au_ranges(doc)


def parse_au_ranges(doc: dict) -> tuple[AURange, ...]:
    """Check and convert a parsed ``au_range.toml`` (``{"points": ..., "au": [...]}``).

    Raises
    ------
    MyofaceValueError
        Naming the AU and what is wrong (unknown AU or point, a range without a source, neither
        a range nor a note saying why there is none, ...).
    """
    points = {str(k): int(v) for k, v in doc["points"].items()}
    table = au_table()
    out = []
    for row in doc["au"]:
        au = int(row["au"])
        _check(au, au in table, "not in the AU table")
        names = tuple(row.get("points", ()))
        q = row["quantity"]
        _check(au, q in QUANTITIES, f"quantity must be one of {QUANTITIES}; got {q!r}")
        _check(au, len(names) > 0 or q == "interincisal", "no points")
        _check(au, q != "interincisal" or not names, "an interincisal opening takes no points")
        _check(au, all(n in points for n in names), f"unknown point in {names}")
        _check(au, q != "opening" or len(names) == 2, "an opening needs exactly two points")
        direction = tuple(row["direction"])
        _check(au, all(d in AXES for d in direction), f"direction must name {tuple(AXES)}")
        rng = row.get("range_mm")
        published = row.get("published", rng is not None)
        _check(au, published == (rng is not None), "range_mm given but published = false")
        if rng is not None:
            _check(au, len(rng) == 2 and 0 <= rng[0] <= rng[1], f"bad range_mm {rng}")
            _check(au, bool(row.get("source")), "a range without a source")
        else:
            _check(au, bool(row.get("note")), "no range and no note saying why")
        out.append(
            AURange(
                au,
                names,
                tuple(points[n] for n in names),
                q,
                direction,
                None if rng is None else (float(rng[0]), float(rng[1])),
                str(row.get("source", "")),
                str(row.get("note", "")),
            )
        )
    return tuple(out)


def _lateral_frame(rest: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Displacements (N, 3) in (lateral, up, forward): x mirrored on the subject's right."""
    side = np.where(rest[:, 0] < -MIDLINE_MM, -1.0, 1.0)
    return d * np.column_stack([side, np.ones_like(side), np.ones_like(side)])


def incisal_edges(dentition, jaw_pose=None) -> np.ndarray:
    """The upper and lower central incisors' edges at the midline, (2, 3) mm (head frame): the
    upper fixed to the skull, the lower moved by the mandible's rigid motion ``jaw_pose``
    (``(rotation (3, 3), translation (3,) mm)``, :meth:`myoface.model.FaceModel.jaw_pose`;
    None: rest). ``dentition``: :class:`myoface.face.teeth.Dentition`."""
    up, lo = dentition.upper, dentition.lower
    upper = np.array([up.xc, up.edge_y, up.z0])
    lower = np.array([lo.xc, lo.edge_y, lo.z0])
    if jaw_pose is not None:
        rot, shift = jaw_pose
        lower = np.asarray(rot) @ lower + np.asarray(shift)
    return np.stack([upper, lower])


def measure_au_range(
    ref: AURange, rest: np.ndarray, moved: np.ndarray, incisors: np.ndarray | None = None
) -> tuple[float, np.ndarray]:
    """The quantity (mm) and mean (lateral, up, forward) displacement (3,) mm of ``ref``'s points
    between skin vertices ``rest`` (V, 3) mm and ``moved`` (V, 3) mm (head frame).

    For an ``"interincisal"`` quantity, ``incisors`` (2, 2, 3) mm are the incisal edges
    (:func:`incisal_edges`, upper then lower) at rest and moved: the value is the distance
    between the edges when moved (what a ruler between the teeth reads, as in the clinic), the
    direction the lower edge's motion relative to the upper's."""
    if ref.quantity == "interincisal":
        if incisors is None:
            raise MyofaceValueError(f"AU{ref.au}: an interincisal opening needs the incisors")
        (u0, l0), (u1, l1) = np.asarray(incisors, dtype=np.float64)
        return float(np.linalg.norm(u1 - l1)), (l1 - l0) - (u1 - u0)
    idx = np.asarray(ref.vertices)
    d = _lateral_frame(rest[idx], moved[idx] - rest[idx])
    if ref.quantity == "opening":
        a, b = idx
        value = float(np.linalg.norm(moved[a] - moved[b]) - np.linalg.norm(rest[a] - rest[b]))
        mean = d[1] - d[0]  # the second point's motion relative to the first
    else:
        value = float(np.linalg.norm(d, axis=1).mean())
        mean = d.mean(axis=0)
    return value, mean


def measure_au_ranges(model=None, aus=None) -> list[AURangeResult]:
    """Relax ``model`` (default: the bundled face) at each AU's full intensity and measure it.

    Parameters
    ----------
    model : FaceModel, optional
        A face in MediaPipe face-mesh topology (the points are its vertex indices).
    aus : iterable of int, optional
        Only these AUs (default: every row of the table).

    Returns
    -------
    list of AURangeResult, in the table's order.
    """
    if model is None:
        model = build_face_model()
    refs = [r for r in au_ranges() if aus is None or r.au in set(aus)]
    nv = model.face.n_vertices
    bad = [r.au for r in refs if r.vertices and max(r.vertices) >= nv]
    if bad:
        raise MyofaceValueError(
            f"the AU range points are MediaPipe face-mesh vertices; this face has {nv} vertices "
            f"(AUs {bad} cannot be measured)"
        )
    if any(r.quantity == "interincisal" for r in refs) and model.dentition is None:
        raise MyofaceValueError("an interincisal opening needs a face with teeth (lip landmarks)")
    rest = model.skin_vertices()
    out = []
    for ref in refs:
        res = model.relax(au_contractions({ref.au: 1.0}, model.ids))
        incisors = None
        if ref.quantity == "interincisal":
            incisors = np.stack(
                [
                    incisal_edges(model.dentition),
                    incisal_edges(model.dentition, model.jaw_pose(res.state)),
                ]
            )
        value, mean = measure_au_range(ref, rest, model.skin_vertices(res.state), incisors)
        out.append(AURangeResult(ref, value, mean, bool(res.converged)))
    return out


def au_range_within(results) -> float:
    """Fraction of the AUs with a published range whose measured value lies inside it."""
    judged = [r.within for r in results if r.within is not None]
    if not judged:
        raise MyofaceValueError("no AU with a published range was measured")
    return float(np.mean(judged))
