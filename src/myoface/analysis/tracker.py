"""What every tracker gives: one :class:`FrameMeasurement` per frame, behind one small protocol
(:class:`Tracker`).

Trackers: the snakes (:class:`~myoface.analysis.pipeline.Analyzer`, the paper's contours and
the curve fit), the 3-D fit of the model to MediaPipe's points
(:class:`~myoface.analysis.fit.FitAnalyzer`) and the paper's 2-D scheme on those points
(:class:`~myoface.analysis.landmarks.LandmarkAnalyzer`). :func:`~myoface.analysis.pipeline.make_analyzer`
chooses and calibrates one; :func:`~myoface.analysis.pipeline.measure_frames` drives it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np


@dataclass
class FrameMeasurement:
    """One frame's measurement: its index and time, ``quality`` (``"ok"`` or why the frame
    could not be measured), the contractions over the tracker's ``ids`` (NaN when not
    measured) and the head's 2-D motion from the calibration frame (the 3-D fit's
    :class:`~myoface.analysis.fit.FitMeasurement` carries the 3-D pose instead)."""

    index: int
    time_s: float
    quality: str  # "ok", or why the frame could not be measured
    contractions: np.ndarray  # (M,) over Analyzer.ids, NaN when not measured
    head_shift_px: np.ndarray  # (2,) the head's translation from the calibration frame
    contours: dict = field(repr=False, default_factory=dict)
    iterations: int = 0
    head_scale: float = 1.0
    head_rot_rad: float = 0.0


@runtime_checkable
class Tracker(Protocol):
    """A calibrated tracker: frame -> measurement. ``ids`` names the contractions it measures
    (muscles, then ``"jaw"``); ``measure`` takes an RGB frame (H, W, 3) uint8 with its index
    and time and never raises on a bad frame (the measurement's ``quality`` says why);
    ``close`` releases its threads and detectors. Calibration is explicit and
    tracker-specific (the snakes: their initial contours on the calibration frame; the 3-D
    fit: ``calibrate(frames)``), done before the first ``measure``."""

    ids: tuple

    def measure(self, frame: np.ndarray, index: int = 0, time_s: float = 0.0): ...

    def close(self) -> None: ...
