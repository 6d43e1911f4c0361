"""The lid margins read from the image: an edge term of the 3-D fit's energy.

The paper's own idea (Terzopoulos & Waters 1993, Section V: the image's edges made into
potentials the model's contours slide into) applied to the fitted model's lid margins. The fit
otherwise places the lids from MediaPipe's lid points, which sit a fraction of a pixel to a
pixel off the image's margins in a way that depends on the face and the view (on the gaze
benchmark's renders the fitted openings' mean point sits 0.5-0.7 px off the truth's), and the
eyeball's centre and the gaze read from it follow.

What is measured (:func:`find_edges`): along each lid margin of the fitted model (the margin's
vertex chain from :func:`lid_chains`, projected into the frame) sample points are taken (the
chain's interior vertices and the midpoints between them; the corners are left out: their
normal is not defined and the margins meet there), and at each the frame's luma is read on a
short profile across the margin (along the projected normal, +-:attr:`LidEdgeSettings.
window_px`, every half pixel, averaged over three parallel lines a pixel apart and smoothed).
The margin is the profile's edge: the strongest extremum of its derivative within the window,
placed to a fraction of a pixel by a parabola through the extremum and its two neighbours.
A sample counts only where that edge is clear (its contrast at least
:attr:`LidEdgeSettings.min_contrast` grey levels per pixel, and the edge not at the window's
end). An eye is not read while its lids are closed (the projected opening narrower than
:attr:`LidEdgeSettings.min_opening_px`), nor when it turns away from the camera.

The term (:class:`LidEdgeTerm`): each found edge ``e`` with the profile's direction ``n`` adds
the row ``n . (proj(R X + t) - e) k / sigma`` for the model's point ``X`` on the margin there
(``k`` mm per pixel at the head's depth, so it is in mm on the face): a point-to-line distance,
since an edge says where the margin is across it, not along it. Huber-weighted (beyond
:attr:`LidEdgeSettings.huber` sigmas), the edges read again at the start of each Gauss-Newton
step (at the step's estimate).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from myoface.analysis.camera import PinholeCamera
from myoface.analysis.terms import Estimate, pixel_mm

#: the eyes' landmark groups (the face's opening margins)
EYE_GROUPS = ("eye_l", "eye_r")
#: luma weights (ITU-R BT.601)
_LUMA = np.array([0.299, 0.587, 0.114])


@dataclass(frozen=True)
class LidEdgeSettings:
    """How the lid margins' edges are read and weighed.

    window_px : the search across the margin, each side of the model's margin (px).
    step_px : the profile's sampling step (px).
    min_contrast : the least edge strength (luma levels per px) that counts.
    min_opening_px : an eye whose projected opening (mean gap between its margins) is
        narrower than this is not read (closed or closing).
    sigma_mm : the edge's scatter about the true margin, mm on the face (the term's unit).
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
    sigma_mm: float = 1.0
    huber: float = 1.5
    polarity: str = "nearest"
    lids: str = "both"
    redetect_px: float = 0.5


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
                for k in range(1, len(ch) - 1):  # interior vertices
                    a.append(ch[k]), b.append(ch[k]), al.append(0.0)
                    eye.append(e), lid.append(li)
                for k in range(1, len(ch) - 2):  # midpoints between interior vertices
                    a.append(ch[k]), b.append(ch[k + 1]), al.append(0.5)
                    eye.append(e), lid.append(li)
        self.a = np.array(a)
        self.b = np.array(b)
        self.alpha = np.array(al)
        self.eye = np.array(eye)
        self.lid = np.array(lid)

    def points(self, v: np.ndarray) -> np.ndarray:
        """The samples' places (N, 3) on vertices ``v`` (V, 3)."""
        w = self.alpha[:, None]
        return (1 - w) * v[self.a] + w * v[self.b]

    def normals(self, uv: np.ndarray, centres: np.ndarray) -> np.ndarray:
        """The unit image directions (N, 2) across the margin at the projected samples ``uv``
        (N, 2), pointing into the opening (towards ``centres`` (2, 2), each eye's)."""
        n = len(uv)
        tang = np.zeros((n, 2))
        # the tangent from the neighbouring samples of the same lid (the samples of a lid are
        # vertices then midpoints: order them along the lid by their vertex positions)
        for e in (0, 1):
            for li in (0, 1):
                idx = np.flatnonzero((self.eye == e) & (self.lid == li))
                p = uv[idx]
                order = np.argsort(p @ (p[-1] - p[0]) if len(p) > 1 else np.zeros(len(p)))
                q = p[order]
                t = np.gradient(q, axis=0) if len(q) > 1 else np.tile([1.0, 0.0], (len(q), 1))
                tang[idx[order]] = t
        tang /= np.maximum(np.linalg.norm(tang, axis=1, keepdims=True), 1e-9)
        nrm = np.column_stack([-tang[:, 1], tang[:, 0]])
        toward = centres[self.eye] - uv
        flip = (nrm * toward).sum(1) < 0
        nrm[flip] *= -1
        return nrm


def _bilinear_luma(img: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The luma of RGB ``img`` (H, W, 3) at pixel positions ``x``, ``y`` (any shape; pixel
    centres at integers), bilinear, clamped to the image."""
    h, w = img.shape[:2]
    x = np.clip(x, 0, w - 1.001)
    y = np.clip(y, 0, h - 1.001)
    x0 = np.floor(x).astype(np.int64)
    y0 = np.floor(y).astype(np.int64)
    fx, fy = x - x0, y - y0
    if img.ndim == 3:
        img = img @ _LUMA
    flat = img.reshape(-1)
    i = y0 * w + x0

    def g(k):
        return flat[k]

    return (
        g(i) * (1 - fx) * (1 - fy)
        + g(i + 1) * fx * (1 - fy)
        + g(i + w) * (1 - fx) * fy
        + g(i + w + 1) * fx * fy
    )


def find_edges(img, uv, normals, settings: LidEdgeSettings | None = None):
    """The edge across each sample's profile: ``uv`` (N, 2) the model's margin points (px),
    ``normals`` (N, 2) unit directions across the margin. Returns the edges' offsets (N,) px
    along the normals from ``uv``, their strength (N,) luma per px, and whether each is
    clear (N,) bool (see the module's docstring)."""
    s = settings or LidEdgeSettings()
    ts = np.arange(-s.window_px - s.step_px, s.window_px + 1.5 * s.step_px, s.step_px)
    tang = np.column_stack([-normals[:, 1], normals[:, 0]])
    side = np.array([-1.0, 0.0, 1.0])
    # (N, 3 lines, T) positions
    px = (
        uv[:, None, None, :]
        + ts[None, None, :, None] * normals[:, None, None, :]
        + side[None, :, None, None] * tang[:, None, None, :]
    )
    # the luma of the samples' neighbourhood only (a crop: a whole frame's costs more)
    lo = np.floor(px.reshape(-1, 2).min(0)).astype(np.int64) - 1
    hi = np.ceil(px.reshape(-1, 2).max(0)).astype(np.int64) + 2
    h, w = img.shape[:2]
    lo = np.clip(lo, 0, [w - 2, h - 2])
    hi = np.clip(hi, lo + 2, [w, h])
    crop = img[lo[1] : hi[1], lo[0] : hi[0]]
    luma = crop @ _LUMA if crop.ndim == 3 else crop.astype(np.float64)
    prof = _bilinear_luma(luma, px[..., 0] - lo[0], px[..., 1] - lo[1]).mean(axis=1)  # (N, T)
    prof = np.concatenate([prof[:, :1], prof, prof[:, -1:]], axis=1)
    prof = 0.25 * prof[:, :-2] + 0.5 * prof[:, 1:-1] + 0.25 * prof[:, 2:]
    der = (prof[:, 2:] - prof[:, :-2]) / (2 * s.step_px)  # at ts[1:-1]
    tc = ts[1:-1]
    mag = np.abs(der)
    n = len(uv)
    if s.polarity == "nearest":
        peak = np.zeros_like(mag, dtype=bool)
        peak[:, 1:-1] = (mag[:, 1:-1] >= mag[:, :-2]) & (mag[:, 1:-1] >= mag[:, 2:])
        peak &= mag >= np.maximum(s.min_contrast, 0.5 * mag.max(axis=1, keepdims=True))
        dist = np.where(peak, np.abs(tc)[None], np.inf)
        k = np.argmin(dist, axis=1)
    else:
        k = np.argmax(mag, axis=1)
    rows = np.arange(n)
    strength = mag[rows, k]
    inside = (k > 0) & (k < len(tc) - 1)
    kk = np.clip(k, 1, len(tc) - 2)
    m0, m1, m2 = mag[rows, kk - 1], mag[rows, kk], mag[rows, kk + 1]
    den = m0 - 2 * m1 + m2
    frac = np.where(den < -1e-9, 0.5 * (m0 - m2) / np.where(den < -1e-9, den, -1.0), 0.0)
    off = tc[kk] + np.clip(frac, -0.5, 0.5) * s.step_px
    ok = inside & (strength >= s.min_contrast) & (np.abs(off) <= s.window_px)
    return off, strength, ok


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
        """(N,) the samples of eyes open and facing the camera."""
        s, sm = self.settings, self.samples
        ok = np.ones(len(uv), dtype=bool)
        for e in (0, 1):
            up = (sm.eye == e) & (sm.lid == 0)
            lo = (sm.eye == e) & (sm.lid == 1)
            gap = float(np.linalg.norm(uv[up].mean(0) - uv[lo].mean(0)))
            # facing: the opening's image area against its extent (a turned-away eye's
            # projected margins cross or collapse)
            cu, cl = uv[up].mean(0), uv[lo].mean(0)
            if gap < s.min_opening_px or cu[1] >= cl[1] - 0.5 * s.min_opening_px:
                ok[sm.eye == e] = False
        return ok

    def detect(self, est: Estimate) -> dict:
        """Read the edges at ``est``; also returned (for checks): the samples' image points,
        normals, offsets, strengths and which count."""
        _, _, uv = self._project(est)
        sm = self.samples
        centres = np.array([uv[sm.eye == e].mean(0) for e in (0, 1)])
        nrm = sm.normals(uv, centres)
        off, strength, ok = find_edges(self.image, uv, nrm, self.settings)
        ok &= self._readable(est, uv)
        if self.settings.lids == "upper":
            ok &= sm.lid == 0
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

    def _residuals(self, est: Estimate) -> np.ndarray:
        if not len(self.used):
            return np.zeros(0)
        _, _, uv = self._project(est)
        d = (uv[self.used] * self.nrm).sum(1) - self.target
        return d * (self.mm_per_px / self.settings.sigma_mm)

    def normal_equations(self, est: Estimate):
        n = est.n_unknowns
        hmat, b = np.zeros((n, n)), np.zeros(n)
        if not len(self.used):
            return hmat, b
        sm = self.samples
        u = self.used
        x = sm.points(est.shape)[u]
        pc = est.pose.apply(x)
        dproj = self.camera.projection_jacobian(pc)  # (n, 2, 3)
        g = np.einsum("ni,nij->nj", self.nrm, dproj) * (self.mm_per_px / self.settings.sigma_mm)
        rx = pc - est.pose.translation_mm  # R X
        jrow = np.zeros((len(u), n))
        # d P / d omega = omega x (R X) -> g . (omega x rx) = omega . (rx x g)
        jrow[:, :3] = np.cross(rx, g)
        jrow[:, 3:6] = g
        if len(est.free):
            al = sm.alpha[u][:, None, None]
            jx = (1 - al) * est.jac[sm.a[u]][:, :, est.free] + al * est.jac[sm.b[u]][:, :, est.free]
            gr = g @ est.pose.rotation  # (n, 3) in the head frame
            jrow[:, 6:] = np.einsum("ni,nif->nf", gr, jx)
        r = self._residuals(est)
        w = self.hw
        hmat = jrow.T @ (jrow * w[:, None])
        b = -jrow.T @ (w * r)
        return hmat, b

    def cost(self, est: Estimate) -> float:
        r = np.abs(self._residuals(est))
        h = self.settings.huber
        return float(np.where(r <= h, r**2, 2 * h * r - h**2).sum())
