"""Points read against the calibration frame, through the model: a drift-free point tracker
for the 3-D fit.

MediaPipe reads about half of a face's motion (a real frame warped by a known field: 0.49-0.66);
optical flow reads nearly all of it, but a flow chained from frame to frame drifts, and a flow
from the calibration frame fails once the head has turned, because the patch around a point no
longer looks as it did (:mod:`myoface.analysis.flow`). Here every point is read against the
calibration frame's appearance, never the previous frame's, with its template warped by what
the model says has happened to the skin around it since:

- at calibration (:meth:`ModelFlow.calibrate`), the reference: where the person's calibrated
  neutral (the fit's ``neutral + identity``) puts each vertex on the calibration frame (its
  pose), and that frame's image. A tracked point is then exactly what the fit's vertex is:
  the skin point that was there at calibration (MediaPipe's own offsets from the vertex play
  no part);
- on each frame (:meth:`ModelFlow.track`), the prediction: the previous frame's fit (its pose
  and skin; :func:`predicted`). Each vertex's local linear map between the calibration
  frame's projection of the mesh and the prediction's (least squares over the vertex's
  neighbours on the mesh: the head's rotation, foreshortening, scale, and the skin's
  stretch as far as the model already follows the expression) warps the template; the
  translation is then found by Lucas-Kanade (:func:`~myoface.analysis._lkkernels.
  track_points`: inverse compositional, the patch's brightness gain and offset matched,
  Huber-weighted, coarse to fine), from the prediction's point moved as MediaPipe's point
  moved since the previous frame;
- a point counts (``ok``) where its surface faces the camera in both views
  (:attr:`ModelFlow.min_cos`), the warp is well posed, the alignment converged, it is within
  :attr:`ModelFlow.tolerance` inter-ocular distances of where it was looked for, and the patch
  found correlates with the template: at least :attr:`ModelFlow.min_ncc`, or at least
  :attr:`ModelFlow.min_ncc_rel` of what a perfect match reaches through both frames' sensor
  noise (estimated on each frame; a smooth cheek's patch correlates at 0.5 when it is found
  exactly); elsewhere MediaPipe's point stands (the fit's landmark term). The lips' inner
  margins are never tracked (their patch takes in the mouth's gap), and the pixels inside
  the gap (the polygon of the inner margins, in the calibration frame and where the
  prediction puts it) weigh nothing in any patch.

The brightness is high-pass filtered first (a Gaussian of :attr:`ModelFlow.highpass_sigma_px`
taken out): shading that does not move with the skin (a light that moves, the head turning
under a light) pulls the alignment less; the patch's gain and offset take out the rest.
Only crops around the face are processed.

Measured 2026-12-02 (issue 30; the numbers of each setting in the report of the commit that
set it): on a textured plane turned 30 degrees the points are found within 0.05 px (median)
from a prediction 3 degrees off (tests/analysis/test_modelflow.py). On the known-warp clips'
smile and surprise (head still), read alone, the tracker finds 0.89 of the mouth corners'
motion, 0.97 of the brows', 1.04 of the lids', 0.96 of the chin's (MediaPipe 0.70, 0.89,
0.64, 0.54). On the head-motion renders, against the exact answer (the true surface point
under each reference pixel), the points it keeps are 0.8 px off (median) with the head
still (the chained flow's 0.8 px, of 98 % of the points) and 2.2 px with it turning (the
chained flow's 4.1 px: its drift), where it keeps 70 % and 47 % of the points (the rest turned
away, the lips' margins, or not matching): the error grows with the head's turn
from the calibration pose, in both directions alike (a forward-backward check, ``fb_max_px``,
keeps a sixth of the points and leaves their error at 1.2 px), because the renders' shading
does not turn with the skin and their skin texture is faint (half resolution). On the
sample video's smile the mouth's and chin's patches stop matching at the apex (teeth, the
lips stretched, the folds), and MediaPipe's points stand there. Window 11 (was 15): the
mouth corners' gain in the fit 0.77 -> 0.81 on the known warps; one pyramid level (two let
the mouth's 60-px patches lock wrongly: corners 0.73).

Cost (2026-12-02, thread CPU on the shared 2-core machine, the sample video, 468 points;
``tools/flow_compare.py`` and the profile in the commit's report): 6.6 ms a frame on the
fit's thread at 12 steps a level (Lucas-Kanade 4.7, the crop and its pyramid 0.9, the frame's
noise 0.6). Now 3.3 ms on the fit's thread (Lucas-Kanade 2.2, the gap's mask and the pyramid
0.7) and 0.8 ms on the detector's (:meth:`ModelFlow.prepare`: the crop, its blur and noise),
by: a kernel with two passes a step where there were five (the same points to 1e-10 px:
4.4 -> 3.1 ms); the noise on every 4th row; the gap's normalised blur only near the gap; at
most 6 steps a level, the coarse level stopping at 0.2 px. Settings against the full
benchmarks' anchored rows (head-motion renders still / moving: skin mm, head deg, worst
muscle RMSE; known warps: the corners' gain, the lowest explained): before (c232522, 12
steps) 0.78 / 1.27 / 0.169, 1.21 / 1.55 / 0.278, 0.80, 0.95; 12 steps and 0.03 px at every
level with this code (the crop, the noise's rows and the gap's blur computed as above: the
same to rounding) 0.76 / 1.33 / 0.158, 1.22 / 1.57 / 0.333: the worst muscle under head
motion moves that much with rounding; 6 steps (these) 0.76 / 1.33 / 0.161, 1.23 / 1.57 /
0.355, 0.80, 0.95 (the default analysis on this code: 1.09 / 1.35 / 0.220, 1.35 / 1.89 /
0.288). Cheaper and not kept: window 9 (Lucas-Kanade 1.5 ms; 0.80 / 1.35 / 0.157,
1.20 / 1.57 / 0.310, 0.81, 0.94) accepts a point whose patch is the flat side of an edge
(tests: test_flat_excluded_and_turned_away_points_are_the_detectors; 81 pixels correlate
by chance where 121 do not); no coarse level (window 9: 1.0 ms; 0.85 / 1.38 / 0.163, 1.24 /
1.74 / 0.285) reads the head's angle under motion worse, as does window 11 without it
(1.72 deg). The fit itself costs ~1 ms more a frame with the flow's term, and relaxes the
tissue more often (the skin it reads moves more).

Off the fit's thread (issue 30, 2026-12-02): the fit's tracker
(:class:`~myoface.analysis.trackers.landmark_fit.FitTracker`) tracks frame k on a thread of
its own from the fit of frame k - :data:`PREDICTION_LAG` (2): while frame k - 1 is fitted,
frame k is prepared and tracked, and the fit waits for it 0.2 ms a frame where it waited
4.6 (``flow_wait`` in ``analysis.fps``' breakdown; 1 is the plain loop, to the bit). The
prediction one frame older changes little (full benchmarks at the same tree, lag 2 / 1:
head-motion renders still 0.80 / 0.80 mm, 1.27 / 1.27 deg, worst RMSE 0.177 / 0.176; moving
1.22 / 1.21 mm, 1.56 / 1.57 deg, 0.269 / 0.264; known warps, head still: corners 0.80 /
0.80, brows 0.87 / 0.87, lips 0.96 / 0.97, chin 0.94 / 0.95, explained >= 0.95, leak 0.059
/ 0.059). The work is the same (5.2 ms CPU a frame on that thread, the fit 1.1 more, at a
load of 6-11 on the 2 cores); it is hidden where a core is free, not where the machine is
saturated: ``analysis.fps`` there gave the default 24.7 frames/s (0.177x MediaPipe), the flow
18.4 (0.132x; process CPU 24.4 against 17.1 ms a frame); at a load of 2.6-5.5, 41.8 (0.184x)
and 34.0 (0.149x), the fit waiting 0.19 ms a frame for the flow (``tools/flow_compare.py fps``
at a load of 1-2.6: 0.239x and 0.195x). Measured and not kept: tracking
3 vertices in 4 and the rest (117, none two neighbours) from their tracked neighbours'
offsets to the prediction (the interpolated points 0.43 px from the tracked ones, median; 1.6 px at the 90th percentile,
where the tracking is within 0.05 px); 4 or 5 steps a level (18 / 8 % fewer steps, 8 / 4
points a frame accepted or rejected otherwise, 0.4 / 0.2 px at the 95th percentile); the
coarse level stopping at 0.5 px (12 %, 6 points, 0.2 px), the image's at 0.1 px (15 %, 0.16
px).

Where the known warps' mouth corners (0.80) and brows (0.87) are held (head still,
``analysis.known_warp_gain``'s clips, the fit with this tracker;
``tools/flow_known_warp_stages.py``, each stage replaced by the warp's answer): the fit given the warp's
exact positions of every tracked vertex reaches 0.92 / 0.97, of the vertices this tracker
keeps (the rest MediaPipe's) 0.89 / 0.98; this tracker with the templates deformed by the
warp's own local maps (not the model's prediction) 0.79 / 0.87, the same: the template's
deformation does not hold them. The tracker alone reads 0.90 of the corners' motion and 0.97
of the brows' at the regions' points (explained 0.98 / 0.99), the same when it starts from
the true position (0.90 / 0.97: the alignment's optimum, not its start or its steps) and
when the mouth's gap is masked where the warp puts it (0.89 / 0.97); a 7-px patch reads
0.91 / 0.97 (the fit 0.81 / 0.89): where the smile's field peaks, the patch's best
translation averages it over its pixels. The fit, which fits the muscles to every point
around, loses another tenth at both (given exact points it loses 0.03-0.08): at the corners
the tracker's reading holds a tenth and the fit (its priors, the muscles' reach) another; at
the brows the reading is 0.03 short and the fit makes it 0.13 (exact readings: 0.02).
"""

from __future__ import annotations

import time

import numpy as np

from myoface.analysis._fitkernels import vertex_normals
from myoface.analysis._lkkernels import OK, local_affines, track_points
from myoface.errors import MyofaceValueError
from myoface.facemesh import import_opencv

#: MediaPipe's outer eye corners (the inter-ocular distance that scales the tolerance)
EYE_CORNERS = (33, 263)
#: Lucas-Kanade stops at a step under this (px, at each level)
EPS_PX = 0.03
#: ... and at the levels above the image at a step under this (px of that level: the image's
#: level refines what they find)
COARSE_EPS_PX = 0.2
#: a frame's noise (:func:`_noise`) is read on every this many rows of its crop
NOISE_STRIDE = 4
#: :meth:`ModelFlow.prepare`'s crop reaches this much further than a patch needs around the
#: detector's points (px): the guess is the prediction moved as the detector moved, a few
#: px from the detector's point (else the crop is made again on the fit's thread)
PREPARED_SLACK_PX = 24
#: the point trackers of the fit's optical flow (:attr:`~myoface.analysis.weights.FitSettings.
#: flow`): ``"anchored"`` this module's, ``"chained"`` :class:`~myoface.analysis.flow.
#: FlowRefiner` (from the first frame, else from the previous one)
FLOW_METHODS = ("anchored", "chained")
#: the one ``myoface analyze --flow`` uses
FLOW_METHOD = "anchored"
#: the fit's tracker (:class:`~myoface.analysis.trackers.landmark_fit.FitTracker`) tracks frame
#: k from the fit of frame k - this (its pose and skin, and the detector's points on it): with
#: 2, frame k is tracked on a thread of its own while frame k - 1 is fitted (1: after it; the
#: same result, run to run, either way)
PREDICTION_LAG = 2
_LAST = object()  # (track()'s ``since`` by default: the frame tracked last)


def _cv2():
    return import_opencv("the model-anchored point tracker")


def mesh_neighbours(triangles, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """Each vertex's neighbours on the mesh (its one-ring) as CSR: ``(start (V + 1,),
    neighbours)``."""
    tri = np.asarray(triangles, dtype=np.int64)
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    e = np.concatenate([e, e[:, ::-1]])
    e = np.unique(e, axis=0)  # (sorted by the first vertex)
    start = np.searchsorted(e[:, 0], np.arange(n_vertices + 1))
    return start.astype(np.int64), np.ascontiguousarray(e[:, 1])


def _noise(flat, offsets, shapes, stride: int = 1) -> float:
    """The sensor's noise (grey levels, 1 sd) in a packed pyramid's level 0
    (:func:`_noise_image`)."""
    h, w = int(shapes[0, 0]), int(shapes[0, 1])
    return _noise_image(flat[offsets[0] : offsets[0] + h * w].reshape(h, w), stride)


def _noise_image(img, stride: int = 1) -> float:
    """The sensor's noise (grey levels, 1 sd) in an image, robustly: the median absolute
    second difference along rows (6 sigma^2 for white noise), which the face's smooth skin
    dominates; over every ``stride``-th row (a frame's crop: every 4th, ~10^4 differences,
    0.1 ms where every row took 0.7)."""
    img = np.asarray(img, dtype=np.float64)[:: max(int(stride), 1)]
    d = np.abs(img[:, :-2] - 2 * img[:, 1:-1] + img[:, 2:]).ravel()
    k = len(d) // 2
    if len(d) % 2:
        med = np.partition(d, k)[k]
    else:
        part = np.partition(d, (k - 1, k))
        med = 0.5 * (part[k - 1] + part[k])
    return float(1.4826 * med / np.sqrt(6.0))


def _margins(face):
    from myoface.face.lips import inner_lip_margins

    return inner_lip_margins(face)


def gap_vertices(face) -> np.ndarray:
    """The vertices whose patch takes in the mouth's gap once the lips part: the lips' inner
    margins (:func:`~myoface.face.lips.inner_lip_margins`; none for a face without them).
    On the known-warp clips the lower lip's inner margin, tracked, moved 0.06 of the warp
    (the patch's edge is the upper lip's, which stays)."""
    m = _margins(face)
    if m is None:
        return np.zeros(0, dtype=np.int64)
    return np.unique(np.concatenate([m[0], m[1]]))


def predicted(fit):
    """The model's prediction for the next frame of ``fit`` (a
    :class:`~myoface.analysis.modelfit.ModelFit`): its previous frame's pose and skin (V, 3),
    or None when it has no previous frame (the calibration frame's pose and the person's
    neutral are then the closest guess: :meth:`ModelFlow.track` takes them)."""
    prev = fit._prev
    if prev is None:
        return None
    return prev.pose, fit.shape(prev.contractions)


class ModelFlow:
    """The model-anchored point tracker (see the module's docstring).

    Parameters
    ----------
    window : the template's side, px (odd), at every pyramid level.
    levels : pyramid levels above the image.
    iterations : Lucas-Kanade steps per level at most.
    coarse_eps_px : the levels above the image stop at a step under this (px of the level;
        the image's at :data:`EPS_PX`).
    min_ncc : a point counts when its patch correlates with the template at least this much.
    tolerance : ... and it is within this many inter-ocular distances of where it was
        looked for.
    min_cos : ... and its surface's normal is within arccos(min_cos) of the view, in the
        calibration frame and in the prediction.
    highpass_sigma_px : the Gaussian blur taken out of the brightness first (0: none).
    huber : Huber's threshold, in mean absolute residuals of the patch.
    smooth_sigma_px : a Gaussian blur of the brightness first (0: none; 1 px made no
        difference on the degraded renders).
    fb_max_px : > 0: a point counts only where tracked back into the calibration frame it
        lands within this of its reference (0: not checked; off, see the module's docstring).
    min_ncc_rel, min_expected_ncc : ... or its correlation is at least ``min_ncc_rel`` times
        what a perfect match reaches through both frames' noise, where that is at least
        ``min_expected_ncc`` (0: ``min_ncc`` alone). Head-motion renders, head still / moving
        (skin mm): ``min_ncc`` 0.6 alone 0.81 / 1.23; with 0.7, 0.2: 0.76 / 1.22.
    """

    def __init__(self, window: int = 11, levels: int = 1, iterations: int = 6,
                 min_ncc: float = 0.6, tolerance: float = 0.15, min_cos: float = 0.25,
                 highpass_sigma_px: float = 4.0, huber: float = 1.5,
                 smooth_sigma_px: float = 0.0, fb_max_px: float = 0.0,
                 min_ncc_rel: float = 0.7, min_expected_ncc: float = 0.2,
                 coarse_eps_px: float = COARSE_EPS_PX):  # fmt: skip
        if int(window) < 5 or int(window) % 2 == 0 or int(levels) < 0 or int(iterations) < 1:
            raise MyofaceValueError(
                "ModelFlow needs an odd window >= 5, levels >= 0, iterations >= 1"
            )
        if not (-1 <= min_ncc < 1 and tolerance > 0 and -1 <= min_cos < 1 and huber > 0):
            raise MyofaceValueError(
                "ModelFlow needs min_ncc and min_cos in [-1, 1), tolerance > 0 and huber > 0"
            )
        self.window = int(window)
        self.levels = int(levels)
        self.iterations = int(iterations)
        self.min_ncc = float(min_ncc)
        self.tolerance = float(tolerance)
        self.min_cos = float(min_cos)
        self.highpass_sigma_px = float(highpass_sigma_px)
        self.huber = float(huber)
        self.smooth_sigma_px = float(smooth_sigma_px)
        self.fb_max_px = float(fb_max_px)
        self.min_ncc_rel = float(min_ncc_rel)
        self.min_expected_ncc = float(min_expected_ncc)
        self.coarse_eps_px = float(coarse_eps_px)
        #: counts over the frames tracked: points read against the calibration frame, points
        #: left at the detector's; and the tracker's own seconds (thread CPU)
        self.stats = {"frames": 0, "tracked": 0, "detector": 0, "cpu_s": 0.0}
        self._ref = None
        self._nbr = None
        self._last = None  # (detector's points, predicted points) of the previous frame

    # ------------------------------------------------------------------ set-up
    @property
    def calibrated(self) -> bool:
        return self._ref is not None

    def reset(self) -> None:
        """After a frame without a face: the next guess starts from the detector's point
        (the reference stays: it is the calibration frame's)."""
        self._last = None

    def _near(self, xy, box) -> np.ndarray:
        """Which points' patches (at any level) may reach the box ``(lo, hi)`` (None: none)."""
        if box is None:
            return np.zeros(len(xy), dtype=bool)
        r = (self.window // 2 + 2) * (1 << self.levels)
        return ((xy > box[0] - r) & (xy < box[1] + r)).all(axis=1)

    def _margin(self) -> int:
        return (self.window // 2 + 3) * (1 << self.levels) + 8

    def prepare(self, frame, points):
        """What of ``frame`` does not depend on the model's prediction, for :meth:`track`
        (its ``prepared``): the crop around the detector's ``points`` (V, 2+) px, grey, its
        blur (the high-pass's) and its noise. Thread-safe (reads only the settings): the fit's
        tracker makes it on the detector's thread, ahead of the fit. None without points."""
        if points is None or frame is None:
            return None
        pts = np.asarray(points, dtype=np.float64)[:, :2]
        if not np.isfinite(pts).all():
            return None
        m = self._margin() + PREPARED_SLACK_PX
        return self._crop(frame, pts.min(0) - m, pts.max(0) + m, noise=True)

    def _crop(self, frame, lo, hi, noise: bool = False):
        """The crop [lo, hi) of ``frame`` (clipped to it): ``(grey, low, origin, (lo, hi),
        noise, high)``: the grey levels (float32), their Gaussian blur of
        :attr:`highpass_sigma_px` (None without), the crop's first pixel, its box, (``noise``)
        the high-passed crop's noise (:func:`_noise`, every :data:`NOISE_STRIDE`-th row; the
        mouth's gap not taken out), and the crop high-passed (smoothed first with
        :attr:`smooth_sigma_px`). None for a crop under 8 px."""
        cv2 = _cv2()
        frame = np.asarray(frame)
        h, w = frame.shape[:2]
        x0, y0 = int(max(np.floor(lo[0]), 0)), int(max(np.floor(lo[1]), 0))
        x1, y1 = int(min(np.ceil(hi[0]), w)), int(min(np.ceil(hi[1]), h))
        if x1 - x0 < 8 or y1 - y0 < 8:
            return None
        crop = frame[y0:y1, x0:x1]
        if crop.ndim == 3:
            grey = cv2.cvtColor(np.ascontiguousarray(crop[..., :3]), cv2.COLOR_RGB2GRAY)
        else:
            grey = crop
        grey = grey.astype(np.float32)
        low = None
        if self.highpass_sigma_px > 0:
            low = cv2.GaussianBlur(grey, (0, 0), self.highpass_sigma_px)
        hp = grey
        if self.smooth_sigma_px > 0:
            hp = cv2.GaussianBlur(grey, (0, 0), self.smooth_sigma_px)
        if low is not None:
            hp = hp - low
        hp = hp.astype(np.float64)  # (the kernels' type; :meth:`_pyramid` changes it in place)
        nz = _noise_image(hp, NOISE_STRIDE) if noise else None
        box = (np.array([x0, y0], dtype=np.float64), np.array([x1, y1], dtype=np.float64))
        return grey, low, box[0], box, nz, hp

    def _pyramid(self, frame, lo, hi, polygon=None, prepared=None):
        """The crop [lo, hi) of ``frame`` (clipped to it), grey, high-passed, as a packed
        pyramid, and the mask of ``polygon`` (K, 2) px packed alike (1 inside: the mouth's
        gap; none: zeros): (flat, mask, offsets, shapes, origin). ``prepared``
        (:meth:`prepare`): its crop where it holds [lo, hi) (then larger; it is used up: its
        high-passed crop is changed in place), else made here."""
        cv2 = _cv2()
        crop = None
        if prepared is not None:
            blo, bhi = prepared[3]
            fh, fw = np.shape(frame)[:2]
            inside = (np.floor(np.maximum(lo, 0)) >= blo).all() and (
                np.ceil(np.minimum(hi, [fw, fh])) <= bhi
            ).all()
            if inside:
                crop = prepared
        if crop is None:
            crop = self._crop(frame, lo, hi)
            if crop is None:
                return None
        grey, low, origin, hp = crop[0], crop[1], crop[2], crop[5]
        x0, y0 = origin
        m0 = None
        if polygon is not None and len(polygon) >= 3:
            m0 = np.zeros(grey.shape, dtype=np.uint8)
            poly = np.round((np.asarray(polygon) - [x0, y0]) * 4).astype(np.int32)
            cv2.fillPoly(m0, [poly], 1, lineType=cv2.LINE_8, shift=2)
            # (the polygon's pixels are within its box: the mask is looked at only there)
            gh, gw = grey.shape
            bx0, by0 = np.maximum(np.floor(poly.min(0) / 4).astype(int) - 1, 0)
            bx1, by1 = np.minimum(np.ceil(poly.max(0) / 4).astype(int) + 2, [gw, gh])
            if bx1 <= bx0 or by1 <= by0 or not m0[by0:by1, bx0:bx1].any():
                m0 = None
        if m0 is not None:
            # the kept pixels' weights (1 but in the gap), made only where they are read:
            # the box, and with the high-pass the crop around it that its blur reads
            sx0, sy0, sx1, sy1 = bx0, by0, bx1, by1
            if low is not None:
                sig = self.highpass_sigma_px
                r = (int(round(sig * 8 + 1)) | 1) // 2
                ix0, iy0 = max(bx0 - r, 0), max(by0 - r, 0)
                ix1, iy1 = min(bx1 + r, gw), min(by1 + r, gh)
                sx0, sy0 = max(bx0 - 2 * r, 0), max(by0 - 2 * r, 0)
                sx1, sy1 = min(bx1 + 2 * r, gw), min(by1 + 2 * r, gh)
            keep = np.ones((sy1 - sy0, sx1 - sx0), dtype=np.float32)
            kbox = (slice(by0 - sy0, by1 - sy0), slice(bx0 - sx0, bx1 - sx0))
            keep[kbox] -= m0[by0:by1, bx0:bx1]
            if low is not None:
                # the gap's pixels out of the neighbourhood's mean (no halo around it): a
                # blur normalised by the kept pixels', which differs from the plain one
                # only within the kernel's reach (OpenCV's float kernel: 4 sigma) of the
                # gap, so it is computed on a crop twice that reach around the gap's box
                gs = grey[sy0:sy1, sx0:sx1]
                norm = cv2.GaussianBlur(gs * keep, (0, 0), sig) / np.maximum(
                    cv2.GaussianBlur(keep, (0, 0), sig), 1e-3
                )
                hp[iy0:iy1, ix0:ix1] += (
                    low[iy0:iy1, ix0:ix1] - norm[iy0 - sy0 : iy1 - sy0, ix0 - sx0 : ix1 - sx0]
                )
            # (the gap at the mean: what pyrDown mixes in is neutral)
            hp[by0:by1, bx0:bx1] *= keep[kbox]
        grey = hp
        levels = [grey]
        for _ in range(self.levels):
            if min(levels[-1].shape) < 16:
                break
            levels.append(cv2.pyrDown(levels[-1]))
        while len(levels) < self.levels + 1:  # (a tiny crop: coarse levels repeat the last)
            levels.append(levels[-1])
        shapes = np.array([lv.shape for lv in levels], dtype=np.int64)
        sizes = shapes[:, 0] * shapes[:, 1]
        offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
        if len(levels) == 1:
            flat = grey.ravel()
        else:
            flat = np.concatenate([lv.ravel() for lv in levels])  # (float64 already)
        if m0 is not None and len(levels) == 1:
            mask = np.zeros_like(flat)
            mask.reshape(grey.shape)[by0:by1, bx0:bx1] = m0[by0:by1, bx0:bx1]
        elif m0 is not None:
            # (each level written into the packed float64 array: no concatenation to copy)
            mask = np.empty_like(flat)
            ml = m0.astype(np.float32)
            mask[: sizes[0]] = ml.ravel()
            for k in range(1, len(levels)):
                ml = cv2.resize(ml, (int(shapes[k, 1]), int(shapes[k, 0])),
                                interpolation=cv2.INTER_AREA)  # fmt: skip
                mask[offsets[k] : offsets[k] + sizes[k]] = ml.ravel()
        else:
            mask = np.zeros_like(flat)
        return flat, mask, offsets, shapes, np.array([x0, y0], dtype=np.float64), crop[4]

    def _view(self, camera, pose, shape, triangles):
        """The vertices' pixels (V, 2) and how squarely each faces the camera (V,)."""
        pc = pose.apply(shape)
        n = vertex_normals(np.ascontiguousarray(shape, dtype=np.float64), triangles)
        n = n @ pose.rotation.T
        view = -pc / np.maximum(np.linalg.norm(pc, axis=1, keepdims=True), 1e-9)
        return camera.project(pc), (n * view).sum(1)

    def calibrate(self, image, camera, pose, shape, triangles, exclude=(), gap=None) -> None:
        """Take the reference: ``image`` (the calibration frame, RGB or grey) and where the
        calibrated neutral ``shape`` (V, 3) mm, head frame, at ``pose`` puts each vertex on it
        through ``camera``; ``triangles`` the mesh's (the neighbours of each vertex);
        ``exclude``: vertices never tracked (their patch is not the skin's: the lips' inner
        margins, whose patch takes in the mouth's gap); ``gap``: the vertices around the
        mouth's gap in order (upper inner margin, then the lower one back), whose polygon's
        pixels weigh nothing in any patch (in the calibration frame, and in each frame where
        the prediction puts it: the teeth and the dark of the mouth are not skin)."""
        tri = np.ascontiguousarray(np.asarray(triangles, dtype=np.int64))
        shape = np.asarray(shape, dtype=np.float64)
        uv, cos = self._view(camera, pose, shape, tri)
        m = self._margin()
        gap = None if gap is None else np.asarray(gap, dtype=np.int64)
        pyr = self._pyramid(image, uv.min(0) - m, uv.max(0) + m, None if gap is None else uv[gap])
        pyr = None if pyr is None else pyr[:5]
        if pyr is None:
            raise MyofaceValueError("the calibration frame has no face to take templates from")
        self._nbr = mesh_neighbours(tri, len(shape))
        usable = np.ones(len(shape), dtype=bool)
        usable[np.asarray(exclude, dtype=np.int64)] = False
        self._ref = {"uv": uv, "cos": cos, "pyr": pyr, "camera": camera, "tri": tri,
                     "pose": pose, "shape": shape, "usable": usable, "gap": gap,
                     "noise": _noise(pyr[0], pyr[2], pyr[3]),
                     "gap_box": None if gap is None else (uv[gap].min(0), uv[gap].max(0))}  # fmt: skip
        self._last = None

    @classmethod
    def of_fit(cls, image, fit, **kw) -> ModelFlow:
        """A tracker calibrated on ``fit``'s calibration (a calibrated
        :class:`~myoface.analysis.modelfit.ModelFit`) and its frame ``image``."""
        out = cls(**kw)
        face = fit.model.face
        margins = _margins(face)
        gap = None if margins is None else np.concatenate([margins[0], margins[1][::-1]])
        out.calibrate(
            image, fit.camera, fit.calibration.pose, fit.neutral + fit.identity_mm,
            face.triangles, exclude=gap_vertices(face), gap=gap,
        )  # fmt: skip
        # the fit compares each point with the model's motion over this tracker's window
        fit.set_flow_footprint(out.window // 2)
        return out

    # ------------------------------------------------------------------ tracking
    def track(self, image, points, prediction=None, prepared=None, since=_LAST):
        """Where each vertex's skin point is on ``image``: ``(xy (V, 2), ok (V,) bool)``,
        ``xy`` the tracked position where ``ok``, the detector's ``points`` (V, 2+) elsewhere;
        None (and the guesses start again) without points. ``prediction``: ``(pose, shape)``
        of the model on this frame (:func:`predicted`: the fit's previous frame, or an earlier
        one's); None: the calibration's pose and neutral. ``prepared``: :meth:`prepare` of
        ``image`` and ``points`` (made on another thread; None: made here). ``since``: the
        detector's points (V, 2+) on the frame the prediction is of (the guess is the
        prediction moved as they moved since; None: the prediction itself); by default the
        points of the frame this tracker tracked last (None after :meth:`reset`): the
        previous frame's. With ``since`` given the call reads nor changes any state of the
        tracker's but its counts: the fit's tracker calls it on a thread of its own
        (:data:`PREDICTION_LAG`)."""
        if self._ref is None:
            raise MyofaceValueError("ModelFlow.track() needs calibrate() first")
        if points is None or image is None:
            self.reset()
            return None
        pts = np.asarray(points, dtype=np.float64)[:, :2]
        if not np.isfinite(pts).all():
            self.reset()
            return None
        t0 = time.thread_time()
        ref = self._ref
        if prediction is None:
            pose, shape = ref["pose"], ref["shape"]
        else:
            pose, shape = prediction
        uv, cos = self._view(ref["camera"], pose, np.asarray(shape, dtype=np.float64), ref["tri"])
        # the guess: the prediction's point moved as the detector's moved since the frame
        # predicted from (the detector's point itself without a prediction)
        explicit = since is not _LAST
        if not explicit:
            since = None if self._last is None else self._last[0]
        if prediction is None:
            guess = pts.copy()
        elif since is not None:
            guess = uv + (pts - np.asarray(since, dtype=np.float64)[:, :2])
        else:
            guess = uv
        amap, cond = local_affines(ref["uv"], uv, *self._nbr)
        det = amap[:, 0, 0] * amap[:, 1, 1] - amap[:, 0, 1] * amap[:, 1, 0]
        active = ref["usable"] & (cos > self.min_cos) & (ref["cos"] > self.min_cos) & (cond > 0.05)
        active &= (det > 0.2) & (det < 5.0)
        safe = np.where(np.abs(det) > 1e-9, det, 1.0)
        ainv = np.empty_like(amap)
        ainv[:, 0, 0] = amap[:, 1, 1] / safe
        ainv[:, 0, 1] = -amap[:, 0, 1] / safe
        ainv[:, 1, 0] = -amap[:, 1, 0] / safe
        ainv[:, 1, 1] = amap[:, 0, 0] / safe
        m = self._margin()
        gap = ref["gap"]
        gap_box = None if gap is None else (uv[gap].min(0), uv[gap].max(0))
        pyr = self._pyramid(
            image, guess.min(0) - m, guess.max(0) + m, None if gap is None else uv[gap],
            prepared,
        )  # fmt: skip
        ok = np.zeros(len(pts), dtype=bool)
        xy = pts.copy()
        if pyr is not None:
            rflat, rmask, roff, rshape, rorg = ref["pyr"]
            cflat, cmask, coff, cshape, corg, cnoise = pyr
            # (the mask is looked up only in the patches that may reach it)
            masked = self._near(ref["uv"], ref["gap_box"]) | self._near(guess, gap_box)
            q, ncc, contrast, step, status, _ = track_points(
                rflat, rmask, roff, rshape, cflat, cmask, coff, cshape,
                np.ascontiguousarray(ref["uv"] - rorg), np.ascontiguousarray(guess - corg),
                np.ascontiguousarray(ainv), active, masked, self.window // 2,
                self.iterations, self.huber, EPS_PX, self.coarse_eps_px,
            )  # fmt: skip
            q = q + corg
            if len(pts) > max(EYE_CORNERS):
                scale = float(np.linalg.norm(uv[EYE_CORNERS[0]] - uv[EYE_CORNERS[1]]))
            else:
                scale = 0.4 * float(np.ptp(uv[:, 0]))
            if self.min_ncc_rel > 0:
                # the correlation a perfect match reaches through both frames' noise
                nr, nc = (
                    ref["noise"] ** 2,
                    (_noise(cflat, coff, cshape, NOISE_STRIDE) if cnoise is None else cnoise) ** 2,
                )
                c2 = np.maximum(contrast - nr, 0.0)
                expected = c2 / np.sqrt(np.maximum((c2 + nr) * (c2 + nc), 1e-12))
                good = (ncc >= self.min_ncc_rel * expected) & (expected >= self.min_expected_ncc)
                good |= ncc >= self.min_ncc
            else:
                good = ncc >= self.min_ncc
            ok = (status == OK) & good & (step < 0.5)
            ok &= np.linalg.norm(q - guess, axis=1) < self.tolerance * scale
            if self.fb_max_px > 0 and ok.any():
                # back: the patch found, seen through the inverse map, looked for in the
                # calibration frame from where the forward correction puts it
                back_guess = ref["uv"] + np.einsum("vij,vj->vi", ainv, q - guess)
                back, _, _, _, st2, _ = track_points(
                    cflat, cmask, coff, cshape, rflat, rmask, roff, rshape,
                    np.ascontiguousarray(q - corg), np.ascontiguousarray(back_guess - rorg),
                    np.ascontiguousarray(amap), ok, masked, self.window // 2,
                    self.iterations, self.huber, EPS_PX, self.coarse_eps_px,
                )  # fmt: skip
                ok &= st2 == OK
                ok &= np.linalg.norm(back + rorg - ref["uv"], axis=1) < self.fb_max_px
            xy[ok] = q[ok]
        if not explicit:
            self._last = (pts.copy(), uv)
        self.stats["frames"] += 1
        self.stats["tracked"] += int(ok.sum())
        self.stats["detector"] += int((~ok).sum())
        self.stats["cpu_s"] += time.thread_time() - t0
        return xy, ok
