"""The paper's analysis loop: face video -> snakes on nine feature contours -> fiducials in a
head frame -> muscle contractions and jaw rotation per frame (Terzopoulos & Waters 1993,
Section V).

Contours (the paper's nine sections) and the model's landmark groups they follow:

=================  ===================  ==========================================
section            landmark group       node order in the image (frontal view)
=================  ===================  ==========================================
hairline           forehead_top         image left -> right
eyebrow_r          eyebrow_r            inner -> outer (image right -> left)
eyebrow_l          eyebrow_l            inner -> outer (image left -> right)
nasolabial_r       nasolabial_r         top -> bottom
nasolabial_l       nasolabial_l         top -> bottom
nose               nose_base            image left -> right
upper_lip          lip_upper_outer      image left -> right (corner to corner)
lower_lip          lip_lower_outer      image left -> right (corner to corner)
chin               chin_outline         image left -> right (the lower edge of the chin)
=================  ===================  ==========================================

``_l`` / ``_r`` are the subject's left / right (the subject's left is on the image's right).
Each landmark vertex of a section is tied to the contour at the same fraction of arc length as
it has along the model's (front-projected) landmark polyline, so the tracked contours give one
image point per landmark vertex: the fiducials. Their displacements from the calibration frame,
in the head frame (translation of the head reference contour removed, pixels scaled to mm with
the model's size), are inverted to contractions by
:class:`~myoface.analysis.estimate.ContractionEstimator`.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from myoface.analysis.estimate import PAPER_ASSIGNMENT, ContractionEstimator, Fiducial
from myoface.analysis.potentials import image_potential
from myoface.analysis.snakes import SnakeParams, Snakes, make_contours, resample_polyline
from myoface.errors import MyofaceFileNotFoundError, MyofaceFormatError, MyofaceValueError

SECTIONS = {
    "hairline": "forehead_top",
    "eyebrow_r": "eyebrow_r",
    "eyebrow_l": "eyebrow_l",
    "nasolabial_r": "nasolabial_r",
    "nasolabial_l": "nasolabial_l",
    "nose": "nose_base",
    "upper_lip": "lip_upper_outer",
    "lower_lip": "lip_lower_outer",
    "chin": "chin_outline",
}
#: the muscles the paper estimates, plus the jaw
PAPER_MUSCLES = tuple(PAPER_ASSIGNMENT)
#: a frame is unusable when more than this fraction of a contour's nodes escaped its edge
ESCAPE_LIMIT = 0.5
#: sections whose mean motion defines the head translation (the paper: the hairline)
HEAD_REFERENCE = ("hairline",)


def _arc_fractions(points: np.ndarray) -> np.ndarray:
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    return s / s[-1] if s[-1] > 0 else np.linspace(0, 1, len(points))


def _at_fractions(nodes: np.ndarray, fractions: np.ndarray) -> np.ndarray:
    f = _arc_fractions(nodes)
    return np.column_stack(
        [np.interp(fractions, f, nodes[:, 0]), np.interp(fractions, f, nodes[:, 1])]
    )


# ------------------------------------------------------------------------------ init files


def load_init(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read an initial-contours file: ``{"contours": {section: [[x, y], ...], ...}}`` (pixels
    of the calibration frame, (x, y) = (column, row)); see :data:`SECTIONS` for the names and
    the node order. Sections may be left out."""
    p = Path(path)
    if not p.is_file():
        raise MyofaceFileNotFoundError(f"no such contour file: {p}")
    try:
        doc = json.loads(p.read_text())
    except json.JSONDecodeError as exc:
        raise MyofaceFormatError(f"{p}: not valid JSON: {exc}") from None
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
        except (TypeError, ValueError):
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
    from myoface._io import atomic_output

    doc = {
        "note": note or "initial contours, pixels (x, y) of the calibration frame",
        "contours": {k: np.round(v, 2).tolist() for k, v in contours.items()},
    }
    with atomic_output(path) as tmp:
        tmp.write_text(json.dumps(doc, indent=1))


def project_sections(model, camera) -> dict[str, np.ndarray]:
    """The model's sections projected by ``camera`` (for synthetic video whose camera is
    known, e.g. the closed-loop test: an exact automatic initialisation)."""
    v = camera.project(model.skin_vertices())[:, :2]
    return {name: v[model.face.landmark(group)] for name, group in SECTIONS.items()}


# ------------------------------------------------------------------------------ the analyzer


@dataclass
class FrameMeasurement:
    index: int
    time_s: float
    quality: str  # "ok", or why the frame could not be measured
    contractions: np.ndarray  # (M,) over Analyzer.ids, NaN when not measured
    head_shift_px: np.ndarray  # (2,)
    contours: dict = field(repr=False, default_factory=dict)
    iterations: int = 0


class Analyzer:
    """Tracks the feature contours of a face video and estimates contractions per frame.

    Parameters
    ----------
    model : FaceModel — its muscles are estimated; its face gives the landmark groups.
    init : {section: (K, 2)} initial contours in the calibration frame (pixels).
    muscle_ids : muscles to estimate (default: the paper's 12 + jaw).
    method : "model" (joint, through the physics; default) or "paper" (each muscle from one
        fiducial, the paper's scheme).
    refine : Gauss-Newton corrections per frame with the ``"model"`` method.
    sigma : Gaussian width (px) of the image potential.
    """

    def __init__(
        self,
        model,
        init: dict[str, np.ndarray],
        muscle_ids=PAPER_MUSCLES,
        method: str = "model",
        refine: int = 1,
        sigma: float = 1.5,
        params: SnakeParams | None = None,
        spacing_px: float = 1.0,
        potential: str = "gaussian",
    ):
        if method not in ("model", "paper"):
            raise MyofaceValueError(f"method must be 'model' or 'paper'; got {method!r}")
        if not init:
            raise MyofaceValueError("no initial contours")
        self.model = model
        self.method = method
        self.refine = int(refine)
        self.sigma = float(sigma)
        self.potential = potential
        self.sections = [s for s in SECTIONS if s in init]
        face = model.face
        front = face.vertices[:, :2]
        fids, self._ties = [], []
        polylines = []
        for s in self.sections:
            verts = face.landmark(SECTIONS[s])
            fr = _arc_fractions(front[verts])
            poly = resample_polyline(init[s], spacing_px)
            polylines.append(poly)
            self._ties.append(fr)
            fids += [Fiducial(f"{s}:{int(v)}", int(v)) for v in verts]
        self.contours = make_contours(polylines, closed=False, names=self.sections)
        self.params = params or SnakeParams(p=0.01)
        self.snakes = Snakes(self.contours, self.params)
        self.ids = tuple(muscle_ids)
        self.estimator = ContractionEstimator(model, fids, self.ids)
        self.fiducials = fids
        self._p0 = None
        self._ref0 = None
        self.mm_per_px = None

    def _fiducial_points(self, contours: list[np.ndarray]) -> np.ndarray:
        return np.concatenate(
            [_at_fractions(c, fr) for c, fr in zip(contours, self._ties, strict=True)]
        )

    def _head_ref(self, contours: list[np.ndarray]) -> np.ndarray:
        ref = [c for s, c in zip(self.sections, contours, strict=True) if s in HEAD_REFERENCE]
        if not ref:  # no hairline: fall back on the nose
            ref = [c for s, c in zip(self.sections, contours, strict=True) if s == "nose"]
        return np.concatenate(ref).mean(axis=0) if ref else np.zeros(2)

    def measure(self, frame: np.ndarray, index: int = 0, time_s: float = 0.0) -> FrameMeasurement:
        """Track the contours into ``frame`` and estimate its contractions. The first frame
        measured is the neutral calibration frame."""
        pot = image_potential(frame, sigma=self.sigma, method=self.potential)
        res = self.snakes.relax(pot)
        conts = res.split()
        pts = self._fiducial_points(conts)
        ref = self._head_ref(conts)
        sizes = np.diff(self.contours.offsets)
        bad = [
            s
            for s, e, n in zip(self.sections, res.escaped, sizes, strict=True)
            if e > ESCAPE_LIMIT * n
        ]
        if self._p0 is None:
            self._p0, self._ref0 = pts, ref
            face = self.model.face
            model_xy = face.vertices[[f.vertex for f in self.fiducials], :2]
            rms_mm = np.sqrt(((model_xy - model_xy.mean(0)) ** 2).sum(1).mean())
            rms_px = np.sqrt(((pts - pts.mean(0)) ** 2).sum(1).mean())
            if rms_px < 5:
                raise MyofaceValueError("the initial contours are too small (under 5 px)")
            self.mm_per_px = rms_mm / rms_px
        shift = ref - self._ref0
        d_px = pts - self._p0 - shift
        d_mm = d_px * self.mm_per_px * np.array([1.0, -1.0])  # image y points down
        named = dict(zip(self.sections, conts, strict=True))
        if bad:
            return FrameMeasurement(
                index,
                time_s,
                "escaped:" + "+".join(bad),
                np.full(len(self.ids), np.nan),
                shift,
                named,
                res.iterations,
            )
        if self.method == "model":
            c = self.estimator.estimate(d_mm, refine=self.refine)
        else:
            c = self.estimator.estimate_paper(
                d_mm,
                {k: self._paper_fiducial(v) for k, v in PAPER_ASSIGNMENT.items() if k in self.ids},
            )
        return FrameMeasurement(index, time_s, "ok", c, shift, named, res.iterations)

    def _paper_fiducial(self, name: str) -> str:
        """The paper's fiducial name -> our fiducial (section:vertex) that stands for it."""
        from myoface.analysis.estimate import paper_fiducials

        v = {f.name: f.vertex for f in paper_fiducials(self.model.face)}[name]
        for f in self.fiducials:
            if f.vertex == v:
                return f.name
        raise MyofaceValueError(f"fiducial {name} is not on the tracked contours")


def write_contractions_csv(path, ids, frames: list[FrameMeasurement], jaw_max_rad: float) -> None:
    """``frame,time_s,quality,<muscle ids...>,jaw_angle_rad,head_dx_px,head_dy_px`` (empty
    cells where a frame could not be measured)."""
    from myoface._io import atomic_output

    cols = ["frame", "time_s", "quality", *ids, "jaw_angle_rad", "head_dx_px", "head_dy_px"]
    lines = [",".join(cols)]
    for f in frames:
        vals = ["" if not np.isfinite(v) else f"{v:.5f}" for v in f.contractions]
        jaw = ""
        if "jaw" in ids and np.isfinite(f.contractions[ids.index("jaw")]):
            jaw = f"{f.contractions[ids.index('jaw')] * jaw_max_rad:.5f}"
        lines.append(
            ",".join(
                [
                    str(f.index),
                    f"{f.time_s:.4f}",
                    f.quality,
                    *vals,
                    jaw,
                    f"{f.head_shift_px[0]:.3f}",
                    f"{f.head_shift_px[1]:.3f}",
                ]
            )
        )
    with atomic_output(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")


def read_contractions_csv(path, muscle_ids) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """(times (T,), contractions (T, M) over ``muscle_ids`` (missing columns = 0), quality).

    Raises a clear error for a missing time column, a header without any known muscle, and
    NaN or out-of-range values in measured ('ok') rows.
    """
    import csv

    p = Path(path)
    if not p.is_file():
        raise MyofaceFileNotFoundError(f"no such CSV file: {p}")
    with open(p, newline="") as fh:
        rows = list(csv.DictReader(fh))
    if not rows:
        raise MyofaceFormatError(f"{p}: no rows")
    head = list(rows[0].keys())
    tcol = "time_s" if "time_s" in head else "time" if "time" in head else None
    if tcol is None:
        raise MyofaceFormatError(f"{p}: missing column 'time_s' (or 'time')")
    known = [m for m in muscle_ids if m in head]
    if not known:
        raise MyofaceFormatError(f"{p}: no column names a muscle of this face model")
    times = np.empty(len(rows))
    table = np.zeros((len(rows), len(muscle_ids)))
    quality = []
    for k, r in enumerate(rows):
        try:
            times[k] = float(r[tcol])
        except (TypeError, ValueError):
            raise MyofaceFormatError(f"{p}: row {k + 2}: bad time {r[tcol]!r}") from None
        q = r.get("quality", "ok") or "ok"
        quality.append(q)
        for m in known:
            cell = (r.get(m) or "").strip()
            if cell == "" and q != "ok":
                table[k, muscle_ids.index(m)] = np.nan
                continue
            try:
                v = float(cell)
            except ValueError:
                raise MyofaceFormatError(f"{p}: row {k + 2}: bad value {cell!r} for {m}") from None
            if not np.isfinite(v) or not 0 <= v <= 1:
                raise MyofaceFormatError(
                    f"{p}: row {k + 2}: {m} must be a number in [0, 1]; got {cell!r}"
                )
            table[k, muscle_ids.index(m)] = v
    if not np.isfinite(times).all() or np.any(np.diff(times) < 0):
        raise MyofaceFormatError(f"{p}: times must be finite and non-decreasing")
    return times, table, quality
