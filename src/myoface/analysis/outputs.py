"""One video's analysis written into a folder: what ``myoface analyze`` (and, per video,
``myoface batch``) writes.

==================  ==========================================================================
contractions.csv    frame, time_s, quality, one column per muscle, jaw_angle_rad, head frame
                    (:func:`~myoface.analysis.contractions_csv.write_contractions_csv`)
analysis.json       settings, calibration and per-frame diagnostics
contractions.png    the contractions over time (the paper's Fig. 8)
expressions.png     the six basic expressions and neutral over time, read from the contractions
                    (:mod:`~myoface.analysis.expressions`; their columns are in the CSV)
overlay.mp4         the contours on the frames (the paper's Fig. 7a)
potential.mp4       (snakes) the contours on the image potential (the paper's Fig. 7b)
==================  ==========================================================================

(and, from ``myoface analyze``, openface.csv and the fidelity report: :data:`ANALYSIS_FILES`.)
The folder is written as one transaction (:func:`analyze_to_folder`, over
:func:`~myoface._io.output_transaction`): a run replaces an earlier run's files when it
succeeds, or is interrupted with frames measured, and leaves them byte for byte when it fails;
the user's other files in the folder are never touched; one run at a time writes it.

Image coordinates are (x, y) = (column, row) pixels.
"""

from __future__ import annotations

import contextlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from myoface._io import atomic_output
from myoface._signals import clear_pending, deferred, held, interrupt_in, raise_pending
from myoface.analysis.contractions_csv import ContractionsCsvWriter
from myoface.analysis.initfiles import load_init
from myoface.analysis.pipeline import Tracking, make_analyzer
from myoface.analysis.video import Video, open_video
from myoface.errors import MyofaceValueError
from myoface.model import load_face_model
from myoface.render import VideoWriter, progress

#: the files :func:`analyze_to_folder` writes for every tracker
FOLDER_FILES = (
    "contractions.csv",
    "analysis.json",
    "contractions.png",
    "expressions.png",
    "overlay.mp4",
)


def draw_contours(frame: np.ndarray, contours: dict, color=(255, 215, 0)) -> np.ndarray:
    """A copy of ``frame`` (H, W, 3) uint8 with the polylines ``contours`` ({name: (K, 2)},
    (x, y) pixels) drawn in ``color``."""
    img = frame.copy()
    h, w = img.shape[:2]
    for pts in contours.values():
        p = np.asarray(pts, float).reshape(-1, 2)
        p = p[np.isfinite(p).all(axis=1)]
        if len(p) < 2:
            continue
        # two samples a pixel along the polyline, at most what crosses the frame a few times
        # (a contour projected from a wild pose can be kilometres long)
        length = float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())
        n = int(min(max(2, length * 2), 8 * (w + h) * len(p)))
        t = np.linspace(0, len(p) - 1, n)
        x = np.interp(t, np.arange(len(p)), p[:, 0])
        y = np.interp(t, np.arange(len(p)), p[:, 1])
        xi = np.round(np.clip(x, 0, w - 1)).astype(int)
        yi = np.round(np.clip(y, 0, h - 1)).astype(int)
        img[yi, xi] = color
    return img


#: a contraction at or above this is at the model's limit (the fit's bound is 1: the most
#: the model's muscle makes)
AT_LIMIT = 0.99
#: :func:`limit_note` names the muscles at their limit on at least this share of the frames
#: measured
LIMIT_NOTE_SHARE = 0.1


def at_limit(ids, table, quality) -> dict[str, float]:
    """Each muscle's share of the measured frames (``quality`` "ok") whose contraction in
    ``table`` (T, M) is at the model's limit (:data:`AT_LIMIT`), for the muscles that reach it,
    largest first. A muscle held there over many frames means the person moved more than the
    model's muscle can move the skin (or the fit gave it motion that belongs to another):
    its contraction reads the model's limit, not the person's effort."""
    table = np.asarray(table, dtype=np.float64)
    ok = np.array([q == "ok" for q in quality], dtype=bool)
    if not ok.any():
        return {}
    share = (table[ok] >= AT_LIMIT).mean(axis=0)
    order = np.argsort(-share, kind="stable")
    return {str(ids[j]): round(float(share[j]), 3) for j in order if share[j] > 0}


def limit_note(shares: dict[str, float]) -> str | None:
    """The line ``myoface analyze`` prints when muscles sit at their limit
    (:func:`at_limit`'s ``shares``) on :data:`LIMIT_NOTE_SHARE` of the frames or more; None
    when none does."""
    many = {k: v for k, v in shares.items() if v >= LIMIT_NOTE_SHARE}
    if not many:
        return None
    named = ", ".join(f"{k} {v:.0%}" for k, v in list(many.items())[:6])
    more = f" and {len(many) - 6} more" if len(many) > 6 else ""
    return (
        f"note: {len(many)} muscle{'s' if len(many) > 1 else ''} at the model's limit "
        f"(contraction 1) on {LIMIT_NOTE_SHARE:.0%} of the measured frames or more ({named}"
        f"{more}): there they read the model's limit, not the person's effort (the skin "
        "moved more than the muscle can move it, or the fit gave the muscle motion that "
        'another makes; docs/expressions.md, "Muscles at their limit") '
        '(analysis.json\'s "at_limit"; red ticks in contractions.png)'
    )


def own_neutral_note(n_measured: int, n_frames: int) -> str | None:
    """The line ``myoface analyze`` prints when a single frame was analysed: the
    calibration takes the person's neutral from the frames it is given, so a lone frame is
    its own neutral and reads no expression whatever the face does (a photo of a smile reads
    every contraction 0). None for more frames."""
    if n_frames != 1 or n_measured != 1:
        return None
    return (
        "note: one frame was analysed, and it is its own neutral (the calibration): every "
        "contraction reads 0 and the expression neutral, whatever the face does; to measure an "
        "expression give a video, or a folder of frames, in which the face is first at rest"
    )


def plot_contractions(path, ids, times, table, quality) -> None:
    """The contractions ``table`` (T, M) over ``times`` (T,) s, one panel per muscle pair
    (the paper's Fig. 8); frames whose ``quality`` is not "ok" shaded grey, and red ticks at
    the top of a panel where a contraction is at the model's limit (:func:`at_limit`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = {}
    for j, k in enumerate(ids):
        base = k[:-2] if k.endswith(("_l", "_r")) else k
        groups.setdefault(base, []).append(j)
    fig, axes = plt.subplots(len(groups), 1, figsize=(8, 1.3 * len(groups) + 0.6), sharex=True)
    axes = np.atleast_1d(axes)
    for ax, (base, cols) in zip(axes, groups.items(), strict=True):
        for j in cols:
            ax.plot(times, table[:, j], label=ids[j][-1] if ids[j][-2] == "_" else "")
        top = (np.nan_to_num(np.asarray(table[:, cols], dtype=np.float64)) >= AT_LIMIT).any(1)
        if top.any():
            ax.plot(np.asarray(times)[top], np.full(int(top.sum()), 1.05), "|", color="tab:red",
                    ms=5, zorder=3)  # fmt: skip
        ax.set_ylim(-0.02, 1.09)
        ax.set_ylabel(base.replace("_", " "), rotation=0, ha="right", fontsize=8)
        ax.tick_params(labelsize=7)
        bad = [t for t, q in zip(times, quality, strict=True) if q != "ok"]
        for t in bad:
            ax.axvline(t, color="0.85", lw=2, zorder=0)
    axes[0].legend(loc="upper right", fontsize=7, ncol=2)
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(
        "estimated contractions (grey: frames that could not be measured; red ticks: at the "
        "model's limit)",
        fontsize=9,
    )
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.35 / fig.get_figheight()))  # (the title clear)
    with atomic_output(path) as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)


class FrameLog:
    """What :func:`analyze_to_folder` keeps of each frame while it streams the rows to the
    CSV: index, time, quality, tracking iterations and contractions (float32), packed in
    growing arrays (about 100 bytes a frame for the 3-D fit's 40 contractions), so an hour of
    video costs a few MB. ``len()`` is the number of frames."""

    def __init__(self, n_ids: int):
        import array

        self.n_ids = int(n_ids)
        self._index = array.array("q")
        self._time = array.array("d")
        self._iterations = array.array("l")
        self._contractions = array.array("f")
        self._quality: list[str] = []
        self._names: dict[str, str] = {}  # one string object per distinct quality

    def append(self, m) -> None:
        """Record the measurement ``m`` (a :class:`~myoface.analysis.trackers.base.FrameMeasurement`
        or the 3-D fit's)."""
        self._index.append(int(m.index))
        self._time.append(float(m.time_s))
        self._iterations.append(int(m.iterations))
        c = np.asarray(m.contractions, dtype=np.float32).reshape(-1)
        if c.size != self.n_ids:
            raise MyofaceValueError(f"expected {self.n_ids} contractions; got {c.size}")
        self._contractions.frombytes(c.tobytes())
        self._quality.append(self._names.setdefault(m.quality, m.quality))

    def __len__(self) -> int:
        return len(self._index)

    @property
    def index(self) -> np.ndarray:
        """(T,) the frames' indices in the video."""
        return np.frombuffer(self._index, dtype=np.int64).copy()

    @property
    def times(self) -> np.ndarray:
        """(T,) s."""
        return np.frombuffer(self._time, dtype=np.float64).copy()

    @property
    def iterations(self) -> np.ndarray:
        """(T,) the tracker's iterations per frame."""
        return np.array(self._iterations, dtype=np.int64)

    @property
    def quality(self) -> list[str]:
        """Per frame ``"ok"`` or why it could not be measured."""
        return list(self._quality)

    @property
    def contractions(self) -> np.ndarray:
        """(T, K) float64 in [0, 1]; NaN rows where a frame could not be measured."""
        c = np.frombuffer(self._contractions, dtype=np.float32)
        return c.reshape(-1, self.n_ids).astype(np.float64)


@dataclass
class FolderResult:
    """What :func:`analyze_to_folder` measured and where it wrote it.

    Attributes
    ----------
    folder : Path — the output folder.
    video : Path — the analysed video.
    ids : tuple of str — the estimated muscles (and ``"jaw"``).
    frames : :class:`FrameLog` — each analysed frame's index, time, quality and contractions,
        in order (``len(frames)`` frames).
    calibration_frame : int — the index of the neutral frame the analysis calibrated on (the
        snakes start there; the 3-D fit analyses from the first frame).
    interrupted : str or None — where the run was interrupted, if it was.
    """

    folder: Path
    video: Path
    ids: tuple
    frames: FrameLog
    calibration_frame: int
    #: None, or where the run was interrupted: ``"frames"``, ``"plots"``, or ``"finish"`` (or
    #: what ``finish`` named its work in :attr:`stage`)
    interrupted: str | None = None
    #: what ``finish`` is doing, for analysis.json's ``"interrupted_in"`` (e.g. ``"report"``)
    stage: str | None = None
    #: what ``finish`` says of an interrupted run (what it did not make), for the note
    notes: list = field(default_factory=list)

    @property
    def n_measured(self) -> int:
        """Frames whose quality is "ok"."""
        return sum(q == "ok" for q in self.frames.quality)

    def at_limit(self) -> dict[str, float]:
        """:func:`at_limit` of the frames analysed."""
        return at_limit(self.ids, self.frames.contractions, self.frames.quality)

    @property
    def measured_fraction(self) -> float:
        return self.n_measured / len(self.frames) if len(self.frames) else 0.0

    @property
    def contractions(self) -> np.ndarray:
        """(T, K) in [0, 1]; NaN rows where a frame could not be measured."""
        return self.frames.contractions

    def mean_contractions(self) -> dict[str, float]:
        """{id: mean contraction over the measured frames} (NaN when none was measured)."""
        ok = np.array([q == "ok" for q in self.frames.quality], dtype=bool)
        table = self.contractions[ok]
        if not len(table):
            return {k: float("nan") for k in self.ids}
        return {k: float(v) for k, v in zip(self.ids, np.nanmean(table, axis=0), strict=True)}


def analyze_to_folder(
    video,
    out,
    *,
    model=None,
    tracker: str = "snakes",
    init=None,
    calibration_frame: int | None = None,
    max_frames: int | None = None,
    refine: int | None = None,
    sigma: float | None = None,
    estimator: str = "curves",
    face: str | None = None,
    show_progress: bool = False,
    finish=None,
    flow: bool = False,
    photometric: bool | None = None,
    two_pass: bool = False,
) -> FolderResult:
    """Analyse ``video`` and write the analysis into the folder ``out`` (see the module's
    table); the code path of ``myoface analyze``.

    The folder is written as one transaction (:func:`~myoface._io.output_transaction`): the
    run writes into a fresh folder beside it, and its files replace the earlier run's
    (:data:`ANALYSIS_FILES`) only when it succeeds, or is interrupted with some of the
    frames measured; a failure leaves the folder as it was, byte for byte. Files of the
    folder that an analysis does not write (the user's) are never touched. While it runs,
    the folder's lock says who writes it, and a second run into it is refused.

    The analysis streams: each frame is decoded, tracked and fitted, and its row appended to
    contractions.csv (flushed at once; see
    :class:`~myoface.analysis.contractions_csv.ContractionsCsvWriter`) and its pictures to the
    overlay videos before the next frame is read, all of a frame or none of it (a stop
    signal waits for the frame's outputs); of each frame only a compact record is kept
    (:class:`FrameLog`, for the plot and analysis.json), so memory does not grow with the
    video's length.

    An interruption (Ctrl-C, or SIGTERM / SIGHUP under ``myoface``: a
    :class:`KeyboardInterrupt`) keeps what was complete, and stops within a second or two:
    in the frames, the CSV with every measured row, the overlay videos of the same frames,
    analysis.json, and the files ``finish`` derives from them (not the plot, which takes
    seconds); later (the plot, ``finish``'s report), all the frames and whatever else was
    finished. analysis.json then says
    ``"interrupted": true`` and where (``"interrupted_in"``: ``"frames"``, ``"plots"`` or
    ``"finish"``, or what ``finish`` named its work in ``result.stage``); the :class:`KeyboardInterrupt` is raised again with a note saying what
    was kept (``myoface`` prints it in its one line). An interruption before the first frame
    keeps nothing, as an error.

    Parameters
    ----------
    video : path or :class:`~myoface.analysis.video.Video`.
    out : the output folder (created with its parents if missing), or an open
        :class:`~myoface.analysis.outputs.OutputTransaction` of :func:`analysis_transaction`
        (``myoface analyze`` opens it before it loads the model, so that a refused folder is
        said at once).
    model : the :class:`~myoface.model.FaceModel` (never changed; may be shared with other
        threads); default: loaded from ``face``.
    tracker, calibration_frame, refine, sigma, estimator, flow, photometric : as in
        :func:`~myoface.analysis.pipeline.make_analyzer`.
    init : initial contours on the calibration frame, for the snakes: a JSON file (see
        :func:`~myoface.analysis.initfiles.load_init`) or {section: (K, 2)} pixels; None:
        found with MediaPipe.
    max_frames : analyse at most this many frames.
    face : the face model's file (``None``: the bundled face); recorded in analysis.json, and
        loaded when ``model`` is None.
    show_progress : a progress bar over the frames on stderr.
    two_pass : the 3-D fit with its photometric term only: a first pass over the video whose
        frames labelled neutral, spread over it, register the appearance of the second (the
        one written; :func:`~myoface.analysis.pipeline.neutral_frames_of`,
        :attr:`~myoface.analysis.trackers.landmark_fit.FitTracker.registration_views`): the
        calibration window shows the face from one view, and what that view cannot tell is
        read at every other as expression (docs/expressions.md, "What holds the readings").
        Twice the time.
    finish : ``finish(folder, result)`` is called once the analysis' files are written into
        ``folder`` (the transaction's, not yet in place), for extra outputs such as
        ``myoface analyze``'s ``--format openface`` and ``--report``; if it fails, nothing
        is kept. After an interruption in the frames or the plot it is called too, with
        ``result.interrupted`` set, for the files made from the kept frames (it should then
        make only quick ones). :attr:`FolderResult.folder` is where the files will be.

    Raises
    ------
    MyofaceError
        On bad input, a video without frames, or when no frame could be measured;
        :class:`~myoface._io.OutputConflictError` for an output folder that is (inside) the
        input or that another run writes.
    KeyboardInterrupt
        When interrupted (see above).
    """
    from myoface._io import OutputTransaction

    if not isinstance(video, Video):
        video = open_video(video)
    how_init = None
    if init is not None and tracker == "landmarks":
        raise MyofaceValueError("--init is for the snakes; the landmark tracker needs none")
    if isinstance(init, str | os.PathLike):
        how_init = str(Path(init).resolve())
        init = load_init(init)
    if isinstance(out, OutputTransaction):
        opened = contextlib.nullcontext(out)
    else:
        opened = analysis_transaction(out, video.path)
    with contextlib.ExitStack() as keep, opened as tx:
        if model is None:
            model = load_face_model(face)

        def analyzer():
            return make_analyzer(
                model, video, tracker, init or None, calibration_frame, refine, sigma,
                estimator=estimator, flow=flow, photometric=photometric,
            )  # fmt: skip

        views = _first_pass(analyzer, video, max_frames, show_progress) if two_pass else None
        an, first = analyzer()
        if views is not None:
            an.registration_views = views
        folder = tx.path
        run = Tracking(video, an, first, max_frames)
        try:
            log, interrupted = _measure_into(run, model, folder, show_progress, keep)
        except BaseException:
            an.close()
            raise
        cal = getattr(an, "calibration_frame", None)  # (the 3-D fit's, once calibrated)
        cal = run.start if cal is None else int(cal)
        result = FolderResult(tx.target, Path(video.path), tuple(an.ids), log, cal)
        stage = "frames" if interrupted is not None else "plots"
        side = (run, log, how_init, tracker, face)
        try:
            an.close()
            if interrupted is None:
                _write_results(folder, *side, interrupted=None)
                stage = "finish"
            else:  # (stop signals held: the kept frames' files are made whole; not the
                # plot, which takes seconds on a busy machine: the run is stopping)
                _write_results(folder, *side, interrupted="frames", plot=False)
                result.interrupted = "frames"
            if finish is not None:
                finish(folder, result)
            if interrupted is None:
                stage = "commit"
                tx.commit()  # (a stop signal in it is raised once it is done)
        except BaseException as err:
            exc = interrupt_in(err)  # (also one wrapped by a C callback it landed in)
            if exc is None:
                raise
            clear_pending()
            keep.enter_context(held())  # the kept files are written whole
            interrupted = exc
            if stage in ("plots", "finish"):  # (the plot was made, or is what was cut)
                if stage == "finish":
                    stage = result.stage or stage
                _write_results(folder, *side, interrupted=stage, plot=False)
                result.interrupted = stage
                if stage == "plots" and finish is not None:
                    finish(folder, result)  # (its quick files, as after the frames)
        if interrupted is not None:
            if not tx.committed:
                tx.commit()
            interrupted.__notes__ = [
                _kept_note(result, tx.target),
                *getattr(interrupted, "__notes__", ()),  # (what ``finish`` did not make)
                *result.notes,
            ]
            raise interrupted
    return result


def _first_pass(analyzer, video, max_frames, show_progress) -> dict:
    """:func:`analyze_to_folder`'s first pass (``two_pass``): the frames that register the
    second's appearance (:func:`~myoface.analysis.pipeline.neutral_frames_of`)."""
    from myoface.analysis.pipeline import neutral_frames_of
    from myoface.analysis.trackers.landmark_fit import FitTracker

    an, first = analyzer()
    if not isinstance(an, FitTracker) or not an.settings.photometric:
        an.close()
        raise MyofaceValueError(
            "two passes (--two-pass) are for the landmarks' 3-D fit with its photometric term"
        )
    return neutral_frames_of(video, an, first, max_frames, show_progress)


def _kept_note(result: FolderResult, target) -> str:
    """What an interrupted :func:`analyze_to_folder` kept, said in one line."""
    n, n_ok = len(result.frames), result.n_measured
    csv = Path(target) / "contractions.csv"
    if result.interrupted == "frames":
        return f"kept the {n} frames analysed ({n_ok} measured) in {csv} (not plotted)"
    if result.interrupted is None:  # (it came as the outputs were put in place)
        return f"the analysis was complete: {n} frames ({n_ok} measured) in {target}"
    if result.interrupted == "plots":
        return f"kept the analysis of all {n} frames ({n_ok} measured) in {csv} (not plotted)"
    return f"kept the analysis of all {n} frames ({n_ok} measured) in {target}"


#: every file an analysis folder may hold (:func:`analyze_to_folder`'s, ``myoface
#: analyze``'s openface.csv and fidelity report): a run replaces the earlier run's and
#: removes those it does not write, so the folder describes one run; any other file in it
#: is the user's and stays
ANALYSIS_FILES = (
    *FOLDER_FILES,
    "potential.mp4",
    "openface.csv",
    "fidelity.json",
    "fidelity.png",
)


#: the fidelity report's files (``myoface analyze --report``): both or neither
REPORT_FILES = ("fidelity.json", "fidelity.png")


def analysis_transaction(
    out, video_path, *, inputs: dict | None = None, what: str = "-o", command: str | None = None
):
    """The transaction of an analysis into the folder ``out``
    (:func:`~myoface._io.output_transaction` over :data:`ANALYSIS_FILES`), refused when
    ``out`` is the video ``video_path`` (a folder of images), inside it, or would write over
    it (or over one of ``inputs``, ``{what: path}``), or when another run writes ``out``."""
    from myoface._io import output_transaction

    label = "the input folder" if Path(video_path).is_dir() else "the input video"
    return output_transaction(
        out,
        ANALYSIS_FILES,
        what=what,
        inputs={label: video_path, **(inputs or {})},
        command=command,
    )


def _write_results(out, run, log, how_init, tracker, face, *, interrupted, plot=True) -> None:
    """analysis.json, contractions.png and expressions.png (contractions.csv is written as
    the frames are; the expressions' plot is of its expression columns);
    ``interrupted``: None, or where the run was interrupted (then said in analysis.json, and
    the plot made unless ``plot`` is false)."""
    video, an = run.video, run.tracker
    side = {
        "video": str(Path(video.path).resolve()),
        "fps": video.fps,
        "size": list(video.size),
        # (the frames as a player shows them: how they were turned from the way they are
        # stored, or None)
        "turned_upright": getattr(video, "turned", None),
        "tracker": tracker,
        "calibration_frame": run.start,
        "face": str(face) if face else "default",
        "muscles": list(an.ids),
    }
    if interrupted is not None:
        side["interrupted"] = True
        side["interrupted_in"] = interrupted
    side["frames"] = [
        {"frame": int(k), "quality": q, "iterations": int(it)}
        for k, q, it in zip(log.index, log.quality, log.iterations, strict=True)
    ]
    # the muscles at the model's limit, and on what share of the measured frames
    side["at_limit"] = at_limit(an.ids, log.contractions, log.quality)
    # the tracker's own account: how it was initialised, mm per pixel, its settings
    side.update(an.describe())
    if how_init is not None:
        side["init"] = how_init
    with atomic_output(out / "analysis.json") as tmp:
        with open(tmp, "w", encoding="utf-8") as fh:
            json.dump(side, fh, indent=1)
    if plot:
        plot_contractions(
            out / "contractions.png", an.ids, log.times, log.contractions, log.quality
        )
        from myoface.analysis.expressions import plot_expressions, read_expressions

        scores, labels = read_expressions(out / "contractions.csv")
        plot_expressions(out / "expressions.png", log.times, scores, labels, log.quality)


def _measure_into(run, model, out, show_progress, keep):
    """Measure every frame of ``run`` (a :class:`~myoface.analysis.pipeline.Tracking`),
    streaming each frame's CSV row and overlay pictures (the contours on the frame, and on
    each of the tracker's :meth:`debug_images`, e.g. the snakes' potential), a frame's all
    or none; ``(FrameLog, None)``, or ``(FrameLog, the KeyboardInterrupt)`` when interrupted
    after the first frame (the CSV and the videos then closed with the frames so far, and
    stop signals held in ``keep``, an ExitStack, until the caller has kept them). A clear
    error when nothing could be measured."""
    video, an = run.video, run.tracker
    start = run.calibrate()  # (before the progress bar: its errors come alone)
    log = FrameLog(len(an.ids))
    n = video.n_frames
    if n is not None:
        n -= start
    if run.max_frames is not None:
        n = run.max_frames if n is None else min(n, run.max_frames)
    csv = ContractionsCsvWriter(out / "contractions.csv", an.ids, model.muscles.jaw)
    interrupted = None
    try:
        with contextlib.ExitStack() as stack:
            vw = stack.enter_context(VideoWriter(out / "overlay.mp4", fps=video.fps))
            extra: dict = {}  # the debug images' videos, opened as they first come
            measured = stack.enter_context(contextlib.closing(iter(run)))
            bar = stack.enter_context(
                progress(None, total=n, desc="analyzing", enabled=show_progress)
            )
            try:
                for frame, m in measured:
                    raise_pending()  # (a stop signal noted and not raised)
                    color = (255, 215, 0) if m.quality == "ok" else (230, 40, 40)
                    pictures = {"overlay": draw_contours(frame, m.contours, color)}
                    for name, img in an.debug_images(frame, m).items():
                        pictures[name] = draw_contours(img, m.contours, color)
                    with deferred():  # the frame's row and pictures, all or none
                        csv.write(m)
                        log.append(m)
                        for name, img in pictures.items():
                            if name not in extra and name != "overlay":
                                extra[name] = stack.enter_context(
                                    VideoWriter(out / f"{name}.mp4", fps=video.fps)
                                )
                            (vw if name == "overlay" else extra[name]).write(img)
                    bar.update()
            except BaseException as err:
                exc = interrupt_in(err)  # (also one wrapped by a C callback it landed in)
                if exc is None:
                    raise
                clear_pending()
                if not len(log) or not vw.n_frames:
                    raise  # nothing kept: as an error, nothing is left
                interrupted = exc  # the writers close and keep the frames so far
                keep.enter_context(held())  # while they do, a second signal waits
            if not len(log):
                raise MyofaceValueError(f"{video.path}: the video has no frames")
            if interrupted is None and not any(q == "ok" for q in log.quality):
                raise MyofaceValueError(
                    f"{video.path}: no frame could be measured (no face found?)"
                )
    except BaseException:
        if interrupted is None:
            csv.discard()
        raise
    finally:
        csv.close()
    return log, interrupted
