"""Optical flow on the landmark tracker's points: the image's own motion where MediaPipe's
face mesh reads it short.

MediaPipe's face mesh regresses its 468 points from each frame with a learned prior on face
shape, and it reads an expression's motion short: on the sample video's first frame, warped
by a known smooth field (mouth corners out and up, brows up, chin up), it finds 0.51-0.66 of
the warp; pyramidal Lucas-Kanade on the same points finds 0.86-0.99 (measured 2026-12-01,
4 % and 8 % of the inter-ocular distance). The fit can only reproduce what its points show,
so the analysis tracks each point by optical flow as well:

- from the *reference* frame (the first frame with a face since the last loss of the face),
  MediaPipe's own displacement since then as the first guess: no drift while the face looks
  much as it did then;
- where that fails (the face turned or changed too much), from the previous frame's refined
  point (a chain, which drifts slowly);
- a track counts when it comes back to its start when run backwards (forward-backward
  error under :attr:`FlowRefiner.fb_max_px`) and stays within :attr:`FlowRefiner.tolerance`
  inter-ocular distances of MediaPipe's point; elsewhere MediaPipe's point stands (and the
  chain restarts from it).

Brightness is high-pass filtered first (a Gaussian of :attr:`FlowRefiner.highpass_sigma_px`
taken out), so that shading which does not move with the skin pulls the flow less. Only a
crop around the face is processed. The depth (MediaPipe's z) is kept as detected.

:class:`FlowDetector` wraps any detector (``detect(frame) -> (N, 3) | None``, ``close()``)
with a :class:`FlowRefiner`. Since 2026-12-02 ``myoface analyze --tracker landmarks --flow``
(:attr:`~myoface.analysis.weights.FitSettings.flow`) reads the points with the
model-anchored tracker instead (:mod:`myoface.analysis.modelflow`: every point against the
calibration frame, its template warped by the model's predicted pose and skin, never
chained); this refiner stays as ``FitTracker(flow_method="chained")``. With the head turning
it drifts: on the head-motion renders its points are 4.1 px (median) from the true skin
point, the anchored tracker's 2.2 px.
"""

from __future__ import annotations

import numpy as np

from myoface.errors import MyofaceValueError
from myoface.facemesh import import_opencv

#: MediaPipe's outer eye corners (the inter-ocular distance that scales the tolerance)
EYE_CORNERS = (33, 263)


def _cv2():
    return import_opencv("the optical flow")


class FlowRefiner:
    """Refine a sequence of landmark arrays by pyramidal Lucas-Kanade optical flow (see the
    module's docstring). Call :meth:`refine` on the frames in order; a frame without points
    (None) restarts the tracks.

    Parameters
    ----------
    window : the flow's window, px (square).
    levels : pyramid levels above the image.
    fb_max_px : a track is kept when, run back, it ends within this distance of its start.
    tolerance : ... and it is within this many inter-ocular distances of the detector's point.
    highpass_sigma_px : the Gaussian blur taken out of the brightness first (0: none).
    """

    def __init__(self, window: int = 13, levels: int = 3, fb_max_px: float = 0.5,
                 tolerance: float = 0.15, highpass_sigma_px: float = 4.0):  # fmt: skip
        if int(window) < 3 or int(levels) < 0 or fb_max_px <= 0 or tolerance <= 0:
            raise MyofaceValueError(
                "FlowRefiner needs window >= 3, levels >= 0, fb_max_px > 0 and tolerance > 0"
            )
        self.window = int(window)
        self.levels = int(levels)
        self.fb_max_px = float(fb_max_px)
        self.tolerance = float(tolerance)
        self.highpass_sigma_px = float(highpass_sigma_px)
        #: counts over the frames refined: points tracked from the reference frame, from
        #: the previous frame, and left at the detector's
        self.stats = {"frames": 0, "direct": 0, "chained": 0, "detector": 0}
        self.reset()

    def reset(self) -> None:
        """Forget the tracks (the next frame with points is the new reference)."""
        self._ref = None  # (image, origin, refined xy, detector's xy) of the reference frame
        self._prev = None  # (image, origin, refined xy) of the previous frame
        self._size = None  # the crop's (width, height)

    def _prepare(self, frame: np.ndarray, xy: np.ndarray):
        """The crop around the points, grey and high-passed (uint8), and its origin."""
        cv2 = _cv2()
        frame = np.asarray(frame)
        h, w = frame.shape[:2]
        if self._size is None:
            ext = xy.max(0) - xy.min(0)
            margin = 2 * self.window + 40
            self._size = np.minimum(np.ceil(ext * 1.3 + 2 * margin).astype(int), [w, h])
        cw, ch = (int(v) for v in np.minimum(self._size, [w, h]))
        c = (xy.max(0) + xy.min(0)) / 2
        x0 = int(np.clip(round(c[0] - cw / 2), 0, w - cw))
        y0 = int(np.clip(round(c[1] - ch / 2), 0, h - ch))
        crop = np.ascontiguousarray(frame[y0 : y0 + ch, x0 : x0 + cw])
        if crop.ndim == 3:
            grey = cv2.cvtColor(crop[..., :3], cv2.COLOR_RGB2GRAY)
        else:
            grey = crop
        grey = grey.astype(np.float32)
        if self.highpass_sigma_px > 0:
            grey = grey - cv2.GaussianBlur(grey, (0, 0), self.highpass_sigma_px)
            grey = grey * 2.0 + 128.0
        grey = np.clip(grey, 0, 255).astype(np.uint8)
        return grey, np.array([x0, y0], dtype=np.float32)

    def _track(self, a, oa, b, ob, start, guess):
        """Track ``start`` (image a) into image b from ``guess``: the points, and which are
        kept by the forward-backward check. Frame coordinates in and out."""
        cv2 = _cv2()
        if a.shape != b.shape:  # (the frame size changed)
            return guess.copy(), np.zeros(len(start), dtype=bool)
        kw = {
            "winSize": (self.window, self.window),
            "maxLevel": self.levels,
            "criteria": (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01),
            "flags": cv2.OPTFLOW_USE_INITIAL_FLOW,
        }
        p = np.ascontiguousarray(start - oa, dtype=np.float32)
        g = np.ascontiguousarray(guess - ob, dtype=np.float32)
        q, st, _ = cv2.calcOpticalFlowPyrLK(a, b, p, g, **kw)
        back, st2, _ = cv2.calcOpticalFlowPyrLK(b, a, q, p.copy(), **kw)
        ok = (st[:, 0] == 1) & (st2[:, 0] == 1)
        ok &= np.linalg.norm(back - p, axis=1) < self.fb_max_px
        ok &= np.isfinite(q).all(axis=1)
        return q + ob, ok

    def track(self, frame, points):
        """Where the flow finds ``points`` (N, 2+) detected on ``frame``: ``(xy (N, 2), ok
        (N,) bool)``, ``xy`` the tracked positions where ``ok`` (the track is sure), the
        detector's elsewhere; None (the tracks reset) for None or non-finite points."""
        if points is None or frame is None:
            self.reset()
            return None
        pts = np.asarray(points, dtype=np.float64)
        xy = pts[:, :2].astype(np.float32)
        if not np.isfinite(xy).all():
            self.reset()
            return None
        img, org = self._prepare(frame, xy)
        self.stats["frames"] += 1
        if self._ref is None:
            self._ref = (img, org, xy.copy(), xy.copy())
            self._prev = (img, org, xy.copy())
            return xy.astype(np.float64), np.zeros(len(xy), dtype=bool)
        rimg, rorg, rxy, rdet = self._ref
        # from the reference frame, the detector's displacement since then the first guess
        q, ok = self._track(rimg, rorg, img, org, rxy, rxy + (xy - rdet))
        self.stats["direct"] += int(ok.sum())
        if not ok.all():
            # the rest from the previous frame's refined points
            pimg, porg, pxy = self._prev
            ix = np.flatnonzero(~ok)
            c, okc = self._track(pimg, porg, img, org, pxy[ix], pxy[ix])
            q[ix[okc]] = c[okc]
            ok[ix[okc]] = True
            self.stats["chained"] += int(okc.sum())
        if len(xy) > max(EYE_CORNERS):
            scale = float(np.linalg.norm(xy[EYE_CORNERS[0]] - xy[EYE_CORNERS[1]]))
        else:
            scale = 0.4 * float(np.ptp(xy[:, 0]))
        ok &= np.linalg.norm(q - xy, axis=1) < self.tolerance * scale
        q[~ok] = xy[~ok]
        self.stats["detector"] += int((~ok).sum())
        self._prev = (img, org, q.copy())
        return q.astype(np.float64), ok

    def refine(self, frame, points):
        """``points`` (N, 2+) detected on ``frame`` (an image), their x, y refined by the
        flow where it is sure (a copy); None stays None."""
        tracked = self.track(frame, points)
        if tracked is None:
            return points
        q, ok = tracked
        out = np.asarray(points, dtype=np.float64).copy()
        out[ok, :2] = q[ok]
        return out


class FlowDetector:
    """A landmark detector whose points are refined by a :class:`FlowRefiner`: the same
    ``detect(frame) -> (N, 3) | None`` and ``close()``, for a sequence of frames in order."""

    def __init__(self, detector, refiner: FlowRefiner | None = None):
        self.detector = detector
        self.refiner = refiner or FlowRefiner()

    def detect(self, frame):
        return self.refiner.refine(frame, self.detector.detect(frame))

    def close(self) -> None:
        self.detector.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
