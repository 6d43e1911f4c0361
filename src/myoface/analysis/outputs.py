"""One video's analysis written into a folder: what ``myoface analyze`` (and, per video,
``myoface batch``) writes.

==================  ==========================================================================
contractions.csv    frame, time_s, quality, one column per muscle, jaw_angle_rad, head frame
                    (:func:`~myoface.analysis.contractions_csv.write_contractions_csv`)
analysis.json       settings, calibration and per-frame diagnostics
contractions.png    the contractions over time (the paper's Fig. 8)
overlay.mp4         the contours on the frames (the paper's Fig. 7a)
potential.mp4       (snakes) the contours on the image potential (the paper's Fig. 7b)
==================  ==========================================================================

Image coordinates are (x, y) = (column, row) pixels.
"""

from __future__ import annotations

import contextlib
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from myoface._io import atomic_output, output_dir
from myoface._signals import clear_pending, raise_pending
from myoface.analysis.contractions_csv import ContractionsCsvWriter
from myoface.analysis.initfiles import load_init
from myoface.analysis.pipeline import Tracking, make_analyzer
from myoface.analysis.video import Video, open_video
from myoface.errors import MyofaceValueError
from myoface.model import load_face_model
from myoface.render import VideoWriter, progress

#: the files :func:`analyze_to_folder` writes for every tracker
FOLDER_FILES = ("contractions.csv", "analysis.json", "contractions.png", "overlay.mp4")


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


def plot_contractions(path, ids, times, table, quality) -> None:
    """The contractions ``table`` (T, M) over ``times`` (T,) s, one panel per muscle pair
    (the paper's Fig. 8); frames whose ``quality`` is not "ok" shaded grey."""
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
        ax.set_ylim(-0.02, 1.02)
        ax.set_ylabel(base.replace("_", " "), rotation=0, ha="right", fontsize=8)
        ax.tick_params(labelsize=7)
        bad = [t for t, q in zip(times, quality, strict=True) if q != "ok"]
        for t in bad:
            ax.axvline(t, color="0.85", lw=2, zorder=0)
    axes[0].legend(loc="upper right", fontsize=7, ncol=2)
    axes[-1].set_xlabel("time (s)")
    fig.suptitle("estimated contractions (grey: frames that could not be measured)", fontsize=9)
    fig.tight_layout()
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
    calibration_frame : int — the index of the neutral frame the analysis started on.
    """

    folder: Path
    video: Path
    ids: tuple
    frames: FrameLog
    calibration_frame: int

    @property
    def n_measured(self) -> int:
        """Frames whose quality is "ok"."""
        return sum(q == "ok" for q in self.frames.quality)

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
    out: str | os.PathLike,
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
    photometric: bool = False,
) -> FolderResult:
    """Analyse ``video`` and write the analysis into the folder ``out`` (see the module's
    table); the code path of ``myoface analyze``.

    The analysis streams: each frame is decoded, tracked and fitted, and its row appended to
    contractions.csv (flushed at once; see
    :class:`~myoface.analysis.contractions_csv.ContractionsCsvWriter`) and its picture to the overlay
    videos before the next frame is read; of each frame only a compact record is kept
    (:class:`FrameLog`, for the plot and analysis.json), so memory does not grow with the
    video's length. The overlay videos are written under temporary names (``.overlay.*.part.mp4``)
    and renamed when they are closed.

    An interruption (Ctrl-C, or SIGTERM / SIGHUP under ``myoface``: a
    :class:`KeyboardInterrupt`) after the first frame keeps what was measured: the CSV with
    every measured row, the overlay videos closed as they stand, analysis.json (with
    ``"interrupted": true``) and the plot of those frames; no temporary file is left, and the
    :class:`KeyboardInterrupt` is raised again with a note saying how many frames were kept
    (``myoface`` prints it in its one line). An interruption before the first frame, or an
    error, removes what this call wrote.

    Parameters
    ----------
    video : path or :class:`~myoface.analysis.video.Video`.
    out : the output folder; created with its parents if missing. If the analysis fails, the
        folders this call created are removed again (a folder that existed is left, and an
        older contractions.csv in it is replaced when the first row is measured).
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
    finish : ``finish(folder, result)`` is called once the analysis' files are written, inside
        the folder's clean-up (if it fails, the folders this call created are removed): extra
        outputs such as ``myoface analyze``'s ``--format openface`` and ``--report``. Not
        called after an interruption.

    Raises
    ------
    MyofaceError
        On bad input, a video without frames, or when no frame could be measured.
    KeyboardInterrupt
        When interrupted (see above).
    """
    if not isinstance(video, Video):
        video = open_video(video)
    how_init = None
    if init is not None and tracker == "landmarks":
        raise MyofaceValueError("--init is for the snakes; the landmark tracker needs none")
    if isinstance(init, str | os.PathLike):
        how_init = str(Path(init).resolve())
        init = load_init(init)
    if model is None:
        pass

        model = load_face_model(face)
    an, first = make_analyzer(
        model, video, tracker, init or None, calibration_frame, refine, sigma,
        estimator=estimator, flow=flow, photometric=photometric,
    )  # fmt: skip
    release = None
    try:
        with output_dir(out) as folder:
            run = Tracking(video, an, first, max_frames)
            try:
                log, interrupted, release = _measure_into(run, model, folder, show_progress)
            finally:
                an.close()
            _write_results(run, folder, log, how_init, tracker, face, interrupted)
            result = FolderResult(folder, Path(video.path), tuple(an.ids), log, run.start)
            if finish is not None and interrupted is None:
                finish(folder, result)
    finally:
        if release is not None:
            release()
    if interrupted is not None:
        n_ok = result.n_measured
        interrupted.add_note(
            f"kept the {len(log)} frames analysed ({n_ok} measured) in {folder}"
            f"{os.sep}contractions.csv"
        )
        raise interrupted
    return result


def _write_results(run, out, log, how_init, tracker, face, interrupted) -> None:
    """analysis.json and contractions.png (contractions.csv is written as the frames are)."""
    video, an = run.video, run.tracker
    side = {
        "video": str(Path(video.path).resolve()),
        "fps": video.fps,
        "size": list(video.size),
        "tracker": tracker,
        "calibration_frame": run.start,
        "face": str(face) if face else "default",
        "muscles": list(an.ids),
    }
    if interrupted is not None:
        side["interrupted"] = True
    side["frames"] = [
        {"frame": int(k), "quality": q, "iterations": int(it)}
        for k, q, it in zip(log.index, log.quality, log.iterations, strict=True)
    ]
    # the tracker's own account: how it was initialised, mm per pixel, its settings
    side.update(an.describe())
    if how_init is not None:
        side["init"] = how_init
    with atomic_output(out / "analysis.json") as tmp:
        with open(tmp, "w", encoding="utf-8") as fh:
            json.dump(side, fh, indent=1)
    plot_contractions(out / "contractions.png", an.ids, log.times, log.contractions, log.quality)


def _measure_into(run, model, out, show_progress):
    """Measure every frame of ``run`` (a :class:`~myoface.analysis.pipeline.Tracking`),
    streaming each frame's CSV row and overlay pictures (the contours on the frame, and on
    each of the tracker's :meth:`debug_images`, e.g. the snakes' potential); ``(FrameLog,
    None)``, or ``(FrameLog, the KeyboardInterrupt)`` when interrupted after the first frame
    (the CSV and the videos then closed with the frames so far). A clear error when nothing
    could be measured (and then no file is left)."""
    video, an = run.video, run.tracker
    start = run.calibrate()  # (before the progress bar: its errors come alone)
    log = FrameLog(len(an.ids))
    release = lambda: None  # noqa: E731
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
                    raise_pending()  # (a stop signal Python swallowed somewhere)
                    # the row first: what the CSV holds was measured, whatever stops the run
                    csv.write(m)
                    log.append(m)
                    color = (255, 215, 0) if m.quality == "ok" else (230, 40, 40)
                    vw.write(draw_contours(frame, m.contours, color))
                    for name, img in an.debug_images(frame, m).items():
                        if name not in extra:
                            extra[name] = stack.enter_context(
                                VideoWriter(out / f"{name}.mp4", fps=video.fps)
                            )
                        extra[name].write(draw_contours(img, m.contours, color))
                    bar.update()
            except KeyboardInterrupt as exc:
                clear_pending()
                if not len(log) or not vw.n_frames:
                    raise  # nothing kept: as an error, nothing is left
                interrupted = exc  # the writers close and keep the frames so far
                release = _hold_signals()  # while they do, a second signal waits
            if not len(log):
                raise MyofaceValueError(f"{video.path}: the video has no frames")
            if interrupted is None and not any(q == "ok" for q in log.quality):
                raise MyofaceValueError(
                    f"{video.path}: no frame could be measured (no face found?)"
                )
    except BaseException:
        if interrupted is None:
            csv.discard()
        release()
        raise
    finally:
        csv.close()
    return log, interrupted, release


def _hold_signals():
    """Ignore SIGINT, SIGTERM and SIGHUP (main thread only) until the returned function is
    called, which restores their handlers: after a first interruption, the kept frames are
    written whole even when the user presses Ctrl-C again (the run is stopping anyway)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    old = {}
    for name in ("SIGINT", "SIGTERM", "SIGHUP"):
        sig = getattr(signal, name, None)
        if sig is not None:
            old[sig] = signal.signal(sig, signal.SIG_IGN)

    def release() -> None:
        for sig, handler in old.items():
            signal.signal(sig, handler)
        old.clear()

    return release
