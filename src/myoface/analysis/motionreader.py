"""A reader of facial motion that is not the fit's instrument: points of a reference frame
followed into later frames by pyramidal Lucas-Kanade optical flow, always against the
reference frame (so that nothing drifts), each frame's search started where the previous
frame's ended; then the head's motion in the image plane taken out by a similarity fitted to
the rigid points (eye corners, nose bridge), and the displacements expressed in inter-ocular
distances.

It is validated on known answers (:mod:`myoface.analysis.knownwarp`: a real frame warped by a
known field, with fake head motion): ``tests/analysis/test_motionreader.py`` holds its gain on
every region within [0.9, 1.1].
"""

from __future__ import annotations

import numpy as np

from myoface.errors import MyofaceValueError
from myoface.facemesh import import_opencv

#: Lucas-Kanade's window, in inter-ocular distances (11 px at the sample video's 99 px): on
#: its first frame warped by smooth fields (bumps of 0.25 IOD radius), with and without fake
#: head motion, a window of 0.11 IOD reads 0.96-1.08 of every region's motion, one of 0.21
#: IOD 0.78-0.94 (it averages the motion over more of the face than moves); sharper fields
#: (0.15 IOD) are read less well: 0.71-1.09 (measured 2026-12-01)
WINDOW_IOD = 0.11
#: pyramid levels: for a frame-to-frame head motion of ~20 px
LEVELS = 3


def window_for(iod_px: float) -> int:
    """Lucas-Kanade's window (odd, pixels) for a face of ``iod_px`` inter-ocular distance."""
    return max(7, 2 * int(round(0.5 * WINDOW_IOD * iod_px)) + 1)


def _grey(frame) -> np.ndarray:
    cv2 = import_opencv("the motion reader")
    img = np.asarray(frame)
    if img.ndim == 3:
        img = cv2.cvtColor(np.ascontiguousarray(img[..., :3]), cv2.COLOR_RGB2GRAY)
    return np.ascontiguousarray(img, dtype=np.uint8)


class FlowMotionReader:
    """Follows ``points`` (N, 2+) pixels of ``reference`` (an RGB frame) into later frames,
    with a Lucas-Kanade window of ``window`` pixels (:func:`window_for` the face's size).

    :meth:`read` gives each frame's points (N, 2) and which are sure (the track runs back to
    the reference point within ``fb_max_px``); a point not sure keeps its last position."""

    def __init__(self, reference, points, window: int, levels: int = LEVELS,
                 fb_max_px: float = 1.0):  # fmt: skip
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] < 2 or not np.isfinite(pts[:, :2]).all():
            raise MyofaceValueError(f"points must be finite (N, 2) pixels; got {pts.shape}")
        self.ref = _grey(reference)
        self.ref_points = np.ascontiguousarray(pts[:, :2], dtype=np.float32)
        self._last = self.ref_points.copy()
        self.window = int(window)
        self.levels = int(levels)
        self.fb_max_px = float(fb_max_px)

    def read(self, frame) -> tuple[np.ndarray, np.ndarray]:
        cv2 = import_opencv("the motion reader")
        img = _grey(frame)
        if img.shape != self.ref.shape:
            raise MyofaceValueError("the frames must have the reference frame's size")
        kw = {
            "winSize": (self.window, self.window),
            "maxLevel": self.levels,
            "criteria": (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 40, 0.005),
            "flags": cv2.OPTFLOW_USE_INITIAL_FLOW,
        }
        q, st, _ = cv2.calcOpticalFlowPyrLK(self.ref, img, self.ref_points, self._last.copy(), **kw)
        back, st2, _ = cv2.calcOpticalFlowPyrLK(img, self.ref, q, self.ref_points.copy(), **kw)
        ok = (st[:, 0] == 1) & (st2[:, 0] == 1) & np.isfinite(q).all(1)
        ok &= np.linalg.norm(back - self.ref_points, axis=1) < self.fb_max_px
        q = np.where(ok[:, None], q, self._last)
        self._last = q.astype(np.float32)
        return q.astype(np.float64), ok


def similarity_2d(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """The least-squares similarity ``dst ~ s R src + t`` of (N, 2) point sets (Umeyama
    1991): (s, R (2, 2), t (2,))."""
    src = np.asarray(src, dtype=np.float64)
    dst = np.asarray(dst, dtype=np.float64)
    ms, md = src.mean(0), dst.mean(0)
    a, b = src - ms, dst - md
    u, sv, vt = np.linalg.svd(b.T @ a)
    d = np.diag([1.0, np.sign(np.linalg.det(u @ vt))])
    r = u @ d @ vt
    var = (a**2).sum()
    if not var > 0:
        raise MyofaceValueError("degenerate rigid points: cannot take out the head's motion")
    s = float(np.trace(np.diag(sv) @ d) / var)
    return s, r, md - s * r @ ms


def aligned_displacements(ref: np.ndarray, cur: np.ndarray, rigid, eye_outer) -> np.ndarray:
    """The displacements (N, 2) of points ``cur`` (N, 2) from ``ref`` (N, 2), the head's
    motion in the image plane taken out (``cur`` mapped onto ``ref`` by the similarity of
    the ``rigid`` points), in inter-ocular distances (``eye_outer``: the two outer eye
    corners' indices), image axes (x right, y down)."""
    rigid = list(rigid)
    s, r, t = similarity_2d(cur[rigid], ref[rigid])
    back = s * cur @ r.T + t
    iod = float(np.linalg.norm(ref[eye_outer[0]] - ref[eye_outer[1]]))
    return (back - ref) / iod


def gain(read: np.ndarray, true: np.ndarray) -> float:
    """The least-squares factor from the true displacements to the read ones,
    ``sum read . true / sum |true|^2`` (1: the reader reads the motion in full)."""
    t = np.asarray(true, dtype=np.float64)
    den = float((t * t).sum())
    return float((np.asarray(read) * t).sum() / den) if den > 0 else float("nan")


def explained(read: np.ndarray, true: np.ndarray) -> float:
    """``1 - sum |read - true|^2 / sum |true|^2`` (1: the motion read exactly)."""
    t = np.asarray(true, dtype=np.float64)
    den = float((t * t).sum())
    return float(1.0 - ((np.asarray(read) - t) ** 2).sum() / den) if den > 0 else float("nan")
