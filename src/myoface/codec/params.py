"""What one frame of a myoface stream carries: :class:`FrameParams`, shared by the stream (the
encoder's quantiser, the packets, the decoder) and the picture (:mod:`myoface.codec.picture`,
which renders a frame from it).

The fields are what the 3-D fit reports (the landmark tracker's
:class:`~myoface.analysis.trackers.landmark_fit.FitMeasurement`): the head's pose in the camera
frame (:class:`~myoface.analysis.camera.HeadPose`: ``P = rotation @ X + translation``, mm; the
camera looks along -z, so ``translation[2] < 0`` in front of it), every contraction over the
model's ids (the muscles, the lids' muscles, then ``"jaw"``, each in [0, 1] as the fit gives
them), and the eyes' gaze (:class:`~myoface.analysis.gaze.Gaze`) in radians.

Differences from the interface's first sketch (codec_interface.md): none in the fields; the
gaze is in radians (the analysis reads degrees; :meth:`FrameParams.from_measurement`
converts), in the order left yaw, left pitch, right yaw, right pitch, each eye's yaw towards
the subject's left and pitch up, head frame (:class:`~myoface.analysis.gaze.EyeGaze`), NaN
where the eye was not read (closed, not found). :attr:`FrameParams.pose` and
:meth:`FrameParams.common_gaze_rad` give the forms the renderer takes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from myoface.analysis.camera import HeadPose

#: the gaze vector's entries, in order
GAZE_FIELDS = ("left_yaw_rad", "left_pitch_rad", "right_yaw_rad", "right_pitch_rad")

#: the face's shading terms (:mod:`myoface.codec.picture`, "Appearance"): a log2 gain over the
#: whole face, then one per smooth bump of the shading basis
N_SHADING_BUMPS = 12
#: the appearance vector's entries, in order (format version 2; docs/codec-format.md): the
#: inside of the mouth's luma gain (log2) and offset (8-bit levels), the face's shading (log2
#: gains: the whole face, then each bump)
APPEARANCE_FIELDS = (
    "mouth_gain_log2",
    "mouth_offset",
    "face_gain_log2",
    *(f"shading_{k}_log2" for k in range(N_SHADING_BUMPS)),
)
N_APPEARANCE = len(APPEARANCE_FIELDS)
#: the appearance's quantiser steps (fixed by the format; every quality the same)
APPEARANCE_STEPS = (1 / 4, 8.0) + (1 / 16,) * (1 + N_SHADING_BUMPS)
#: each appearance entry's bound (the encoder clips to it; a decoded value beyond it is a
#: corrupted stream)
APPEARANCE_LIMITS = (2.0, 128.0) + (1.0,) * (1 + N_SHADING_BUMPS)


@dataclass
class FrameParams:
    """One frame's parameters, what a packet carries (after decoding: dequantised).

    Attributes
    ----------
    rotation : (3, 3) the head's rotation, head frame -> camera frame.
    translation : (3,) mm, the head frame's origin in the camera frame (z < 0 in front).
    contractions : (M,) over the model's ids (muscles, lids, jaw last), in [0, 1].
    gaze : (4,) rad: left yaw, left pitch, right yaw, right pitch (:data:`GAZE_FIELDS`); NaN
        where the eye was not read.
    measured : False when the analysis did not measure the frame (no face, a misfit, an
        occluder): the other fields then repeat the last measured frame's (the decoder holds
        it).
    appearance : (:data:`N_APPEARANCE`,) the picture's appearance terms
        (:data:`APPEARANCE_FIELDS`: the mouth's inside, the face's shading), which the encoder
        measures on the frame against the decoder's picture; zeros (None given): the
        calibration picture's own.
    """

    rotation: np.ndarray
    translation: np.ndarray
    contractions: np.ndarray
    gaze: np.ndarray
    measured: bool = True
    appearance: np.ndarray | None = None

    def __post_init__(self):
        self.rotation = np.asarray(self.rotation, dtype=np.float64).reshape(3, 3)
        self.translation = np.asarray(self.translation, dtype=np.float64).reshape(3)
        self.contractions = np.asarray(self.contractions, dtype=np.float64).reshape(-1)
        self.gaze = np.asarray(self.gaze, dtype=np.float64).reshape(4)
        self.measured = bool(self.measured)
        a = np.zeros(N_APPEARANCE) if self.appearance is None else self.appearance
        self.appearance = np.asarray(a, dtype=np.float64).reshape(N_APPEARANCE)

    @property
    def pose(self) -> HeadPose:
        """The head's pose as the analysis and the renderer take it."""
        return HeadPose(self.rotation, self.translation)

    def common_gaze_rad(self) -> tuple[float, float] | None:
        """Both eyes' common gaze ``(yaw, pitch)`` rad (the mean of the eyes read; the
        renderer turns both eyes alike), None when neither was read (as
        :meth:`~myoface.analysis.gaze.Gaze.common_rad`)."""
        g = self.gaze.reshape(2, 2)
        read = np.isfinite(g).all(axis=1)
        if not read.any():
            return None
        yaw, pitch = g[read].mean(axis=0)
        return float(yaw), float(pitch)

    @classmethod
    def neutral(cls, n_contractions: int, pose: HeadPose | None = None) -> FrameParams:
        """All contractions 0, the eyes not read, at ``pose`` (default: 600 mm in front)."""
        pose = pose or HeadPose.from_euler()
        return cls(pose.rotation, pose.translation_mm, np.zeros(n_contractions), np.full(4, np.nan))

    @classmethod
    def from_measurement(cls, m, last: FrameParams | None = None) -> FrameParams:
        """The parameters of a 3-D fit's measurement (a
        :class:`~myoface.analysis.trackers.landmark_fit.FitMeasurement`); on a frame not
        measured (``m.quality != "ok"``), ``last``'s values with ``measured=False`` (``last``
        None: a neutral face at the default pose)."""
        if m.quality != "ok" or m.pose is None or not np.isfinite(m.contractions).all():
            base = last if last is not None else cls.neutral(len(m.contractions))
            return cls(base.rotation, base.translation, base.contractions, base.gaze, False,
                       base.appearance)  # fmt: skip
        gaze = np.full(4, np.nan)
        if m.gaze is not None:
            for k, eye in enumerate((m.gaze.left, m.gaze.right)):
                if eye.ok:
                    gaze[2 * k : 2 * k + 2] = eye.angles_rad
        return cls(m.pose.rotation, m.pose.translation_mm, np.clip(m.contractions, 0, 1), gaze)

    def copy(self) -> FrameParams:
        return FrameParams(
            self.rotation.copy(),
            self.translation.copy(),
            self.contractions.copy(),
            self.gaze.copy(),
            self.measured,
            self.appearance.copy(),
        )
