"""The paper's 2-D scheme on MediaPipe's points: the landmark tracker with the paper's 12
muscles, read from the fiducials' displacements in a 2-D head frame (Terzopoulos & Waters
1993, Section V-C) instead of the 3-D fit."""

from __future__ import annotations

import numpy as np

from myoface.analysis.estimate import ContractionEstimator
from myoface.analysis.landmarks import (
    _apply_similarity,
    contours_from_landmarks,
    fit_similarity,
    rigid_vertices,
)
from myoface.analysis.sections import PAPER_MUSCLES, SECTIONS, model_fiducials
from myoface.analysis.trackers.base import FrameMeasurement, TrackerBase
from myoface.errors import MyofaceValueError
from myoface.facemesh import FaceMeshDetector


class PaperLandmarkTracker(TrackerBase):
    """The analysis loop with MediaPipe's face mesh as the feature tracker instead of snakes.

    Beyond the paper: the detector gives every frame the 468 points of the default face's
    topology, so the fiducials are read at the very vertices the estimator's forward model
    uses (no sliding along contours). The head frame is the similarity (translation, scale,
    in-plane rotation) that best maps the current frame's rigid points (vertices that no
    muscle moves, :func:`rigid_vertices`) onto the calibration frame's. Frames without a face
    are reported (``quality="no_face"``) with empty values; the calibration frame is the first
    frame with a face.

    ``measure(frame, index, time_s)`` returns the same
    :class:`~myoface.analysis.trackers.base.FrameMeasurement` as the snake
    :class:`~myoface.analysis.trackers.snakes.Analyzer`; its contours are the sections read off the
    detected points (for the overlay).
    """

    def __init__(self, model, muscle_ids=None, refine: int = 1, detector=None):
        if model.face.n_vertices != 468:
            raise MyofaceValueError(
                "the landmark tracker needs a face model with MediaPipe's 468-point topology "
                f"(the default face); this one has {model.face.n_vertices} vertices"
            )
        self.model = model
        self.refine = int(refine)
        self.ids = tuple(PAPER_MUSCLES if muscle_ids is None else muscle_ids)
        self.sections = [s for s in SECTIONS if s != "hairline"]
        self.fiducials = [
            f for f in model_fiducials(model.face) if not f.name.startswith(("hairline", "nose"))
        ]
        self.estimator = ContractionEstimator(model, self.fiducials, self.ids)
        self.rigid = rigid_vertices(model)
        self.detector = detector if detector is not None else FaceMeshDetector(video=True)
        self.mm_per_px = None
        self._ref = None  # calibration points (468, 2)
        self._p0 = None

    def describe(self) -> dict:
        return {"init": "MediaPipe face mesh on every frame", "mm_per_px": self.mm_per_px,
                "refine": self.refine}  # fmt: skip

    def measure(self, frame, index: int = 0, time_s: float = 0.0, observation=None):
        pts = self.detector.detect(frame)
        nan = np.full(len(self.ids), np.nan)
        if pts is None:  # (before a face is seen, calibration waits for the first face)
            return FrameMeasurement(index, time_s, "no_face", nan, np.full(2, np.nan), {}, 0)
        xy = pts[:, :2]
        contours = contours_from_landmarks(self.model.face, xy, self.sections)
        if self._ref is None:
            self._ref = xy.copy()
            model_xy = self.model.face.vertices[:, :2] * np.array([1.0, -1.0])
            s, _, _ = fit_similarity(xy, model_xy)
            self.mm_per_px = float(abs(s))
            self._p0 = self.estimator.weights @ xy
        # the current frame mapped into the calibration frame by its rigid points
        s, ms, md = fit_similarity(xy[self.rigid], self._ref[self.rigid])
        cal = _apply_similarity(s, ms, md, xy)
        d_mm = (self.estimator.weights @ cal - self._p0) * self.mm_per_px * np.array([1.0, -1.0])
        c = self.estimator.estimate(d_mm, refine=self.refine)
        # head motion (calibration -> current): the rigid points' centroid shift, and the
        # scale and rotation of the inverse map
        inv = 1.0 / s
        head_t = ms - md
        return FrameMeasurement(
            index,
            time_s,
            "ok",
            c,
            np.asarray(head_t, dtype=np.float64),
            contours,
            0,
            float(abs(inv)),
            float(np.angle(inv)),
        )

    def close(self) -> None:
        self.detector.close()
