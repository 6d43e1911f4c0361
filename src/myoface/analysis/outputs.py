"""One video's analysis written into a folder: what ``myoface analyze`` (and, per video,
``myoface batch``) writes.

==================  ==========================================================================
contractions.csv    frame, time_s, quality, one column per muscle, jaw_angle_rad, head frame
                    (:func:`~myoface.analysis.pipeline.write_contractions_csv`)
analysis.json       settings, calibration and per-frame diagnostics
contractions.png    the contractions over time (the paper's Fig. 8)
overlay.mp4         the contours on the frames (the paper's Fig. 7a)
potential.mp4       (snakes) the contours on the image potential (the paper's Fig. 7b)
==================  ==========================================================================

Image coordinates are (x, y) = (column, row) pixels.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from myoface.errors import MyofaceValueError

#: the files :func:`analyze_to_folder` writes for every tracker
FOLDER_FILES = ("contractions.csv", "analysis.json", "contractions.png", "overlay.mp4")


def draw_contours(frame: np.ndarray, contours: dict, color=(255, 215, 0)) -> np.ndarray:
    """A copy of ``frame`` (H, W, 3) uint8 with the polylines ``contours`` ({name: (K, 2)},
    (x, y) pixels) drawn in ``color``."""
    img = frame.copy()
    h, w = img.shape[:2]
    for pts in contours.values():
        p = np.asarray(pts, float)
        n = max(2, int(np.linalg.norm(np.diff(p, axis=0), axis=1).sum() * 2))
        t = np.linspace(0, len(p) - 1, n)
        x = np.interp(t, np.arange(len(p)), p[:, 0])
        y = np.interp(t, np.arange(len(p)), p[:, 1])
        xi = np.clip(np.round(x).astype(int), 0, w - 1)
        yi = np.clip(np.round(y).astype(int), 0, h - 1)
        img[yi, xi] = color
    return img


def potential_image(pot: np.ndarray) -> np.ndarray:
    """The potential (H, W) as a grey RGB image, edges (its ravines) dark, as in the paper's
    Fig. 7b."""
    lo, hi = np.percentile(pot, [1, 99.5])
    g = np.clip((pot - lo) / max(hi - lo, 1e-12), 0, 1)
    return np.repeat((g * 255).astype(np.uint8)[:, :, None], 3, axis=2)


def plot_contractions(path, ids, times, table, quality) -> None:
    """The contractions ``table`` (T, M) over ``times`` (T,) s, one panel per muscle pair
    (the paper's Fig. 8); frames whose ``quality`` is not "ok" shaded grey."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from myoface._io import atomic_output

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


@dataclass
class FolderResult:
    """What :func:`analyze_to_folder` measured and where it wrote it.

    Attributes
    ----------
    folder : Path — the output folder.
    video : Path — the analysed video.
    ids : tuple of str — the estimated muscles (and ``"jaw"``).
    frames : list of :class:`~myoface.analysis.pipeline.FrameMeasurement`, in order.
    calibration_frame : int — the index of the neutral frame the analysis started on.
    """

    folder: Path
    video: Path
    ids: tuple
    frames: list
    calibration_frame: int

    @property
    def n_measured(self) -> int:
        """Frames whose quality is "ok"."""
        return sum(f.quality == "ok" for f in self.frames)

    @property
    def measured_fraction(self) -> float:
        return self.n_measured / len(self.frames) if self.frames else 0.0

    @property
    def contractions(self) -> np.ndarray:
        """(T, K) in [0, 1]; NaN rows where a frame could not be measured."""
        return np.array([f.contractions for f in self.frames]).reshape(-1, len(self.ids))

    def mean_contractions(self) -> dict[str, float]:
        """{id: mean contraction over the measured frames} (NaN when none was measured)."""
        ok = [f.quality == "ok" for f in self.frames]
        table = self.contractions[np.array(ok, dtype=bool)]
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
) -> FolderResult:
    """Analyse ``video`` and write the analysis into the folder ``out`` (see the module's
    table); the code path of ``myoface analyze``.

    Parameters
    ----------
    video : path or :class:`~myoface.analysis.video.Video`.
    out : the output folder; created with its parents if missing. If the analysis fails, the
        folders this call created are removed again (a folder that existed is left, and the
        files in it are only ever replaced whole).
    model : the :class:`~myoface.model.FaceModel` (never changed; may be shared with other
        threads); default: loaded from ``face``.
    tracker, calibration_frame, refine, sigma, estimator : as in
        :func:`~myoface.analysis.pipeline.make_analyzer`.
    init : initial contours on the calibration frame, for the snakes: a JSON file (see
        :func:`~myoface.analysis.pipeline.load_init`) or {section: (K, 2)} pixels; None:
        found with MediaPipe.
    max_frames : analyse at most this many frames.
    face : the face model's file (``None``: the bundled face); recorded in analysis.json, and
        loaded when ``model`` is None.
    show_progress : a progress bar over the frames on stderr.

    Raises
    ------
    MyofaceError
        On bad input, a video without frames, or when no frame could be measured.
    """
    from myoface._io import output_dir
    from myoface.analysis.pipeline import load_init, make_analyzer
    from myoface.analysis.video import Video, open_video

    if not isinstance(video, Video):
        video = open_video(video)
    how_init = None
    if init is not None and tracker == "landmarks":
        raise MyofaceValueError("--init is for the snakes; the landmark tracker needs none")
    if isinstance(init, str | os.PathLike):
        how_init = str(Path(init).resolve())
        init = load_init(init)
    if model is None:
        from myoface.model import load_face_model

        model = load_face_model(face)
    an, how, start = make_analyzer(
        model, video, tracker, init or None, calibration_frame, refine, sigma, estimator=estimator
    )
    with output_dir(out) as folder:
        try:
            frames = _measure_into(video, an, folder, start, max_frames, tracker, show_progress)
        finally:
            an.close()
        _write_results(video, model, an, folder, frames, how_init or how, start, tracker, face)
    return FolderResult(folder, Path(video.path), tuple(an.ids), frames, start)


def _write_results(video, model, an, out, frames, how, start, tracker, face) -> None:
    """contractions.csv, contractions.png and analysis.json."""
    import json

    from myoface._io import atomic_output
    from myoface.analysis.pipeline import write_contractions_csv

    jaw_max = model.muscles.jaw.max_angle_rad if model.muscles.jaw is not None else 0.0
    write_contractions_csv(out / "contractions.csv", an.ids, frames, jaw_max)
    table = np.array([f.contractions for f in frames])
    times = np.array([f.time_s for f in frames])
    plot_contractions(out / "contractions.png", an.ids, times, table, [f.quality for f in frames])
    side = {
        "video": str(Path(video.path).resolve()),
        "fps": video.fps,
        "size": list(video.size),
        "tracker": tracker,
        "init": how,
        "calibration_frame": start,
        "face": str(face) if face else "default",
        "muscles": list(an.ids),
        "mm_per_px": an.mm_per_px,
        "refine": an.refine,
        "frames": [
            {"frame": f.index, "quality": f.quality, "iterations": f.iterations} for f in frames
        ],
    }
    if hasattr(an, "describe"):  # the 3-D fit: its calibration, camera and weights
        side.update(an.describe())
    if tracker == "snakes":
        side["sigma_px"] = an.sigma
        side["estimator"] = an.method
        side["snake_params"] = {
            k: float(np.mean(v)) if not isinstance(v, int) else v
            for k, v in vars(an.params).items()
        }
    with atomic_output(out / "analysis.json") as tmp:
        tmp.write_text(json.dumps(side, indent=1))


def _measure_into(video, an, out, start, max_frames, tracker, show_progress) -> list:
    """Measure every frame from ``start`` on, writing the overlay videos; a clear error when
    nothing could be measured."""
    import contextlib

    from myoface.analysis.pipeline import measure_frames
    from myoface.render import VideoWriter, progress

    frames = []
    n = video.n_frames
    if n is not None:
        n -= start
    if max_frames is not None:
        n = max_frames if n is None else min(n, max_frames)
    with contextlib.ExitStack() as stack:
        vw = stack.enter_context(VideoWriter(out / "overlay.mp4", fps=video.fps))
        pw = None
        if tracker == "snakes":
            pw = stack.enter_context(VideoWriter(out / "potential.mp4", fps=video.fps))
        measured = measure_frames(video, an, start, max_frames)
        for frame, m in progress(measured, total=n, desc="analyzing", enabled=show_progress):
            frames.append(m)
            color = (255, 215, 0) if m.quality == "ok" else (230, 40, 40)
            vw.write(draw_contours(frame, m.contours, color))
            if pw is not None:
                pw.write(draw_contours(potential_image(an.last_potential), m.contours, color))
        if not frames:
            raise MyofaceValueError(f"{video.path}: the video has no frames")
        if not any(f.quality == "ok" for f in frames):
            raise MyofaceValueError(f"{video.path}: no frame could be measured (no face found?)")
    return frames
