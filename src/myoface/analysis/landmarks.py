"""Automatic initialisation from a face landmark detector (optional: MediaPipe).

MediaPipe's legacy face mesh (``mediapipe==0.10.14``, ``solutions.face_mesh``; Kartynnik et al.
2019, "Real-time Facial Surface Geometry from Monocular Video on Mobile GPUs") ships its models
inside the wheel and runs offline. Its 468 points have the topology of myoface's default face
(both are the MediaPipe canonical face), so every section contour of
:data:`~myoface.analysis.sections.SECTIONS` is read off the detected points by the same vertex
indices as on the model. Install it with ``pip install "myoface[mediapipe]"``.

The hairline is left out of the automatic contours: the face mesh ends on the forehead, below
the real hairline, so its top row does not lie on an image edge.
"""

from __future__ import annotations

import numpy as np

from myoface.analysis.sections import section_vertices
from myoface.errors import MyofaceValueError
from myoface.facemesh import FaceMeshDetector
from myoface.render import progress

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


def contours_from_landmarks(face, points, sections=AUTO_SECTIONS) -> dict[str, np.ndarray]:
    """Section contours (pixels) from detected points sharing ``face``'s topology."""
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[0] != face.n_vertices or p.shape[1] < 2:
        raise MyofaceValueError(
            f"the landmarks must be ({face.n_vertices}, 2|3) points of the face's topology; "
            f"got shape {p.shape}"
        )
    return {s: p[section_vertices(face, s), :2].copy() for s in sections}


def auto_init(
    frames,
    face,
    max_search: int | None = None,
    *,
    show_progress: bool = False,
    total: int | None = None,
):
    """Find the first frame (of at most ``max_search``; default: all of them) with a face
    whose contours lie inside the frame, and return ``(index, frame, contours, points)``; a
    clear error when no face is found. ``show_progress``: a progress bar on stderr while the
    search goes on (``total``: the number of frames, when known)."""
    seen = 0
    with FaceMeshDetector(video=False) as det:
        bar = progress(
            None, total=total, desc="searching for a face", enabled=show_progress, unit="frame"
        )
        try:
            for k, frame in enumerate(frames):
                if max_search is not None and k >= max_search:
                    break
                seen += 1
                bar.update(1)
                pts = det.detect(frame)
                if pts is None:
                    continue
                conts = contours_from_landmarks(face, pts)
                h, w = np.shape(frame)[:2]
                allp = np.concatenate(list(conts.values()))
                if (
                    (allp >= 0).all()
                    and (allp[:, 0] <= w - 1).all()
                    and (allp[:, 1] <= h - 1).all()
                ):
                    return k, frame, conts, pts
        finally:
            bar.close()
    raise MyofaceValueError(
        f"no face found in the {seen} frames of the video searched (MediaPipe face mesh); "
        "is there a frontal face in it?"
    )


# ------------------------------------------------------------------ landmark tracking (option 3)


def rigid_vertices(model, fraction: float = 0.05) -> np.ndarray:
    """Skin vertices that no muscle moves by more than ``fraction`` of the largest motion any
    unit contraction causes (the head frame is fitted to them). Computed once per model."""

    def compute():
        rest = model.skin_vertices()
        moved = np.zeros(len(rest))
        for mid in model.ids:
            skin = model.skin_vertices(model.relax({mid: 1.0}).state)
            moved = np.maximum(moved, np.linalg.norm(skin - rest, axis=1))
        out = np.flatnonzero(moved < fraction * moved.max())
        out.flags.writeable = False
        return out

    return model.memo(("rigid", fraction), compute)


def fit_similarity(src: np.ndarray, dst: np.ndarray):
    """Least-squares similarity (complex scale s = scale * e^{i theta}, translations) with
    ``dst ~ s (src - src_mean) + dst_mean`` for (N, 2) point sets."""
    ms, md = src.mean(axis=0), dst.mean(axis=0)
    za = (src[:, 0] - ms[0]) + 1j * (src[:, 1] - ms[1])
    zb = (dst[:, 0] - md[0]) + 1j * (dst[:, 1] - md[1])
    den = np.vdot(za, za).real
    if den <= 0:
        raise MyofaceValueError("degenerate point set for the head frame")
    return np.vdot(za, zb) / den, ms, md


def similarity_affine(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`fit_similarity` as a matrix and an offset: ``dst ~ matrix @ src + offset``."""
    z, ms, md = fit_similarity(src, dst)
    mat = np.array([[z.real, -z.imag], [z.imag, z.real]])
    return mat, md - mat @ ms


def _apply_similarity(s, ms, md, pts):
    z = ((pts[:, 0] - ms[0]) + 1j * (pts[:, 1] - ms[1])) * s
    return np.stack([z.real + md[0], z.imag + md[1]], axis=1)
