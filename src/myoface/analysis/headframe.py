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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
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


def _tukey(r, k):
    w = np.zeros_like(r)
    m = np.abs(r) < k
    w[m] = (1 - (r[m] / k) ** 2) ** 2
    return w


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
        for lev in range(self.levels):
            f = 2**lev
            sm = ndimage.gaussian_filter(img, self.sigma * f)
            ys = np.arange(y0, y1 + 1e-9, f)
            xs = np.arange(x0, x1 + 1e-9, f)
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
        self.current = Similarity(c=tuple(self.c))
        self.residual = 0.0

    def track(self, frame) -> Similarity:
        """The similarity from the calibration frame to ``frame``, starting from the last one."""
        img = to_intensity(frame)
        if img.shape != self.shape:
            raise MyofaceValueError(f"frame size {img.shape} differs from the first {self.shape}")
        m = self.current.matrix()
        t = np.asarray(self.current.t, dtype=np.float64)
        for lev in reversed(range(self.levels)):
            q, tmpl, sd = self._templates[lev]
            sm = ndimage.gaussian_filter(img, self.sigma * 2**lev)
            scale = 1.0
            for _ in range(self.iterations):
                pts = q @ m.T + self.c + t
                warped = ndimage.map_coordinates(
                    sm, [pts[:, 1], pts[:, 0]], order=1, mode="nearest"
                )
                r = warped - tmpl
                r = r - np.median(r)  # global brightness change
                mad = 1.4826 * np.median(np.abs(r)) + 1e-6
                scale = max(mad, 1.0)
                wgt = _tukey(r, 4.685 * scale)
                h = (sd * wgt[:, None]).T @ sd
                g = (sd * wgt[:, None]).T @ r
                try:
                    dp = np.linalg.solve(h + 1e-9 * np.eye(4), g)
                except np.linalg.LinAlgError:
                    break
                # inverse composition: W(x; p) <- W(x; p) o W(x; dp)^-1
                da, db = _params_to_affine(dp)
                dai = np.linalg.inv(da)
                t = t - m @ dai @ db
                m = m @ dai
                if np.abs(dp[2:]).max() < 0.01 and np.abs(dp[:2]).max() < 1e-4:
                    break
            self.residual = float(scale)
        s = float(np.sqrt(abs(np.linalg.det(m))))
        theta = float(np.arctan2(m[1, 0], m[0, 0]))
        self.current = Similarity(s, theta, (float(t[0]), float(t[1])), tuple(self.c))
        return self.current


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
