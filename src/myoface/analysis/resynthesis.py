"""Resynthesis: the face model driven by an analysis' contractions and rendered (the paper's
Fig. 7c).

An analysis (:func:`~myoface.analysis.outputs.analyze_to_folder`) writes one row of
contractions per frame to ``contractions.csv``; the resynthesis reads them back
(:func:`read_performance`), relaxes the model to each row's equilibrium, warm-started from the
previous row's, and renders it front on, ``size`` x ``size`` pixels
(:func:`resynthesis_renderer`), optionally turned and moved by the head pose the 3-D fit
measured (:class:`PosedRenderer`), its eyes turned where the analysis read the person's gaze
(:attr:`Performance.gaze`: the renderer turns both eyes alike, by the mean of the two eyes
read; through a blink the eyes hold where they last looked). The same code serves ``myoface resynth`` (a video,
:func:`resynthesize`), the fidelity measure (the frames, :func:`resynthesis_frames`, in
:mod:`myoface.analysis.fidelity`) and the resynthesis benchmark (``synth.resynth_fps_512``)::

    perf = read_performance("out/contractions.csv", model, pose=True)
    resynthesize(model, perf.times, perf.contractions, "resynth.mp4", perf.fps,
                 poses=perf.poses, gaze=perf.gaze)
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass

import numpy as np

from myoface.analysis.contractions_csv import (
    display_gaze,
    display_poses,
    hold_last_measured,
    read_contractions_csv,
    read_gaze,
    read_head_poses,
)
from myoface.analysis.video import open_video
from myoface.errors import MyofaceValueError, MyofaceWarning
from myoface.render import Renderer
from myoface.render.renderer import resize_nearest
from myoface.synth import Synthesizer, make_camera

__all__ = [
    "DEFAULT_SIZE",
    "Performance",
    "PosedRenderer",
    "read_performance",
    "resynthesis_frames",
    "resynthesis_renderer",
    "resynthesize",
]

#: the side (pixels) of a resynthesis' square frames unless one is given
DEFAULT_SIZE = 360
#: the highest frame rate (frames per second) a video is written at
#: (:class:`~myoface.render.VideoWriter`'s limit): a CSV's rows must be at least 1/240 s apart
MAX_FPS = 240.0
#: the longest time (s) between two rows of a CSV that is still read as a video's frames
MAX_ROW_INTERVAL_S = 60.0
#: the frame rate (frames per second) of a CSV of one row, which has no interval to go by
ONE_ROW_FPS = 30.0
#: the longest video (s) a resynthesis writes: one hour, as ``myoface synth``'s limit
MAX_VIDEO_S = 3600.0


@dataclass(frozen=True)
class Performance:
    """An analysis' measurements, ready to drive a face model (:func:`read_performance`).

    Attributes
    ----------
    times : (T,) ndarray — each row's time, s.
    contractions : (T, M) ndarray — contractions over the model's ``ids``; a row the analysis
        did not measure holds the last measured row (zeros before the first).
    quality : list of str — each row's quality as the analysis wrote it ("ok", ...).
    fps : float — frames per second: 1 / the median interval between rows.
    poses : list of (rotation (3, 3), translation (3,) mm), or None — the head pose per row
        for the renderer (:func:`~myoface.analysis.contractions_csv.display_poses`), when asked for.
    gaze : (T, 2) ndarray rad, or None — the eyes' ``(yaw, pitch)`` per row for the renderer
        (:func:`~myoface.analysis.contractions_csv.display_gaze`: the eyes read averaged, held
        through rows without a reading), when the CSV has the gaze columns.
    """

    times: np.ndarray
    contractions: np.ndarray
    quality: list
    fps: float
    poses: list | None = None
    gaze: np.ndarray | None = None

    @property
    def n_frames(self) -> int:
        return len(self.contractions)


def read_performance(
    path: str | os.PathLike, model, *, pose: bool = False, gaze: bool = True
) -> Performance:
    """The contractions of the analysis' CSV ``path`` (``contractions.csv``, as
    :func:`~myoface.analysis.contractions_csv.read_contractions_csv` reads it) over
    ``model.ids``, each unmeasured row holding the last measured one, at the CSV's frame rate;
    with ``pose``, also the head pose of each row (the 3-D fit's ``head_yaw_deg`` ...
    ``head_tz_mm`` columns; rows without one hold the last); with ``gaze`` (default), the
    eyes' gaze of each row where the CSV has it (the 3-D fit's ``gaze_l_yaw_deg`` ...
    columns, :func:`~myoface.analysis.contractions_csv.read_gaze`; None without them).

    A muscle of the model without a column stays at rest, said in a warning that names them
    (with the columns that name no muscle, in one line).

    Raises
    ------
    MyofaceError
        For a CSV that cannot be read (see ``read_contractions_csv``; a head pose outside
        its bounds, ``read_head_poses``), without a measured row (every row's quality other
        than "ok": the video would show the face at rest throughout), whose rows are not
        1/240 to 60 s apart (median), or whose video would last more than
        :data:`MAX_VIDEO_S` s.
    """
    with warnings.catch_warnings(record=True) as said:  # said after the checks, if they pass
        warnings.simplefilter("always", MyofaceWarning)
        times, table, quality = read_contractions_csv(path, list(model.ids), warn_missing=True)
    measured = [q == "ok" and np.isfinite(row).all() for q, row in zip(quality, table, strict=True)]
    if not any(measured):
        said = sorted(set(quality))
        raise MyofaceValueError(
            f"{path}: no row was measured (quality {', '.join(repr(q[:20]) for q in said[:4])}"
            f"{', ...' if len(said) > 4 else ''}, never 'ok'): nothing to resynthesize"
        )
    poses = None
    if pose:
        poses = display_poses(read_head_poses(path))
    eyes = read_gaze(path) if gaze else None
    eyes = None if eyes is None else display_gaze(eyes[0])
    table = hold_last_measured(table)
    dt = float(np.median(np.diff(times))) if len(times) > 1 else 1.0 / ONE_ROW_FPS
    if not 1.0 / MAX_FPS <= dt <= MAX_ROW_INTERVAL_S:
        raise MyofaceValueError(
            f"{path}: its rows are {dt:.3g} s apart (median); a video's frames are "
            f"{1 / MAX_FPS:.3g} to {MAX_ROW_INTERVAL_S:g} s apart"
        )
    length_s = len(times) * dt  # one frame per row, at 1 / dt frames per second
    if length_s > MAX_VIDEO_S:
        raise MyofaceValueError(
            f"{path}: its {len(times)} rows, {dt:.3g} s apart, make a video of "
            f"{length_s / 60:.0f} minutes; a video is at most {MAX_VIDEO_S / 3600:g} hour "
            f"({MAX_VIDEO_S:g} s)"
        )
    for w in said:
        warnings.warn(w.message, w.category, stacklevel=2)
    return Performance(
        np.asarray(times, dtype=np.float64), table, list(quality), 1.0 / dt, poses, eyes
    )


class PosedRenderer:
    """A renderer whose successive renders take the successive head ``poses``: each call of
    :meth:`render` draws the face as ``renderer`` does, turned and moved by the next pose
    (``(rotation (3, 3), translation (3,) mm)``, :meth:`~myoface.render.Renderer.render`'s
    ``pose``)."""

    def __init__(self, renderer, poses):
        self._renderer = renderer
        self._poses = iter(poses)
        self.camera = renderer.camera

    def render(self, vertices=None, **kw):  # kw: the renderer's others, e.g. jaw=
        return self._renderer.render(vertices, pose=next(self._poses), **kw)


def resynthesis_renderer(model, size: int = DEFAULT_SIZE, poses=None):
    """The renderer of a resynthesis: ``model``'s face front on (``make_camera(...,
    "front")``), ``size`` x ``size`` pixels; with ``poses`` (one per frame, see
    :class:`PosedRenderer`) each successive render takes the next head pose."""
    h = int(size)
    renderer = Renderer(model.face, make_camera(model.face.vertices, "front", h, h))
    return renderer if poses is None else PosedRenderer(renderer, poses)


def resynthesis_frames(model, table, size: int = DEFAULT_SIZE, *, poses=None, gaze=None):
    """The model driven by ``table`` (T, M) contractions over ``model.ids`` (rows with NaN
    hold the last measured row), rendered by :func:`resynthesis_renderer`, the eyes turned by
    ``gaze`` (T, 2) rad if given: a generator of ``size`` x ``size`` RGB uint8 images, the
    frames :func:`resynthesize` encodes."""
    syn = Synthesizer(model, resynthesis_renderer(model, size, poses))
    table = hold_last_measured(np.asarray(table, dtype=np.float64))
    gaze = _check_gaze(gaze, len(table))
    yield from syn.frames(table, np.arange(len(table), dtype=np.float64), gaze)


def _check_gaze(gaze, n: int):
    """``gaze`` as a finite (n, 2) array rad within the renderer's range, or None."""
    if gaze is None:
        return None
    from myoface.render.renderer import MAX_GAZE_RAD

    g = np.asarray(gaze, dtype=np.float64)
    if g.shape != (n, 2) or not np.isfinite(g).all():
        raise MyofaceValueError(
            f"gaze must be finite (T, 2) (yaw, pitch) rad, one row per frame ({n}); got "
            f"shape {g.shape}"
        )
    return np.clip(g, -MAX_GAZE_RAD, MAX_GAZE_RAD)


def resynthesize(
    model,
    times,
    table,
    output,
    fps: float,
    *,
    size: int = DEFAULT_SIZE,
    side_by_side=None,
    show_progress: bool = True,
    poses=None,
    gaze=None,
):
    """Render ``model`` driven by the contractions ``table`` (T, M) at ``times`` (T,) s to the
    video ``output`` at ``fps``: one ``size`` x ``size`` frame per row (front view), each the
    equilibrium of its row warm-started from the previous one, encoded while the next is made;
    with the frames of the video ``side_by_side`` (scaled to ``size`` rows) on the left.
    ``poses``: per row ``(rotation, translation mm)`` of the head
    (:func:`~myoface.analysis.contractions_csv.display_poses`), or None for the still front view.
    ``gaze``: per row the eyes' ``(yaw, pitch)`` rad (:attr:`Performance.gaze`), or None for
    eyes looking straight ahead.

    Returns the :class:`~myoface.synth.Synthesizer`, whose ``stats`` hold the per-frame times
    of the physics, the rendering and the encoding.

    Raises
    ------
    MyofaceValueError
        When the ``side_by_side`` video has fewer frames than ``table`` rows (the video is
        then not written).
    """
    h = int(size)
    gaze = _check_gaze(gaze, len(table))
    syn = Synthesizer(model, resynthesis_renderer(model, h, poses))
    compose = None
    if side_by_side:
        src = iter(open_video(side_by_side))

        def compose(k, img):
            frame = next(src, None)
            if frame is None:
                raise MyofaceValueError("the side-by-side video is shorter than the CSV")
            return np.concatenate([resize_nearest(frame, h), img], axis=1)

    syn.write_video(
        table,
        times,
        output,
        fps,
        compose=compose,
        show_progress=show_progress,
        desc="resynthesizing",
        gaze=gaze,
    )
    return syn
