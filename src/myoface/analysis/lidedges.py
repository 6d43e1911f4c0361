"""The lid margins read from the image: an edge term of the 3-D fit's energy.

The paper's own idea (Terzopoulos & Waters 1993, Section V: the image's edges made into
potentials the model's contours slide into) applied to the fitted model's lid margins. The fit
otherwise places the lids from MediaPipe's lid points, which sit a fraction of a pixel to a
pixel off the image's margins in a way that depends on the face and the view (on the gaze
benchmark's renders the fitted openings' mean point sits 0.5-0.7 px off the truth's), and the
eyeball's centre and the gaze read from it follow.

What is measured (:func:`find_edges`, compiled): along each lid margin of the fitted model
(the margin's vertex chain from :func:`lid_chains`, projected into the frame) sample points are
taken (the chain's interior vertices and the midpoints between them: 13 a lid; the corners are
left out, their normal is not defined and the margins meet there), and at each the frame's
luma is read on a short profile across the margin (along the projected normal,
+-:attr:`LidEdgeSettings.window_px`, every half pixel, averaged over three parallel lines a
pixel apart and smoothed). The margin is an extremum of the profile's derivative, the clear one
nearest the model's margin (at least half the strongest in the window and
:attr:`LidEdgeSettings.min_contrast` grey levels a pixel, not at the window's end), placed to a
fraction of a pixel by a parabola through it and its two neighbours. On the upper lid only an
edge that brightens into the opening counts (:attr:`LidEdgeSettings.upper_sign`): the lashes
make a dark band whose upper edge (skin to lashes, darkening) lies 1-2 px above the margin and
is often the stronger; the margin is the band's lower edge, lashes to eyeball. By default only
the upper lids are read (:attr:`LidEdgeSettings.lids`): the lower lid's edge is a broad ramp
(no lashes; sclera or iris inside) that the finder puts 0.8-0.9 px inside the true margin on
the renders. An eye is not read while its lids are closed (the projected opening narrower
than :attr:`LidEdgeSettings.min_opening_px`), upside down, or turned more than
:data:`FACING_DEG` from the line of sight.

The term (:class:`LidEdgeTerm`): each found edge ``e`` with the profile's direction ``n`` adds
the row ``n . (proj(R X + t) - e) k / sigma`` for the model's point ``X`` on the margin there
(``k`` mm per pixel at the head's depth, so it is in mm on the face): a point-to-line distance,
since an edge says where the margin is across it, not along it (which is also why it cannot
move an opening sideways: the upper lid's normals are near vertical). Huber-weighted (beyond
:attr:`LidEdgeSettings.huber` sigmas); the edges are read at a frame's first Gauss-Newton step
and again when the margins have moved :attr:`LidEdgeSettings.redetect_px` since.

Measured 2026-12-02 (``tools/lidedge_check.py``, ``tools/lidedge_headmotion.py``; the gaze
benchmark's two 90-frame clips, degraded renders of the personal face, head +-30 deg):

- the finder on the known answer (started from the true margins moved -1.5..+1.5 px across
  them): without the polarity rule the upper lids' edges 0.16-0.28 px inside the true margin,
  RMS 1.0-1.4 px, lower lids 0.8-0.9 inside, RMS 1.2-1.4; with it (the default) the upper
  lids 0.7-0.86 px inside, RMS 1.25-1.33; on the head-motion benchmark's 90 renders
  (expressions, lids at rest) the upper lids 0.79-1.05 px inside, RMS 1.37-1.41 (without the
  rule 0.05-0.48, RMS 1.03-1.51), the lower 0.62-0.70, RMS 1.03-1.32. On the renders the eyeball shows a dark ring
  inside the skin's margin (the renderer's socket between lid and eyeball), so the
  appearance's edge is not the mesh's margin there: the finder's offset is the renderer's as
  much as the finder's.
- the fitted upper margins against the truth (signed distance along the normal, + into the
  opening, over the frames at rest / the blinks' edges), off -> on: clip 1 left -0.55 / -2.25
  px bias (RMS 1.26 / 2.64) -> +0.28 / -0.97 (1.09 / 2.34), right -0.06 / -1.09 (0.89 / 1.69)
  -> +0.40 / +0.50 (0.75 / 0.78); clip 2 left RMS 1.43 / 2.80 -> 1.17 / 2.12, right 1.13 /
  2.07 -> 0.73 / 1.26. The upper lids sit closer to the margins, most at a blink's start,
  where the fit lagged. The lower lids follow them a little (clip 2 RMS 1.27 / 0.80 -> 1.41 /
  0.91 px, bias +0.33 -> +0.45): below the neutral's upper lid the fit has only the palpebral
  orbicularis to lower it (the levator is already at 0), and it raises the lower lid too.
- the gaze does not follow: ``analysis.gaze_error_deg`` 4.60 -> 4.58 on clip 1 (the fitted
  openings' mean, ``eye_opening_px_mean``, left (0.50, -0.54) -> (0.46, -0.21) px, right
  (0.67, 0.09) -> (0.66, 0.27)), 5.18 -> 6.17 on clip 2 (the partly closed frames, 4-5 an
  eye, read 3 -> 8 deg off: the reader's), analysis by synthesis 5.34 -> 6.18, the
  photometric fit 6.66 -> 7.89 (with both lids and no polarity rule, sigma 1 mm: 4.64 ->
  4.75, photometric 6.60 -> 4.24).
- the head-motion loop (90 frames): worst RMSE 0.288 -> 0.287, median 0.163 -> 0.165, head
  1.89 -> 1.86 deg; the levator palpebrae 0.26 / 0.26 -> 0.23 / 0.17, the palpebral
  orbicularis 0.05 / 0.05 -> 0.15 / 0.09: with the render's edge inside the margin the lids
  are read as closing a little.
- single_face.mp4: the polarity-free finder put the left upper lid on the lashes' top edge
  (the skin-to-lashes edge); with the rule the fitted upper margins sit on the lash line's
  lower edge where the eye begins (by eye, on frames 5, 20, 40, 60), 1-1.5 px lower than
  without the term, and the palpebral orbicularis reads 0.28 / 0.35 on average instead of
  0.14 / 0.12 (the person's neutral lids, placed by MediaPipe's points at calibration, are
  higher than the edges say: the rest reads as a partial closure). The gaze's spread over
  the clip, left 1.6 / 3.1 -> 1.0 / 1.1 deg (yaw / pitch SD), right 1.7 / 2.8 -> 2.2 / 1.6.
- tried and not kept: the edges taken relative to the calibration frame's (each lid's
  median offset there, taken off later frames, so that the appearance's own offset from the
  margin cancels): 5.30 / 5.40 deg on the clips, one frame's reading of a lid is too noisy.
- tried and not kept: the person's neutral upper lids moved onto the calibration frame's
  edges (each eye's median offset, the margin's vertices by it and the next ring by half, the
  lids' gains scaled again), so that rest reads as rest: gaze 5.09 / 5.84 deg on the clips
  (4.58 / 6.17 without, 4.60 / 5.18 off): the eyeball's centre is placed from the neutral's
  opening, so it moves with the lids.
- cost: the finder 0.12 ms for the 52 samples, a step's rows 0.03 ms and its cost 0.008 ms;
  in the fit 1.2 ms a frame of CPU (about 4.7 steps), and the fit takes about one more
  Gauss-Newton step a frame with it (4.2 -> 6.2 ms a frame of the fit's CPU on clip 1).
  ``analysis.fps`` with the term on 62.1 fps (0.244x MediaPipe), off 52.3 (0.178x), the same
  loaded machine one after the other: within its noise.

In a blink (``single_face.mp4``, frames 25-29, 2026-12-02, with it on): at the frames where
the person's lids meet (26, 27) it found no edge on any upper lid sample (0 of 13 an eye):
the fit's margins, following MediaPipe's points, stayed 3.4-4.1 px apart (the mean gap) where
the person's had closed, the closed lid's lash line lay beyond the +-3 px window below them,
and the lid's skin within the window has no edge. At the blink's edges (25, 28, 29) it found
edges 1.6-2.4 px into the opening on 12-92 % of the samples, pulling the lids down, and
stopped reading an eye once its fitted opening fell below ``min_opening_px``. So it cannot
close the lids; :mod:`myoface.analysis.lidtemplate` reads the lid itself sliding over the eye
against the calibration frame, and is the fit's lid term
(:data:`myoface.analysis.lidtemplate.READERS`; this term is there as ``"edges"``).

So it is opt-in (:data:`myoface.analysis.lidtemplate.READERS`): it puts the upper
lids nearer the image's margins on the renders and on the sample, but the gaze benchmark is
better on one clip and worse on the other, and the lid muscles read at rest move with where
the neutral's lids were put at calibration. What it needs to be the default: the person's
neutral lids placed by the same edges at calibration (so that rest is rest), and the gaze
reader checked on the lids it then gets.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from myoface.analysis.camera import PinholeCamera
from myoface.analysis.terms import Estimate, pixel_mm

#: the eyes' landmark groups (the face's opening margins)
EYE_GROUPS = ("eye_l", "eye_r")
#: an eye turned further than this from the line of sight is not read (its margins are seen
#: edge-on: the lid's own skin, not the opening, makes the edge)
FACING_DEG = 60.0


@dataclass(frozen=True)
class LidEdgeSettings:
    """How the lid margins' edges are read and weighed.

    window_px : the search across the margin, each side of the model's margin (px).
    step_px : the profile's sampling step (px).
    min_contrast : the least edge strength (luma levels per px) that counts.
    min_opening_px : an eye whose projected opening (mean gap between its margins) is
        narrower than this is not read (closed or closing).
    sigma_mm : the term's unit, mm on the face. 0.5 mm: of 0.3, 0.5 and 1 mm tried on the
        gaze benchmark's clip (upper lids, no polarity rule) it put the upper lids nearest
        the truth at the blinks' edges (left RMS 1.75 / 1.26 / 2.01 px) without moving them
        off at rest; it is stronger than the finder's own scatter per sample (1.0-1.4 px,
        0.8-1.1 mm) would say, because what the term is to overrule is MediaPipe's lid
        points' bias, which no number of frames averages away.
    huber : Huber's threshold (sigmas).
    polarity : which edge is the margin: ``"strongest"`` (the strongest either way),
        ``"nearest"`` (the clear extremum nearest the model's margin).
    lids : which margins are read: ``"both"`` or ``"upper"``.
    redetect_px : the edges are read again at a Gauss-Newton step's start once a sample has
        moved this far in the image since they were last read (else kept: reading them costs
        most of the term's time).
    """

    window_px: float = 3.0
    step_px: float = 0.5
    min_contrast: float = 4.0
    min_opening_px: float = 3.0
    sigma_mm: float = 0.5
    huber: float = 1.5
    polarity: str = "nearest"
    lids: str = "upper"
    redetect_px: float = 0.5
    upper_sign: int = 1


def lid_chains(face) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each eye's (upper, lower) lid margin as vertex chains corner to corner (the eye's
    landmark group's ring split at its extremes in x; the upper the one higher in the head
    frame)."""
    out = []
    for group in EYE_GROUPS:
        ring = np.asarray(face.landmarks[group], dtype=np.int64)
        x = face.vertices[ring, 0]
        i, j = sorted((int(np.argmin(x)), int(np.argmax(x))))
        one = ring[i : j + 1]
        other = np.concatenate([ring[j:], ring[: i + 1]])[::-1]
        if face.vertices[one, 1].mean() < face.vertices[other, 1].mean():
            one, other = other, one
        out.append((one, other))
    return out


class MarginSamples:
    """The sample points on the lid margins: per point the two vertices it lies between
    (``a``, ``b``) and its weight ``alpha`` on ``b`` (its place ``(1 - alpha) X_a + alpha X_b``),
    its eye (0, 1) and lid (0 upper, 1 lower)."""

    def __init__(self, face):
        a, b, al, eye, lid = [], [], [], [], []
        self.chains = lid_chains(face)
        for e, chains in enumerate(self.chains):
            for li, ch in enumerate(chains):
                # along the lid: interior vertex, midpoint to the next, ..., last interior
                for k in range(1, len(ch) - 1):
                    a.append(ch[k]), b.append(ch[k]), al.append(0.0)
                    eye.append(e), lid.append(li)
                    if k < len(ch) - 2:
                        a.append(ch[k]), b.append(ch[k + 1]), al.append(0.5)
                        eye.append(e), lid.append(li)
        self.a = np.array(a)
        self.b = np.array(b)
        self.alpha = np.array(al)
        self.eye = np.array(eye)
        self.lid = np.array(lid)
        # each sample's neighbours along its lid (itself at the lid's ends)
        n = len(self.a)
        same = np.r_[False, (self.eye[1:] == self.eye[:-1]) & (self.lid[1:] == self.lid[:-1])]
        idx = np.arange(n)
        self._prev = np.where(same, idx - 1, idx)
        self._next = np.where(np.r_[same[1:], False], idx + 1, idx)
        #: per eye: its upper lid's samples, its lower lid's, and all of its samples
        self.groups = [
            (
                np.flatnonzero((self.eye == e) & (self.lid == 0)),
                np.flatnonzero((self.eye == e) & (self.lid == 1)),
                np.flatnonzero(self.eye == e),
            )
            for e in (0, 1)
        ]

    def points(self, v: np.ndarray) -> np.ndarray:
        """The samples' places (N, 3) on vertices ``v`` (V, 3)."""
        w = self.alpha[:, None]
        return (1 - w) * v[self.a] + w * v[self.b]

    def normals(self, uv: np.ndarray) -> np.ndarray:
        """The unit image directions (N, 2) across the margin at the projected samples ``uv``
        (N, 2), pointing into the opening (towards the centroid of its eye's samples)."""
        tang = uv[self._next] - uv[self._prev]
        tang /= np.maximum(np.linalg.norm(tang, axis=1, keepdims=True), 1e-9)
        nrm = np.column_stack([-tang[:, 1], tang[:, 0]])
        centres = np.array([uv[self.eye == e].mean(0) for e in (0, 1)])
        toward = centres[self.eye] - uv
        flip = (nrm * toward).sum(1) < 0
        nrm[flip] *= -1
        return nrm


@njit(cache=True, nogil=True)
def _luma_at(img, x, y):
    """The BT.601 luma of RGB ``img`` (H, W, 3) at ``(x, y)`` (pixel centres at integers),
    bilinear, clamped to the image."""
    h, w = img.shape[0], img.shape[1]
    x = min(max(x, 0.0), w - 1.001)
    y = min(max(y, 0.0), h - 1.001)
    x0, y0 = int(np.floor(x)), int(np.floor(y))
    fx, fy = x - x0, y - y0
    out = 0.0
    for c in range(3):
        wc = 0.299 if c == 0 else (0.587 if c == 1 else 0.114)
        v = (
            img[y0, x0, c] * (1 - fx) * (1 - fy)
            + img[y0, x0 + 1, c] * fx * (1 - fy)
            + img[y0 + 1, x0, c] * (1 - fx) * fy
            + img[y0 + 1, x0 + 1, c] * fx * fy
        )
        out += wc * v
    return out


@njit(cache=True, nogil=True)
def _edges(img, uv, nrm, sign, window, step, min_contrast, nearest):
    """:func:`find_edges`' loop (compiled): per sample the profile, its derivative, the
    edge's offset, signed strength and whether it is clear."""
    n = uv.shape[0]
    nt = int(np.floor((2 * window + 2 * step) / step + 1e-9)) + 1  # ts from -window - step
    off = np.zeros(n)
    strength = np.zeros(n)
    ok = np.zeros(n, dtype=np.bool_)
    prof = np.zeros(nt)
    smooth = np.zeros(nt)
    nd = nt - 2
    der = np.zeros(nd)
    mag = np.zeros(nd)
    for i in range(n):
        nx, ny = nrm[i, 0], nrm[i, 1]
        tx, ty = -ny, nx
        for k in range(nt):
            t = -window - step + k * step
            acc = 0.0
            for sd in (-1.0, 0.0, 1.0):
                acc += _luma_at(img, uv[i, 0] + t * nx + sd * tx, uv[i, 1] + t * ny + sd * ty)
            prof[k] = acc / 3.0
        for k in range(nt):
            a = prof[max(k - 1, 0)]
            b = prof[min(k + 1, nt - 1)]
            smooth[k] = 0.25 * a + 0.5 * prof[k] + 0.25 * b
        best, bmax = -1, 0.0
        for k in range(nd):
            der[k] = (smooth[k + 2] - smooth[k]) / (2 * step)
            m = abs(der[k])
            if sign[i] > 0:
                m = max(der[k], 0.0)
            elif sign[i] < 0:
                m = max(-der[k], 0.0)
            mag[k] = m
            if m > bmax:
                bmax, best = m, k
        if nearest:
            thr = max(min_contrast, 0.5 * bmax)
            best, dbest = -1, 1e30
            for k in range(1, nd - 1):
                if mag[k] >= mag[k - 1] and mag[k] >= mag[k + 1] and mag[k] >= thr:
                    d = abs(-window + k * step)
                    if d < dbest:
                        dbest, best = d, k
        if best <= 0 or best >= nd - 1:
            continue
        m0, m1, m2 = mag[best - 1], mag[best], mag[best + 1]
        den = m0 - 2 * m1 + m2
        frac = 0.5 * (m0 - m2) / den if den < -1e-9 else 0.0
        frac = min(max(frac, -0.5), 0.5)
        o = -window + best * step + frac * step
        off[i] = o
        strength[i] = m1 if der[best] >= 0 else -m1
        ok[i] = m1 >= min_contrast and abs(o) <= window
    return off, strength, ok


@njit(cache=True, nogil=True)
def _rows(rot, trans, shape, jac, free, ia, ib, alpha, nrm, target, scale, f, cx, cy, hw,
          huber, want_normal):  # fmt: skip
    """The term's residuals at a pose and skin: its cost (Huber's) and, with
    ``want_normal``, its normal equations (H, b) in (omega, dt, dc[free])."""
    n = ia.shape[0]
    nf = free.shape[0]
    nu = 6 + nf
    hmat = np.zeros((nu, nu))
    bvec = np.zeros(nu)
    row = np.zeros(nu)
    cost = 0.0
    for i in range(n):
        al = alpha[i]
        x = (1 - al) * shape[ia[i]] + al * shape[ib[i]]
        rx = rot @ x
        pc = rx + trans
        d = max(-pc[2], 1e-6)
        u = cx + f * pc[0] / d
        v = cy - f * pc[1] / d
        r = (nrm[i, 0] * u + nrm[i, 1] * v - target[i]) * scale
        ar = abs(r)
        cost += r * r if ar <= huber else 2 * huber * ar - huber * huber
        if not want_normal:
            continue
        # g = n^T d(u, v)/dP, scaled
        g0 = nrm[i, 0] * f / d * scale
        g1 = -nrm[i, 1] * f / d * scale
        g2 = (nrm[i, 0] * f * pc[0] / d**2 - nrm[i, 1] * f * pc[1] / d**2) * scale
        row[0] = rx[1] * g2 - rx[2] * g1
        row[1] = rx[2] * g0 - rx[0] * g2
        row[2] = rx[0] * g1 - rx[1] * g0
        row[3], row[4], row[5] = g0, g1, g2
        # head-frame direction R^T g
        h0 = rot[0, 0] * g0 + rot[1, 0] * g1 + rot[2, 0] * g2
        h1 = rot[0, 1] * g0 + rot[1, 1] * g1 + rot[2, 1] * g2
        h2 = rot[0, 2] * g0 + rot[1, 2] * g1 + rot[2, 2] * g2
        for j in range(nf):
            m = free[j]
            row[6 + j] = (1 - al) * (
                h0 * jac[ia[i], 0, m] + h1 * jac[ia[i], 1, m] + h2 * jac[ia[i], 2, m]
            ) + al * (h0 * jac[ib[i], 0, m] + h1 * jac[ib[i], 1, m] + h2 * jac[ib[i], 2, m])
        w = hw[i]
        for p in range(nu):
            bvec[p] -= w * row[p] * r
            for q in range(p, nu):
                hmat[p, q] += w * row[p] * row[q]
    for p in range(nu):
        for q in range(p):
            hmat[p, q] = hmat[q, p]
    return cost, hmat, bvec


def find_edges(img, uv, normals, settings: LidEdgeSettings | None = None, sign=None):
    """The edge across each sample's profile: ``uv`` (N, 2) the model's margin points (px),
    ``normals`` (N, 2) unit directions across the margin, on ``img`` (H, W, 3) RGB. Returns
    the edges' offsets (N,) px along the normals from ``uv``, their strength (N,) luma per
    px (signed: + where the luma rises along the normal), and whether each is clear (N,)
    bool (see the module's docstring). ``sign`` (N,): +1 where only an edge that brightens
    along the normal counts, -1 where only one that darkens, 0 either (default)."""
    s = settings or LidEdgeSettings()
    uv = np.ascontiguousarray(uv, dtype=np.float64)
    normals = np.ascontiguousarray(normals, dtype=np.float64)
    sg = np.zeros(len(uv)) if sign is None else np.asarray(sign, dtype=np.float64)
    return _edges(
        np.asarray(img), uv, normals, np.ascontiguousarray(sg), float(s.window_px),
        float(s.step_px), float(s.min_contrast), s.polarity == "nearest",
    )  # fmt: skip


class LidEdgeTerm:
    """The lid margins' image edges against the model's margin points (see the module's
    docstring).

    Parameters
    ----------
    image : the frame (H, W, 3) RGB.
    samples : :class:`MarginSamples` of the face.
    camera : PinholeCamera.
    settings : LidEdgeSettings.
    """

    def __init__(self, image, samples: MarginSamples, camera: PinholeCamera,
                 settings: LidEdgeSettings | None = None):  # fmt: skip
        self.image = np.asarray(image)
        self.samples = samples
        self.camera = camera
        self.settings = settings or LidEdgeSettings()
        self.mm_per_px = 1.0
        # the edges found at the step's start: (rows used, normals, their targets n . e)
        self.used = np.zeros(0, dtype=np.int64)
        self.nrm = np.zeros((0, 2))
        self.target = np.zeros(0)
        self.hw = np.zeros(0)
        self._at = None  # the samples' image points where the edges were last read

    # ---------------------------------------------------------- what the frame says
    def _project(self, est: Estimate):
        x = self.samples.points(est.shape)
        pc = est.pose.apply(x)
        return x, pc, self.camera.project(pc)

    def _readable(self, est: Estimate, uv) -> np.ndarray:
        """(N,) the samples of the eyes that are open (the mean gap between the projected
        margins at least :attr:`LidEdgeSettings.min_opening_px`, the upper above the lower in
        the head's own up direction) and face the camera (the head's forward axis within
        :data:`FACING_DEG` of the line of sight to the eye)."""
        s, sm = self.settings, self.samples
        ok = np.ones(len(uv), dtype=bool)
        rot = est.pose.rotation
        up_img = np.array([rot[0, 1], -rot[1, 1]])  # the head's +y in the image (y down)
        fwd = rot[:, 2]
        for iu, il, ie in sm.groups:
            d = uv[iu].mean(0) - uv[il].mean(0)
            gap = float(np.hypot(*d))
            pc = est.pose.apply(est.shape[sm.a[ie[:1]]])[0]
            facing = float(-pc @ fwd / max(np.linalg.norm(pc), 1e-9))
            if gap < s.min_opening_px or d @ up_img <= 0 or facing < np.cos(np.radians(FACING_DEG)):
                ok[ie] = False
        return ok

    def detect(self, est: Estimate) -> dict:
        """Read the edges at ``est``; also returned (for checks): the samples' image points,
        normals, offsets, strengths and which count."""
        _, _, uv = self._project(est)
        sm = self.samples
        nrm = sm.normals(uv)
        want = self._readable(est, uv)
        if self.settings.lids == "upper":
            want &= sm.lid == 0
        sel = np.flatnonzero(want)
        sign = np.where(sm.lid[sel] == 0, self.settings.upper_sign, 0)
        off = np.zeros(len(uv))
        strength = np.zeros(len(uv))
        ok = np.zeros(len(uv), dtype=bool)
        if len(sel):
            off[sel], strength[sel], ok[sel] = find_edges(
                self.image, uv[sel], nrm[sel], self.settings, sign
            )
        self.used = np.flatnonzero(ok)
        self.nrm = nrm[self.used]
        self.target = ((uv[self.used] + off[self.used, None] * self.nrm) * self.nrm).sum(1)
        return {"uv": uv, "normals": nrm, "offsets": off, "strength": strength, "ok": ok}

    def prepare(self, est: Estimate) -> None:
        self.mm_per_px = pixel_mm(self.camera, est.pose)
        _, _, uv = self._project(est)
        if self._at is None or np.abs(uv - self._at).max() > self.settings.redetect_px:
            self.detect(est)
            self._at = uv
        r = self._residuals(est)
        h = self.settings.huber
        self.hw = np.where(np.abs(r) > h, h / np.maximum(np.abs(r), 1e-12), 1.0)

    def _call(self, est: Estimate, want_normal: bool):
        sm, u = self.samples, self.used
        cam = self.camera
        return _rows(
            np.ascontiguousarray(est.pose.rotation), np.asarray(est.pose.translation_mm, float),
            np.ascontiguousarray(est.shape, dtype=np.float64), est.jac,
            np.asarray(est.free, dtype=np.int64), sm.a[u], sm.b[u], sm.alpha[u], self.nrm,
            self.target, self.mm_per_px / self.settings.sigma_mm, float(cam.focal_px),
            float(cam.cx), float(cam.cy), self.hw, self.settings.huber, want_normal,
        )  # fmt: skip

    def _residuals(self, est: Estimate) -> np.ndarray:
        if not len(self.used):
            return np.zeros(0)
        _, _, uv = self._project(est)
        d = (uv[self.used] * self.nrm).sum(1) - self.target
        return d * (self.mm_per_px / self.settings.sigma_mm)

    def normal_equations(self, est: Estimate):
        if not len(self.used):
            n = est.n_unknowns
            return np.zeros((n, n)), np.zeros(n)
        _, hmat, b = self._call(est, True)
        return hmat, b

    def cost(self, est: Estimate) -> float:
        if not len(self.used):
            return 0.0
        return float(self._call(est, False)[0])
