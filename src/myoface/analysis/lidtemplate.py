"""The upper lids read against the calibration frame: how far each lid has slid over its eye.

MediaPipe's lid points do not close in a blink (on ``single_face.mp4``'s blink, frames 26-28,
where the person's lids meet, the fit that follows them closed the palpebral orbicularis to
0.42), and the lid margins' edges (:mod:`myoface.analysis.lidedges`) are lost as the eye
closes: a closed lid has no margin edge near where the open one was. What does not go away in a
blink is the lid itself: the band along its margin (the lashes, the lid's skin above them)
slides down over the eye and stays in view down to the lower lid. This module follows that
band, in the person's own appearance, against the calibration frame (never frame to frame, so
it does not drift).

The geometry (:class:`LidTemplate`), in the head frame of the person's calibrated neutral: for
each interior vertex ``u`` of an eye's upper margin (:func:`~myoface.analysis.lidedges.
lid_chains`; those within the middle :attr:`LidTemplateSettings.columns` of the eye's width)
the lower margin's point below it (at the same x, along the lower chain), the gap ``G`` between
them, and the column of points ``P(tau) = X_u + tau G``: ``tau`` 0 on the upper margin, 1 on the
lower one. The model's lids move along these columns: the palpebral orbicularis brings the
upper margin to ``tau = (1 - LOWER_SHARE) k`` at closure ``k``, and the levator raises it to
``tau < 0`` (:mod:`myoface.muscles.lids`), nearly the same ``tau`` along the whole lid.

The reading (:meth:`LidTemplate.read`): the calibration frame along each column (projected
through the calibration's pose) over the band ``tau`` in :attr:`LidTemplateSettings.band`
(half a gap above the upper margin to a tenth below it) is the upper lid's template: its luma
with each column's mean taken off (a change of brightness does not count) and its r, g
chromaticities (:attr:`LidTemplateSettings.chroma_weight`: skin is told from the white of the
eye by its colour, not by its brightness). The frame along the same columns (through the
frame's pose) is compared with it slid down by ``delta``, the band's skin above the margin
following the margin less the further up (:attr:`LidTemplateSettings.follow`), summed over the
eye's columns, for ``delta`` in :attr:`LidTemplateSettings.search`; the least sum, placed
between samples by a parabola, is where the eye's upper margin is, in gaps. The lower lid is
read alike (a band from a tenth of a gap above its margin to half a gap below, slid by -0.6 to
0.4). What the term takes is the **closure**, the upper lid's shift less the lower lid's: the
fit's pose is off by a pixel or two at the eyes (on the gaze benchmark's renders at 30 deg of
yaw; in the sample's smile 1-2.5 px above the corners DIS follows) and that moves both lids'
readings alike, so the closure keeps none of it (the upper lid alone read a rest as 0.2-0.4 of
a gap closed there). A reading counts when its minimum is clear
(:attr:`LidTemplateSettings.min_clarity`) and not at the search's ends, and the eye faces the
camera.

The term (:class:`LidTemplateTerm`; :func:`lid_term` makes it for the fit,
:attr:`~myoface.analysis.weights.FitSettings.lid_edges`): for each column of an eye read, the
row ``(G^ . ((X_u - X_u0) - (X_l - X_l0)) - closure |G|) / sigma`` (mm on the face): the model's
opening closed along the column as far as the image says, relative to the calibration, so a
rest is a rest whatever offset MediaPipe's points had there. It moves the lid muscles only
(levator, palpebral orbicularis; the head frame only, no pose): read through the brow muscles'
small share of the lid, a closing lid lowered the brows. It counts from a closure of 0.3 of a
gap, in full from 0.6 (:data:`CLOSING`: two and four times the reader's scatter on open eyes
at the fit's poses, 0.15 RMS on the gaze benchmark's renders), and as it counts MediaPipe's
points on the eye's upper margin weigh down to :data:`LANDMARK_WEIGHT` (0) in the landmark
term (:meth:`_Sum.landmark_weights`): they say open where the lid is closed, and with them
in, the fit moved other muscles (the zygomaticus minor, the depressor supercilii) to hold
them. Below it MediaPipe's points keep the lids: on open eyes the reader is no better than
they are, and lids placed by it moved the gaze's reading (``analysis.gaze_error_deg`` 5.05 ->
5.48 deg with the upper lid's reading counted at every closure; the closure counted from 0.15,
in full from 0.35: 5.01, quick 7.45 against 6.88, its five partly closed frames read worse).

Measured 2026-12-02:

- the reader on known answers, renders of the default face (no lashes, no texture; head turned
  8/-4/3 deg) closing by 0.3, 0.6, 0.8, 1 (``tests/analysis/test_lidtemplate.py``): the upper
  margin within 0.01-0.07 of a gap up to 0.8, the closure within 0.00-0.10 (a little short as
  the lids close), the same through a pose 1.5 mm off, where the upper margin alone is 0.16-0.23
  off; the full closure (no line left to see) read at 0.74-0.77. The gaze benchmark's 90
  degraded renders of the personal face (head +-30 deg, eyes turning +-24 deg, four blinks;
  ``tools/lidtemplate_check.py``): at the true poses the upper margin 0.11 of a gap RMS off
  on open eyes (the worst 0.28; 0.47 and 1.07 without the chroma: a dark iris turned under
  the margin reads as the lashes coming down), 0.12 RMS in the blinks (a quarter of the
  readings not clear); the closure 0.095 RMS on open eyes (the worst 0.37), 0.08 in the
  blinks at a gain of 0.95 (40 % not clear); at the fit's poses the upper margin 0.24 RMS off
  on open eyes, the closure 0.15 (36 % of the readings not clear);
- on ``single_face.mp4`` at the fit's poses, the upper margin: rest 0.00-0.05, the blink 0.51
  / 0.35 (frame 25), 0.83 / 0.73, 0.89 / 0.99, 0.71 / 0.68 (26-28), 0.52 / 0.33 (29), the
  smile 0.27-0.33 / 0.17-0.22 (of which 0.1-0.2 is the fit's pose: with the columns moved
  onto the eye corners' skin, :attr:`LidTemplateSettings.anchor`, 0.11-0.15 / 0.04-0.09; the
  anchor stays off: its patch did not follow the face's surface as the head turned, and read
  shifts of up to 4 mm on the gaze benchmark's renders where there were none);
- the fit end to end (``myoface analyze``'s 3-D fit) on a known answer: the person's own face
  (``face_from_photo`` on the sample's frame 0) rendered over 40 frames, its palpebral
  orbicularis blinking (0.5, 1, 1, 0.5) and holding a half closure (0.3, 0.5 x4, 0.3), head
  still: fitted at the blink's closed frames 0.30-0.35 without the term, 0.53-0.71 with it; in
  the held half closure 0.16 -> 0.20-0.22; over the clip RMSE 0.207 -> 0.150, gain 0.32 ->
  0.52 (``tests/analysis/test_lidtemplate.py::test_the_fit_follows_a_rendered_blink``; with
  :data:`CLOSING` at 0.15-0.35 the half closure 0.35, the gain 0.66, but see the gaze above);
- on ``single_face.mp4`` the fitted palpebral orbicularis at the blink 0.43 / 0.63, 0.47 /
  0.59, 0.62 / 0.67 (frames 26-28; 0.33-0.42 without the term; the person's lids meet):
  the closure read there is short of the upper lid's own shift (the lower lid's band reads
  the closed lid's lash line below the lower margin as the lower lid moving down);
- the benchmarks, without / with the term: ``analysis.gaze_error_deg`` 5.05 -> 5.03 deg (quick
  6.88 -> 6.95); ``analysis.fidelity`` on ``single_face.mp4`` 0.756 -> 0.763, eyelids
  explained 0.349 -> 0.378 (gain 0.47 -> 0.54), every region at least as before (mouth
  corners 0.895 / 0.892, lower lip 0.561 / 0.592, brows 0.701 / 0.727, chin 0.153 / 0.169);
  with ``--flow`` 0.779 -> 0.776 (eyelids 0.371 -> 0.381, lower lip 0.630 -> 0.609, brows
  0.754 -> 0.747, chin 0.300 -> 0.320).
- What holds the eyelids' fidelity: the judge's reader on a known blink (the person's face
  rendered closing to 0.13 of its opening, ``tests/analysis/test_fidelity.py::_blinking``)
  reads the upper lids at 0.76 of their motion, the lower lids moving down by 0.019 IOD where
  they rose by 0.019, and the upper lids moving sideways by 0.03-0.045 IOD where they did not:
  the exact blink is read at 0.615 explained. On the sample the blink's frames carry 73 % of
  the eyelids' motion, read with the lower lids moving down by 0.02-0.056 IOD and the upper
  lids sideways by up to 0.098: the model's reach there (contractions fitted to the judge's
  own readings) is 0.51, and the fitted lids closing as the person's do (palpebral orbicularis
  0.3, 0.9, 1, 0.8, 0.3 over frames 25-29, the rest as fitted) score 0.36. The judge also
  aligns each side on the nose ridge alone where that side's lid opening is below 0.7 of the
  reference's (:data:`~myoface.analysis.fidelity.CLOSING_OPENING`, for the flow's drag at the
  eye corners), the model's side too, whose corners no lid drags: a model squinting a little
  more in the smile is then aligned otherwise than the input (an earlier version of this term,
  the upper lid alone at every closure: the chin -0.69, the measure 0.668).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from myoface.analysis._lidkernels import slide_cost
from myoface.analysis.camera import HeadPose, PinholeCamera
from myoface.analysis.lidedges import FACING_DEG, lid_chains
from myoface.analysis.terms import Estimate


@dataclass(frozen=True)
class LidTemplateSettings:
    """How the lids are read against the calibration frame, and weighed.

    band : the template, in gap units from the upper margin (negative: above it).
    search : the shifts tried (gap units; 1 is the lower margin's place at calibration).
    step : the profile's sampling step (gap units).
    columns : the share of the eye's width (about its middle) whose upper margin vertices
        are read: near the corners the gap is too short to read.
    min_gap_px : a column whose gap projects shorter than this (px) is not read.
    min_contrast : a column whose template varies by less than this (luma SD) is not read.
    min_clarity : a reading counts when its least cost is below ``1 - min_clarity`` of the
        median cost over the shifts tried.
    blur_px : the frame is smoothed by a Gaussian of this SD (px) before it is sampled.
    sigma_mm : the term's unit, mm on the face, per column.
    huber : Huber's threshold (sigmas).
    redetect_px : the frame is read again at a Gauss-Newton step's start once the columns
        have moved this far in the image since the last reading.
    """

    band: tuple[float, float] = (-0.5, 0.1)
    search: tuple[float, float] = (-0.4, 1.1)
    step: float = 0.025
    columns: float = 0.6
    min_gap_px: float = 2.0
    min_contrast: float = 3.0
    min_clarity: float = 0.3
    blur_px: float = 0.7
    sigma_mm: float = 0.5
    huber: float = 1.5
    redetect_px: float = 0.5
    follow: float = 1.5
    anchor: bool = False
    anchor_patch: float = 0.6
    anchor_search: float = 0.5
    anchor_step: float = 0.5
    anchor_out: float = 0.25
    chroma_weight: float = 2.0


def _luma(img) -> np.ndarray:
    img = np.asarray(img)
    if img.ndim == 2:
        return img.astype(np.float32)
    return (0.299 * img[..., 0] + 0.587 * img[..., 1] + 0.114 * img[..., 2]).astype(np.float32)


def _sample(grey: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear samples of ``grey`` (H, W) at ``uv`` (..., 2) px (pixel centres at integers;
    clamped to the image)."""
    import cv2

    shp = uv.shape[:-1]
    flat = uv.reshape(-1, 2)
    n = len(flat)
    w = 1024  # (remap's maps are images: fewer than 32767 rows)
    m = np.zeros((-(-n // w) * w, 2), dtype=np.float32)
    m[:n] = flat
    m = m.reshape(-1, w, 2)
    out = cv2.remap(grey, m[..., 0], m[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return out.reshape(-1)[:n].reshape(shp).astype(np.float64)


def _channels(first, more, dtype) -> np.ndarray:
    """(C, ...) ``first`` (...) and, unless None, the channels ``more`` (C - 1, ...) stacked,
    contiguous, of ``dtype`` (the compiled slide's layout, :func:`_lidkernels.slide_cost`)."""
    out = first[None] if more is None else np.concatenate([first[None], np.asarray(more)])
    return np.ascontiguousarray(out, dtype=dtype)


def _blurred(image, sigma: float) -> np.ndarray:
    import cv2

    g = _luma(image)
    return cv2.GaussianBlur(g, (0, 0), sigma) if sigma > 0 else g


def _chroma(image, sigma: float, weight: float) -> np.ndarray:
    """(2, H, W) the frame's r and g chromaticities (each channel over their sum), smoothed,
    times 255 ``weight`` (in luma levels)."""
    import cv2

    img = np.asarray(image, dtype=np.float32)
    if sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), sigma)
    tot = np.maximum(img.sum(-1), 1.0)
    return np.stack([img[..., 0] / tot, img[..., 1] / tot]) * np.float32(255.0 * weight)


class _SurfaceDepth:
    """Points (..., 3) of the head frame put onto the face's surface near the anchor points:
    their z from the neutral's vertices' (linear over a triangulation of their x, y)."""

    def __init__(self, shape, centres, radius: float):
        from scipy.interpolate import LinearNDInterpolator

        c = np.asarray(centres).reshape(-1, 3)
        near = np.zeros(len(shape), dtype=bool)
        for p in c:
            near |= np.linalg.norm(shape[:, :2] - p[:2], axis=1) < 2.0 * radius + 2.0
        v = shape[near]
        self._z = LinearNDInterpolator(v[:, :2], v[:, 2])

    def __call__(self, p) -> np.ndarray:
        p = np.array(p, dtype=np.float64)
        z = self._z(p[..., 0], p[..., 1])
        p[..., 2] = np.where(np.isfinite(z), z, p[..., 2])
        return p


class LidTemplate:
    """The columns of each eye's upper lid and the calibration frame's template along them
    (see the module's docstring).

    Parameters
    ----------
    face : the face model's face (its landmark groups ``eye_l``, ``eye_r``).
    shape : (V, 3) mm, the person's calibrated neutral (head frame).
    reference : the calibration frame (H, W, 3) RGB.
    camera : PinholeCamera; pose : the calibration frame's HeadPose.
    """

    def __init__(self, face, shape, reference, camera: PinholeCamera, pose: HeadPose,
                 settings: LidTemplateSettings | None = None):  # fmt: skip
        s = self.settings = settings or LidTemplateSettings()
        self.camera = camera
        shape = np.asarray(shape, dtype=np.float64)
        verts, x0, gaps, eyes, low = [], [], [], [], []
        chains = lid_chains(face)
        #: each eye's corners (the anchor: :meth:`anchor`), head frame
        self.canthi = np.array([shape[[up[0], up[-1]]] for up, _ in chains])  # (2, 2, 3)
        for e, (upper, lower) in enumerate(chains):
            xs_l = shape[lower, 0]
            order = np.argsort(xs_l)
            lo, hi = shape[upper, 0].min(), shape[upper, 0].max()
            mid, half = 0.5 * (lo + hi), 0.5 * s.columns * (hi - lo)
            for u in upper[1:-1]:
                x = shape[u, 0]
                if abs(x - mid) > half:
                    continue
                xs = xs_l[order]
                i = int(np.clip(np.searchsorted(xs, x), 1, len(xs) - 1))
                al = float(np.clip((x - xs[i - 1]) / max(xs[i] - xs[i - 1], 1e-9), 0.0, 1.0))
                la, lb = lower[order][i - 1], lower[order][i]
                below = (1 - al) * shape[la] + al * shape[lb]
                verts.append(u), x0.append(shape[u]), gaps.append(below - shape[u]), eyes.append(e)
                low.append((la, lb, al))
        self.vertices = np.array(verts, dtype=np.int64)
        #: the lower margin's point below each column: between vertices ``lower_a`` and
        #: ``lower_b``, ``lower_alpha`` of the way to the second; at rest ``x0 + gap``
        self.lower_a = np.array([a for a, _, _ in low], dtype=np.int64)
        self.lower_b = np.array([b for _, b, _ in low], dtype=np.int64)
        self.lower_alpha = np.array([al for _, _, al in low], dtype=np.float64)
        #: each eye's upper margin's interior vertices (MediaPipe's upper lid points)
        self.upper_margin = [np.asarray(up[1:-1], dtype=np.int64) for up, _ in chains]
        self.x0 = np.array(x0).reshape(-1, 3)
        self.gap = np.array(gaps).reshape(-1, 3)
        self.gap_mm = np.linalg.norm(self.gap, axis=1)
        self.dir = self.gap / np.maximum(self.gap_mm[:, None], 1e-9)
        self.eye = np.array(eyes, dtype=np.int64)
        b0, b1 = s.band
        self._band = np.arange(round(b0 / s.step), round(b1 / s.step) + 1) * s.step
        self._shifts = np.arange(round(s.search[0] / s.step), round(s.search[1] / s.step) + 1)
        self._shifts = self._shifts * s.step
        # the frame's profile covers every shifted band
        self._taus = np.arange(
            round((s.search[0] + b0) / s.step), round((s.search[1] + b1) / s.step) + 1
        ) * s.step  # fmt: skip
        # how much of the margin's shift the band's samples follow: 1 at the margin, falling
        # as a raised cosine to 0 at s.follow gaps above it
        d = np.clip(-self._band / s.follow, 0.0, 1.0)
        self._follow = 0.5 + 0.5 * np.cos(np.pi * d)
        grey = _blurred(reference, s.blur_px)
        # the anchor's patches: a grid in the head frame's x, y about each anchor point, a
        # pixel's mm at calibration apart (:meth:`anchor`)
        uv0 = self._uv(pose, np.array([0.0, 1.0]))
        gap_px = float(np.median(np.linalg.norm(uv0[:, 1] - uv0[:, 0], axis=1)))
        self._mm = float(np.median(self.gap_mm)) / max(gap_px, 1e-9)  # mm a pixel
        h = max(2, int(round(s.anchor_patch * gap_px)))
        g = np.arange(-h, h + 1, dtype=np.float64) * self._mm
        gx, gy = np.meshgrid(g, g)
        self._patch = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
        r = max(1, int(round(s.anchor_search * gap_px / s.anchor_step)))
        self._offsets = np.arange(-r, r + 1) * s.anchor_step * self._mm
        if s.anchor:
            a = self._anchor_points()
            self._surface = _SurfaceDepth(
                shape, a, float(np.abs(g).max() + np.abs(self._offsets).max())
            )
            self._corner_ref = _sample(
                grey, self._project(pose, self._surface(a[:, :, None, :] + self._patch))
            )
            self._corner_ref -= self._corner_ref.mean(-1, keepdims=True)
        self.template = _sample(grey, self._uv(pose, self._band))
        self.template -= self.template.mean(1, keepdims=True)
        self.chroma = None
        if s.chroma_weight > 0 and np.ndim(reference) == 3:
            ch = _chroma(reference, s.blur_px, s.chroma_weight)
            self.chroma = np.stack([_sample(c, self._uv(pose, self._band)) for c in ch])
        # the lower lid: the band from a tenth of a gap above its margin to half a gap below,
        # slid up (negative) or down
        self._band_lo = 1.0 + np.arange(round(-0.1 / s.step), round(0.5 / s.step) + 1) * s.step
        d = np.clip((self._band_lo - 1.0) / s.follow, 0.0, 1.0)
        self._follow_lo = 0.5 + 0.5 * np.cos(np.pi * d)
        self._shifts_lo = np.arange(round(-0.6 / s.step), round(0.4 / s.step) + 1) * s.step
        self.template_lo = _sample(grey, self._uv(pose, self._band_lo))
        self.template_lo -= self.template_lo.mean(1, keepdims=True)
        self.chroma_lo = None
        if self.chroma is not None:
            self.chroma_lo = np.stack([_sample(c, self._uv(pose, self._band_lo)) for c in ch])
        self.usable = self.template.std(1) >= s.min_contrast
        # what the compiled slide (_lidkernels.slide_cost) takes that never changes: each
        # lid's template stacked with its chromaticities, the columns, each eye's centre
        self._stacked = (_channels(self.template, self.chroma, np.float64),
                         _channels(self.template_lo, self.chroma_lo, np.float64))  # fmt: skip
        self._x0c = np.ascontiguousarray(self.x0, dtype=np.float64)
        self._gapc = np.ascontiguousarray(self.gap, dtype=np.float64)
        self._centres = [
            self.x0[self.eye == e].mean(0)[None] if (self.eye == e).any() else None for e in (0, 1)
        ]
        uv0 = self._uv(pose, np.array([0.0, 1.0]))
        self.usable &= np.linalg.norm(uv0[:, 1] - uv0[:, 0], axis=1) >= s.min_gap_px

    def _uv(self, pose: HeadPose, taus) -> np.ndarray:
        """(N, len(taus), 2) the columns' points at ``taus`` in the image at ``pose``."""
        p = self.x0[:, None, :] + np.asarray(taus)[None, :, None] * self.gap[:, None, :]
        return self.camera.project(pose.apply(p.reshape(-1, 3))).reshape(len(p), -1, 2)

    def _project(self, pose: HeadPose, p) -> np.ndarray:
        """Head-frame points (..., 3) -> image points (..., 2) at ``pose``."""
        p = np.asarray(p)
        return self.camera.project(pose.apply(p.reshape(-1, 3))).reshape(*p.shape[:-1], 2)

    def _anchor_points(self) -> np.ndarray:
        """(2, 2, 3) the anchor's points, head frame: beside each eye's corners,
        :attr:`LidTemplateSettings.anchor_out` of the eye's width outwards (away from the
        lids, which drag a corner's patch as they close)."""
        c = self.canthi
        return c + self.settings.anchor_out * (c - c[:, ::-1])

    def anchor(self, grey, pose: HeadPose, origin=(0.0, 0.0)) -> np.ndarray:
        """(2, 3) mm: per eye, how far (x, y of the head frame) the frame's skin beside the eye
        corners lies from where ``pose`` puts it (each patch, a grid in the head frame's x, y
        seen through ``pose``, matched against the calibration frame's by the least sum of
        squared differences over shifts on a grid, placed between grid points by a parabola;
        the two corners' mean): the pose's own error at the eye, which the lids are read
        relative to."""
        s = self.settings
        a = self._anchor_points()
        o = self._offsets
        n = len(o)
        ox, oy = np.meshgrid(o, o)
        sh = np.column_stack([ox.ravel(), oy.ravel(), np.zeros(ox.size)])  # (S, 3)
        out = np.zeros((2, 3))
        step = s.anchor_step * self._mm
        for e in (0, 1):
            found = []
            for c in (0, 1):
                pts = a[e, c][None, None, :] + sh[:, None, :] + self._patch[None, :, :]
                win = _sample(grey, self._project(pose, self._surface(pts)) - origin)
                win -= win.mean(-1, keepdims=True)
                cost = ((win - self._corner_ref[e, c][None]) ** 2).mean(-1).reshape(n, n)
                iy, ix = np.unravel_index(int(np.argmin(cost)), cost.shape)
                d = [o[ix], o[iy]]
                for ax, (i, line) in enumerate(((ix, cost[iy, :]), (iy, cost[:, ix]))):
                    if 0 < i < n - 1:
                        den = line[i - 1] - 2 * line[i] + line[i + 1]
                        if den > 1e-12:
                            frac = 0.5 * (line[i - 1] - line[i + 1]) / den
                            d[ax] += np.clip(frac, -0.5, 0.5) * step
                found.append(d)
            out[e, :2] = np.mean(found, axis=0)
        return out

    def _facing(self, pose: HeadPose) -> np.ndarray:
        """(2,) whether each eye faces the camera within :data:`FACING_DEG`."""
        fwd = pose.rotation[:, 2]
        out = np.zeros(2, dtype=bool)
        for e in (0, 1):
            if self._centres[e] is None:
                continue
            pc = pose.apply(self._centres[e])[0]
            out[e] = -pc @ fwd / max(np.linalg.norm(pc), 1e-9) >= np.cos(np.radians(FACING_DEG))
        return out

    def read(self, image, pose: HeadPose, grey=None, chroma=None, origin=None) -> dict:
        """The lids of ``image`` at head pose ``pose``: per eye (0, 1) the upper lid's shift
        ``delta``, the lower lid's ``delta_lower`` and the ``closure`` (the first less the
        second; gap units; NaN: not read), the clarities, and the upper lid's cost curve.
        ``grey``, ``chroma``: the frame's (:func:`_blurred`, :func:`_chroma`) if already
        made, of the crop of the frame whose top left corner is ``origin`` (x, y) px."""
        s = self.settings
        origin = np.zeros(2) if origin is None else np.asarray(origin, dtype=np.float64)
        if grey is None:
            grey = _blurred(image, s.blur_px)
        if chroma is None and self.chroma is not None:
            chroma = _chroma(image, s.blur_px, s.chroma_weight)
        shift = self.anchor(grey, pose, origin) if s.anchor else np.zeros((2, 3))
        imgs = _channels(grey, chroma if self.chroma is not None else None, np.float32)
        up = self._slide(imgs, pose, shift, self._band, self._follow, self._shifts,
                         self._stacked[0], origin)  # fmt: skip
        lo = self._slide(imgs, pose, shift, self._band_lo, self._follow_lo, self._shifts_lo,
                         self._stacked[1], origin)  # fmt: skip
        return {
            "delta": up[0], "clarity": up[1], "cost": up[2], "shifts": self._shifts,
            "delta_lower": lo[0], "clarity_lower": lo[1], "closure": up[0] - lo[0],
            "anchor_mm": shift,
        }  # fmt: skip

    def _slide(self, imgs, pose, shift, band, follow, shifts, tmpls, origin):
        """Per eye the shift of ``band`` (the template ``tmpl``, ``tmpl_chroma``) along the
        columns that the frame matches best (see the module's docstring): (delta (2,), clarity
        (2,), the cost curves)."""
        s = self.settings
        # the frame along the columns where each template sample lands for each shift: the
        # lid's skin beyond the margin moves with it, less the further away (``follow``)
        where = band[None, :] + shifts[:, None] * follow[None, :]  # (S, nb)
        # (N, S): the frame's channels ``imgs`` (:func:`_channels`) sampled where the templates'
        # samples land, the luma less its mean, against the stacked templates ``tmpls``
        cost = slide_cost(
            self._x0c, self._gapc, np.ascontiguousarray(np.asarray(shift, float)[self.eye]),
            np.ascontiguousarray(where, dtype=np.float64), pose.rotation, pose.translation_mm,
            float(self.camera.focal_px), float(self.camera.cx), float(self.camera.cy),
            float(origin[0]), float(origin[1]), imgs, tmpls,
        )  # fmt: skip
        delta = np.full(2, np.nan)
        clarity = np.zeros(2)
        curves = [None, None]
        facing = self._facing(pose)
        for e in (0, 1):
            sel = (self.eye == e) & self.usable
            if not sel.any() or not facing[e]:
                continue
            c = cost[sel].sum(0)
            curves[e] = c
            i = int(np.argmin(c))
            med = float(np.median(c))
            clarity[e] = 1.0 - c[i] / med if med > 0 else 0.0
            if i == 0 or i == len(c) - 1 or clarity[e] < s.min_clarity:
                continue
            c0, c1, c2 = c[i - 1], c[i], c[i + 1]
            den = c0 - 2 * c1 + c2
            frac = 0.5 * (c0 - c2) / den if den > 1e-12 else 0.0
            delta[e] = shifts[i] + np.clip(frac, -0.5, 0.5) * s.step
        return delta, clarity, curves


class LidTemplateTerm:
    """The upper lids' margins moved along their columns as far as the frame shows
    (:class:`LidTemplate`; see the module's docstring)."""

    def __init__(self, image, template: LidTemplate, lid_muscles=None):
        self.template = template
        self.image = image
        #: (M,) bool: the contractions the term moves (the lid muscles; None: all)
        self.lid_muscles = None if lid_muscles is None else np.asarray(lid_muscles, bool)
        self._grey = None
        self._at = None
        self.delta = np.full(2, np.nan)
        self._share = None  # (share()'s, made once a reading)
        self.rows = np.zeros(0, dtype=np.int64)
        self.hw = np.zeros(0)

    def detect(self, pose: HeadPose) -> dict:
        """Read the lids at ``pose`` (the rows then follow the reading)."""
        t = self.template
        if self._grey is None:
            # the frame about the eyes only: the columns' whole search and a margin
            uv = t._uv(pose, np.array([-1.2, 0.5, 1.8])).reshape(-1, 2)
            h, w = np.shape(self.image)[:2]
            m = CROP_MARGIN_PX
            x0, y0 = (int(max(np.floor(uv[:, i].min()) - m, 0)) for i in (0, 1))
            x1 = int(min(np.ceil(uv[:, 0].max()) + m + 1, w))
            y1 = int(min(np.ceil(uv[:, 1].max()) + m + 1, h))
            if x1 <= x0 + 2 or y1 <= y0 + 2:  # (off the frame)
                x0, y0, x1, y1 = 0, 0, w, h
            crop = np.asarray(self.image)[y0:y1, x0:x1]
            self._origin = np.array([x0, y0], dtype=np.float64)
            self._grey = _blurred(crop, t.settings.blur_px)
            if t.chroma is not None:
                self._chroma = _chroma(crop, t.settings.blur_px, t.settings.chroma_weight)
        out = t.read(None, pose, self._grey, getattr(self, "_chroma", None), self._origin)
        self._at = t._uv(pose, np.array([0.0]))[:, 0]
        self.delta = out["closure"]
        self.rows = np.flatnonzero(t.usable & np.isfinite(self.delta[t.eye]))
        self._share = None
        return out

    def prepare(self, est: Estimate) -> None:
        t = self.template
        uv = t._uv(est.pose, np.array([0.0]))[:, 0]
        if self._at is None or np.abs(uv - self._at).max() > t.settings.redetect_px:
            self.detect(est.pose)
        share = self.share()[t.eye[self.rows]]
        if not share.any():  # (open eyes: the term weighs nothing; nothing to compute)
            self.hw = share
            return
        r = self._residuals(est)
        h = t.settings.huber
        self.hw = np.where(np.abs(r) > h, h / np.maximum(np.abs(r), 1e-12), 1.0)
        self.hw = self.hw * share

    def share(self) -> np.ndarray:
        """(2,) how much each eye's reading counts: 0 up to :data:`CLOSING` [0] of a gap
        closed, 1 from :data:`CLOSING` [1] (smoothly between), 0 where not read. Below it the
        lids are left to MediaPipe's points: the reader's own scatter on open eyes (0.11 of
        a gap RMS on the gaze benchmark's renders at the true poses, more at the fit's) is no
        better than theirs, and a lid placed by it moved the gaze's reading; what it is for
        is the closing lid, where the points stay open."""
        if self._share is None:  # (the reading's: made anew by detect())
            a, b = CLOSING
            x = np.clip((np.nan_to_num(self.delta, nan=-1.0) - a) / (b - a), 0.0, 1.0)
            self._share = x * x * (3 - 2 * x) * self.read_eyes()
        return self._share

    def read_eyes(self) -> np.ndarray:
        """(2,) bool: the eyes whose lids the last reading read."""
        return np.isfinite(self.delta) & np.array(
            [(self.template.usable & (self.template.eye == e)).any() for e in (0, 1)]
        )

    def _residuals(self, est: Estimate) -> np.ndarray:
        t, j = self.template, self.rows
        al = t.lower_alpha[j, None]
        lower = (1 - al) * est.shape[t.lower_a[j]] + al * est.shape[t.lower_b[j]]
        closed = est.shape[t.vertices[j]] - t.x0[j] - (lower - t.x0[j] - t.gap[j])
        moved = (closed * t.dir[j]).sum(1)
        return (moved - self.delta[t.eye[j]] * t.gap_mm[j]) / t.settings.sigma_mm

    def normal_equations(self, est: Estimate):
        n = est.n_unknowns
        hmat, b = np.zeros((n, n)), np.zeros(n)
        if not len(self.rows) or not np.any(self.hw):
            return hmat, b
        t, j = self.template, self.rows
        r = self._residuals(est)
        # d r / d dc: the vertex's response along its column
        al = t.lower_alpha[j, None, None]
        jv = est.jac[t.vertices[j]][:, :, est.free] - (
            (1 - al) * est.jac[t.lower_a[j]][:, :, est.free]
            + al * est.jac[t.lower_b[j]][:, :, est.free]
        )
        jr = np.einsum("nk,nkf->nf", t.dir[j], jv)
        jr /= t.settings.sigma_mm
        if self.lid_muscles is not None:
            jr[:, ~self.lid_muscles[est.free]] = 0.0
        w = self.hw
        hmat[6:, 6:] = (jr * w[:, None]).T @ jr
        b[6:] = -(jr * w[:, None]).T @ r
        return hmat, b

    def cost(self, est: Estimate) -> float:
        if not len(self.rows):
            return 0.0
        share = self.share()[self.template.eye[self.rows]]
        if not share.any():
            return 0.0
        r = np.abs(self._residuals(est))
        h = self.template.settings.huber
        return float((share * np.where(r <= h, r * r, 2 * h * r - h * h)).sum())


#: the frame is read about the eyes only: the columns' extent and this margin (px; the pose
#: moves by less within a frame's fit)
CROP_MARGIN_PX = 24
#: the weight of MediaPipe's upper lid margin points where the lids are read
#: (:meth:`_Sum.landmark_weights`)
LANDMARK_WEIGHT = 0.0
#: the closure read (gaps) from which the reading starts to count, and from which it counts
#: in full (:meth:`LidTemplateTerm.share`)
CLOSING = (0.3, 0.6)
#: which lid readers the fit's lid term uses (:func:`lid_term`): ``"template"`` (this
#: module's), ``"edges"`` (:class:`~myoface.analysis.lidedges.LidEdgeTerm`) or both
READERS = ("template",)


class _Sum:
    """Terms summed as one."""

    def __init__(self, terms):
        self.terms = list(terms)

    def prepare(self, est: Estimate) -> None:
        for t in self.terms:
            t.prepare(est)

    def normal_equations(self, est: Estimate):
        n = est.n_unknowns
        hmat, b = np.zeros((n, n)), np.zeros(n)
        for t in self.terms:
            h1, b1 = t.normal_equations(est)
            hmat += h1
            b += b1
        return hmat, b

    def cost(self, est: Estimate) -> float:
        return float(sum(t.cost(est) for t in self.terms))

    def landmark_weights(self, weights) -> np.ndarray:
        """The landmarks' per-vertex ``weights`` (V,) with MediaPipe's upper lid margin
        points of each eye read closing weighed down towards :data:`LANDMARK_WEIGHT` by the
        reading's share (:meth:`LidTemplateTerm.share`; they do not close in a blink: the
        lids are read from the image instead)."""
        w = np.array(weights, dtype=np.float64)
        for t in self.terms:
            if isinstance(t, LidTemplateTerm):
                for e, share in enumerate(t.share()):
                    w[t.template.upper_margin[e]] *= 1.0 - share * (1.0 - LANDMARK_WEIGHT)
        return w


def lid_term(fit, image, readers=None):
    """The lids' term of the frame ``image`` for the fit ``fit``
    (:class:`~myoface.analysis.modelfit.ModelFit`): the readers of :data:`READERS` summed
    (the template's once the fit has its reference, :meth:`~myoface.analysis.modelfit.
    ModelFit.set_lid_reference`)."""
    from myoface.analysis.lidedges import LidEdgeTerm, MarginSamples

    readers = READERS if readers is None else readers
    terms = []
    template = getattr(fit, "lid_template", None)
    if "template" in readers and template is not None:
        kinds = {m.id: getattr(m, "kind", "") for m in fit.model.muscles.muscles}
        lid = np.array([kinds.get(i) == "lid" for i in fit.ids])
        term = LidTemplateTerm(image, template, lid)
        # read at once, at the last frame's pose (or the calibration's): the landmarks'
        # weights (:meth:`_Sum.landmark_weights`) are set before the first step
        prev = getattr(fit, "_prev", None)
        pose = prev.pose if prev is not None else fit.calibration.pose
        term.detect(pose)
        terms.append(term)
    if "edges" in readers:
        if getattr(fit, "_lid_samples", None) is None:
            fit._lid_samples = MarginSamples(fit.model.face)
        terms.append(LidEdgeTerm(image, fit._lid_samples, fit.camera))
    return _Sum(terms)
