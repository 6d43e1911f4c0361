"""The head reference frame: the rigid motion of the head in the image plane, per frame.

The paper (T&W 1993, Section V-C) takes the head's translation from the hairline contour.
A real face also moves towards and away from the camera and tilts; the features' motion then
holds a change of scale and rotation that no muscle made. :class:`HeadTracker` estimates a 2-D
similarity (scale, rotation, translation) that maps the calibration frame's region of the upper
face (hair, forehead, eyes, nose) onto the current frame, by Gauss-Newton image registration
(Lucas & Kanade 1981; the inverse-compositional form of Baker & Matthews 2004) on a
two-level pyramid, with Tukey-biweight weights so that blinking eyes and moving brows count
as outliers rather than as head motion. Feature points are mapped back through the inverse
similarity before their displacements are read as muscle action.

A similarity is stored as ``(s, theta, tx, ty)``: ``x' = s R(theta) (x - c) + c + t`` with
``c`` the region's centre in the calibration frame.

Each frame is registered on a window around where the region was on the last one (its size
plus a margin for the motion between two frames), not on the whole frame. A registration that
fails (its residual as large as the region's own texture, i.e. the registered region correlates
with the calibration's by less than :data:`LOST_CORRELATION`, or the region leaving the frame:
:meth:`HeadTracker.lost`) is retried from a search of the whole frame for the region
(normalised cross-correlation at a coarse scale, :meth:`HeadTracker.search`), which also finds
the face again after it was lost. A face found by the search must match the calibration's more
closely, in its fine detail too (:data:`FOUND_CORRELATION`, :data:`FOUND_DETAIL`): a
registration of four parameters reaches a correlation of about 0.6 on unrelated images (a
cartoon), but not in their detail.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy import ndimage

from myoface.analysis.potentials import to_intensity
from myoface.errors import MyofaceValueError


@dataclass(frozen=True)
class Similarity:
    """``x' = s R(theta) (x - c) + c + t`` on (x, y) pixel coordinates."""

    s: float = 1.0
    theta: float = 0.0
    t: tuple = (0.0, 0.0)
    c: tuple = (0.0, 0.0)

    def matrix(self) -> np.ndarray:
        co, si = np.cos(self.theta), np.sin(self.theta)
        return self.s * np.array([[co, -si], [si, co]])

    def apply(self, pts) -> np.ndarray:
        p = np.asarray(pts, dtype=np.float64)
        c = np.asarray(self.c)
        return (p - c) @ self.matrix().T + c + np.asarray(self.t)

    def inverse_apply(self, pts) -> np.ndarray:
        p = np.asarray(pts, dtype=np.float64)
        c = np.asarray(self.c)
        return (p - c - np.asarray(self.t)) @ np.linalg.inv(self.matrix()).T + c

    def relative_to(self, prev: Similarity) -> tuple[np.ndarray, np.ndarray]:
        """(A, b) of the map from ``prev``'s image to this one's: x -> A x + b."""
        a = self.matrix() @ np.linalg.inv(prev.matrix())
        b = self.apply(np.zeros(2)) - a @ prev.apply(np.zeros(2))
        return a, b


def _params_to_affine(p):
    """p = (a, b, tx, ty): x' = [[1 + a, -b], [b, 1 + a]] x + t (centred coordinates)."""
    return np.array([[1 + p[0], -p[1]], [p[1], 1 + p[0]]]), np.array([p[2], p[3]])


#: the registration has lost the face when the registered region correlates with the
#: calibration's by less than this (its residual as large as the texture's own spread: 2 (1 -
#: 0.5) = 1 in units of the texture's variance). Measured: 0.61-1.0 through the sample video's
#: smile (the eyes narrow and the cheeks rise inside the region), at most 0.47 when a cartoon
#: frame is registered from the last face's pose, 0.0 on a black frame
LOST_CORRELATION = 0.5
#: a face found by the search must correlate by this much, and by FOUND_DETAIL in its fine
#: detail (the band-pass DoG image): measured, a cartoon frame reaches 0.54-0.63 after the
#: registration but at most 0.08 in its detail; the sample face 0.06-0.99 (the lowest in a
#: blink)
FOUND_CORRELATION = 0.6
FOUND_DETAIL = 0.3
#: ... or this fraction of the region lies outside the frame
LOST_OUTSIDE = 0.25
#: ... or its scale changed by more than this factor from the calibration frame
LOST_SCALE = 2.0
#: the window of a frame that is registered: the region's box grown by this fraction of its
#: size on each side (the head's motion between two frames)
WINDOW_MARGIN = 0.3
#: the whole-frame search: the coarse scale's pixel size (px of the region's width / this) and
#: the scales tried around the last one
SEARCH_WIDTH_PX = 32
#: the region is sampled every this many pixels on the fine level (twice that on the coarse
#: one): the image is blurred by ``sigma`` = 1.5 px first, so every other pixel carries about
#: all it shows, at a quarter of the cost
SAMPLE_PX = 2
#: the registration has converged when a Gauss-Newton step moves no point of the region by more
#: than this (px); on the coarse level, by more than CONVERGED_PX_COARSE
CONVERGED_PX = 0.05
CONVERGED_PX_COARSE = 0.1
SEARCH_SCALES = (0.8, 1.0, 1.25)


@njit(cache=True, nogil=True)
def _robust_normal_equations(img, pts, tmpl, sd, warped):
    """One robust Gauss-Newton system of the registration: ``img`` (H, W) sampled bilinearly
    at ``pts`` (N, 2) (x, y) into ``warped`` (N,) (clamped to the image, as
    ``map_coordinates(mode="nearest")``), the residual against ``tmpl`` (N,) less its median
    (a global brightness change), Tukey's biweight at 4.685 robust scales (1.4826 x the median
    absolute residual, at least 1 grey level; medians over every 4th point), and the weighted
    normal equations ``(sd' W sd, sd' W r)`` of the steepest-descent images ``sd`` (N, P).
    Returns ``(H (P, P), g (P,), scale)``."""
    h, w = img.shape
    n, npar = sd.shape
    for i in range(n):
        x = min(max(pts[i, 0], 0.0), w - 1.0)
        y = min(max(pts[i, 1], 0.0), h - 1.0)
        x0 = min(int(x), w - 2)
        y0 = min(int(y), h - 2)
        fx, fy = x - x0, y - y0
        warped[i] = (img[y0, x0] * (1 - fx) + img[y0, x0 + 1] * fx) * (1 - fy) + (
            img[y0 + 1, x0] * (1 - fx) + img[y0 + 1, x0 + 1] * fx
        ) * fy
    r = warped - tmpl
    sub = r[::4].copy()
    r -= np.median(sub)
    scale = max(1.4826 * np.median(np.abs(r[::4])) + 1e-6, 1.0)
    k = 4.685 * scale
    hm = np.zeros((npar, npar))
    g = np.zeros(npar)
    for i in range(n):
        u = r[i] / k
        if abs(u) >= 1.0:
            continue
        wt = (1.0 - u * u) ** 2
        for a in range(npar):
            va = wt * sd[i, a]
            g[a] += va * r[i]
            for b in range(a, npar):
                hm[a, b] += va * sd[i, b]
    for a in range(npar):
        for b in range(a):
            hm[a, b] = hm[b, a]
    return hm, g, scale


class HeadTracker:
    """Registers a rigid region of the calibration frame to each new frame.

    Parameters
    ----------
    frame0 : the calibration frame (H, W[, 3]).
    box : (x0, y0, x1, y1) pixels, the region of the upper face to register (see
        :func:`head_box`).
    sigma : Gaussian pre-smoothing, pixels.
    """

    def __init__(self, frame0, box, sigma: float = 1.5, levels: int = 2, iterations: int = 30):
        img = to_intensity(frame0)
        h, w = img.shape
        x0, y0, x1, y1 = (float(v) for v in box)
        x0, y0 = max(x0, 2.0), max(y0, 2.0)
        x1, y1 = min(x1, w - 3.0), min(y1, h - 3.0)
        if x1 - x0 < 8 or y1 - y0 < 8:
            raise MyofaceValueError(f"the head region {box} is too small or outside the image")
        self.box = (x0, y0, x1, y1)
        self.c = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
        self.sigma = float(sigma)
        self.levels = int(levels)
        self.iterations = int(iterations)
        self.shape = (h, w)
        self._templates = []
        # the region itself, blurred to the coarse scale of the whole-frame search
        self._search_pixel = max((x1 - x0) / SEARCH_WIDTH_PX, 1.0)
        self._search_template = ndimage.gaussian_filter(img, 0.5 * self._search_pixel)[
            int(np.ceil(y0)) : int(y1) + 1, int(np.ceil(x0)) : int(x1) + 1
        ]
        for lev in range(self.levels):
            f = 2**lev
            sm = ndimage.gaussian_filter(img, self.sigma * f)
            ys = np.arange(y0, y1 + 1e-9, SAMPLE_PX * f)
            xs = np.arange(x0, x1 + 1e-9, SAMPLE_PX * f)
            gx, gy = np.meshgrid(xs, ys)
            pts = np.stack([gx.ravel(), gy.ravel()], 1)
            t = ndimage.map_coordinates(sm, [pts[:, 1], pts[:, 0]], order=1)
            dy, dx = np.gradient(sm)
            ix = ndimage.map_coordinates(dx, [pts[:, 1], pts[:, 0]], order=1)
            iy = ndimage.map_coordinates(dy, [pts[:, 1], pts[:, 0]], order=1)
            q = pts - self.c
            # steepest-descent images for p = (a, b, tx, ty) at the identity
            sd = np.stack([ix * q[:, 0] + iy * q[:, 1], -ix * q[:, 1] + iy * q[:, 0], ix, iy], 1)
            self._templates.append((q, t, sd))
        self._radius = [float(np.abs(tq[0]).max()) for tq in self._templates]
        q0, _, sd0 = self._templates[0]
        # steepest-descent images of the region's scalings along its own x and y axes
        self._sd_axes = np.ascontiguousarray(
            np.stack([sd0[:, 2] * q0[:, 0], sd0[:, 3] * q0[:, 1]], 1)
        )
        self._detail_template = ndimage.map_coordinates(
            _detail(img, self.sigma), [q0[:, 1] + self.c[1], q0[:, 0] + self.c[0]], order=1
        )
        self.current = Similarity(c=tuple(self.c))
        self.residual = 0.0  # the robust scale of the last registration's residual, grey levels
        self.correlation = 1.0  # the last registered region's correlation with the calibration's
        self.foreshortening = 1.0  # its width over its height, relative to the calibration's

    def corners(self, sim: Similarity | None = None) -> np.ndarray:
        """The region's corners (4, 2) in the frame under ``sim`` (default: the current one)."""
        x0, y0, x1, y1 = self.box
        return (self.current if sim is None else sim).apply(
            np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
        )

    def outside_fraction(self, sim: Similarity | None = None) -> float:
        """About how much of the region lies outside the frame under ``sim`` (its bounding
        box's share outside)."""
        c = self.corners(sim)
        h, w = self.shape
        lo, hi = c.min(0), c.max(0)
        area = max(float(np.prod(hi - lo)), 1e-9)
        inside = np.clip(np.minimum(hi, (w - 1, h - 1)) - np.maximum(lo, 0), 0, None)
        return 1.0 - float(np.prod(inside)) / area

    def lost(self, sim: Similarity | None = None, correlation: float | None = None) -> str | None:
        """Why the registration ``sim`` (default: the current one) whose region correlates
        with the calibration's by ``correlation`` (default: the last registration's) does not
        hold the face, or None when it does."""
        sim = self.current if sim is None else sim
        r = self.correlation if correlation is None else correlation
        if not np.isfinite([sim.s, sim.theta, *sim.t]).all():
            return "diverged"
        if not 1 / LOST_SCALE <= sim.s <= LOST_SCALE:
            return "scale"
        if self.outside_fraction(sim) > LOST_OUTSIDE:
            return "outside"
        if not r >= LOST_CORRELATION:
            return "unlike"
        return None

    def detail_correlation(self, frame, sim: Similarity | None = None) -> float:
        """The correlation of the region's fine detail (band-pass, difference of Gaussians)
        under ``sim`` (default: the current one) with the calibration's."""
        sim = self.current if sim is None else sim
        x0, y0, x1, y1 = self._window(sim, 0.05)
        d = _detail(to_intensity(np.asarray(frame)[y0 : y1 + 1, x0 : x1 + 1]), self.sigma)
        q0 = self._templates[0][0]
        pts = sim.apply(q0 + self.c) - (x0, y0)
        w = ndimage.map_coordinates(d, [pts[:, 1], pts[:, 0]], order=1, mode="nearest")
        return _correlation(w, self._detail_template)

    def _window(self, sim: Similarity, margin: float):
        """The frame window (x0, y0, x1, y1), integers, around the region under ``sim``."""
        c = self.corners(sim)
        lo, hi = c.min(0), c.max(0)
        pad = margin * (hi - lo).max() + 3 * self.sigma * 2 ** (self.levels - 1) + 2
        h, w = self.shape
        x0, y0 = (int(max(np.floor(v - pad), 0)) for v in lo)
        x1 = int(min(np.ceil(hi[0] + pad), w - 1))
        y1 = int(min(np.ceil(hi[1] + pad), h - 1))
        return x0, y0, max(x1, x0 + 4), max(y1, y0 + 4)

    def track(self, frame, start: Similarity | None = None) -> Similarity:
        """The similarity from the calibration frame to ``frame``, starting from ``start``
        (default: the last one). Sets :attr:`residual`, :attr:`correlation` and
        :attr:`foreshortening`; see :meth:`lost`.

        From the last frame's similarity only the fine level is registered (the head moves
        a few pixels between frames); the coarse-to-fine pyramid runs from a given ``start``,
        and again when the fine level alone did not converge or lost the face."""
        frame = np.asarray(frame)
        if frame.shape[:2] != self.shape:
            raise MyofaceValueError(
                f"frame size {frame.shape[:2]} differs from the first {self.shape}"
            )
        pyramid = start is not None
        start = self.current if start is None else start
        if self.lost(start, 1.0) in ("diverged", "scale"):
            start, pyramid = Similarity(c=tuple(self.c)), True
        x0, y0, x1, y1 = self._window(start, WINDOW_MARGIN)
        img = to_intensity(frame[y0 : y1 + 1, x0 : x1 + 1])
        org = np.array([x0, y0], dtype=np.float64)
        smooth = {}
        levels = list(reversed(range(self.levels))) if pyramid else [0]
        m, t, ok = self._register(img, org, smooth, start, levels)
        corr = self._fine_correlation(smooth, org, m, t)
        if not pyramid and (not ok or corr < LOST_CORRELATION):
            m, t, _ = self._register(img, org, smooth, start, list(reversed(range(self.levels))))
            corr = self._fine_correlation(smooth, org, m, t)
        # how much the registered region looks like the calibration's (finest level)
        self.correlation = corr
        q, tmpl, _ = self._templates[0]
        sm = smooth[0]
        warped = np.empty(len(q))
        # the region's horizontal foreshortening, x -> S(c + diag(kx, ky) (x - c)): the region
        # scaled along its own axes on top of the similarity, (kx, ky) by Gauss-Newton
        # (inverse compositional); a head turned by yaw about its vertical axis shows its face
        # kx / ky ~ cos(yaw) narrower than it is tall
        sd_k = self._sd_axes
        kxy = np.ones(2)
        for _ in range(2):
            pts = (q * kxy) @ m.T + (self.c + t - org)
            hk, gk, _ = _robust_normal_equations(sm, pts, tmpl, sd_k, warped)
            try:
                dk = np.linalg.solve(hk + 1e-9 * np.eye(2), gk)
            except np.linalg.LinAlgError:
                break
            kxy = kxy / (1.0 + dk)
        self.foreshortening = float(kxy[0] / kxy[1])
        s = float(np.sqrt(abs(np.linalg.det(m))))
        theta = float(np.arctan2(m[1, 0], m[0, 0]))
        self.current = Similarity(s, theta, (float(t[0]), float(t[1])), tuple(self.c))
        return self.current

    def _smoothed(self, img, smooth: dict, lev: int) -> np.ndarray:
        if lev not in smooth:
            smooth[lev] = ndimage.gaussian_filter(img, self.sigma * 2**lev)
        return smooth[lev]

    def _fine_correlation(self, smooth, org, m, t) -> float:
        q, tmpl, sd = self._templates[0]
        warped = np.empty(len(q))
        _robust_normal_equations(smooth[0], q @ m.T + (self.c + t - org), tmpl, sd, warped)
        return _correlation(warped, tmpl)

    def _register(self, img, org, smooth, start: Similarity, levels):
        """Gauss-Newton registration (inverse compositional, robust) of the region on the
        window ``img`` (its origin ``org`` in the frame) over ``levels`` from ``start``:
        ``(matrix, t, converged)``."""
        m = start.matrix()
        t = np.asarray(start.t, dtype=np.float64)
        converged = False
        for lev in levels:
            q, tmpl, sd = self._templates[lev]
            sm = self._smoothed(img, smooth, lev)
            warped = np.empty(len(q))
            scale = 1.0
            converged = False
            for _ in range(self.iterations):
                pts = q @ m.T + (self.c + t - org)
                h, g, scale = _robust_normal_equations(sm, pts, tmpl, sd, warped)
                try:
                    dp = np.linalg.solve(h + 1e-9 * np.eye(4), g)
                except np.linalg.LinAlgError:
                    break
                # inverse composition: W(x; p) <- W(x; p) o W(x; dp)^-1
                da, db = _params_to_affine(dp)
                dai = np.linalg.inv(da)
                t = t - m @ dai @ db
                m = m @ dai
                # converged when the step moves no point of the region by more than
                # CONVERGED_PX (CONVERGED_PX_COARSE on the coarse level, which only has to
                # bring the fine one close)
                move = np.abs(dp[2:]).max() + np.abs(dp[:2]).max() * self._radius[lev]
                if move < (CONVERGED_PX if lev == 0 else CONVERGED_PX_COARSE):
                    converged = True
                    break
            self.residual = float(scale)
        return m, t, converged

    def search(self, frame, scale: float | None = None) -> Similarity | None:
        """Find the region anywhere in ``frame``: normalised cross-correlation of the
        calibration region over the whole frame at a coarse scale (the region about
        :data:`SEARCH_WIDTH_PX` wide), at :data:`SEARCH_SCALES` around ``scale`` (default:
        the current one), then the registration from the best match. Returns the
        similarity when it holds the face (:meth:`lost` is None; it becomes the current
        one), else None (the current one is kept)."""
        img = to_intensity(frame)
        if img.shape != self.shape:
            raise MyofaceValueError(f"frame size {img.shape} differs from the first {self.shape}")
        f = self._search_pixel
        coarse = ndimage.zoom(ndimage.gaussian_filter(img, 0.5 * f), 1 / f, order=1)
        if scale is None:
            scale = self.current.s if 1 / LOST_SCALE <= self.current.s <= LOST_SCALE else 1.0
        best = (-np.inf, None)
        for k in SEARCH_SCALES:
            sc = scale * k
            tm = ndimage.zoom(self._search_template, sc / f, order=1)
            if (
                min(tm.shape) < 4
                or tm.shape[0] >= coarse.shape[0]
                or tm.shape[1] >= coarse.shape[1]
            ):
                continue
            ncc = _ncc(coarse, tm)
            iy, ix = np.unravel_index(int(np.argmax(ncc)), ncc.shape)
            if ncc[iy, ix] > best[0]:
                # where the region's centre is in the frame
                centre = (np.array([ix, iy]) + 0.5 * (np.array(tm.shape[::-1]) - 1)) * f
                best = (float(ncc[iy, ix]), (sc, centre))
        if best[1] is None:
            return None
        sc, centre = best[1]
        # x' = s R (x - c) + c + t puts the centre c at c + t
        t = centre - self.c
        theta = self.current.theta if np.isfinite(self.current.theta) else 0.0
        keep = self.current, self.residual, self.correlation
        sim = self.track(frame, Similarity(sc, theta, (float(t[0]), float(t[1])), tuple(self.c)))
        if (
            self.lost() is not None
            or self.correlation < FOUND_CORRELATION
            or self.detail_correlation(frame) < FOUND_DETAIL
        ):
            self.current, self.residual, self.correlation = keep
            return None
        return sim


def _detail(img: np.ndarray, sigma: float) -> np.ndarray:
    """The band-pass detail of an image: its difference of Gaussians at ``sigma`` and 3
    ``sigma``."""
    return ndimage.gaussian_filter(img, sigma) - ndimage.gaussian_filter(img, 3 * sigma)


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    """Pearson correlation of two samples (0 when either is flat)."""
    a = a - a.mean()
    b = b - b.mean()
    den = np.sqrt((a * a).sum() * (b * b).sum())
    return float((a * b).sum() / den) if den > 0 else 0.0


def _ncc(img: np.ndarray, tm: np.ndarray) -> np.ndarray:
    """Normalised cross-correlation (Lewis 1995) of template ``tm`` (h, w) at every position
    of ``img`` (H, W) where it fits: (H - h + 1, W - w + 1), in [-1, 1]."""
    from scipy.signal import fftconvolve

    h, w = tm.shape
    t = tm - tm.mean()
    tn = np.sqrt((t * t).sum())
    num = fftconvolve(img, t[::-1, ::-1], mode="valid")
    ii = np.pad(img, ((1, 0), (1, 0))).cumsum(0).cumsum(1)
    ii2 = np.pad(img * img, ((1, 0), (1, 0))).cumsum(0).cumsum(1)

    def box(a):
        return a[h:, w:] - a[:-h, w:] - a[h:, :-w] + a[:-h, :-w]

    s1, s2 = box(ii), box(ii2)
    var = np.maximum(s2 - s1 * s1 / (h * w), 0.0)
    return num / np.maximum(np.sqrt(var) * tn, 1e-9 * max(tn, 1e-12))


def head_box(contours: dict, image_shape) -> tuple[float, float, float, float]:
    """The registration region from the calibration contours: from just below the brows down
    to the nose base, as wide as the brows (eyes, nose bridge and upper cheeks). The forehead
    and brows are left out because the frontalis moves them (a region that included them
    mistook brow raises for head motion in the closed-loop test), and so are the mouth, lower
    cheeks and jaw."""
    brows = [contours[k] for k in ("eyebrow_r", "eyebrow_l") if k in contours]
    nose = contours.get("nose")
    if not brows or nose is None:
        raise MyofaceValueError("the head frame needs the eyebrow and nose contours")
    b = np.concatenate(brows)
    x0, x1 = b[:, 0].min(), b[:, 0].max()
    brow_low, bottom = b[:, 1].max(), nose[:, 1].max()
    top = brow_low + 0.1 * (bottom - brow_low)
    if bottom - top < 4 or x1 - x0 < 8:
        raise MyofaceValueError("the face is too small for the head frame (brows to nose)")
    h, w = image_shape[:2]
    return (max(0.0, x0), max(0.0, top), min(w - 1.0, x1), min(h - 1.0, bottom))
