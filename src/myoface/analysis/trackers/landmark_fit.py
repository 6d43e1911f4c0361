"""The landmark tracker with the 3-D fit: MediaPipe's face mesh on every frame, the whole face
model (head pose and every muscle) fitted to its points
(:class:`~myoface.analysis.modelfit.ModelFit`)."""

from __future__ import annotations

import itertools
import threading
import time
from concurrent.futures import Future
from dataclasses import asdict, dataclass, field, replace
from typing import ClassVar, NamedTuple

import numpy as np

from myoface._threads import OrderedWorker, run_ahead
from myoface.analysis.camera import POSE_COLUMNS, HeadPose, PinholeCamera
from myoface.analysis.flow import FlowDetector, FlowRefiner
from myoface.analysis.gaze import GAZE_COLUMNS, GAZE_STATE_COLUMNS, Gaze, GazeEstimator
from myoface.analysis.landmarks import TrackerOffsets
from myoface.analysis.modelfit import (
    CALIBRATION_FRAMES,
    CALIBRATION_WINDOW_S,
    REGISTRATION_SPAN,
    Calibration,
    ModelFit,
    calibration_frames,
    choose_calibration_frame,
    registers_appearance,
    registration_frames,
)
from myoface.analysis.modelflow import FLOW_METHODS, ModelFlow
from myoface.analysis.sections import SECTIONS, section_vertices
from myoface.analysis.synthesis import LandmarkSynthesis
from myoface.analysis.trackers.base import NOT_OBSERVED, Measurement, TrackerBase
from myoface.analysis.weights import FitSettings
from myoface.errors import MyofaceValueError
from myoface.facemesh import DETECT_AHEAD_FRAMES, FaceMeshDetector, import_mediapipe

#: how the landmark tracker's contractions are estimated: the 3-D fit (default), the 3-D fit
#: with analysis by synthesis (:class:`LandmarkSynthesis`), or the paper's 2-D head frame and
#: 12 muscles (:class:`~myoface.analysis.trackers.landmark_paper.PaperLandmarkTracker`)
LANDMARK_ESTIMATORS = ("fit", "fit-synthesis", "paper")
#: a frame whose landmarks stay farther than this (mm RMS) from the fitted model is not
#: measured (``quality="misfit"``): MediaPipe lost the face, or the face is not the model's
MISFIT_RMS_MM = 6.0
#: the same with the photometric term, which weighs MediaPipe's points a tenth: the fit then
#: follows the pixels where the points are wrong, and their distance from it is MediaPipe's
#: error as much as the fit's (measured 2026-12-04, the degraded head-motion renders, head
#: turning to 30 deg: up to 6.4 mm RMS with the fit's skin within 0.93 mm of the truth; a
#: lost face puts them tens of mm away)
MISFIT_RMS_MM_PHOTOMETRIC = 10.0
#: with the photometric term, a frame where more than this share of the face's visible,
#: textured patches do not look as they did at calibration is not measured
#: (``quality="occluded"``: a hand over the mouth is not an expression), and the next frame is
#: fitted from the last measured one
OCCLUDED_FRACTION = 0.15
# (measured 2026-12-01: on single_face.mp4's real smile the share is at most 0.086, 90 % of
# frames under 0.064; a skin-toned blob over the mouth and chin of the known-warp smile makes
# it 0.17-0.18, the frames around it 0.0. 2026-12-04, the patches compared with the
# appearance under the frame's light (photometric.OCCLUSION_LIT): the real smile at most
# 0.068, the blob 0.19-0.21, the head-motion renders, head turning to 30 deg and every frame
# fitted, at most 0.122 clean and degraded (0.197 and 0.168 against the calibration frame's
# brightness, which the turning head's shading changes), where 0.12 had marked frames occluded)


def frame_quality(result, photometric: bool) -> str:
    """How :class:`FitTracker` takes a frame's fit ``result`` (a
    :class:`~myoface.analysis.modelfit.FrameFit`): ``"occluded"`` (the photometric term's share
    of patches unlike the appearance over :data:`OCCLUDED_FRACTION`), ``"misfit"`` (the
    landmarks farther from the model than :data:`MISFIT_RMS_MM`, or with the photometric term
    :data:`MISFIT_RMS_MM_PHOTOMETRIC`) or ``"ok"`` (measured). The benchmarks that fit frames
    themselves (:func:`~myoface.bench.headmotion.run_headmotion`) take them alike."""
    if result.occlusion > OCCLUDED_FRACTION:
        return "occluded"
    limit = MISFIT_RMS_MM_PHOTOMETRIC if photometric else MISFIT_RMS_MM
    if not result.residual_mm <= limit:
        return "misfit"
    return "ok"


#: while the calibration's window is still being detected and scored, measure its frames on
#: the calibration the frames scored so far choose (:class:`_Speculation`): kept when the
#: whole window chooses the same frames, else measured again. The results are the same
#: either way (the same calibration, the same frames fitted in the same order); the
#: measuring is done while MediaPipe detects the window's later frames instead of after.
#: Not with the optical flow or analysis by synthesis (their trackers start at calibration).
SPECULATE = True
#: provisional calibrations tried at most in one window (each costs an identity fit)
MAX_SPECULATIONS = 3


def _flow_method(method: str | None) -> str:
    from myoface.analysis import modelflow

    method = modelflow.FLOW_METHOD if method is None else method
    if method not in FLOW_METHODS:
        raise MyofaceValueError(f"flow_method must be one of {FLOW_METHODS}; got {method!r}")
    return method


class LandmarkObservation(NamedTuple):
    """What :meth:`FitTracker.observe` sees on a frame with a face: MediaPipe's ``points``
    (468, 3), and ``flow``, ``(xy (468, 2), tracked (468,) bool)`` where optical flow tracked
    them (:attr:`~myoface.analysis.weights.FitSettings.flow`; else None; with the
    model-anchored tracker run ahead, a :class:`~concurrent.futures.Future` of it, which
    :meth:`FitTracker.measure` waits for); ``prepared``: not used (kept for callers that
    build observations)."""

    points: np.ndarray
    flow: tuple | None = None
    prepared: tuple | None = None

    @property
    def seen(self) -> np.ndarray:
        """The points, at the flow's position where it tracked them."""
        if self.flow is None:
            return self.points
        xy, ok = self.flow
        out = np.array(self.points, dtype=np.float64)
        out[ok, :2] = xy[ok]
        return out


@dataclass
class FitMeasurement(Measurement):
    """One frame of the 3-D fit: a :class:`~myoface.analysis.trackers.base.Measurement`
    with the head's ``pose`` (None when not measured) and the fit's ``residual_mm`` (its
    CSV columns, :attr:`HEAD_COLUMNS`), and the model's contours for the overlay."""

    pose: HeadPose | None = None
    residual_mm: float = float("nan")
    contours: dict = field(repr=False, default_factory=dict)
    iterations: int = 0
    #: the photometric term's share of patches that do not look as they did at calibration
    #: (:attr:`~myoface.analysis.modelfit.FrameFit.occlusion`)
    occlusion: float = float("nan")
    #: each eye's gaze (:class:`~myoface.analysis.gaze.GazeEstimator`), on measured frames
    gaze: Gaze | None = None

    HEAD_COLUMNS: ClassVar[tuple] = (
        *POSE_COLUMNS, "residual_mm", *GAZE_COLUMNS, *GAZE_STATE_COLUMNS,
    )  # fmt: skip

    def head_cells(self) -> list[str]:
        """The values of :data:`HEAD_COLUMNS` as CSV cells (empty when not measured)."""
        if self.pose is None:
            return [""] * len(self.HEAD_COLUMNS)
        vals = [*self.pose.columns().values(), self.residual_mm]
        cells = ["" if not np.isfinite(v) else f"{v:.3f}" for v in vals]
        n_gaze = len(GAZE_COLUMNS) + len(GAZE_STATE_COLUMNS)
        return cells + (self.gaze.cells() if self.gaze is not None else [""] * n_gaze)


def _passed_over(frames, n: int):
    """``frames`` with their first ``n`` taken but given as None (passed over: not kept, not
    detected), then the next one; nothing after it."""
    it = iter(frames)
    for _ in range(n):
        if next(it, _END) is _END:
            return
        yield None
    frame = next(it, _END)
    if frame is not _END:
        yield frame


_END = object()


class FitTracker(TrackerBase):
    """The landmark tracker with the 3-D fit: MediaPipe's face mesh on every frame (detection
    on each, or tracking with :attr:`FitSettings.tracking`), :class:`ModelFit` on its points.
    ``measure(frame, index, time_s)`` returns a :class:`FitMeasurement`; frames without a face
    are ``quality="no_face"`` (the next face starts the fit afresh).

    Parameters
    ----------
    model : FaceModel in the default topology (never changed).
    fps : the video's frame rate.
    camera : PinholeCamera, or None: a vertical field of view of :data:`DEFAULT_FOV_DEG` on the
        first frame's size.
    settings : FitSettings.
    detector : an object with ``detect(frame) -> (468, 3) | None`` and ``close()`` (default:
        MediaPipe's face mesh, in the mode :attr:`FitSettings.tracking` says).
    synthesis : analysis by synthesis (:class:`LandmarkSynthesis`, made at calibration): the
        face model's own texture if it has one (e.g. ``face from-photo``), else the
        calibration frame.
    deferred_relax : relax the tissue at a frame's estimate on a second thread while the
        next frame is fitted, once its skin has moved :attr:`FitSettings.relax_step_mm` since
        the last relax (:meth:`ModelFit.fit` ``deferred=True``; what a video analysis does,
        what a video's analysis does), instead of a second fitting round through it.

    calibration_frame : the frame (its index in the video) to calibrate on; None: the most
        neutral of the first :data:`~myoface.analysis.modelfit.CALIBRATION_WINDOW_S` s from
        the first frame with a face. Either way the analysis starts at the first frame given
        (:meth:`calibrate`): a neutral frame in the middle of a video calibrates the frames
        before it too.

    The driver (:class:`~myoface.analysis.pipeline.Tracking`) runs :meth:`observe`
    (MediaPipe) on a worker thread ahead of :meth:`measure` (the fit).
    """

    OBSERVES_AHEAD = True

    def __init__(self, model, fps: float = 30.0, camera: PinholeCamera | None = None,
                 settings: FitSettings | None = None, detector=None,
                 synthesis: bool = False, deferred_relax: bool = False,
                 calibration_frame: int | None = None, gaze: bool = True,
                 flow_method: str | None = None, flow_lag: int | None = None):  # fmt: skip
        if model.face.n_vertices != 468:
            raise MyofaceValueError(
                "the landmark tracker needs a face model with MediaPipe's 468-point topology "
                f"(the default face); this one has {model.face.n_vertices} vertices"
            )
        self.model = model
        self.ids = tuple(model.ids)
        self.settings = settings or FitSettings()
        self.refine = self.settings.refine
        self.fps = float(fps)
        self._camera = camera
        self.fit: ModelFit | None = None
        self._sections = {s: section_vertices(model.face, s) for s in SECTIONS}
        self._own_detector = detector is None
        if detector is None:
            import_mediapipe()  # (fails now, with the pip command, if it is not installed)
        #: the detector; made when first needed (the calibration hands its own over)
        self._detector = detector
        #: with FitSettings.flow, which tracker reads the points
        #: (:data:`~myoface.analysis.modelflow.FLOW_METHODS`; None: the module's default)
        self.flow_method = _flow_method(flow_method)
        #: the optical flow (FitSettings.flow), read by the fit as a term of its own: the
        #: chained flow on the detector's thread (FlowRefiner), or the model-anchored
        #: tracker (ModelFlow, made at calibration; it runs with the fit, which predicts)
        chained = self.settings.flow and self.flow_method == "chained"
        self._flow = FlowRefiner() if chained else None
        self._anchored: ModelFlow | None = None
        #: the anchored tracker tracks frame k from the fit of frame k - this
        #: (:data:`~myoface.analysis.modelflow.PREDICTION_LAG`), on a thread of its own when
        #: the driver observes ahead (:meth:`observe`)
        from myoface.analysis import modelflow

        self.flow_lag = modelflow.PREDICTION_LAG if flow_lag is None else int(flow_lag)
        if self.flow_lag < 1:
            raise MyofaceValueError(f"flow_lag must be >= 1; got {flow_lag}")
        self._flow_worker: OrderedWorker | None = None
        self._flow_cond = threading.Condition()
        self._flow_closing = False
        #: observations and measurements since the anchored tracker was made (in step: one
        #: of each a frame), and the predictions the measurements left, by that count
        self._n_observed = 0
        self._n_measured = 0
        self._predictions: dict = {}
        self._ok_prediction: tuple = (None, None)  # (the last measured frame's)
        #: whichever refiner counts the flow's points (describe()): ours, or a flow
        #: detector's given to the tracker (which refines its points itself)
        self._refiner = self._flow
        if isinstance(detector, FlowDetector):
            self._refiner = detector.refiner
        #: {frame index: landmarks or None} of the calibration frames, taken by measure()
        self._detected: dict = {}
        #: {frame index: FitMeasurement} measured during the calibration (SPECULATE), and
        #: {frame index: LandmarkObservation} observed then but not measured
        self._speculated: dict = {}
        self._observed_ahead: dict = {}
        #: relax the tissue on a second thread while the next frame is fitted
        #: (:meth:`ModelFit.fit`'s ``deferred``; the tissue then lags the estimate)
        self.deferred_relax = bool(deferred_relax)
        self.calibration: Calibration | None = None
        #: the frame to calibrate on (None: chosen), then the frame calibrated on
        self.calibration_frame: int | None = (
            None if calibration_frame is None else int(calibration_frame)
        )
        self._chosen = calibration_frame is None
        #: None, or neutral frames from anywhere in the video that register the photometric
        #: fit's appearance in place of the calibration window's, ``{frame index: (landmarks,
        #: image)}`` (:meth:`ModelFit.set_appearance`'s ``views``; e.g. a first pass's
        #: :func:`~myoface.analysis.modelfit.neutral_views`); set before the calibration
        self.registration_views: dict | None = None
        self._first_index = 0
        self.how = ""
        self.use_synthesis = bool(synthesis)
        self.synthesis: LandmarkSynthesis | None = None
        #: where the time goes (for the benchmark's breakdown): the calibration's wall time
        #: (s; its MediaPipe, scores and identity fit), and the detector's wall time (s) and
        #: count on the frames after it (on the thread that runs :meth:`observe`)
        #: and with the anchored flow, its frames tracked, its thread CPU (the crop and the
        #: tracking, on whichever thread ran them) and the fit's wait for it (wall)
        self.timings = {"calibration_s": 0.0, "detections": 0, "detect_s": 0.0}
        if self.settings.flow and self.flow_method == "anchored":
            self.timings.update({"flows": 0, "flow_cpu_s": 0.0, "flow_wait_s": 0.0})
        #: each eye's gaze on the measured frames (None: not read)
        self.gaze = GazeEstimator(model.face) if gaze else None

    @property
    def detector(self):
        """The landmark detector (MediaPipe's face mesh unless one was given)."""
        if self._detector is None:
            self._detector = self._new_detector()
        return self._detector

    def _new_detector(self):
        """MediaPipe's face mesh in the mode :attr:`FitSettings.tracking` says."""
        return FaceMeshDetector(video=self.settings.tracking)

    def _observed(self, detector, frame) -> LandmarkObservation | None:
        """``detector``'s points on ``frame`` and, with the flow, where it tracks them (None:
        no face; the flow's tracks then start again)."""
        pts = detector.detect(frame)
        flow = None if self._flow is None else self._flow.track(frame, pts)
        if pts is None:
            return None
        return LandmarkObservation(pts, flow)

    @property
    def mm_per_px(self) -> float | None:
        """mm on the face per pixel at the calibration frame's head distance."""
        if self.calibration is None or self.fit is None:
            return None
        return self.fit._pixel_mm(self.calibration.pose)

    def _ensure_fit(self, shape) -> ModelFit:
        if self.fit is None:
            h, w = shape[:2]
            cam = self._camera or PinholeCamera.for_image(w, h)
            self.fit = ModelFit(self.model, cam, self.settings, fps=self.fps)
        return self.fit

    def _ensure_offsets(self, shape) -> None:
        """The detector's offsets on the person's face (:attr:`FitSettings.tracker_offsets`:
        :class:`~myoface.analysis.landmarks.TrackerOffsets`), given to the fit before it
        calibrates: with a model that has its own texture, without analysis by synthesis
        (which measures them at each frame) and with MediaPipe as the detector (the offsets
        are its own)."""
        fit = self.fit
        if not self._wants_offsets():
            return
        h, w = shape[:2]
        offsets = TrackerOffsets.of_textured_face(
            self.model.face, fit.neutral, fit.camera, (w, h), self.settings.tracking
        )
        if offsets is not None:
            fit.set_offsets(offsets)

    def _wants_offsets(self) -> bool:
        return (
            self.fit.offsets is None
            and self.settings.tracker_offsets
            and not self.use_synthesis
            and self._own_detector
        )

    def _offsets_from_frame(self, frame, points) -> None:
        """For a model without a texture (:attr:`FitSettings.tracker_offsets_frame`): the
        offsets' table rendered with the calibration frame as the texture
        (:meth:`LandmarkSynthesis.from_frame`: the person's calibrated neutral, each vertex
        where the calibration put it on the frame), then the calibration done again on the
        same frame with the points corrected by it (``points``: the calibration's)."""
        fit, cal = self.fit, self.calibration
        if frame is None:
            return
        shape = fit.neutral + fit.identity_mm
        try:
            syn = LandmarkSynthesis.from_frame(
                self.model.face, fit.camera, frame, shape, cal.pose,
                tracking=self.settings.tracking,
            )  # fmt: skip
        except MyofaceValueError:  # (a camera whose principal point is off the centre)
            return
        fit.set_offsets(TrackerOffsets(syn, shape, fit.camera))
        self.calibration = fit.calibrate(points, cal.index, scores=cal.scores)

    def calibrate(self, frames, first_index: int = 0) -> int:
        """The protocol's calibration: on ``frames`` (the video's from ``first_index`` on),
        the most neutral frame of the first :data:`CALIBRATION_WINDOW_S` s from the first
        frame with a face, or the frame :attr:`calibration_frame` (at or after
        ``first_index``: the frames before it are passed over here, neither kept nor
        detected); the analysis starts at the first frame given (returns 0)."""
        what = "the 3-D fit" + (" with analysis by synthesis" if self.use_synthesis else "")
        if self._chosen:
            window = max(1, int(round(CALIBRATION_WINDOW_S * self.fps)))
            cal = self._calibrate(frames, None, first_index, window=window)
            self.how = (
                f"MediaPipe face mesh on every frame, {what}; calibrated on frame {cal}, "
                f"the most neutral of the first {CALIBRATION_WINDOW_S:g} s"
            )
        else:
            first = self.calibration_frame
            if first < first_index:
                raise MyofaceValueError(
                    f"calibration frame {first} is before the first frame given ({first_index})"
                )
            ahead = first - first_index
            given = list(_passed_over(frames, ahead))
            if len(given) <= ahead:
                raise MyofaceValueError(f"the video has no frame {first}")
            cal = self._calibrate(given, first, first_index=first_index, skipped=ahead)
            self.how = f"MediaPipe face mesh on every frame, {what}; calibrated on frame {cal}"
        return 0

    def _calibrate(self, frames, calibration_frame: int | None = None, first_index: int = 0,
                   window: int | None = None, skipped: int = 0):  # fmt: skip
        """Calibrate on ``frames`` (an iterable of RGB frames, or None for a frame without a
        face: the first :data:`CALIBRATION_WINDOW_S` s of the video, from its frame
        ``first_index``): the most neutral one, or the frame ``calibration_frame`` (an index
        into the video). Runs MediaPipe as the analysis does (:attr:`FitSettings.tracking`:
        its two modes place the points a little differently); with the analyzer's
        own detector, the analysis then goes on with this one and takes these frames' points
        from the calibration instead of detecting them again (it starts on the first of
        them). ``window``: ``frames`` are the video's frames from ``first_index`` on, of
        which those up to ``window`` frames after the first with a face are taken (none
        after them: an iterator can go on from there); an error when no frame has a face.
        ``skipped``: the first frames of ``frames`` are None because they were passed over,
        not because they show no face (:meth:`calibrate` with a calibration frame after the
        first): nothing is kept of them, and the analysis starts afresh at the first frame
        (the fit as after a lost face, a detector of its own).
        Returns the calibration frame's index in the video."""
        t_start = time.perf_counter()
        self._first_index = int(first_index)  # (the window's first frame, in the video)
        if self._flow is not None and self._refiner is self._flow:
            # the flow's tracks and counts start with the calibration's first frame
            self._flow = self._refiner = FlowRefiner()
        # the frames up to the first there is (its size makes the fit's camera); the rest are
        # taken as they come (``frames`` may be decoding meanwhile), on the detector's thread
        timed = frames  # (a driver's frames carry the time of the frame last taken, time_s)
        frames = iter(frames)
        head: list = []
        for frame in frames:
            head.append(frame)
            if frame is not None:
                break
        if not head or head[-1] is None:
            raise MyofaceValueError("the video has no frames to calibrate on")
        self._ensure_fit(np.shape(head[-1]))
        self._ensure_offsets(np.shape(head[-1]))
        images: list = []
        points: list = []  # the landmarks the calibration reads
        observed: list = []  # what observe() would give on those frames
        first_face: list = []  # the index of the first frame with a face, once there is one
        # (a detector given to the tracker detects the calibration's frames too)
        det = self._new_detector() if self._own_detector else self._detector
        end = object()

        def source():
            # (runs on the detector's thread, which detects each frame before taking the next)
            it = itertools.chain(head, frames)
            k = 0
            times: list = []
            while window is None or not first_face or k - first_face[0] < window:
                frame = next(it, end)
                if frame is end:
                    break
                # the window is CALIBRATION_WINDOW_S seconds of the video's own times where
                # the frames have them (a variable frame rate spaces frames unevenly), else
                # ``window`` frames
                t = getattr(timed, "time_s", None)
                times.append(t)
                images.append(frame)
                yield k, frame
                k += 1
                if (
                    window is not None
                    and first_face
                    and t is not None
                    and times[first_face[0]] is not None
                    and t - times[first_face[0]] >= CALIBRATION_WINDOW_S - 1e-9
                ):
                    break
            if window is not None and not first_face:
                raise MyofaceValueError(
                    f"no face found in the {k} frames of the video (MediaPipe face mesh)"
                )

        def detect(item):
            k, frame = item
            obs = None if frame is None else self._observed(det, frame)  # (None: no face)
            if obs is not None and not first_face:
                first_face.append(k)
            if obs is None and not first_face and window is not None:
                images[k] = None  # (not kept: the search for a face may be long)
            return obs

        def detected():
            # MediaPipe on a worker thread a few frames ahead while each frame is scored
            # (ModelFit.calibrate takes the points as they come)
            for _, obs in run_ahead(source(), detect, DETECT_AHEAD_FRAMES, "myoface-detect"):
                observed.append(obs)
                # (the calibration reads the points where the flow put them)
                pts = None if obs is None else obs.seen
                points.append(pts)
                yield pts

        stream = detected()
        spec = None
        if calibration_frame is None and SPECULATE and self._can_speculate():
            spec = _Speculation(self, images, observed, first_index)
        finished = False  # (the calibration's frames set up on the fit: the speculation's)
        try:
            if calibration_frame is None:
                scoring = self.fit
                got, scores = scoring.score(stream, on_scored=spec and spec.scored)
                index = choose_calibration_frame(scores)
                if spec is not None and spec.adopt(index, scores):
                    finished = True
                else:
                    if spec is not None:
                        spec.drop()
                    self.calibration = scoring.calibrate(got, index, scores=scores)
            else:
                for _ in stream:
                    pass
        except BaseException:
            stream.close()  # (stops the detector's thread before the detector closes)
            if spec is not None:
                spec.drop()
            if self._own_detector:
                det.close()
            raise
        # the analysis goes on with this detector, and takes the calibration frames' points
        # from it rather than detecting them twice: the same points a detector tracking from
        # the first of these frames gives (the analysis starts there)
        if self._own_detector:
            if self._detector is not None:
                self._detector.close()
            self._detector = det
        self._detected = {first_index + k: obs for k, obs in enumerate(observed)}
        if skipped:
            # (the analysis starts before the calibration frame: the detector and the flow
            # start there again, MediaPipe tracking from the frames it is then given)
            self._detected = {}
            if self._own_detector:
                self._detector.close()
                self._detector = None
            if self._flow is not None and self._refiner is self._flow:
                self._flow = self._refiner = FlowRefiner()
        if calibration_frame is not None:
            idx = int(calibration_frame) - first_index
            if not 0 <= idx < len(points):
                raise MyofaceValueError(
                    f"calibration frame {calibration_frame} is outside the frames given"
                )
            if points[idx] is None:
                raise MyofaceValueError(f"no face found on calibration frame {calibration_frame}")
            self.calibration = self.fit.calibrate(points, idx)
        if (
            self.settings.tracker_offsets_frame
            and self._wants_offsets()
            and self.model.face.texture is None
        ):
            self._offsets_from_frame(images[self.calibration.index], points)
        if self.use_synthesis:
            cal = self.calibration
            fit = self.fit
            frame = images[cal.index]
            size = (np.shape(frame)[1], np.shape(frame)[0])
            if self.model.face.texture is not None:
                self.synthesis = LandmarkSynthesis(
                    self.model.face, fit.camera, size, tracking=self.settings.tracking
                )
            else:
                shape = fit.neutral + fit.identity_mm
                self.synthesis = LandmarkSynthesis.from_frame(
                    self.model.face, fit.camera, frame, shape, cal.pose,
                    tracking=self.settings.tracking,
                )  # fmt: skip
            self.calibration = fit.calibrate(points, cal.index, synthesis=self.synthesis)
            self.calibration.scores = cal.scores
        if not finished:
            self._set_up(images)
        if skipped:
            self._lose_track()  # (the first frame measured is not the calibration's)
        self.calibration_frame = first_index + self.calibration.index
        self.timings["calibration_s"] += time.perf_counter() - t_start
        return self.calibration_frame

    def _set_up(self, images) -> None:
        """What the fit and the gaze take from the calibration (after :meth:`ModelFit.calibrate`;
        ``images``: the calibration window's frames by position, None where one was not
        kept): the appearance for the photometric term (registered on every frame the
        calibration used), the lids' template, the person's eyeballs; before them, with a
        face of its own texture, the detector's context on the calibration's frames
        (:attr:`~myoface.analysis.weights.FitSettings.detector_context`)."""
        if self.model.face.texture is not None:  # (not a table textured by the frame)
            self.fit.measure_detector_context(images)
            self.calibration = self.fit.calibration
        cal = self.fit.calibration
        frame = images[cal.index]
        if self.settings.photometric:
            if frame is None:
                raise MyofaceValueError("the calibration frame was not kept")
            views = self.registration_views
            if views is not None:  # (by their place in the window, as the calibration's)
                views = {k - self._first_index: v for k, v in views.items()}
            self.fit.set_appearance(frame, images, views=views)
        if self.settings.reads_lids and frame is not None:
            self.fit.set_lid_reference(frame)  # (the lids' template)
        if self.gaze is not None:  # the person's eyeballs and open lids
            self.gaze.calibrate(self.fit.neutral + self.fit.identity_mm)
        if self.settings.flow and self.flow_method == "anchored":
            # the points read against the calibration frame, through the model (ModelFlow)
            if frame is None:
                raise MyofaceValueError("the calibration frame was not kept")
            self._anchored = self._refiner = ModelFlow.of_fit(frame, self.fit)
            self._n_observed = self._n_measured = 0
            self._predictions = {}
            self._ok_prediction = (None, None)

    def _can_speculate(self) -> bool:
        """Whether the calibration's frames can be measured before it ends (SPECULATE): not
        with the chained optical flow (its tracks start with the calibration's detections)
        or analysis by synthesis, nor with the offsets taken from the calibration frame."""
        return not (
            self._flow is not None or self.use_synthesis or self.settings.tracker_offsets_frame
        )

    def observe(self, frame, index: int = 0) -> LandmarkObservation | None:
        """The frame's :class:`LandmarkObservation`, or None without a face: the
        calibration's (frames it detected), else detected. Called once per frame, in order;
        may run on another thread than :meth:`measure` (the driver runs it ahead), which
        takes its result as ``observation``. With the model-anchored flow, its tracking of
        the frame is handed to a thread of its own (the observation's ``flow`` a future):
        it waits there for the fit of frame k - :attr:`flow_lag` (:meth:`_track_anchored`)."""
        if index in self._speculated:  # (measured during the calibration: tracked there)
            return self._observe(frame, index)
        if index in self._observed_ahead:  # (observed during the calibration, not measured)
            self._observe(frame, index)
            return self._observed_ahead.pop(index)
        replayed = index in self._detected  # (detected by the calibration: no MediaPipe here)
        return self._anchor(frame, self._observe(frame, index), ahead=True, prepare=replayed)

    def _anchor(self, frame, obs, ahead: bool, prepare: bool = False):
        """``obs`` with the anchored tracker's points as its ``flow`` (none without it):
        tracked on the flow's thread (``ahead``: a future) or here. ``prepare``: the frame's
        crop made here (:meth:`~myoface.analysis.modelflow.ModelFlow.prepare`), not on the
        flow's thread: on the frames the calibration detected, the detector's thread has no
        MediaPipe to run, and the flow's thread, which the fit waits for when the machine
        is busy, 0.8 ms a frame less to do (the same crop either way)."""
        if self._anchored is None:
            return obs
        seq = self._n_observed
        self._n_observed += 1
        if obs is None:
            return None
        if not ahead:
            return obs._replace(flow=self._track_anchored(seq, frame, obs.points))
        prepared = None
        if prepare:
            c0 = time.thread_time()
            prepared = self._anchored.prepare(frame, obs.points)
            with self._flow_cond:
                self.timings["flow_cpu_s"] += time.thread_time() - c0
        if self._flow_worker is None:
            self._flow_worker = OrderedWorker("myoface-flow")
        return obs._replace(
            flow=self._flow_worker.submit(
                self._track_anchored, seq, frame, obs.points, prepared
            )  # fmt: skip
        )

    def _track_anchored(self, seq: int, frame, points, prepared=None):
        """The anchored tracker on observation ``seq`` (counted from the calibration):
        the frame's crop (:meth:`~myoface.analysis.modelflow.ModelFlow.prepare`; unless
        ``prepared`` gives it), then, once measurement ``seq - flow_lag`` is done, tracked
        from the prediction it left (:meth:`_publish`). The same points whichever thread
        runs it and whenever."""
        anchored = self._anchored
        c0 = time.thread_time()  # (waiting takes no CPU)
        if prepared is None:
            prepared = anchored.prepare(frame, points)
        need = seq - self.flow_lag
        with self._flow_cond:
            while need >= 0 and self._n_measured <= need and not self._flow_closing:
                self._flow_cond.wait()
            if need >= 0 and self._n_measured <= need:
                return None  # (closed meanwhile: not used)
            prediction, since = self._predictions.get(need, (None, None))
        out = anchored.track(frame, points, prediction, prepared=prepared, since=since)
        with self._flow_cond:  # (the timings are the driver's thread's too)
            self.timings["flows"] += 1
            self.timings["flow_cpu_s"] += time.thread_time() - c0
        return out

    def _publish(self, prediction=None, since=None) -> None:
        """A measurement done: the prediction it leaves for the frames after it (the
        fit's pose and skin, and the detector's points on that frame; None: none, the
        calibration's pose and neutral and the detector's points)."""
        if self._anchored is None:
            return
        with self._flow_cond:
            seq = self._n_measured
            self._predictions[seq] = (prediction, since)
            # (the observations up to this one are tracked: the next read seq + 1 - lag on)
            for old in [k for k in self._predictions if k <= seq - self.flow_lag]:
                del self._predictions[old]
            self._n_measured += 1
            self._flow_cond.notify_all()

    def _observe(self, frame, index: int = 0) -> LandmarkObservation | None:
        """(:meth:`observe` without the anchored flow.)"""
        if index in self._detected:
            return self._detected.pop(index)
        self._detected.clear()  # (past the calibration frames: the detector tracks from here)
        t0 = time.perf_counter()
        obs = self._observed(self.detector, frame)
        self.timings["detections"] += 1
        self.timings["detect_s"] += time.perf_counter() - t0
        return obs

    def measure(self, frame, index: int = 0, time_s: float = 0.0,
                observation=NOT_OBSERVED) -> FitMeasurement:  # fmt: skip
        """The frame's measurement; ``observation``: its :meth:`observe` (None without a
        face; by default observed here)."""
        done = self._speculated.pop(index, None)
        if done is not None:  # (measured while the calibration's window was scored)
            return replace(done, time_s=time_s)
        return self._measure(frame, index, time_s, observation)

    def _measure(self, frame, index: int, time_s: float, observation) -> FitMeasurement:
        """:meth:`measure`'s work (the speculation's measurements call it: the frames the
        caller measures are the caller's calls to :meth:`measure`, one a frame)."""
        fit = self._ensure_fit(np.shape(frame))
        if observation is NOT_OBSERVED:
            obs = self._anchor(frame, self._observe(frame, index), ahead=False)
        else:
            obs = observation
        nan = np.full(len(self.ids), np.nan)
        if obs is None:
            self._lose_track()
            return FitMeasurement(index, time_s, "no_face", nan, None, float("nan"))
        before = fit.frame_state()
        flow = obs.flow
        if isinstance(flow, Future):  # (the anchored flow, tracked on its thread)
            t0 = time.perf_counter()
            flow = flow.result()
            self.timings["flow_wait_s"] += time.perf_counter() - t0
        try:
            r = fit.fit(
                obs.points, self.synthesis, deferred=self.deferred_relax, flow=flow,
                image=frame if self.settings.photometric or self.settings.reads_lids else None,
            )  # fmt: skip
        except (np.linalg.LinAlgError, MyofaceValueError):
            self._lose_track()
            return FitMeasurement(index, time_s, "fit_failed", nan, None, float("nan"))
        shape = fit.shape(r.contractions)
        # the prediction this frame leaves for the anchored flow (ModelFlow.track; as soon
        # as it is known, so that the next frame's tracking runs while this one's gaze is
        # read): the fit's pose and skin here, unless the frame is not measured
        quality = frame_quality(r, self.settings.photometric)
        occluded = quality == "occluded"
        if occluded:
            self._publish(*self._ok_prediction)  # (the last measured frame's)
        elif quality == "ok":
            self._ok_prediction = ((r.pose, shape), obs.points)
            self._publish(*self._ok_prediction)
        uv = fit.camera.project(r.pose.apply(shape))
        contours = {s: uv[v] for s, v in self._sections.items()}
        if occluded:
            if self.gaze is not None:
                self.gaze.reset()  # (its filter averages measured frames only)
            fit.restore_frame_state(before)  # (the next frame starts from the last measured one)
            return FitMeasurement(
                index, time_s, "occluded", nan, r.pose, r.residual_mm, contours, r.iterations,
                r.occlusion,
            )  # fmt: skip
        if quality == "misfit":
            self._lose_track()
            return FitMeasurement(
                index, time_s, "misfit", nan, r.pose, r.residual_mm, contours, r.iterations
            )
        gaze = None
        if self.gaze is not None:
            gaze = self.gaze.measure(frame, fit.camera, r.pose, shape, obs.points)
        return FitMeasurement(
            index, time_s, "ok", r.contractions, r.pose, r.residual_mm, contours, r.iterations,
            r.occlusion, gaze,
        )  # fmt: skip

    def _lose_track(self) -> None:
        """After a frame not measured: the fit and the gaze's filter start again (and the
        anchored flow from the detector's points)."""
        self.fit.lose_track()
        if self._anchored is not None:
            self._anchored.reset()
            self._ok_prediction = (None, None)
            self._publish()
        if self.gaze is not None:
            self.gaze.reset()

    def describe(self) -> dict:
        """For analysis.json: the estimator, the calibration, the camera, the weights and the
        gaze's settings."""
        out = {
            "init": self.how,
            "mm_per_px": self.mm_per_px,
            "refine": self.refine,
            "estimator": "fit-synthesis" if self.use_synthesis else "fit",
            "fit_settings": asdict(self.settings),
            "gaze": None if self.gaze is None else self.gaze.describe(),
        }
        if self._refiner is not None:
            # the optical flow's points (FitSettings.flow): tracked from the first frame,
            # from the previous frame, or left at MediaPipe's
            out["optical_flow_points"] = dict(self._refiner.stats)
        if self._anchored is not None:
            # the fit's frame each frame's anchored tracking predicts from (k - this)
            out["optical_flow_lag"] = self.flow_lag
        if self.fit is not None:
            cam = self.fit.camera
            out["camera"] = {"focal_px": cam.focal_px, "cx": cam.cx, "cy": cam.cy}
            out["unconverged_relaxes"] = self.fit.unconverged_relaxes
            if self.settings.photometric:
                # the gain at which MediaPipe read the skin's motion on this video, as the
                # photometric fit estimated it (FitSettings.photo_landmark_gain)
                out["landmark_gain"] = round(self.fit.landmark_gain(), 4)
        if self.calibration is not None:
            cal = self.calibration
            out["calibration_frame"] = self.calibration_frame
            out["calibration"] = {
                "scores_mm": [
                    None if not np.isfinite(v) else round(float(v), 4) for v in cal.scores
                ],  # fmt: skip
                "frames_used": [
                    self.calibration_frame - cal.index + k for k in cal.extra["frames"]
                ],
                "identity_rms_mm": float(np.sqrt((cal.identity_mm**2).sum(1).mean())),
                "residual_mm": cal.residual_mm,
                "lid_gains": cal.extra.get("lid_gains", {}),
                "pose": cal.pose.columns(),
            }
            if "detector_context" in cal.extra:
                # MediaPipe's error among the video's surroundings beyond its offsets'
                # table (FitSettings.detector_context): on how many calibration frames, its
                # size (mm RMS over the face) and how far it turned the calibration's pose
                out["calibration"]["detector_context"] = cal.extra["detector_context"]
            if "registration" in cal.extra:
                # the photometric fit's appearance: the frames it was registered on, and how
                # far their landmarks moved it from the calibration frame's (head frame)
                out["calibration"]["appearance_registered_on"] = [
                    self.calibration_frame - cal.index + k for k in cal.extra["registration"]
                ]
                out["calibration"]["appearance_offset"] = cal.extra.get("appearance_offset")
                # and the turn the parallax of the frames seen from other views gave it
                # (modelfit.PARALLAX_REFINE; its frames as the video counts them)
                par = cal.extra.get("appearance_parallax")
                if par is not None:
                    par = {**par, "frames": [self.calibration_frame - cal.index + k
                                             for k in par["frames"]]}  # fmt: skip
                out["calibration"]["appearance_parallax"] = par
        return out

    def close(self) -> None:
        if self._flow_worker is not None:
            with self._flow_cond:
                self._flow_closing = True
                self._flow_cond.notify_all()
            self._flow_worker.close()
            self._flow_worker = None
        if self.fit is not None:
            self.fit.close()
        if self._detector is not None:
            self._detector.close()
        if self.synthesis is not None:
            self.synthesis.close()
        if self.fit is not None and self.fit.offsets is not None:
            self.fit.offsets.close()


class _Speculation:
    """The calibration's frames measured while its window is still detected and scored
    (:data:`SPECULATE`). After each scored frame (:meth:`ModelFit.score`'s ``on_scored``), the
    frames scored so far choose a calibration frame and the frames around it
    (:func:`~myoface.analysis.modelfit.choose_calibration_frame`,
    :func:`~myoface.analysis.modelfit.calibration_frames`, and with the photometric term the
    frames its appearance is registered on, :func:`~myoface.analysis.modelfit.
    registration_frames`); once the frames that could calibrate (and register) with it are
    scored, a fit of its own (:class:`ModelFit`, and a gaze estimator)
    is calibrated on them and measures the window's frames scored so far, from the first, as
    :meth:`FitTracker.measure` would after the calibration. The tracker's scoring fit is left as it was. When the whole
    window chooses the same frames, that fit and its measurements are the tracker's
    (:meth:`adopt`: the same calibration, the same frames fitted in the same order, so the
    same results); when the choice changes, they are dropped (at most
    :data:`MAX_SPECULATIONS` tries) and the frames are measured after the calibration."""

    def __init__(self, tracker: FitTracker, images: list, observed: list, first_index: int):
        self.tracker = tracker
        self.images = images
        self.observed = observed
        self.first = int(first_index)
        self.scoring = (tracker.fit, tracker.gaze)
        #: the anchored flow's state before (made again by each calibration's set-up)
        self.flow_state = self._flow_state()
        self.fit: ModelFit | None = None
        self.choice: tuple | None = None
        self.results: dict = {}
        self.next = 0  # the next frame of the window to measure
        self.anchored = 0  # the next frame of the window to observe (the anchored flow's)
        self.observations: dict = {}  # {frame of the window: observation not yet measured}
        self.tries = 0

    def scored(self, frames: list, scores: list) -> None:
        sc = np.asarray(scores, dtype=np.float64)
        last = len(sc) - 1
        if not np.isfinite(sc).any():
            return
        index = choose_calibration_frame(sc)
        if last < index + self._reach():
            return  # (frames that could calibrate with it are still to come)
        choice = self._choice(sc, index)
        if self.fit is not None and choice != self.choice:
            self.drop()
        if self.fit is None:
            if self.tries >= MAX_SPECULATIONS:
                return
            self._start(frames, sc, choice)
            if self.fit is None:
                return
        tr = self.tracker
        # the anchored flow tracks each frame on its own thread a frame ahead of the
        # measurements, as with the driver's observe(): frame k is tracked while k - 1 is
        # measured (its tracking waits for measurement k - flow_lag, done by then; the same
        # points whichever thread tracks them)
        while self.anchored <= last:
            k = self.anchored
            self.anchored += 1
            self.observations[k] = tr._anchor(self.images[k], self.observed[k], ahead=True)
        upto = last - 1 if tr._anchored is not None else last
        while self.next <= upto:
            k = self.next
            self.next += 1
            self.results[self.first + k] = tr._measure(
                self.images[k], self.first + k, 0.0, self.observations.pop(k)
            )  # fmt: skip

    def _reach(self) -> int:
        """How many frames after the calibration frame its choice depends on: the frames
        that calibrate with it, and with the photometric term those that register its
        appearance (:func:`~myoface.analysis.modelfit.registration_frames`)."""
        if self._registers():
            return max(CALIBRATION_FRAMES - 1, REGISTRATION_SPAN)
        return CALIBRATION_FRAMES - 1

    def _registers(self) -> bool:
        return registers_appearance(self.tracker.settings)

    def _choice(self, scores, index: int) -> tuple:
        """The frames calibration frame ``index`` calibrates with (and registers the
        appearance on), from ``scores``: the speculation's fit holds while they stay."""
        choice = (index, calibration_frames(scores, index))
        if self._registers():
            choice += (registration_frames(scores, index),)
        return choice

    def _flow_state(self) -> tuple:
        tr = self.tracker
        return (
            tr._anchored, tr._refiner, tr._n_observed, tr._n_measured, tr._predictions,
            tr._ok_prediction,
        )  # fmt: skip

    def _start(self, frames: list, scores: np.ndarray, choice: tuple) -> None:
        tr = self.tracker
        base, _ = self.scoring
        self.tries += 1
        fit = ModelFit(tr.model, base.camera, tr.settings, fps=tr.fps)
        if base.offsets is not None:
            fit.set_offsets(base.offsets)
        self.fit, self.choice = fit, choice
        tr.fit = fit
        tr.gaze = None if self.scoring[1] is None else GazeEstimator(tr.model.face)
        try:
            tr.calibration = fit.calibrate(list(frames), choice[0], scores=scores)
            tr._set_up(self.images)
        except MyofaceValueError:
            # (no speculation on this window: the calibration at its end says what fails)
            self.drop()
            self.tries = MAX_SPECULATIONS
            return
        except BaseException:
            self.drop()
            raise
        self.next = self.anchored = 0  # (the analysis starts at the first frame given)

    def adopt(self, index: int, scores: np.ndarray) -> bool:
        """The tracker keeps the speculation's fit and measurements if the whole window
        chose the same frames (True), else nothing changes (False)."""
        if self.fit is None or self._choice(scores, index) != self.choice:
            return False
        self.fit.calibration.scores = np.asarray(scores, dtype=np.float64)
        tr = self.tracker
        tr.calibration = self.fit.calibration
        tr._speculated = self.results
        tr._observed_ahead = {self.first + k: obs for k, obs in self.observations.items()}
        self.scoring[0].close()
        self.fit = None
        return True

    def drop(self) -> None:
        """Forget the speculation: the tracker's scoring fit and gaze back."""
        if self.fit is None:
            return
        for obs in self.observations.values():  # (the flow's thread done with them)
            if obs is not None and isinstance(obs.flow, Future):
                try:
                    obs.flow.result()
                except Exception:  # (dropped with them)
                    pass
        self.observations = {}
        self.fit.close()
        tr = self.tracker
        tr.fit, tr.gaze = self.scoring
        tr.calibration = None
        (
            tr._anchored, tr._refiner, tr._n_observed, tr._n_measured, tr._predictions,
            tr._ok_prediction,
        ) = self.flow_state  # fmt: skip
        self.fit, self.choice = None, None
        self.results = {}
