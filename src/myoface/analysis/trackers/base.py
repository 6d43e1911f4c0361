"""What every tracker gives and how the driver talks to it.

A tracker turns frames into one :class:`Measurement` per frame. The driver
(:func:`myoface.analysis.pipeline.measure_frames`) owns the video's frames and calls, in order:

1. :meth:`Tracker.calibrate` once, with the video's frames from where the analysis may start
   (``first_index``, the first one's index in the video);
   the tracker takes as many as it needs (the snakes: none when their contours are given, else
   up to the first face; the 3-D fit: the first seconds, to find the person's neutral) and
   returns the position, in those frames, of the first frame to measure. The driver keeps the
   frames it handed over and gives them again to :meth:`Tracker.measure`: no frame is decoded
   twice unless the calibration took more than the driver keeps (:data:`KEEP_BYTES`).
2. per frame, :meth:`Tracker.observe` (the part that may run ahead on a worker thread, a few
   frames before the frame is measured: MediaPipe's face mesh; None for trackers with nothing
   to run ahead), then :meth:`Tracker.measure` with its result;
3. :meth:`Tracker.describe` for ``analysis.json``, :meth:`Tracker.debug_images` for the
   overlay videos beside the CSV, and :meth:`Tracker.close`.

:class:`TrackerBase` gives the defaults. The trackers: the paper's snakes
(:class:`~myoface.analysis.trackers.snakes.SnakeTracker`), the 3-D fit of the whole model to
MediaPipe's points (:class:`~myoface.analysis.trackers.landmark_fit.FitTracker`) and the paper's
2-D scheme on those points (:class:`~myoface.analysis.trackers.landmark_paper.PaperLandmarkTracker`).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import ClassVar, Protocol, runtime_checkable

import numpy as np

#: frames the driver keeps from those the calibration took, to measure them without decoding
#: them again (bytes of RGB; a 640 x 360 frame is 0.7 MB, 2 s of a 1080p video 370 MB)
KEEP_BYTES = 512 * 2**20
#: :meth:`Tracker.measure`'s default ``observation``: the frame is observed there and then
NOT_OBSERVED = object()


@dataclass
class Measurement:
    """One frame's measurement: its index and time, ``quality`` (``"ok"`` or why the frame
    could not be measured), the contractions over the tracker's ``ids`` (NaN when not
    measured), the contours drawn on the overlay, and the iterations it took. Subclasses add
    the head's motion and name its CSV columns (:attr:`HEAD_COLUMNS`, :meth:`head_cells`)."""

    index: int
    time_s: float
    quality: str  # "ok", or why the frame could not be measured
    contractions: np.ndarray  # (M,) over the tracker's ids, NaN when not measured

    #: the CSV's columns after the muscles and the jaw angle
    HEAD_COLUMNS: ClassVar[tuple] = ()

    def head_cells(self) -> list[str]:
        """The values of :attr:`HEAD_COLUMNS` as CSV cells (empty when not measured)."""
        return []


def _cells(vals, digits) -> list[str]:
    return ["" if not np.isfinite(v) else f"{v:.{d}f}" for v, d in zip(vals, digits, strict=True)]


@dataclass
class FrameMeasurement(Measurement):
    """A measurement in the paper's 2-D head frame (the snakes, the paper's landmark scheme):
    the head's translation (px), scale and rotation from the calibration frame."""

    head_shift_px: np.ndarray = field(default_factory=lambda: np.zeros(2))
    contours: dict = field(repr=False, default_factory=dict)
    iterations: int = 0
    head_scale: float = 1.0
    head_rot_rad: float = 0.0

    HEAD_COLUMNS: ClassVar[tuple] = ("head_dx_px", "head_dy_px", "head_scale", "head_rot_deg")

    def head_cells(self) -> list[str]:
        vals = (*self.head_shift_px[:2], self.head_scale, np.degrees(self.head_rot_rad))
        return _cells(vals, (3, 3, 5, 3))


@runtime_checkable
class Tracker(Protocol):
    """A tracker (see the module's docstring). ``ids`` names the contractions it measures
    (muscles, then ``"jaw"``); ``measure`` never raises on a bad frame (the measurement's
    ``quality`` says why); ``refine`` is the relaxes of the tissue per frame it makes."""

    ids: tuple
    #: whether :meth:`observe` does work worth running ahead on a worker thread
    OBSERVES_AHEAD: bool

    def calibrate(self, frames: Iterable, first_index: int = 0) -> int: ...

    def observe(self, frame: np.ndarray, index: int): ...

    def measure(self, frame: np.ndarray, index: int, time_s: float, observation=NOT_OBSERVED): ...

    def describe(self) -> dict: ...

    def debug_images(self, frame: np.ndarray, measurement) -> dict: ...

    def close(self) -> None: ...


class TrackerBase:
    """The protocol's defaults: nothing to calibrate (the first frame given is measured
    first), nothing to observe ahead, nothing to describe or draw beyond the contours."""

    ids: tuple = ()
    OBSERVES_AHEAD = False

    def calibrate(self, frames: Iterable, first_index: int = 0) -> int:
        return 0

    def observe(self, frame: np.ndarray, index: int):
        return None

    def describe(self) -> dict:
        return {}

    def debug_images(self, frame: np.ndarray, measurement) -> dict:
        return {}

    def close(self) -> None:
        pass
