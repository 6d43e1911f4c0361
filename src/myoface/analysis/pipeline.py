"""The paper's analysis loop: face video -> snakes on nine feature contours -> fiducials in a
head frame -> muscle contractions and jaw rotation per frame (Terzopoulos & Waters 1993,
Section V), and the driver of every tracker.

The analysis level, one module a stage:

- :mod:`~myoface.analysis.sections`: the feature contours (sections), their features and the
  model's skin curves they are compared with;
- :mod:`~myoface.analysis.initfiles`: the snakes' initial contours as JSON;
- trackers, each behind :class:`~myoface.analysis.tracker.Tracker` (frame ->
  :class:`~myoface.analysis.tracker.FrameMeasurement`): the snakes
  (:class:`~myoface.analysis.snaketracker.Analyzer`),
  the 3-D fit of the model to MediaPipe's points (:mod:`~myoface.analysis.fit`) and the
  paper's 2-D scheme on those points (:mod:`~myoface.analysis.landmarks`);
- :mod:`~myoface.analysis.contractions_csv`: the measurements as a CSV, and back;
- :mod:`~myoface.analysis.outputs`: a whole run to a folder (CSV, plot, overlays, JSON).

This module makes and calibrates a tracker (:func:`make_analyzer`) and drives it over a video
(:func:`measure_frames`, :func:`analyze_video`). Features are geometric (extremes,
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
from dataclasses import dataclass

import numpy as np

from myoface.analysis.contractions_csv import (  # noqa: F401  (re-exported: the analysis' API)
    CSV_OTHER_COLUMNS,
    HEAD_2D_COLUMNS,
    ContractionsCsvWriter,
    contractions_csv_header,
    contractions_csv_row,
    hold_last_measured,
    read_contractions_csv,
    write_contractions_csv,
)
from myoface.analysis.initfiles import load_init, save_init  # noqa: F401  (re-exported)
from myoface.analysis.sections import (  # noqa: F401  (re-exported)
    CURVE_EXCLUDED,
    FEATURES,
    LINE_SECTIONS,
    PAPER_MUSCLES,
    SECTIONS,
    curve_centroid,
    model_fiducials,
    project_sections,
    section_features,
    section_vertices,
)
from myoface.analysis.snaketracker import (  # noqa: F401  (re-exported)
    ESTIMATORS,
    MOUTH_SECTIONS,
    SIGMA_MM,
    Analyzer,
    lips_tone,
)
from myoface.analysis.tracker import FrameMeasurement, Tracker  # noqa: F401  (re-exported)
from myoface.errors import MyofaceValueError


def make_analyzer(
    model,
    video,
    tracker: str = "snakes",
    init=None,
    calibration_frame: int = 0,
    refine=None,
    sigma: float | None = None,
    estimator: str = "curves",
    show_progress: bool | None = None,
    flow: bool = False,
):
    """The analyzer for ``video`` (a :class:`~myoface.analysis.video.Video`), how it was
    initialised (text) and the calibration frame's index.

    ``tracker="snakes"``: :class:`Analyzer` from ``init`` (contours on the calibration frame)
    or, when ``init`` is None, from MediaPipe's face mesh on the first frame with a face from
    ``calibration_frame`` on (the whole video is searched if need be; ``show_progress``: with
    a progress bar on stderr; default: when stderr is a terminal). ``tracker="landmarks"``:
    ``estimator`` ``"fit"`` (default): the 3-D fit of the whole model
    (:func:`~myoface.analysis.fit.make_fit_analyzer`: head pose and every muscle, calibrated on
    ``calibration_frame``, or when it is None on the most neutral frame of the first seconds,
    the analysis then starting at frame 0); ``"paper"``: the paper's 12 muscles in a 2-D head
    frame (:class:`~myoface.analysis.landmarks.LandmarkAnalyzer`). ``init`` must be None.
    ``refine`` defaults to 1 for the snakes, 0 for the paper's landmark scheme and
    :attr:`~myoface.analysis.fit.FitSettings.refine` for the fit; ``estimator`` for the
    snakes: ``"curves"`` (default) or ``"fiducials"`` (see :class:`Analyzer`). ``flow``: the
    3-D fit's points refined by optical flow (:attr:`~myoface.analysis.fit.FitSettings.flow`;
    for the landmark tracker's fit only).
    """
    import itertools

    if flow and tracker != "landmarks":
        raise MyofaceValueError(
            "--flow refines the landmark tracker's points; use it with --tracker landmarks"
        )
    first = 0 if calibration_frame is None else int(calibration_frame)
    if first < 0 or (video.n_frames is not None and first >= video.n_frames):
        raise MyofaceValueError(
            f"--calibration-frame must be in [0, {video.n_frames}); got {first}"
        )
    if tracker == "landmarks":
        from myoface.analysis.fit import LANDMARK_ESTIMATORS, FitSettings, make_fit_analyzer
        from myoface.analysis.landmarks import LandmarkAnalyzer

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
            synthesis = est == "fit-synthesis"
            settings = FitSettings(flow=bool(flow))
            return make_fit_analyzer(
                model, video, calibration_frame, refine, settings=settings, synthesis=synthesis
            )
        if flow:
            raise MyofaceValueError("--flow is for the 3-D fit, not --estimator paper")
        an = LandmarkAnalyzer(model, refine=0 if refine is None else refine)
        return an, "MediaPipe face mesh on every frame", first
    if tracker != "snakes":
        raise MyofaceValueError(f"tracker must be 'snakes' or 'landmarks'; got {tracker!r}")
    if init is not None:
        how, start = "contours given", first
    else:
        import sys

        from myoface.analysis.landmarks import auto_init

        if show_progress is None:
            show_progress = sys.stderr.isatty()
        k, _, init, _ = auto_init(
            itertools.islice(video, first, None),
            model.face,
            show_progress=show_progress,
            total=None if video.n_frames is None else video.n_frames - first,
        )
        start = first + k
        how = f"automatic: MediaPipe face mesh on frame {start}"
    w, h = video.size
    for name, pts in init.items():
        if (pts < 0).any() or (pts[:, 0] > w - 1).any() or (pts[:, 1] > h - 1).any():
            raise MyofaceValueError(f"contour {name!r} lies outside the frame")
    an = Analyzer(
        model,
        init,
        refine=1 if refine is None else refine,
        sigma=sigma,
        estimator=estimator or "curves",
        deferred_relax=True,  # a video: the tissue relaxed on a second thread
    )
    return an, how, start


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
    from myoface.analysis.video import Video, open_video
    from myoface.render import progress

    if model is None:
        from myoface.model import build_face_model

        model = build_face_model()
    if not isinstance(video, Video):
        video = open_video(video)
    if isinstance(init, str | os.PathLike):
        init = load_init(init)
    an, _, start = make_analyzer(
        model, video, tracker, init, calibration_frame, estimator=estimator
    )
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


def measure_frames(video, analyzer, start: int = 0, max_frames: int | None = None):
    """Yield ``(frame, FrameMeasurement)`` for the frames of ``video`` from ``start`` on (at
    most ``max_frames``).

    An analyzer with an ``observe(frame, index)`` method (the 3-D fit's
    :class:`~myoface.analysis.fit.FitAnalyzer`: MediaPipe's face mesh) has it run on a
    worker thread a few frames ahead (:func:`~myoface.analysis.landmarks.detect_ahead`),
    and its ``measure`` takes the result as ``observation``: the face mesh tracks the next
    frames while this one is fitted. The results are the same as frame by frame (each frame
    is observed once, in order). Stopping early (closing this generator) stops the thread.
    An analyzer with a ``replay(video, start)`` method gives the frames itself when it can
    (the 3-D fit: its calibration's decoded frames, then the rest of its decode)."""

    def frames():
        # an analyzer that kept its calibration's decoded frames hands them over (``replay``:
        # the 3-D fit's), else the video is decoded from its start
        replay = getattr(analyzer, "replay", None)
        source = None if replay is None else replay(video, start)
        if source is None:
            source = ((k, f) for k, f in enumerate(video) if k >= start)
        n = 0
        try:
            for k, frame in source:
                if max_frames is not None and n >= max_frames:
                    return
                n += 1
                yield k, frame
        finally:
            source.close()

    observe = getattr(analyzer, "observe", None)
    if observe is None:
        for k, frame in frames():
            yield frame, analyzer.measure(frame, k, k / video.fps)
        return
    from myoface.analysis.landmarks import detect_ahead

    ahead = detect_ahead(frames(), lambda kf: observe(kf[1], kf[0]))
    try:
        for (k, frame), obs in ahead:
            yield frame, analyzer.measure(frame, k, k / video.fps, observation=obs)
    finally:
        ahead.close()
