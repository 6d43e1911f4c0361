"""MediaPipe's legacy face mesh (optional: ``pip install "myoface[mediapipe]"``) as a detector
of 468 points on RGB frames, below every level that uses it (personal faces from photos, the
analysis' trackers, the benchmarks).

``mediapipe==0.10.14``, ``solutions.face_mesh`` (Kartynnik et al. 2019, "Real-time Facial
Surface Geometry from Monocular Video on Mobile GPUs") ships its models inside the wheel and
runs offline. Its 468 points have the topology of myoface's default face (both are the
MediaPipe canonical face): point i is vertex i.

Why ``refine_landmarks=False`` (the attention mesh, which refines the eyes', the lips' and
the irises' points, is not run). Measured 2026-12-04 (issue 35; the gaze benchmark's two
clips, ``tools/gaze_replay.py record`` with the detector switched, and the benchmarks'
own functions; on the renders whose eye sockets were still near-black, see
:data:`myoface.render.dressing.SOCKET`): it is the better detector of the eyes, and a mixed
one for the analysis.
The eye openings' centroid against the truth's, px RMS (x, y), base -> attention mesh: left
(1.21, 1.27) -> (0.90, 0.54), right (1.39, 1.15) -> (1.12, 0.77) on the first clip, (1.80,
1.32) -> (1.22, 0.93) and (1.38, 1.02) -> (1.02, 1.08) on the second; all 468 points 4.9 ->
4.3 and 5.0 -> 4.7 px RMS. Through the 3-D fit (its offsets table made with the same graph):
the moving head's pose 1.82 -> 1.48 deg, its median muscle 0.194 -> 0.182, skin 1.47 -> 1.37
mm, but the still head's median muscle 0.127 -> 0.163; the expressions' apex / rest 0.646 /
0.664 -> 0.448 / 0.897 (the AUs' leak at rest gone, and the apexes read short), with
``--photometric`` 0.740 / 0.784 -> 0.771 / 0.828; the gaze's worse eye 4.28 -> 4.78 and
5.21 -> 6.21 deg (the fit's head pitch 2.5 -> 1.3 deg RMS, but the eyes placed 1.2-1.8 px
nearer each other: the offsets table, read on clean renders, takes off more than the
degraded frames show), with ``--photometric`` 3.33 -> 4.08 and 5.15 -> 5.56. It costs
MediaPipe 2.63 -> 3.34 ms a frame (tracking mode, single_face.mp4, medians of 3).
"""

from __future__ import annotations

import contextlib
import os
import sys
import warnings

import numpy as np

from myoface.errors import MyofaceDependencyError, MyofaceValueError

#: the most faces :class:`FaceMeshDetector` finds in one image (``max_faces``)
MAX_FACES = 10
#: how to install MediaPipe (the last release whose wheel ships solutions.face_mesh)
PIP_HINT = 'pip install "myoface[mediapipe]"   (mediapipe==0.10.14)'


@contextlib.contextmanager
def _quiet_native_stderr():
    """Silence the native (C++) log lines MediaPipe and TensorFlow Lite print to the process's
    stderr while they set up (``INFO: Created TensorFlow Lite XNNPACK delegate``, ...)."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no real stderr (e.g. captured): nothing to silence
        yield
        return
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def import_mediapipe():
    """MediaPipe and its face mesh solution, quiet; a :class:`MyofaceDependencyError` with the
    pip command when it is not installed."""
    os.environ.setdefault("GLOG_minloglevel", "2")
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            import mediapipe as mp
            from mediapipe.python.solutions import face_mesh
    except ImportError as exc:
        raise MyofaceDependencyError(
            f"automatic initialisation needs MediaPipe's face mesh, which is not installed "
            f"({exc}); install it with: {PIP_HINT}, or give the contours with --init"
        ) from None
    # MediaPipe 0.10 calls a protobuf API that protobuf deprecates, on every frame. The
    # per-call catch_warnings of FaceMeshDetector.detect does not hold while other threads
    # (decoding ahead, the deferred relax) change the warning filters: filter it for good
    warnings.filterwarnings(
        "ignore", message=r"SymbolDatabase\.GetPrototype\(\) is deprecated", category=UserWarning
    )
    return mp, face_mesh


def mediapipe_available() -> bool:
    try:
        import_mediapipe()
    except MyofaceDependencyError:
        return False
    return True


class FaceMeshDetector:
    """MediaPipe's face mesh on RGB frames: :meth:`detect` gives (468, 3) points, x and y in
    pixels (column, row), z in pixels towards the camera negative; or None without a face.

    ``video=True`` tracks between successive frames (MediaPipe's own tracking mode), which is
    faster on a video; ``video=False`` detects on every frame independently. ``max_faces``:
    how many faces :meth:`detect_all` finds at most (:meth:`detect` gives MediaPipe's first,
    which with several faces is not necessarily the largest).
    """

    def __init__(self, video: bool = False, min_confidence: float = 0.5, max_faces: int = 1):
        if not (isinstance(max_faces, int) and 1 <= max_faces <= MAX_FACES):
            raise MyofaceValueError(f"max_faces must be an integer in [1, {MAX_FACES}]")
        _, face_mesh = import_mediapipe()
        with warnings.catch_warnings(), _quiet_native_stderr():
            warnings.simplefilter("ignore")
            self._fm = face_mesh.FaceMesh(
                static_image_mode=not video,
                max_num_faces=max_faces,
                refine_landmarks=False,
                min_detection_confidence=min_confidence,
                min_tracking_confidence=min_confidence,
            )
            # start the graph now (its threads log as they start), inside the silenced window
            self._fm.process(np.zeros((64, 64, 3), dtype=np.uint8))

    def detect(self, frame) -> np.ndarray | None:
        """(468, 3) points of the first face MediaPipe finds in ``frame``, or None."""
        faces = self.detect_all(frame)
        return faces[0] if faces else None

    def detect_all(self, frame) -> list[np.ndarray]:
        """(468, 3) points of each face found in ``frame`` (at most ``max_faces``), in
        MediaPipe's order; an empty list without a face."""
        img = np.asarray(frame)
        if img.ndim == 2:
            img = np.repeat(img[:, :, None], 3, axis=2)
        if img.ndim != 3 or img.shape[2] not in (3, 4):
            raise MyofaceValueError(f"a frame must be (H, W) or (H, W, 3); got {img.shape}")
        img = np.ascontiguousarray(img[:, :, :3])
        if img.dtype != np.uint8:
            scale = 255.0 if img.max() <= 1.0 else 1.0
            img = np.clip(img * scale, 0, 255).astype(np.uint8)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = self._fm.process(img)
        if not res.multi_face_landmarks:
            return []
        h, w = img.shape[:2]
        scale = np.array([w, h, w])
        return [
            np.array([(p.x, p.y, p.z) for p in face.landmark], dtype=np.float64)[:468] * scale
            for face in res.multi_face_landmarks
        ]

    def close(self) -> None:
        self._fm.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


#: frames the face mesh is run ahead of the analysis on a thread of its own
#: (:func:`myoface._threads.run_ahead`): MediaPipe works without the GIL (its graph runs on
#: threads of its own), so on a second core it tracks the next frames while this one is
#: fitted; a few frames absorb the jitter between the two (a frame's fit costs more where a
#: relax of the tissue is taken up)
DETECT_AHEAD_FRAMES = 8


def import_opencv(what: str):
    """OpenCV's ``cv2`` (it comes with MediaPipe); a :class:`MyofaceDependencyError` saying
    ``what`` needs it and how to install it, when it is not installed."""
    try:
        import cv2
    except ImportError as e:  # pragma: no cover - it comes with mediapipe
        raise MyofaceDependencyError(
            f"{what} needs OpenCV (it comes with MediaPipe: {PIP_HINT})"
        ) from e
    return cv2
