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

A 2-D similarity cannot take out a turn of the head out of the image plane: on renders of the
person's face whose head turns by 5 degrees (``tests/analysis/test_fidelity.py::
test_the_reader_under_3d_head_motion``, 2026-12-02) it read a nod as 0.019 inter-ocular
distances RMS of chin motion and 0.012 of the mouth corners', a turn as 0.010 of the brows'.
:class:`HeadPose3D` fits a head pose in 3-D to the rigid points instead, their depths from a
3-D face of the person (the fidelity measure's: the face model made from the calibration
frame, never the analysis' fit): 0.004-0.010 there; on the known warps DIS then reads
0.95-1.04 (explained 0.987-0.999).
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
#: a point given a support (:class:`DenseFlowMotionReader`'s ``support``) is read as the flow's
#: mean over a Gaussian of that width, cut at this many widths
SUPPORT_CUT = 2.5


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
    ``fb_max_px`` of where it started.

    ``support`` (N,) pixels (0: none, the default): a point with a support is read as the mean
    of the forward flow over the pixels around it, weighted by a Gaussian of that width (cut at
    :data:`SUPPORT_CUT` widths) and left out where the flow back does not return within
    ``fb_max_px``; it is sure when at least half that weight returns. For a point on a motion
    boundary: a mouth corner, where the lips' slit ends, sits between the upper lip's flow and
    the lower lip's (on a smile's render they differ by 10 px at 6 px from it), and the flow at
    its pixel is whichever side DIS's smoothing leans to, which a few pixels of the render
    change (see :mod:`myoface.analysis.fidelity`'s ``CORNER_SUPPORT_IOD``)."""

    def __init__(self, reference, points, finest_scale: int = DIS_FINEST_SCALE,
                 fb_max_px: float = 1.0, margin: float = DIS_MARGIN,
                 support=None):  # fmt: skip
        cv2 = import_opencv("the motion reader")
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] < 2 or not np.isfinite(pts[:, :2]).all():
            raise MyofaceValueError(f"points must be finite (N, 2) pixels; got {pts.shape}")
        img = grey(reference)
        # the flow is computed on the points' box with a margin (the face, not the frame)
        sup = np.zeros(len(pts)) if support is None else np.asarray(support, dtype=np.float64)
        if sup.shape != (len(pts),) or not (np.isfinite(sup).all() and (sup >= 0).all()):
            raise MyofaceValueError(f"support must be (N,) widths >= 0; got {sup.shape}")
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
        self.support = sup
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
        for i in np.flatnonzero(self.support > 0):
            q[i], ok[i] = self._supported(p[i], self.support[i])
        return q + self._origin, ok

    def _supported(self, p: np.ndarray, width: float) -> tuple[np.ndarray, bool]:
        """The reading of the point ``p`` (the box's pixels) over its support of ``width``."""
        h, w = self._fwd.shape[:2]
        r = SUPPORT_CUT * width
        x0, x1 = max(0, int(np.floor(p[0] - r))), min(w - 1, int(np.ceil(p[0] + r)))
        y0, y1 = max(0, int(np.floor(p[1] - r))), min(h - 1, int(np.ceil(p[1] + r)))
        ys, xs = np.mgrid[y0 : y1 + 1, x0 : x1 + 1]
        xy = np.column_stack([xs.ravel(), ys.ravel()]).astype(np.float64)
        d2 = ((xy - p) ** 2).sum(1)
        inside = d2 <= r * r
        xy, d2 = xy[inside], d2[inside]
        u = self._fwd[ys.ravel()[inside], xs.ravel()[inside]].astype(np.float64)
        back = xy + u + bilinear(self._bwd, xy + u)
        wgt = np.exp(-0.5 * d2 / width**2)
        good = np.isfinite(u).all(1) & (np.linalg.norm(back - xy, axis=1) < self.fb_max_px)
        total = float(wgt.sum())
        kept = float(wgt[good].sum())
        if not kept > 0:
            return p + bilinear(self._fwd, p[None])[0], False
        return p + (wgt[good, None] * u[good]).sum(0) / kept, kept >= 0.5 * total


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


#: the largest face the readers read at its own resolution: its inter-ocular distance (outer
#: eye corners, px). A larger face is read on frames scaled down to bring it to this
#: (:class:`ScaledReader`), inside the scales where the readers were validated (the sample
#: video's face, 99.5 px, on known warps; renders of the person's face, 157 px), and the
#: forward-backward check's 1 px is :data:`FB_IOD_PX`'s, in proportion on a larger face.
#: Why (2026-12-06): ``single_face.mp4`` scaled up to 1280 x 720 and 1920 x 1080 (the same
#: motion, as a phone films it) and analysed, the model's motion came out the same to
#: 0.004-0.006 inter-ocular distances (IOD) RMS in every region, but the judge read at the
#: video's own resolution with a 1 px check scored its fidelity 0.778 / 0.672 / 0.246: at
#: 1080p 38 % of its readings failed the check (10 % at 640 x 360), so the frames were taken
#: for blinks and the head's pose fitted to the nose ridge alone, and its regions' readings
#: were 0.007-0.084 IOD RMS off the 640 x 360 reading's (the chin 0.084, its motion 0.024
#: IOD RMS). Read so, 14 % fail and the regions are 0.003-0.016 off (the mouth corners 0.039;
#: the same 640 x 360 frames encoded again move them by 0.002-0.007 and 0.028), the 1080p
#: reading 2.6 times faster (8.0 s against 21.0 for the 72 frames; ``tests/analysis/
#: test_fidelity.py::test_a_large_face_is_read_at_the_readers_scale``); the analyses' fidelity
#: 0.778 / 0.779 / 0.685 (the 1080p's mouth corners 0.76 against 0.90: the judge's corners
#: move with any re-encoding, and the analysis itself a little with the resolution, its
#: muscles 0.014 from the 640 x 360 analysis' on average). Scaled down to 100 px instead
#: (1080p 0.730), the renders' happiness read its lower lip at 0.82 of its motion, below the
#: 0.85 their validation holds at their own scale: a sharp face loses what the scaling
#: takes away. A small face scaled up (measured, not done): brought to 100 px, the known warps
#: of the sample's first frame at 50 and 33 px read 0.85-1.06 -> 0.93-1.10 and 0.64-1.10 ->
#: 0.84-1.22 of their regions' motion, but the sample's own frames at 320 x 180 and 214 x 120
#: came no nearer the 640 x 360 reading (the regions 0.005-0.018 IOD RMS off -> 0.003-0.022,
#: the corners 0.036-0.048 -> 0.057-0.064).
READER_IOD_PX = 160.0
#: the forward-backward check's 1 px is for a face of this inter-ocular distance (px; the
#: sample video's, where the readers were validated on real frames); a larger face read at
#: its own resolution has it in proportion (renders of 157 px: 1.57 px; with 1 px, before
#: 2026-12-06, the renders' validation read 8 of its 32 gains and explained fractions
#: 0.006-0.014 lower, and 1 of the 3-D head motion test's 4, 0.005; none of the others moved)
FB_IOD_PX = 100.0


def make_reader(method: str, reference, points, iod_px: float, support_iod=None):
    """The reader ``method`` ("lk": :class:`FlowMotionReader` with :func:`window_for`
    ``iod_px``; "dis": :class:`DenseFlowMotionReader`, ``support_iod`` (N,) its points'
    supports in inter-ocular distances, default none) of ``points`` in ``reference``. (Lucas-
    Kanade reads every point over its window: ``support_iod`` does not apply.) A face whose
    ``iod_px`` is more than :data:`READER_IOD_PX` is read on frames scaled down to that
    (:class:`ScaledReader`); the points are given and returned in the frames' own pixels."""
    if method not in METHODS:
        raise MyofaceValueError(
            f"the motion reader's method must be one of {METHODS}; got {method!r}"
        )
    scale = min(1.0, READER_IOD_PX / float(iod_px)) if iod_px > 0 else 1.0

    def make(ref, pts):
        iod = float(iod_px) * scale
        fb = max(1.0, iod / FB_IOD_PX)
        if method == "lk":
            return FlowMotionReader(ref, pts, window=window_for(iod), fb_max_px=fb)
        sup = None if support_iod is None else np.asarray(support_iod, float) * iod
        return DenseFlowMotionReader(ref, pts, support=sup, fb_max_px=fb)

    if scale >= 1.0:
        return make(reference, points)
    return ScaledReader(make, reference, points, scale)


class ScaledReader:
    """A reader (``make(reference, points)``: :class:`FlowMotionReader` or
    :class:`DenseFlowMotionReader`) run on frames scaled by ``scale`` (< 1, OpenCV's area
    resampling); :meth:`read` takes and gives the frames' own pixels (pixel centres at
    integers: a point at ``x`` is at ``(x + 0.5) s - 0.5`` of the scaled frame)."""

    def __init__(self, make, reference, points, scale: float):
        img = np.asarray(reference)
        h, w = img.shape[:2]
        self._size = (max(1, int(round(w * scale))), max(1, int(round(h * scale))))
        self._s = np.array([self._size[0] / w, self._size[1] / h])
        pts = np.asarray(points, dtype=np.float64)[:, :2]
        self.reader = make(self._resized(img), self._to(pts))

    def _resized(self, frame) -> np.ndarray:
        cv2 = import_opencv("the motion reader")
        return cv2.resize(np.ascontiguousarray(frame), self._size, interpolation=cv2.INTER_AREA)

    def _to(self, p: np.ndarray) -> np.ndarray:
        return (p + 0.5) * self._s - 0.5

    def read(self, frame) -> tuple[np.ndarray, np.ndarray]:
        q, ok = self.reader.read(self._resized(frame))
        return (q + 0.5) / self._s - 0.5, ok


#: :class:`StabilizedReader` turns a frame back only where the head has moved further than
#: the reader reads without it, and changes the similarity it turns by only where the
#: frame's own is that far from it: (degrees of roll, relative scale, pixels of shift at the
#: face). Measured 2026-12-07 (known warps of ``single_face.mp4``'s first frame, the
#: expression's fields with the head's motion rising and falling over 16 frames, DIS, the
#: 3-D alignment): unturned, a roll of 10 degrees with a scale of 1.1 and a shift of 30 px
#: was read at gains 0.96-1.07, explained 0.90-1.0 (the eyelids the least), a roll of 8
#: degrees with a scale of 1.15 at 0.93-1.10, explained 0.92-0.99 (1.2: the lips' gain 1.11),
#: one of 20 degrees at -0.70 of the brows' motion explained. The sample video's own head
#: moves by up to 14 px, a scale of 1.08 and 1.7 degrees of roll (MediaPipe's midline
#: points), the codec's decoded sample by a scale of up to 1.11: read unturned, as validated.
#: (With a range of 3 degrees, 2 % and 5 px the measure of the sample went 0.776 -> 0.733-0.751
#: as its frames were turned, and with 10 % of scale the codec's decoded fidelity 0.618 ->
#: 0.589: the mouth corners' and the chin's readings move with a resampling, see
#: :data:`~myoface.analysis.fidelity.STABILIZER_POINTS`.)
STABILIZE_BEYOND = (8.0, 0.15, 25.0)


class StabilizedReader:
    """A reader (:func:`make_reader`'s) run on each frame turned back onto the reference: the
    frame is resampled by a 2-D similarity that takes ``anchors`` (K, 2), the frame's own
    places of some of the face's points (the fidelity measure's: MediaPipe's midline points on
    that frame), onto ``reference_anchors`` (the same points in the reference frame), the
    reader reads the points there, and its readings are mapped back through the same
    similarity. The similarity is a known motion that is undone exactly, so whatever the
    anchors' own errors it adds nothing to a reading and takes nothing from it: it only
    brings the face to where the reader was validated, within a few pixels and degrees of
    the reference. Without it a roll of the head beyond about 10 degrees was misread (known
    warps of the sample's first frame, the head rolled 20 / 35 degrees and shifted 30 px on top
    of the expression's fields: the brows' explained fraction -0.70 / -7.9, the chin's 0.98 /
    0.09; ``tests/analysis/test_motionreader.py``).

    The similarity in use changes only when the frame's own is further from it than the
    validated range (:data:`STABILIZE_BEYOND`): a face within it of the reference is read as
    it is, as validated, and a frame is turned by the same similarity as the frame before
    unless the head has moved on, so the reader's start from the previous frame's flow is
    the right one and the anchors' own jitter (the eye corners in a blink) does not reach
    the readings. (Turned afresh on every frame, a blink with the head nodded was read as
    0.019 IOD of lower-lip motion against 0.008 in the open frames, and frames read forward
    and back from the reference differed by 1.5 px at the mouth corners, where they differ by
    1.3 without it.) A frame without anchors (no face found: a hand over it) is turned by the
    similarity in use.

    :meth:`read` takes ``(frame, anchors)`` and gives the frame's points (N, 2) in its own
    pixels and which are sure (the reader's forward-backward check, made on the turned
    frame)."""

    def __init__(self, reader, reference_anchors):
        self.reader = reader
        self.ref_anchors = np.asarray(reference_anchors, dtype=np.float64)[:, :2]
        if len(self.ref_anchors) < 2 or not np.isfinite(self.ref_anchors).all():
            raise MyofaceValueError("the stabilizer needs at least 2 finite reference anchors")
        # the similarity in use (2, 3): frame pixels -> reference pixels (None: none)
        self._m = None

    def _beyond(self, m: np.ndarray) -> bool:
        """Whether the similarity ``m`` (2, 3) takes the face further than
        :data:`STABILIZE_BEYOND` from where the one in use (or none) puts it."""
        a, t = m[:, :2], m[:, 2]
        if self._m is not None:  # m relative to the one in use: m o used^-1
            ai = np.linalg.inv(self._m[:, :2])
            a, t = a @ ai, t - a @ ai @ self._m[:, 2]
        scale = float(np.sqrt(abs(np.linalg.det(a))))
        roll = float(np.degrees(np.arctan2(a[1, 0], a[0, 0])))
        deg, rel, px = STABILIZE_BEYOND
        c = self.ref_anchors.mean(0)  # (the shift where the face is)
        shift = float(np.linalg.norm(a @ c + t - c))
        return abs(roll) > deg or abs(scale - 1.0) > rel or shift > px

    def read(self, frame, anchors=None) -> tuple[np.ndarray, np.ndarray]:
        cv2 = import_opencv("the motion reader")
        if anchors is not None:
            a = np.asarray(anchors, dtype=np.float64)[:, :2]
            if a.shape == self.ref_anchors.shape and np.isfinite(a).all():
                s, r, t = similarity_2d(a, self.ref_anchors)
                m = np.column_stack([s * r, t])
                if self._beyond(m):
                    self._m = m
        if self._m is None:
            return self.reader.read(frame)
        img = np.ascontiguousarray(frame)
        h, w = img.shape[:2]
        turned = cv2.warpAffine(img, self._m, (w, h), flags=cv2.INTER_CUBIC,
                                borderMode=cv2.BORDER_REPLICATE)  # fmt: skip
        q, ok = self.reader.read(turned)
        # back: x = A^-1 (y - t)
        a, t = self._m[:, :2], self._m[:, 2]
        return (q - t) @ np.linalg.inv(a).T, ok


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


# ------------------------------------------------------------------ the head's motion in 3-D

#: :func:`fit_pose_3d`'s Gauss-Newton iterations (a few degrees from the start: converged to
#: 1e-9 in 4-6)
POSE_ITERATIONS = 20
#: :class:`HeadPose3D`'s prior on the turn out of the image plane (yaw and pitch from the
#: reference frame's), in inter-ocular distances of residual per radian on each axis: a turn
#: of 1 degree costs as much as 0.005 IOD (half a pixel on the sample video) of one rigid
#: point's misfit. Eight rigid points with ~30 mm of depth between the eye corners and the
#: nose ridge tell a turn from a point that moves by about 2 degrees a pixel, so without it
#: any motion of the rigid points (a lid's bump reaching an eye corner, a squint) becomes a
#: turn that moves every region. Chosen on the two known answers (2026-12-02): at 0 the known
#: warps' eyelids read at 0.87 (their bumps move the eye corners), at 1 a nod of 5 degrees on
#: the renders leaks 0.017 IOD into the chin (as the 2-D alignment's 0.019); at 0.3 the warps
#: read 0.95-1.04 and the renders leak 0.010 at most. It leaves 35-38 % of an exact turn's
#: parallax (``test_the_3d_alignment_takes_out_a_turn_of_the_head``)
POSE_PRIOR = 0.3


def _rotvec_matrix(w: np.ndarray) -> np.ndarray:
    """The rotation (3, 3) of the rotation vector ``w`` (Rodrigues)."""
    th = float(np.linalg.norm(w))
    if th < 1e-12:
        return np.eye(3)
    k = np.asarray(w, dtype=np.float64) / th
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(th) * kx + (1.0 - np.cos(th)) * kx @ kx


def _rotvec(r: np.ndarray) -> np.ndarray:
    """The rotation vector of the rotation ``r`` (3, 3) (angles below pi)."""
    c = np.clip(0.5 * (np.trace(r) - 1.0), -1.0, 1.0)
    th = float(np.arccos(c))
    v = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    return 0.5 * v if th < 1e-9 else th / (2.0 * np.sin(th)) * v


def fit_pose_3d(face: np.ndarray, image_up: np.ndarray, start=None, prior=None):
    """The scaled orthographic pose ``(s, R, t)`` that brings the 3-D points ``face`` (N, 3;
    head frame: x across, y up, z towards the viewer) nearest to ``image_up`` (N, 2; pixels
    with y up), ``image_up ~ s (R face)[:, :2] + t``, in least squares (Gauss-Newton on the
    rotation vector, the scale and the translation, from ``start`` or else from the affine
    camera's orthonormalised rows). Needs 4 or more points, not all in a line."""
    x = np.asarray(face, dtype=np.float64)
    q = np.asarray(image_up, dtype=np.float64)
    n = len(x)
    if n < 4 or x.shape != (n, 3) or q.shape != (n, 2):
        raise MyofaceValueError(f"a 3-D pose needs 4 or more (3-D, 2-D) points; got {n}")
    if start is None:
        xc, qc = x - x.mean(0), q - q.mean(0)
        m = np.linalg.lstsq(xc, qc, rcond=None)[0].T  # the affine camera (2, 3)
        s = 0.5 * float(np.linalg.norm(m[0]) + np.linalg.norm(m[1]))
        if not s > 0:
            raise MyofaceValueError("degenerate points: cannot fit the head's pose")
        r1 = m[0] / np.linalg.norm(m[0])
        r2 = m[1] - r1 * (r1 @ m[1])
        r2 = r2 / np.linalg.norm(r2)
        u, _, vt = np.linalg.svd(np.array([r1, r2, np.cross(r1, r2)]))
        r = u @ vt
        t = q.mean(0) - s * (x.mean(0) @ r.T)[:2]
    else:
        s, r, t = float(start[0]), np.asarray(start[1], float), np.asarray(start[2], float)
    zero, one = np.zeros(n), np.ones(n)
    for _ in range(POSE_ITERATIONS):
        y = x @ r.T
        res = (s * y[:, :2] + t - q).reshape(-1)
        a, b, c = y.T
        jac = np.empty((2 * n, 6))
        # d(R x)/d(w) for R <- exp([w]x) R: w x (R x)
        jac[0::2] = np.column_stack([zero, s * c, -s * b, y[:, 0], one, zero])
        jac[1::2] = np.column_stack([-s * c, zero, s * a, y[:, 1], zero, one])
        if prior is not None:  # (rotation, weight px / rad): the turn out of the image plane
            e = _rotvec(r @ np.asarray(prior[0]).T)[:2]
            jac = np.vstack([jac, np.hstack([prior[1] * np.eye(2), np.zeros((2, 4))])])
            res = np.concatenate([res, prior[1] * e])
        step = np.linalg.lstsq(jac, -res, rcond=None)[0]
        r = _rotvec_matrix(step[:3]) @ r
        s += float(step[3])
        t = t + step[4:]
        if np.abs(step).max() < 1e-10:
            break
    return s, r, t


class HeadPose3D:
    """The head's motion taken out in 3-D: the reference frame's points ``ref`` (N, 2,
    pixels, image axes) given depths by a 3-D face of the person (``face``: (N, 3) mm, the
    same points in the head frame, x across, y up, z towards the viewer; e.g. the face model
    made from the reference frame). The reference frame's pose is the scaled orthographic
    one of every point; the face's x and y are then corrected so that it projects exactly
    onto ``ref`` (the reference frame's own 3-D face: its x and y, the face's depths). Each
    later frame's pose is fitted to its ``rigid`` points (:func:`fit_pose_3d`, without those
    it leaves far off, as :func:`aligned_displacements`), and each point's displacement is
    what is left of it once the head's motion is predicted: taken back through the pose's
    rotation and scale into the head frame's x and y (a displacement towards the camera is
    not seen), over the face's inter-ocular distance (``eye_outer``).

    A 2-D similarity cannot take out a turn of the head out of the image plane: points in
    front of the rigid ones or behind them move against them (a nod moves the chin against
    the eyes); this does, to first order, as far as the rigid points' flow and the face's
    depths are right. Scaled orthographic: a camera's perspective (the face's depth over its
    distance) is left."""

    def __init__(self, ref, face, rigid, eye_outer, prior: float = None):
        ref = np.asarray(ref, dtype=np.float64)
        x = np.array(face, dtype=np.float64)
        if x.shape != (len(ref), 3) or not np.isfinite(x).all():
            raise MyofaceValueError(
                f"the face must be finite (N, 3) points, one per reference point; got {x.shape}"
            )
        self.rigid = np.asarray(list(rigid))
        self.prior = POSE_PRIOR if prior is None else float(prior)
        q0 = ref * _UP
        s0, r0, t0 = fit_pose_3d(x, q0)
        x[:, :2] += np.linalg.solve(s0 * r0[:2, :2], (q0 - s0 * (x @ r0.T)[:, :2] - t0).T).T
        self.face = x
        self.reference_pose = (s0, r0, t0)
        self.iod = float(np.linalg.norm(x[eye_outer[0], :2] - x[eye_outer[1], :2]))

    def pose(self, cur, rigid=None, towards=None) -> tuple[float, np.ndarray, np.ndarray]:
        """The pose ``(s, R, t)`` of the frame whose points are ``cur`` (N, 2, pixels), fitted
        to ``rigid`` (default: the rigid points given at construction), the turn out of the
        image plane held towards the rotation ``towards`` (3, 3; default the reference
        frame's) by the prior."""
        q = np.asarray(cur, dtype=np.float64) * _UP
        rigid = self.rigid if rigid is None else np.asarray(list(rigid))
        keep = rigid
        s0, r0, _ = self.reference_pose
        centre = r0 if towards is None else np.asarray(towards, dtype=np.float64)
        prior = (centre, self.prior * s0 * self.iod) if self.prior > 0 else None
        pose = fit_pose_3d(self.face[keep], q[keep], self.reference_pose, prior)
        for _ in range(OUTLIER_ROUNDS):
            s, r, t = pose
            res = np.linalg.norm(s * (self.face[rigid] @ r.T)[:, :2] + t - q[rigid], axis=1)
            res = res / (s * self.iod)
            cut = max(OUTLIER_FACTOR * float(np.median(res)), OUTLIER_FLOOR_IOD)
            new = rigid[res <= cut]
            if len(new) < 5 or len(new) == len(keep):
                break
            keep = new
            pose = fit_pose_3d(self.face[keep], q[keep], pose, prior)
        return pose

    def displacements(self, cur, rigid=None, towards=None) -> np.ndarray:
        """The displacements (N, 2) of the points ``cur`` (N, 2, pixels) from the reference's,
        the head's motion taken out (the pose fitted to ``rigid``, default the rigid points,
        held towards ``towards`` as :meth:`pose`), in the head frame's x and y (y up), over the
        inter-ocular distance."""
        return self.displacements_at(cur, self.pose(cur, rigid, towards))

    def sequence_poses(self, seq, fallback, narrow) -> list:
        """The pose of each frame of ``seq`` (T, N, 2, pixels; rows with a NaN: None). A frame
        whose ``fallback`` (T,) is true (e.g. the eyes closing, which drags the flow at the eye
        corners) is fitted to the points ``narrow`` (e.g. the nose ridge, which tells the turn
        out of the image plane poorly), with that turn held towards the rotation between the
        nearest other frames' (interpolated in time; the one on one side at the sequence's
        ends; the reference frame's if there is none): a head turned and held, then blinking,
        is not read as turning back to the reference in the blink."""
        seq = np.asarray(seq, dtype=np.float64)
        ok = [bool(np.isfinite(cur).all()) for cur in seq]
        poses = [self.pose(cur) if o and not f else None
                 for cur, o, f in zip(seq, ok, fallback, strict=True)]  # fmt: skip
        full = [k for k, p in enumerate(poses) if p is not None]
        for k in range(len(seq)):
            if not ok[k] or poses[k] is not None:
                continue
            before = [j for j in full if j < k]
            after = [j for j in full if j > k]
            if before and after:
                a, b = before[-1], after[0]
                ra, rb = poses[a][1], poses[b][1]
                w = _rotvec(rb @ ra.T) * (k - a) / (b - a)
                towards = _rotvec_matrix(w) @ ra
            elif before or after:
                towards = poses[(before or after)[-1 if before else 0]][1]
            else:
                towards = None
            poses[k] = self.pose(seq[k], narrow, towards)
        return poses

    def displacements_at(self, cur, pose) -> np.ndarray:
        """:meth:`displacements` of ``cur`` (N, 2, pixels) at a given ``pose`` ``(s, R, t)``."""
        s, r, t = pose
        q = np.asarray(cur, dtype=np.float64) * _UP
        left = q - (s * (self.face @ r.T)[:, :2] + t)
        return np.linalg.solve(s * r[:2, :2], left.T).T / self.iod


_UP = np.array([1.0, -1.0])
