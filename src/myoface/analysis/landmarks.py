"""Automatic initialisation from a face landmark detector (optional: MediaPipe).

MediaPipe's legacy face mesh (``mediapipe==0.10.14``, ``solutions.face_mesh``; Kartynnik et al.
2019, "Real-time Facial Surface Geometry from Monocular Video on Mobile GPUs") ships its models
inside the wheel and runs offline. Its 468 points have the topology of myoface's default face
(both are the MediaPipe canonical face), so every section contour of
:data:`~myoface.analysis.pipeline.SECTIONS` is read off the detected points by the same vertex
indices as on the model. Install it with ``pip install "myoface[mediapipe]"``.

The hairline is left out of the automatic contours: the face mesh ends on the forehead, below
the real hairline, so its top row does not lie on an image edge.
"""

from __future__ import annotations

import os
import warnings

import numpy as np

from myoface.errors import MyofaceDependencyError, MyofaceValueError

PIP_HINT = 'pip install "myoface[mediapipe]"   (mediapipe==0.10.14)'
#: sections the automatic initialisation provides
AUTO_SECTIONS = (
    "eyebrow_r",
    "eyebrow_l",
    "nasolabial_r",
    "nasolabial_l",
    "nose",
    "lips",
    "chin",
)


def _import_mediapipe():
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
    return mp, face_mesh


def mediapipe_available() -> bool:
    try:
        _import_mediapipe()
    except MyofaceDependencyError:
        return False
    return True


class FaceMeshDetector:
    """MediaPipe's face mesh on RGB frames: :meth:`detect` gives (468, 3) points, x and y in
    pixels (column, row), z in pixels towards the camera negative; or None without a face.

    ``video=True`` tracks between successive frames (MediaPipe's own tracking mode), which is
    faster on a video; ``video=False`` detects on every frame independently.
    """

    def __init__(self, video: bool = False, min_confidence: float = 0.5):
        _, face_mesh = _import_mediapipe()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            self._fm = face_mesh.FaceMesh(
                static_image_mode=not video,
                max_num_faces=1,
                refine_landmarks=False,
                min_detection_confidence=min_confidence,
                min_tracking_confidence=min_confidence,
            )

    def detect(self, frame) -> np.ndarray | None:
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
            return None
        h, w = img.shape[:2]
        lm = res.multi_face_landmarks[0].landmark
        pts = np.array([(p.x, p.y, p.z) for p in lm], dtype=np.float64)[:468]
        return pts * np.array([w, h, w])

    def close(self) -> None:
        self._fm.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def contours_from_landmarks(face, points, sections=AUTO_SECTIONS) -> dict[str, np.ndarray]:
    """Section contours (pixels) from detected points sharing ``face``'s topology."""
    from myoface.analysis.pipeline import section_vertices

    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[0] != face.n_vertices or p.shape[1] < 2:
        raise MyofaceValueError(
            f"the landmarks must be ({face.n_vertices}, 2|3) points of the face's topology; "
            f"got shape {p.shape}"
        )
    return {s: p[section_vertices(face, s), :2].copy() for s in sections}


def auto_init(frames, face, max_search: int = 30):
    """Find the first frame (of at most ``max_search``) with a face and return
    ``(index, frame, contours, points)``; a clear error when no face is found."""
    seen = 0
    with FaceMeshDetector(video=False) as det:
        for k, frame in enumerate(frames):
            if k >= max_search:
                break
            seen += 1
            pts = det.detect(frame)
            if pts is not None:
                return k, frame, contours_from_landmarks(face, pts), pts
    raise MyofaceValueError(
        f"no face found in the first {seen} frames of the video (MediaPipe face mesh); "
        "is there a frontal face in it?"
    )
