"""Image potentials for deformable contours (Terzopoulos & Waters 1993, eq. (13)).

Images are 2-D arrays indexed ``[row, column]``; contour nodes are (x, y) = (column, row) in
pixels, pixel centres at integer coordinates. Intensities are grey levels on the 8-bit scale
(0-255) whatever the input dtype, so the paper's image-force strength p = 0.001 keeps its
meaning. Colour frames are reduced to intensity with the Rec. 601 luma weights
(0.299 R + 0.587 G + 0.114 B).
"""

from __future__ import annotations

import types
from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from myoface.errors import MyofaceValueError

LUMA_601 = (0.299, 0.587, 0.114)
#: images up to this many pixels are filtered on one thread (see _blur_separable_1)
SERIAL_PIXELS = 200_000
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


def _blur_separable_py(img, kernel, out, tmp):
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


def _neg_grad_mag_central_py(img, out):
    h, w = img.shape
    for y in prange(h):
        for x in range(w):
            gx = 0.5 * (img[y, min(x + 1, w - 1)] - img[y, max(x - 1, 0)])
            gy = 0.5 * (img[min(y + 1, h - 1), x] - img[max(y - 1, 0), x])
            out[y, x] = -np.sqrt(gx * gx + gy * gy)


def _two_builds(fn):
    """``fn`` compiled twice: threads over its rows (``prange``) for whole frames, and on one
    thread for the small windows around a face's contours, where the threads' start-up and,
    on a busy machine, their waiting for each other cost more than the work (measured: 7x
    on a 200 x 240 window). The one-thread build gets its own name, so that numba's on-disk
    cache keeps the two apart."""
    one = types.FunctionType(
        fn.__code__, fn.__globals__, fn.__name__ + "_1", fn.__defaults__, fn.__closure__
    )
    one.__qualname__ = fn.__qualname__ + "_1"
    return njit(cache=True, parallel=True)(fn), njit(cache=True, nogil=True)(one)


_blur_separable, _blur_separable_1 = _two_builds(_blur_separable_py)
_neg_grad_mag_central, _neg_grad_mag_central_1 = _two_builds(_neg_grad_mag_central_py)


@njit(cache=True, nogil=True)
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


#: the mouth layer's step between the skin and the lips (grey levels; :func:`mouth_image`):
#: about the lips' luminance step at rest on the sample video (skin 135, lips 86-90)
MOUTH_CONTRAST = 50.0
#: gaps in the mouth's outline closed before its holes are filled (px)
MOUTH_GAP_PX = 4


@dataclass(frozen=True)
class MouthTones:
    """A face's colours around its mouth, measured on a calibration frame (see
    :func:`mouth_image`): the pseudo-hue R / (R + G) of the skin around the lips and of the
    lips, the grey level below which a pixel is the mouth's dark inside, and the HSV
    saturation below which it is a tooth."""

    skin_hue: float
    lip_hue: float
    floor: float
    teeth_saturation: float


def pseudo_hue(image) -> np.ndarray:
    """(H, W) R / (R + G) of an RGB image (0.5 where both are 0): high on the lips, lower on
    the skin around them, lowest on the teeth (the pseudo-hue with which Eveno, Caplier &
    Coulon 2004 find the lips' outline)."""
    rgb = np.asarray(image)[..., :3].astype(np.float64)
    s = rgb[..., 0] + rgb[..., 1]
    return np.where(s > 0, rgb[..., 0] / np.maximum(s, 1e-9), 0.5)


def saturation(image) -> np.ndarray:
    """(H, W) HSV saturation (max - min) / max of an RGB image's channels (0 where black)."""
    rgb = np.asarray(image)[..., :3].astype(np.float64)
    hi, lo = rgb.max(axis=-1), rgb.min(axis=-1)
    return (hi - lo) / np.maximum(hi, 1e-9)


def mouth_image(image, tones: MouthTones, contrast: float = MOUTH_CONTRAST) -> np.ndarray:
    """(H, W) grey levels in which the whole mouth, lips, teeth and its dark inside, is one
    dark region on the skin, for the lips' outer outline. The mouth's inside (darker than
    ``tones.floor``) and the teeth (less saturated than ``tones.teeth_saturation``) are given
    the lips' pseudo-hue; each pixel's pseudo-hue (then blurred by a pixel: video keeps
    colour at half resolution) is placed between the skin's (0) and the lips' (1) and clipped
    there; the holes the mouth encloses are mouth (1) too, gaps of up to
    :data:`MOUTH_GAP_PX` in its outline closed (where a stretched lip is thinnest, the teeth
    that neither test caught touch the skin); the mouth at ``contrast`` grey levels below
    the skin. A grey image has no hue: its grey
    levels raised to the floor instead."""
    a = np.asarray(image)
    if a.ndim != 3 or a.shape[2] < 3:
        return np.maximum(to_intensity(a), float(tones.floor))
    from scipy.ndimage import binary_closing, binary_fill_holes, gaussian_filter

    span = tones.lip_hue - tones.skin_hue
    span = span if abs(span) > 1e-3 else 1e-3
    hue = pseudo_hue(a)
    hue[(to_intensity(a) < tones.floor) | (saturation(a) < tones.teeth_saturation)] = (
        tones.skin_hue + span
    )
    g = np.clip((gaussian_filter(hue, 1.0, mode="nearest") - tones.skin_hue) / span, 0.0, 1.0)
    mouth = g > 0.5
    closed = binary_closing(mouth, np.ones((3, 3), bool), MOUTH_GAP_PX // 2, border_value=0)
    g[binary_fill_holes(closed) & ~mouth] = 1.0
    return np.ascontiguousarray(200.0 - contrast * g)


def _kernel_reach(sigma: float, methods) -> int:
    """How far (px) the potentials ``methods`` at ``sigma`` look from a pixel (their widest
    Gaussian's radius, plus the two central differences of the edge potential and of its
    gradient)."""
    widest = 4.0 * sigma if "line" in methods else sigma
    return len(gaussian_kernel(float(widest))) // 2 + 2


@dataclass
class PotentialField:
    """Potential layers over a window of an image, and their gradients: what the contours
    move in (:meth:`~myoface.analysis.snakes.Snakes.relax`).

    Attributes
    ----------
    potential : (L, h, w) float64 — layer ``l`` at window pixel ``[row, col]``.
    gx, gy : (L, h, w) float64 — its central-difference gradient (one-sided at the window's
        border).
    origin : (x0, y0) int — the image pixel (column, row) of the window's ``[0, 0]``.
    image_size : (W, H) — the whole image's size, pixels.
    layer_boxes : per layer, None or the box (x0, y0, x1, y1), image pixels, outside which
        that layer was not computed (see :func:`potential_field`).
    """

    potential: np.ndarray
    gx: np.ndarray
    gy: np.ndarray
    origin: tuple = (0, 0)
    image_size: tuple | None = None
    layer_boxes: tuple | None = None

    @classmethod
    def from_potential(cls, potential, origin=(0, 0), image_size=None) -> PotentialField:
        """The field of a potential (H, W) or stack (L, H, W), validated; by default the whole
        image."""
        pot = np.ascontiguousarray(potential, dtype=np.float64)
        if pot.ndim == 2:
            pot = pot[None]
        if pot.ndim != 3 or min(pot.shape[1:]) < 3:
            raise MyofaceValueError(
                f"the potential must be a 2-D image (or a stack of them); got shape {pot.shape}"
            )
        if not np.isfinite(pot).all():
            raise MyofaceValueError("the potential contains NaN or Inf")
        gx = np.empty_like(pot)
        gy = np.empty_like(pot)
        gradient = potential_gradient if pot[0].size > SERIAL_PIXELS else _potential_gradient_1
        for q in range(len(pot)):
            gradient(pot[q], gx[q], gy[q])
        size = (pot.shape[2], pot.shape[1]) if image_size is None else tuple(image_size)
        return cls(pot, gx, gy, (int(origin[0]), int(origin[1])), size)

    @property
    def shape(self) -> tuple[int, int]:
        """(h, w) of the window."""
        return self.potential.shape[1:]

    @property
    def box(self) -> tuple[int, int, int, int]:
        """(x0, y0, x1, y1): the window's first and last pixel, image coordinates."""
        h, w = self.shape
        return (self.origin[0], self.origin[1], self.origin[0] + w - 1, self.origin[1] + h - 1)

    def covers(self, nodes: np.ndarray, margin_px: float = 0.0, layer: int | None = None) -> bool:
        """Whether the (x, y) ``nodes`` lie inside the window (``layer``'s box, when it has
        one), ``margin_px`` from its sides (sides on the image's border need no margin:
        nothing lies beyond them)."""
        x0, y0, x1, y1 = self.box
        if layer is not None and self.layer_boxes and self.layer_boxes[layer] is not None:
            x0, y0, x1, y1 = self.layer_boxes[layer]
        wi, hi = self.image_size
        lo = np.array([x0 + (margin_px if x0 > 0 else 0), y0 + (margin_px if y0 > 0 else 0)])
        hi_ = np.array(
            [x1 - (margin_px if x1 < wi - 1 else 0), y1 - (margin_px if y1 < hi - 1 else 0)]
        )
        return bool(((nodes >= lo) & (nodes <= hi_)).all())

    def full_layer(self, layer: int = 0, fill: float = 0.0) -> np.ndarray:
        """Layer ``layer`` as a whole image (H, W), ``fill`` outside the window."""
        wi, hi = self.image_size
        out = np.full((hi, wi), fill)
        x0, y0, x1, y1 = self.box
        out[y0 : y1 + 1, x0 : x1 + 1] = self.potential[layer]
        return out


def _clip_box(box, w: int, h: int):
    """(x0, y0, x1, y1) integers inside a w x h image, or None when less than 3 px wide."""
    x0, y0 = max(int(np.floor(box[0])), 0), max(int(np.floor(box[1])), 0)
    x1, y1 = min(int(np.ceil(box[2])), w - 1), min(int(np.ceil(box[3])), h - 1)
    return None if x1 - x0 < 2 or y1 - y0 < 2 else (x0, y0, x1, y1)


def _box_potentials(a: np.ndarray, sigma: float, methods, box, floor=None, outward=None):
    """The potentials ``methods`` of image ``a`` and their gradients on ``box`` (x0, y0, x1,
    y1), each (L, y1 - y0 + 1, x1 - x0 + 1): filtered on the box grown by the blur's reach,
    so that they equal the whole image's inside it. ``floor``: grey levels below it are
    raised to it first, or a :class:`MouthTones`: the image is then :func:`mouth_image`'s of
    the grown box (whose holes are those the box shows); ``outward``: an ellipse for
    :func:`_outward_edges` (see :func:`potential_field`)."""
    h, w = a.shape[:2]
    x0, y0, x1, y1 = box
    smooth = [m for m in methods if m != "paper"]
    reach = max(_kernel_reach(float(sigma), methods) if smooth else 0, 4)  # "paper": 2 + 2
    cx0, cy0 = max(x0 - reach, 0), max(y0 - reach, 0)
    cx1, cy1 = min(x1 + reach, w - 1), min(y1 + reach, h - 1)
    crop = a[cy0 : cy1 + 1, cx0 : cx1 + 1]
    if isinstance(floor, MouthTones):
        img = mouth_image(crop, floor)
    else:
        img = np.ascontiguousarray(to_intensity(crop))
        if floor is not None:
            np.maximum(img, float(floor), out=img)
    tmp = np.empty_like(img)
    threads = img.size > SERIAL_PIXELS
    blur = _blur_separable if threads else _blur_separable_1
    grad_mag = _neg_grad_mag_central if threads else _neg_grad_mag_central_1
    gradient = potential_gradient if threads else _potential_gradient_1
    blurred = None
    layers = []
    for m in methods:
        out = np.empty_like(img)
        if m == "paper":
            _paper_potential(img, out, tmp)
        else:
            if blurred is None:
                blurred = np.empty_like(img)
                blur(img, gaussian_kernel(float(sigma)), blurred, tmp)
            if m == "line":
                wide = np.empty_like(img)
                blur(img, gaussian_kernel(4.0 * float(sigma)), wide, tmp)
                np.subtract(blurred, wide, out=out)
            elif outward is not None:
                _outward_edges(blurred, outward, (cx0, cy0), out)
            else:
                grad_mag(blurred, out)
                if m == "line+edge":
                    out += blurred
        layers.append(out)
    pot = np.stack(layers)
    gx = np.empty_like(pot)
    gy = np.empty_like(pot)
    for q in range(len(pot)):
        gradient(pot[q], gx[q], gy[q])
    sl = (slice(None), slice(y0 - cy0, y1 - cy0 + 1), slice(x0 - cx0, x1 - cx0 + 1))
    return pot[sl], gx[sl], gy[sl]


def _outward_edges(blurred: np.ndarray, outward, origin, out: np.ndarray) -> None:
    """``out`` = -max(0, grad(blurred) . d): the edges whose grey levels rise outwards from
    an ellipse's centre, d the unit normal of the concentric ellipse through each pixel;
    ``outward`` = (cx, cy, ax, ay) image px, ``origin`` the image pixel of ``blurred[0, 0]``."""
    cx, cy, ax, ay = (float(v) for v in outward)
    gy, gx = np.gradient(blurred)
    h, w = blurred.shape
    x = np.arange(w, dtype=np.float64) + origin[0] - cx
    y = np.arange(h, dtype=np.float64) + origin[1] - cy
    dx = np.broadcast_to(x[None, :] / ax**2, (h, w))
    dy = np.broadcast_to(y[:, None] / ay**2, (h, w))
    norm = np.maximum(np.hypot(dx, dy), 1e-12)
    np.minimum(-(gx * dx + gy * dy) / norm, 0.0, out=out)


def potential_field(
    image,
    sigma: float = 2.0,
    methods=("gaussian",),
    window=None,
    layer_windows=None,
    layer_floors=None,
    layer_sigmas=None,
    layer_outward=None,
) -> PotentialField:
    """The potentials ``methods`` (one layer each, see :func:`image_potential`) of ``image``
    (H, W[, 3]) over ``window`` = (x0, y0, x1, y1) pixels (inclusive; clipped to the image;
    default: the whole image), with their gradients.

    Only the window, grown by the blur's reach, is read and filtered, so the values inside
    the window equal those of :func:`image_potential` on the whole image; a window around
    the contours costs a fraction of the frame. The Gaussian blur is shared by the layers.

    ``layer_windows``: one entry per method, None or a smaller window (x0, y0, x1, y1): that
    layer is computed only there and is 0 elsewhere (with a 0 gradient), e.g. the "line"
    layer, whose wide blur costs most, around the few contours that move in it. Its values
    inside its window are again those of the whole image.

    ``layer_floors``: one entry per method, None or a grey level (0-255) below which that
    layer's image is raised to it before filtering: what is darker than the feature itself
    makes no edge. For the lips' outline (:class:`~myoface.analysis.trackers.snakes.Analyzer`,
    ``mouth_sections``): the mouth's dark inside, seen as the lips part, is then no darker
    than the lips, and the only edge left near it is the lips' with the skin. An entry may
    be :class:`MouthTones` instead: that layer is then made from :func:`mouth_image` of its
    window (grown by the blur's reach), the lips, the teeth and the mouth's inside one region.

    ``layer_sigmas``: one entry per method, None or that layer's own Gaussian width (px), e.g.
    a coarse copy of a layer, whose wider ravines draw a contour from farther (its potential
    multiplied by the ratio of the widths, so that its ravines are as deep).

    ``layer_outward``: one entry per method, None or an ellipse (cx, cy, ax, ay), image px,
    around a closed feature: that edge layer keeps only the edges whose grey levels rise
    outwards from the ellipse's centre (``P = -max(0, grad(G * I) . d)``, d the outward
    normal of the concentric ellipse through the pixel): of a dark feature's outline, the
    outer side only.
    """
    for m in methods:
        if m not in METHODS:
            raise MyofaceValueError(f"method must be one of {METHODS}; got {m!r}")
    a = np.asarray(image)
    if a.ndim < 2:
        raise MyofaceValueError(f"an image must be (H, W) or (H, W, 3); got shape {a.shape}")
    h, w = a.shape[:2]
    box = (0, 0, w - 1, h - 1) if window is None else _clip_box(window, w, h)
    if box is None:
        raise MyofaceValueError(f"the window {tuple(window)} lies outside the {w}x{h} image")
    if any(m != "paper" for m in methods) and not (np.isfinite(sigma) and sigma > 0):
        raise MyofaceValueError(f"sigma must be > 0 pixels; got {sigma}")
    sub = [None] * len(methods) if layer_windows is None else list(layer_windows)
    if len(sub) != len(methods):
        raise MyofaceValueError("layer_windows must have one entry (or None) per method")
    floors = [None] * len(methods) if layer_floors is None else list(layer_floors)
    if len(floors) != len(methods):
        raise MyofaceValueError("layer_floors must have one entry (or None) per method")
    for fl in floors:
        if fl is None or isinstance(fl, MouthTones):
            continue
        if not (np.isfinite(fl) and 0 <= fl <= 255):
            raise MyofaceValueError(f"a layer's floor must be a grey level in [0, 255]; got {fl}")
    sigmas = [None] * len(methods) if layer_sigmas is None else list(layer_sigmas)
    if len(sigmas) != len(methods):
        raise MyofaceValueError("layer_sigmas must have one entry (or None) per method")
    for sg in sigmas:
        if sg is not None and not (np.isfinite(sg) and sg > 0):
            raise MyofaceValueError(f"a layer's sigma must be > 0 pixels; got {sg}")
    outs = [None] * len(methods) if layer_outward is None else list(layer_outward)
    if len(outs) != len(methods):
        raise MyofaceValueError("layer_outward must have one entry (or None) per method")
    for j, o in enumerate(outs):
        if o is not None and (methods[j] in ("paper", "line") or not min(o[2:]) > 0):
            raise MyofaceValueError("layer_outward: an edge layer and an ellipse with axes > 0")
    x0, y0, x1, y1 = box

    def own(j):  # a layer computed on its own (not with the others on the whole window)
        return any(v[j] is not None for v in (sub, floors, sigmas, outs))

    whole = [j for j in range(len(methods)) if not own(j)]
    shape = (len(methods), y1 - y0 + 1, x1 - x0 + 1)
    pot, gx, gy = np.zeros(shape), np.zeros(shape), np.zeros(shape)
    if whole:
        p, u, v = _box_potentials(a, sigma, [methods[j] for j in whole], box)
        pot[whole], gx[whole], gy[whole] = p, u, v
    boxes = [None] * len(methods)
    for j, lw in enumerate(sub):
        if not own(j):
            continue
        if lw is None:  # a floored (or own sigma's) layer over the whole window
            b = box
        else:
            b = _clip_box((max(lw[0], x0), max(lw[1], y0), min(lw[2], x1), min(lw[3], y1)), w, h)
            boxes[j] = b if b is not None else (x0, y0, x0, y0)
        if b is None:
            continue
        sg = sigma if sigmas[j] is None else sigmas[j]
        p, u, v = _box_potentials(a, sg, [methods[j]], b, floors[j], outs[j])
        if sigmas[j] is not None:
            # a wider blur lowers an edge's slope by the blurs' ratio: the coarse layer's
            # ravines are deepened by it (scale-normalised derivatives, Lindeberg 1998)
            k = sg / sigma
            p, u, v = p * k, u * k, v * k
        sl = (slice(b[1] - y0, b[3] - y0 + 1), slice(b[0] - x0, b[2] - x0 + 1))
        pot[j][sl], gx[j][sl], gy[j][sl] = p[0], u[0], v[0]
    return PotentialField(pot, gx, gy, (x0, y0), (w, h), tuple(boxes))


def image_potential_numpy(image, sigma: float = 2.0) -> np.ndarray:
    """Reference for the ``"gaussian"`` potential with scipy.ndimage (for tests)."""
    from scipy.ndimage import correlate1d

    img = to_intensity(image)
    k = gaussian_kernel(float(sigma))
    b = correlate1d(correlate1d(img, k, axis=1, mode="nearest"), k, axis=0, mode="nearest")
    gy, gx = np.gradient(b)
    return -np.hypot(gx, gy)


def _potential_gradient_py(pot, gx, gy):
    """Central-difference gradient of the potential (one-sided at the borders)."""
    h, w = pot.shape
    for y in prange(h):
        for x in range(w):
            x0, x1 = max(x - 1, 0), min(x + 1, w - 1)
            y0, y1 = max(y - 1, 0), min(y + 1, h - 1)
            gx[y, x] = (pot[y, x1] - pot[y, x0]) / max(x1 - x0, 1)
            gy[y, x] = (pot[y1, x] - pot[y0, x]) / max(y1 - y0, 1)


potential_gradient, _potential_gradient_1 = _two_builds(_potential_gradient_py)


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


def potential_image(pot: np.ndarray) -> np.ndarray:
    """The potential (H, W) as a grey RGB image, edges (its ravines) dark, as in the paper's
    Fig. 7b."""
    lo, hi = np.percentile(pot, [1, 99.5])
    g = np.clip((pot - lo) / max(hi - lo, 1e-12), 0, 1)
    return np.repeat((g * 255).astype(np.uint8)[:, :, None], 3, axis=2)
