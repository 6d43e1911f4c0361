"""The paper's analysis loop: face video -> snakes on nine feature contours -> fiducials in a
head frame -> muscle contractions and jaw rotation per frame (Terzopoulos & Waters 1993,
Section V), and the driver of every tracker.

The analysis level, one module a stage:

- :mod:`~myoface.analysis.sections`: the feature contours (sections), their features and the
  model's skin curves they are compared with;
- :mod:`~myoface.analysis.initfiles`: the snakes' initial contours as JSON;
- :mod:`~myoface.analysis.trackers`: each tracker behind one protocol (frames ->
  :class:`~myoface.analysis.trackers.base.Measurement`): the snakes
  (:mod:`~myoface.analysis.trackers.snakes`), the 3-D fit of the model to MediaPipe's points
  (:mod:`~myoface.analysis.trackers.landmark_fit`, the fit itself in
  :mod:`~myoface.analysis.modelfit`: terms over one solver) and the paper's 2-D scheme on
  those points (:mod:`~myoface.analysis.trackers.landmark_paper`);
- :mod:`~myoface.analysis.contractions_csv`: the measurements as a CSV, and back;
- :mod:`~myoface.analysis.outputs`: a whole run to a folder (CSV, plot, overlays, JSON).

This module makes a tracker (:func:`make_analyzer`) and drives it over a video: calibrates it,
then measures (:class:`Tracking`, :func:`measure_frames`, :func:`analyze_video`). Features are geometric (extremes,
centroids) rather than node identities, because snake nodes slide along the edges they sit on.
By default (``estimator="curves"``) the contractions come from the whole contours, not from
these points: :class:`~myoface.analysis.curvefit.CurveEstimator` fits the model's curves to
them. With ``estimator="fiducials"`` (the paper's scheme) the fiducials' displacements from the
calibration frame, in the head frame (translation of the head reference contour removed, pixels
scaled to mm with the model's size), are inverted to contractions by
:class:`~myoface.analysis.estimate.ContractionEstimator`. The analysis never changes the
caller's face model: each tracker keeps its own state.
"""

from __future__ import annotations

import os
import sys
from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from myoface._threads import run_ahead, short_switch_interval
from myoface.analysis.initfiles import load_init
from myoface.analysis.trackers.base import KEEP_BYTES
from myoface.analysis.trackers.landmark_fit import LANDMARK_ESTIMATORS, FitTracker
from myoface.analysis.trackers.landmark_paper import PaperLandmarkTracker
from myoface.analysis.trackers.snakes import SnakeTracker
from myoface.analysis.video import Video, open_video
from myoface.analysis.weights import FitSettings
from myoface.errors import MyofaceValueError
from myoface.facemesh import DETECT_AHEAD_FRAMES
from myoface.model import build_face_model
from myoface.render import progress

#: the errors of ``photometric`` (``--photometric``) where there is no 3-D fit to add it to
PHOTOMETRIC_NEEDS_LANDMARKS = (
    "--photometric is a term of the landmark tracker's 3-D fit; use it with --tracker landmarks"
)
PHOTOMETRIC_NOT_PAPER = "--photometric is for the 3-D fit, not --estimator paper"


def resolve_photometric(photometric, tracker: str, estimator) -> bool:
    """Whether the analysis reads the frames' pixels (the 3-D fit's photometric term,
    :attr:`~myoface.analysis.weights.FitSettings.photometric`): ``photometric`` True or
    False as given, None (the default) on wherever there is a 3-D fit to add it to (the
    landmark tracker with the estimator ``"fit"`` or ``"fit-synthesis"``: the best measured
    analysis, README's "The default analysis reads the pixels") and off elsewhere (the snakes, the
    paper's landmark scheme).

    Raises
    ------
    MyofaceValueError
        ``photometric`` not None, True or False, or True where there is no 3-D fit.
    """
    if photometric is None:
        return tracker == "landmarks" and estimator not in ("paper", "fiducials")
    if not isinstance(photometric, bool):
        raise MyofaceValueError(f"photometric must be True, False or None; got {photometric!r}")
    if photometric and tracker != "landmarks":
        raise MyofaceValueError(PHOTOMETRIC_NEEDS_LANDMARKS)
    if photometric and estimator in ("paper", "fiducials"):
        raise MyofaceValueError(PHOTOMETRIC_NOT_PAPER)
    return bool(photometric)


def make_analyzer(
    model,
    video,
    tracker: str = "snakes",
    init=None,
    calibration_frame: int | None = 0,
    refine=None,
    sigma: float | None = None,
    estimator: str = "curves",
    show_progress: bool | None = None,
    flow: bool = False,
    photometric: bool | None = None,
):
    """The tracker for ``video`` (a :class:`~myoface.analysis.video.Video`), not yet
    calibrated, and the frame from which :func:`measure_frames` hands it the video's frames
    (to calibrate on, then to measure from where its calibration says).

    ``tracker="snakes"``: :class:`~myoface.analysis.trackers.snakes.SnakeTracker` from
    ``init`` (contours on the calibration frame) or, when ``init`` is None, from MediaPipe's
    face mesh on the first frame with a face from ``calibration_frame`` on (the whole video is
    searched if need be; ``show_progress``: with a progress bar on stderr; default: when
    stderr is a terminal). ``tracker="landmarks"``: ``estimator`` ``"fit"`` (default): the
    3-D fit of the whole model (:class:`~myoface.analysis.trackers.landmark_fit.FitTracker`:
    head pose and every muscle, calibrated on ``calibration_frame``, or when it is None on the
    most neutral frame of the first seconds; either way the analysis starts at frame 0);
    ``"fit-synthesis"``: the same with analysis by synthesis; ``"paper"``: the paper's 12
    muscles in a 2-D head frame
    (:class:`~myoface.analysis.trackers.landmark_paper.PaperLandmarkTracker`). ``init`` must
    be None. ``refine`` defaults to 1 for the snakes, 0 for the paper's landmark scheme and
    :attr:`~myoface.analysis.weights.FitSettings.refine` for the fit; ``estimator`` for the
    snakes: ``"curves"`` (default) or ``"fiducials"`` (with the landmark tracker the library
    takes these for their counterparts, ``"fit"`` and ``"paper"``; the command line refuses
    them there as a usage error, :func:`myoface.commands._common.analysis_settings`).
    ``flow``: the 3-D fit's points refined
    by optical flow (:attr:`~myoface.analysis.weights.FitSettings.flow`). ``photometric``:
    the 3-D fit also reads the frame's pixels against the calibration frame's appearance
    (:attr:`~myoface.analysis.weights.FitSettings.photometric`; None, the default: on with
    the 3-D fit, :func:`resolve_photometric`); both are the fit's, refused with the snakes
    and with ``estimator="paper"``.
    """
    if flow and tracker != "landmarks":
        raise MyofaceValueError(
            "--flow refines the landmark tracker's points; use it with --tracker landmarks"
        )
    photometric = resolve_photometric(photometric, tracker, estimator)
    first = 0 if calibration_frame is None else int(calibration_frame)
    if first < 0 or (video.n_frames is not None and first >= video.n_frames):
        raise MyofaceValueError(
            f"--calibration-frame must be in [0, {video.n_frames}); got {first}"
        )
    fps = float(video.fps) if video.fps and video.fps > 0 else 30.0
    if tracker == "landmarks":
        if init is not None:
            raise MyofaceValueError("--init is for the snakes; the landmark tracker needs none")
        # the landmarks' estimators: the 3-D fit ("fit"; also the snakes' default "curves",
        # the model fitted) or the paper's 2-D scheme ("paper"; also "fiducials")
        est = {None: "fit", "curves": "fit", "fiducials": "paper"}.get(estimator, estimator)
        if est not in LANDMARK_ESTIMATORS:
            raise MyofaceValueError(
                f"the landmark tracker's estimator must be one of {LANDMARK_ESTIMATORS}; "
                f"got {estimator!r}"
            )
        if est != "paper":
            settings = FitSettings(flow=bool(flow), photometric=bool(photometric))
            if refine is not None:
                settings = replace(settings, refine=int(refine))
            an = FitTracker(
                model, fps=fps, settings=settings, synthesis=est == "fit-synthesis",
                deferred_relax=True, calibration_frame=calibration_frame,
            )  # fmt: skip
            return an, 0  # (calibrated on its frame, every frame analysed)
        if flow:
            raise MyofaceValueError("--flow is for the 3-D fit, not --estimator paper")
        if photometric:
            raise MyofaceValueError(PHOTOMETRIC_NOT_PAPER)
        return PaperLandmarkTracker(model, refine=0 if refine is None else refine), first
    if tracker != "snakes":
        raise MyofaceValueError(f"tracker must be 'snakes' or 'landmarks'; got {tracker!r}")
    if show_progress is None:
        show_progress = sys.stderr.isatty()
    an = SnakeTracker(
        model,
        init,
        show_progress=show_progress and init is None,
        total=None if video.n_frames is None else video.n_frames - first,
        refine=1 if refine is None else refine,
        sigma=sigma,
        estimator=estimator or "curves",
        deferred_relax=True,  # a video: the tissue relaxed on a second thread
    )
    return an, first


@dataclass
class VideoAnalysis:
    """What :func:`analyze_video` measured.

    Attributes
    ----------
    ids : tuple of str — the estimated muscles (and ``"jaw"``), column order of
        :attr:`contractions`.
    frames : list of FrameMeasurement — one per analysed frame, in order.
    """

    ids: tuple
    frames: list

    @property
    def times(self) -> np.ndarray:
        """(T,) s."""
        return np.array([f.time_s for f in self.frames])

    @property
    def contractions(self) -> np.ndarray:
        """(T, K) in [0, 1]; NaN rows where a frame could not be measured."""
        return np.array([f.contractions for f in self.frames]).reshape(-1, len(self.ids))

    @property
    def quality(self) -> list[str]:
        """Per frame ``"ok"`` or why it could not be measured."""
        return [f.quality for f in self.frames]


def analyze_video(
    video,
    model=None,
    *,
    tracker: str = "snakes",
    init=None,
    calibration_frame: int = 0,
    max_frames: int | None = None,
    estimator: str = "curves",
    show_progress: bool = False,
) -> VideoAnalysis:
    """Track the face in ``video`` (a path, or a :class:`~myoface.analysis.video.Video`) and
    estimate the muscle contractions of each frame (T&W 1993, Section V).

    ``model`` defaults to the bundled face model (never changed: the analysis keeps its own
    state). ``tracker``, ``init`` (contours on the calibration frame; default: found with
    MediaPipe), ``calibration_frame`` and ``estimator`` are as in :func:`make_analyzer`.
    The command ``myoface analyze`` does the same and also writes the CSV, plot and overlays.

    Every frame's measurement is kept (its contours too: a few kB a frame); for a long video,
    :func:`measure_frames` yields them one at a time, and
    :func:`~myoface.analysis.outputs.analyze_to_folder` streams them to files in flat memory.
    """
    if model is None:
        pass

        model = build_face_model()
    if not isinstance(video, Video):
        video = open_video(video)
    if isinstance(init, str | os.PathLike):
        init = load_init(init)
    an, start = make_analyzer(model, video, tracker, init, calibration_frame, estimator=estimator)
    try:
        n = None if video.n_frames is None else video.n_frames - start
        if max_frames is not None:
            n = max_frames if n is None else min(n, max_frames)
        frames = [
            m
            for _, m in progress(
                measure_frames(video, an, start, max_frames),
                total=n,
                desc="analyzing",
                enabled=show_progress,
            )
        ]
    finally:
        an.close()
    return VideoAnalysis(tuple(an.ids), frames)


class _Keeper:
    """The frames of ``source`` (``(index, time_s, frame)`` items) as they are taken, the
    frames alone handed on, kept (up to ``limit`` bytes) with their indices and times so that
    they can be given again. :attr:`time_s` is the time of the frame last taken (a
    calibration that spans a time, not a number of frames, can read it)."""

    def __init__(self, source, limit: int = KEEP_BYTES):
        self.source = source
        self.kept: deque = deque()
        self.taken = 0
        self.time_s: float | None = None
        self.complete = True  # every frame taken is kept
        self._bytes = 0
        self._limit = limit

    def __iter__(self):
        return self

    def __next__(self):
        item = next(self.source)
        self.time_s, frame = item[1], item[2]
        self.taken += 1
        if self.complete:
            self._bytes += getattr(frame, "nbytes", 0)
            if self._bytes > self._limit:
                self.complete = False
                self.kept.clear()
            else:
                self.kept.append(item)
        return frame


def timed_frames(video):
    """``(time_s, frame)`` of each frame of ``video``: its own times
    (:meth:`~myoface.analysis.video.Video.timed`: a movie's timestamps) where it has them,
    else frame k at ``k / video.fps``."""
    timed = getattr(video, "timed", None)
    if timed is not None:
        return timed()
    fps = float(video.fps)
    return ((k / fps, f) for k, f in enumerate(video))


class Tracking:
    """A calibrated tracker run over a video: iterate for ``(frame, measurement)`` per frame
    (the driver of every tracker, :mod:`myoface.analysis.trackers.base`).

    The video is decoded from ``first`` on; the tracker's :meth:`calibrate` takes what it
    needs of those frames, and the frames from the one it names (:attr:`start`, known once
    iteration began) are measured, at most ``max_frames``: those the calibration took are
    given again from memory, the rest decoded as measuring goes on. Each measurement's time
    is its frame's (:func:`timed_frames`: a movie's own timestamps, so that a video of
    variable frame rate is timed as it was filmed). A tracker whose
    ``OBSERVES_AHEAD`` is true has its :meth:`observe` run on a worker thread a few frames
    ahead (:data:`~myoface.facemesh.DETECT_AHEAD_FRAMES`: MediaPipe tracks the next frames
    while this one is fitted); the results are the same as frame by frame (each frame is
    observed once, in order). Closing the iteration early stops the threads."""

    def __init__(self, video, tracker, first: int = 0, max_frames: int | None = None,
                 keep_bytes: int = KEEP_BYTES):  # fmt: skip
        self.video = video
        self.tracker = tracker
        self.first = int(first)
        self.max_frames = max_frames
        self.keep_bytes = int(keep_bytes)
        #: the first frame measured (its index in the video), once the calibration chose it
        self.start: int | None = None
        #: frames decoded (the calibration's and the measured ones; more when the
        #: calibration took more than :attr:`keep_bytes` and they were decoded again)
        self.decoded = 0
        self._source = None  # the frames to measure, once calibrated
        self._decoded = None

    def _decoded_from(self, k0: int):
        """``(index, time_s, frame)`` of the video's frames from ``k0`` on (its decoder
        stopped when this generator is closed)."""
        it = timed_frames(self.video)
        try:
            for k, (t, f) in enumerate(it):
                self.decoded += 1
                if k >= k0:
                    yield k, t, f
        finally:
            close = getattr(it, "close", None)
            if close is not None:
                close()

    def calibrate(self) -> int:
        """Calibrate the tracker on the video's frames from :attr:`first` (once; iterating
        does it when it was not done): returns :attr:`start`."""
        if self._source is not None:
            return self.start
        decoded = self._decoded_from(self.first)
        keeper = _Keeper(decoded, self.keep_bytes)
        try:
            offset = int(self.tracker.calibrate(keeper, self.first))
        except BaseException:
            decoded.close()
            raise
        self.start = self.first + offset
        self._decoded = decoded
        if keeper.complete and offset <= keeper.taken:
            kept = deque(list(keeper.kept)[offset:])
            keeper.kept.clear()
            self._source = self._replayed(kept, decoded)
        else:  # the calibration took more than was kept: decode again
            decoded.close()
            self._source = self._decoded_from(self.start)
        return self.start

    def _frames(self):
        self.calibrate()
        source = self._source
        n = 0
        try:
            for k, t, frame in source:
                if self.max_frames is not None and n >= self.max_frames:
                    return
                n += 1
                yield k, t, frame
        finally:
            source.close()
            self._decoded.close()

    def _replayed(self, kept: deque, decoded):
        """The kept frames from :attr:`start` on (released as they are given), then the rest
        of the decode."""
        while kept:
            yield kept.popleft()
        try:
            yield from decoded
        finally:
            decoded.close()

    def __iter__(self):
        # (MediaPipe and the decoder run on threads that release the GIL: they take it
        # back sooner while the fit computes in Python)
        with short_switch_interval():
            yield from self._measured()

    def _measured(self):
        tr = self.tracker
        frames = self._frames()
        if not tr.OBSERVES_AHEAD:
            try:
                for k, t, frame in frames:
                    yield frame, tr.measure(frame, k, t)
            finally:
                frames.close()
            return
        ahead = run_ahead(
            frames, lambda ktf: tr.observe(ktf[2], ktf[0]), DETECT_AHEAD_FRAMES, "myoface-detect"
        )
        try:
            for (k, t, frame), obs in ahead:
                yield frame, tr.measure(frame, k, t, observation=obs)
        finally:
            ahead.close()


def measure_frames(video, tracker, first: int = 0, max_frames: int | None = None):
    """Yield ``(frame, measurement)`` for the frames of ``video``: ``tracker`` calibrated on
    them from ``first`` on, then measuring (see :class:`Tracking`)."""
    run = Tracking(video, tracker, first, max_frames)
    it = iter(run)
    try:
        yield from it
    finally:
        it.close()


#: :func:`neutral_frames_of`: the candidates kept while the first pass runs, at most this many
#: times the frames wanted (every other one dropped when there are more, and from then on
#: every other one taken: spread over the video whatever its length)
FIRST_PASS_KEEP = 4


def neutral_frames_of(video, tracker, first: int = 0, max_frames: int | None = None,
                      show_progress: bool = False) -> dict:  # fmt: skip
    """A first pass of ``tracker`` (a 3-D fit's :class:`FitTracker`, made by
    :func:`make_analyzer`; closed here) over ``video``: its frames labelled neutral by the
    expression reader (:class:`~myoface.analysis.expressions.ExpressionReader`, as
    contractions.csv labels them), spread over the video
    (:func:`~myoface.analysis.modelfit.neutral_views`), as ``{frame index: (MediaPipe's
    points, image)}``: a second pass's :attr:`FitTracker.registration_views` (``myoface
    analyze --two-pass``). Only those frames' images are kept (at most
    :data:`~myoface.analysis.modelfit.NEUTRAL_VIEWS_MAX` x :data:`FIRST_PASS_KEEP`), and their
    points are detected again on each image alone."""
    from myoface.analysis.expressions import ExpressionReader
    from myoface.analysis.modelfit import NEUTRAL_VIEWS_MAX, NEUTRAL_VIEWS_RUN, spread_evenly

    reader = ExpressionReader(tracker.ids)
    kept: dict = {}  # (candidate frame index -> image)
    stride, seen = 1, 0
    run, last = 0, None  # (the frames labelled neutral in a row, up to the last one handed)
    try:
        frames = measure_frames(video, tracker, first, max_frames)
        for frame, m in progress(frames, desc="first pass", enabled=show_progress):
            ok = m.quality == "ok" and np.isfinite(m.contractions).all()
            neutral = ok and reader.read(m.contractions, m.pose.angles_deg)[1] == "neutral"
            if not neutral:
                run = 0
            elif last is not None and m.index != last + 1:
                run = 1  # (a frame not handed between two is not measured: a new run)
            else:
                run += 1
            last = m.index
            if run >= NEUTRAL_VIEWS_RUN:
                if seen % stride == 0:
                    kept[m.index] = frame
                seen += 1
                if len(kept) > FIRST_PASS_KEEP * NEUTRAL_VIEWS_MAX:
                    kept = dict(list(kept.items())[::2])
                    stride *= 2
    finally:
        tracker.close()
    # (the candidates are neutral_views' frames, every stride-th: spread over them)
    return detected_views({k: kept[k] for k in spread_evenly(sorted(kept), NEUTRAL_VIEWS_MAX)})


def detected_views(images: dict) -> dict:
    """``{frame index: (MediaPipe's points, image)}`` of ``images`` ({frame index: image}),
    each detected alone (frames with no face left out): registration views
    (:meth:`~myoface.analysis.modelfit.ModelFit.set_appearance`'s ``views``)."""
    from myoface.facemesh import FaceMeshDetector

    out = {}
    with FaceMeshDetector(video=False) as det:
        for k, image in images.items():
            p = det.detect(image)
            if p is not None:
                out[k] = (p, image)
    return out
