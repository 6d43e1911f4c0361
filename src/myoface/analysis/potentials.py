"""Image potentials for deformable contours (Terzopoulos & Waters 1993, eq. (13)).

Images are 2-D arrays indexed ``[row, column]``; contour nodes are (x, y) = (column, row) in
pixels, pixel centres at integer coordinates. Intensities are grey levels on the 8-bit scale
(0-255) whatever the input dtype, so the paper's image-force strength p = 0.001 keeps its
meaning. Colour frames are reduced to intensity with the Rec. 601 luma weights
(0.299 R + 0.587 G + 0.114 B).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from myoface.errors import MyofaceValueError

LUMA_601 = (0.299, 0.587, 0.114)
METHODS = ("gaussian", "paper", "line+edge", "line")


def to_intensity(image) -> np.ndarray:
    """(H, W) float64 grey levels on the 0-255 scale from (H, W) or (H, W, 3|4) input.

    uint8 is taken as is; other integer types are scaled from their range; floats are taken
    as 0-1 if their maximum is at most 1, else as 0-255.
    """
    a = np.asarray(image)
    if a.ndim == 3 and a.shape[2] in (3, 4):
        rgb = a[:, :, :3].astype(np.float64)
        a_f = rgb @ np.asarray(LUMA_601)
        src = a.dtype
    elif a.ndim == 2:
        a_f = a.astype(np.float64)
        src = a.dtype
    else:
        raise MyofaceValueError(f"an image must be (H, W) or (H, W, 3); got shape {a.shape}")
    if a_f.size == 0 or min(a_f.shape) < 3:
        raise MyofaceValueError(f"the image is empty or too small: {a.shape}")
    if not np.isfinite(a_f).all():
        raise MyofaceValueError("the image contains NaN or Inf")
    if np.issubdtype(src, np.integer) and src != np.uint8:
        a_f = a_f * (255.0 / np.iinfo(src).max)
    elif np.issubdtype(src, np.floating) and a_f.max() <= 1.0:
        a_f = a_f * 255.0
    return a_f


@njit(cache=True, parallel=True)
def _blur_separable(img, kernel, out, tmp):
    """Separable correlation with ``kernel`` (odd length), edges replicated."""
    h, w = img.shape
    r = kernel.shape[0] // 2
    for y in prange(h):
        for x in range(w):
            s = 0.0
            if r <= x < w - r:
                for k in range(-r, r + 1):
                    s += kernel[k + r] * img[y, x + k]
            else:
                for k in range(-r, r + 1):
                    s += kernel[k + r] * img[y, min(max(x + k, 0), w - 1)]
            tmp[y, x] = s
    for y in prange(h):
        if r <= y < h - r:
            for x in range(w):
                out[y, x] = 0.0
            for k in range(-r, r + 1):
                kk = kernel[k + r]
                for x in range(w):
                    out[y, x] += kk * tmp[y + k, x]
        else:
            for x in range(w):
                s = 0.0
                for k in range(-r, r + 1):
                    s += kernel[k + r] * tmp[min(max(y + k, 0), h - 1), x]
                out[y, x] = s


@njit(cache=True, parallel=True)
def _neg_grad_mag_central(img, out):
    h, w = img.shape
    for y in prange(h):
        for x in range(w):
            gx = 0.5 * (img[y, min(x + 1, w - 1)] - img[y, max(x - 1, 0)])
            gy = 0.5 * (img[min(y + 1, h - 1), x] - img[max(y - 1, 0), x])
            out[y, x] = -np.sqrt(gx * gx + gy * gy)


@njit(cache=True)
def _paper_potential(img, out, tmp):
    """Two passes of 4-neighbour averaging, then -|forward-difference gradient|."""
    h, w = img.shape
    src = img.copy()
    for _ in range(2):
        for y in range(h):
            for x in range(w):
                tmp[y, x] = 0.25 * (
                    src[y, max(x - 1, 0)]
                    + src[y, min(x + 1, w - 1)]
                    + src[max(y - 1, 0), x]
                    + src[min(y + 1, h - 1), x]
                )
        src[:, :] = tmp
    for y in range(h):
        for x in range(w):
            gx = src[y, min(x + 1, w - 1)] - src[y, x]
            gy = src[min(y + 1, h - 1), x] - src[y, x]
            out[y, x] = -np.sqrt(gx * gx + gy * gy)


def gaussian_kernel(sigma: float) -> np.ndarray:
    r = max(1, int(np.ceil(3.0 * sigma)))
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
    return k / k.sum()


def image_potential(image, sigma: float = 2.0, method: str = "gaussian") -> np.ndarray:
    """The potential P (H, W) float64 whose ravines are the image's edges.

    ``"gaussian"``: eq. (13), ``P = -|grad(G_sigma * I)|`` (separable Gaussian, central
    differences; sigma in pixels widens the ravines so they attract from farther away).
    ``"paper"``: the variant of the paper's experiment (T&W 1993, Section V-E): two passes of
    4-neighbour averaging and the forward-difference gradient (``sigma`` is ignored).
    ``"line+edge"``: ``G_sigma * I - |grad(G_sigma * I)|``: eq. (13) plus the "line" term of
    Kass, Witkin & Terzopoulos (1988). Thin dark features (brows, furrows, pencilled lines) are
    ridges of eq. (13) (its ravines run along their two sides); with the intensity term their
    centre lines become the ravines.
    ``"line"``: ``G_sigma * I - G_(4 sigma) * I``, a difference of Gaussians (Marr & Hildreth
    1980): about 0 on smooth skin, negative along thin dark lines (furrows, pencilled lines)
    with its ravine on their centre line, so that an open contour on a line neither sits on
    one of its sides nor slides off its ends as it does on eq. (13).
    """
    if method not in METHODS:
        raise MyofaceValueError(f"method must be one of {METHODS}; got {method!r}")
    img = np.ascontiguousarray(to_intensity(image))
    out = np.empty_like(img)
    tmp = np.empty_like(img)
    if method == "paper":
        _paper_potential(img, out, tmp)
        return out
    if not (np.isfinite(sigma) and sigma > 0):
        raise MyofaceValueError(f"sigma must be > 0 pixels; got {sigma}")
    blurred = np.empty_like(img)
    _blur_separable(img, gaussian_kernel(float(sigma)), blurred, tmp)
    if method == "line":
        wide = np.empty_like(img)
        _blur_separable(img, gaussian_kernel(4.0 * float(sigma)), wide, tmp)
        np.subtract(blurred, wide, out=out)
        return out
    _neg_grad_mag_central(blurred, out)
    if method == "line+edge":
        out += blurred
    return out


def image_potential_numpy(image, sigma: float = 2.0) -> np.ndarray:
    """Reference for the ``"gaussian"`` potential with scipy.ndimage (for tests)."""
    from scipy.ndimage import correlate1d

    img = to_intensity(image)
    k = gaussian_kernel(float(sigma))
    b = correlate1d(correlate1d(img, k, axis=1, mode="nearest"), k, axis=0, mode="nearest")
    gy, gx = np.gradient(b)
    return -np.hypot(gx, gy)


@njit(cache=True, parallel=True)
def potential_gradient(pot, gx, gy):
    """Central-difference gradient of the potential (one-sided at the borders)."""
    h, w = pot.shape
    for y in prange(h):
        for x in range(w):
            x0, x1 = max(x - 1, 0), min(x + 1, w - 1)
            y0, y1 = max(y - 1, 0), min(y + 1, h - 1)
            gx[y, x] = (pot[y, x1] - pot[y, x0]) / max(x1 - x0, 1)
            gy[y, x] = (pot[y1, x] - pot[y0, x]) / max(y1 - y0, 1)


@njit(cache=True, inline="always")
def _cell(h, w, x, y):
    """Clamp (x, y) into the image; the cell's corner (x0, y0) and the fractions (fx, fy)."""
    if x < 0.0:
        x = 0.0
    elif x > w - 1.0:
        x = w - 1.0
    if y < 0.0:
        y = 0.0
    elif y > h - 1.0:
        y = h - 1.0
    x0 = min(int(x), w - 2) if w > 1 else 0
    y0 = min(int(y), h - 2) if h > 1 else 0
    return x0, y0, x - x0, y - y0


@njit(cache=True, inline="always")
def bilinear(img, x, y):
    """Bilinear sample of ``img`` at (x, y) = (column, row), clamped to the image."""
    x0, y0, fx, fy = _cell(img.shape[0], img.shape[1], x, y)
    a = img[y0, x0] * (1 - fx) + img[y0, x0 + 1] * fx
    b = img[y0 + 1, x0] * (1 - fx) + img[y0 + 1, x0 + 1] * fx
    return a * (1 - fy) + b * fy


@njit(cache=True, inline="always")
def bilinear2(ga, gb, x, y):
    """Bilinear samples of two same-shape images at (x, y), sharing the index arithmetic."""
    x0, y0, fx, fy = _cell(ga.shape[0], ga.shape[1], x, y)
    w00 = (1 - fx) * (1 - fy)
    w01 = fx * (1 - fy)
    w10 = (1 - fx) * fy
    w11 = fx * fy
    a = w00 * ga[y0, x0] + w01 * ga[y0, x0 + 1] + w10 * ga[y0 + 1, x0] + w11 * ga[y0 + 1, x0 + 1]
    b = w00 * gb[y0, x0] + w01 * gb[y0, x0 + 1] + w10 * gb[y0 + 1, x0] + w11 * gb[y0 + 1, x0 + 1]
    return a, b
