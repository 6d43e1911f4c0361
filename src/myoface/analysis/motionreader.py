"""Readers of facial motion that are not the fit's instrument: points of a reference frame
followed into later frames by optical flow, always against the reference frame (so that
nothing drifts), each frame's search started where the previous frame's ended; then the
head's motion in the image plane taken out by a similarity fitted to the rigid points (eye
corners, nose bridge), and the displacements expressed in inter-ocular distances.

Two readers (:func:`make_reader`): pyramidal Lucas-Kanade at the points
(:class:`FlowMotionReader`, "lk") and OpenCV's DIS dense optical flow sampled at the points
(:class:`DenseFlowMotionReader`, "dis"). The analysis' own optical flow is Lucas-Kanade's,
so the fidelity measure (:mod:`myoface.analysis.fidelity`) reads with DIS.

Both are validated on known answers (:mod:`myoface.analysis.knownwarp`: a real frame warped by
a known field, with fake head motion): ``tests/analysis/test_motionreader.py`` holds their
gain on every region within [0.9, 1.1] and their explained fraction at least 0.9. Measured on
the sample video's first frame (2026-12-01; bumps of 0.25 IOD, head still and moving): LK
gain 0.96-1.08, explained 0.92-0.998; DIS 0.96-1.04, 0.988-1.0, at 75-85 ms a frame (its flow
forward and back, on the face's box of the 640 x 360 frame), LK's 1-2 ms. On sharper fields
(bumps of 0.15 IOD) LK reads 0.71-1.10 (explained down to 0.75), DIS 0.89-1.04 (0.93).
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
#: DIS's finest scale (0: full resolution; its "medium" preset stops at 1, half of it)
DIS_FINEST_SCALE = 0
#: DIS's flow is computed on the points' box grown by this fraction of its larger side (+ 8 px)
DIS_MARGIN = 0.3


def window_for(iod_px: float) -> int:
    """Lucas-Kanade's window (odd, pixels) for a face of ``iod_px`` inter-ocular distance."""
    return max(7, 2 * int(round(0.5 * WINDOW_IOD * iod_px)) + 1)


def grey(frame) -> np.ndarray:
    """``frame`` (RGB or grey) as a contiguous uint8 grey image."""
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
        self.ref = grey(reference)
        self.ref_points = np.ascontiguousarray(pts[:, :2], dtype=np.float32)
        self._last = self.ref_points.copy()
        self.window = int(window)
        self.levels = int(levels)
        self.fb_max_px = float(fb_max_px)

    def read(self, frame) -> tuple[np.ndarray, np.ndarray]:
        cv2 = import_opencv("the motion reader")
        img = grey(frame)
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


class DenseFlowMotionReader:
    """Follows ``points`` (N, 2+) pixels of ``reference`` (an RGB frame) into later frames by
    OpenCV's DIS dense optical flow (Kroeger et al. 2016: inverse-search patches, densified,
    refined variationally), the flow always from the reference frame to the frame, initialised
    with the previous frame's flow (so that a large head motion is found step by step), and
    sampled bilinearly at the points. An instrument of its own, unlike the Lucas-Kanade of
    :class:`FlowMotionReader`, which the analysis' optical flow also uses.

    DIS's preset "medium" (patches of 8 px every 3 px, 25 gradient-descent iterations, 5 of the
    variational refinement) down to the full resolution (``finest_scale=0``; the preset stops
    at half of it). :meth:`read` gives each frame's points (N, 2) and which are sure: the flow
    back from the frame to the reference, computed the same way, brings the point within
    ``fb_max_px`` of where it started."""

    def __init__(self, reference, points, finest_scale: int = DIS_FINEST_SCALE,
                 fb_max_px: float = 1.0, margin: float = DIS_MARGIN):  # fmt: skip
        cv2 = import_opencv("the motion reader")
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] < 2 or not np.isfinite(pts[:, :2]).all():
            raise MyofaceValueError(f"points must be finite (N, 2) pixels; got {pts.shape}")
        img = grey(reference)
        # the flow is computed on the points' box with a margin (the face, not the frame)
        lo, hi = pts[:, :2].min(0), pts[:, :2].max(0)
        m = margin * float((hi - lo).max()) + 8.0
        h, w = img.shape
        x0, y0 = int(max(0, np.floor(lo[0] - m))), int(max(0, np.floor(lo[1] - m)))
        x1, y1 = int(min(w, np.ceil(hi[0] + m) + 1)), int(min(h, np.ceil(hi[1] + m) + 1))
        self._box = (slice(y0, y1), slice(x0, x1))
        self._origin = np.array([x0, y0], dtype=np.float64)
        self._shape = img.shape
        self.ref = np.ascontiguousarray(img[self._box])
        self.ref_points = pts[:, :2].copy()
        self.fb_max_px = float(fb_max_px)
        self._dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
        self._dis.setFinestScale(int(finest_scale))
        self._dis.setUseSpatialPropagation(True)
        self._fwd = None  # the previous frame's flows, each frame's start
        self._bwd = None

    def read(self, frame) -> tuple[np.ndarray, np.ndarray]:
        img = grey(frame)
        if img.shape != self._shape:
            raise MyofaceValueError("the frames must have the reference frame's size")
        img = np.ascontiguousarray(img[self._box])
        # calc(I0, I1, flow) starts from ``flow`` when it is given (of I0's size, float32 x 2)
        self._fwd = self._dis.calc(self.ref, img, self._fwd)
        self._bwd = self._dis.calc(img, self.ref, self._bwd)
        p = self.ref_points - self._origin
        q = p + bilinear(self._fwd, p)
        back = q + bilinear(self._bwd, q)
        ok = np.isfinite(q).all(1) & (np.linalg.norm(back - p, axis=1) < self.fb_max_px)
        return q + self._origin, ok


def bilinear(field: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``field`` (H, W, C) sampled bilinearly at ``points`` (N, 2) pixels (x, y; pixel centres
    at integers), the border values held outside: (N, C)."""
    f = np.asarray(field, dtype=np.float64)
    h, w = f.shape[:2]
    x = np.clip(np.asarray(points[:, 0], dtype=np.float64), 0, w - 1)
    y = np.clip(np.asarray(points[:, 1], dtype=np.float64), 0, h - 1)
    x0 = np.minimum(np.floor(x).astype(int), w - 2)
    y0 = np.minimum(np.floor(y).astype(int), h - 2)
    ax, ay = (x - x0)[:, None], (y - y0)[:, None]
    return (1 - ay) * ((1 - ax) * f[y0, x0] + ax * f[y0, x0 + 1]) + ay * (
        (1 - ax) * f[y0 + 1, x0] + ax * f[y0 + 1, x0 + 1]
    )


#: the readers :func:`make_reader` makes
METHODS = ("lk", "dis")


def make_reader(method: str, reference, points, iod_px: float):
    """The reader ``method`` ("lk": :class:`FlowMotionReader` with :func:`window_for`
    ``iod_px``; "dis": :class:`DenseFlowMotionReader`) of ``points`` in ``reference``."""
    if method == "lk":
        return FlowMotionReader(reference, points, window=window_for(iod_px))
    if method == "dis":
        return DenseFlowMotionReader(reference, points)
    raise MyofaceValueError(f"the motion reader's method must be one of {METHODS}; got {method!r}")


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


#: the rigid points' alignment drops, in up to this many rounds, a point whose residual after
#: the similarity is over :data:`OUTLIER_FACTOR` times the median's (and over
#: :data:`OUTLIER_FLOOR_IOD`): a blink drags the outer eye corners' readings by up to 0.055 IOD
#: on the sample video (2026-12-01), and a least-squares alignment on them put that error into
#: every region's displacement
OUTLIER_ROUNDS = 2
OUTLIER_FACTOR = 3.0
OUTLIER_FLOOR_IOD = 0.005


def aligned_displacements(ref: np.ndarray, cur: np.ndarray, rigid, eye_outer) -> np.ndarray:
    """The displacements (N, 2) of points ``cur`` (N, 2) from ``ref`` (N, 2), the head's
    motion in the image plane taken out (``cur`` mapped onto ``ref`` by the similarity of
    the ``rigid`` points, without those it leaves far off: :data:`OUTLIER_ROUNDS`), in
    inter-ocular distances (``eye_outer``: the two outer eye corners' indices), image axes
    (x right, y down)."""
    rigid = np.asarray(list(rigid))
    iod = float(np.linalg.norm(ref[eye_outer[0]] - ref[eye_outer[1]]))
    keep = rigid
    s, r, t = similarity_2d(cur[keep], ref[keep])
    for _ in range(OUTLIER_ROUNDS):
        res = np.linalg.norm(s * cur[rigid] @ r.T + t - ref[rigid], axis=1) / iod
        cut = max(OUTLIER_FACTOR * float(np.median(res)), OUTLIER_FLOOR_IOD)
        new = rigid[res <= cut]
        if len(new) < 3 or len(new) == len(keep):
            break
        keep = new
        s, r, t = similarity_2d(cur[keep], ref[keep])
    back = s * cur @ r.T + t
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
