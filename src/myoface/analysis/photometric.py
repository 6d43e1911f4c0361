"""The photometric term of the 3-D fit: the model, posed and deformed, seen through the camera,
reproduces the frame's pixels at the model's visible surface points (the image-level analysis
the paper's discussion asks for; the photometric term of model-based trackers such as
Face2Face, Thies et al. 2016, and optical flow as a constraint on a deformable face model,
DeCarlo & Metaxas 2000).

**Why pixels, not points.** A landmark detector reads an expression's motion short (MediaPipe's
face mesh 0.5-0.7 of it), and a tracker of patches (Lucas-Kanade) assumes that the motion is
constant over its window, which the skin's motion near the lips and the mouth corners is not:
on a real frame warped by the face model's own smile, patch flow read 0.70 of the mouth
corners' motion, where the fit given the exact points reproduced 0.91 (2026-12-01,
``myoface bench --only analysis.known_warp``). Here every sample point lies on a triangle of
the face mesh at fixed barycentric coordinates, so it moves exactly as the model's skin moves
there (piecewise linearly between the vertices); no window's motion is assumed.

**The appearance** is the calibration frame's: each sample's brightness there, the model at the
calibration pose and the person's neutral (:meth:`Appearance.from_frame`). A frame is always
compared with it, never with the previous frame, so the fit does not drift. The lighting of a
frame is a gain and an offset per region of the face (:data:`LIGHT_REGIONS`: left and right,
upper and lower), solved in closed form at each step's start: a light that changes slowly, or
the camera's exposure, is followed, not fitted as expression. (Second-order spherical harmonics
with an albedo, as Face2Face fits, would also follow shading that moves across the face as the
head turns; not done yet.)

**Coarse to fine.** The images are blurred by a Gaussian of :data:`BLUR_SCHEDULE_PX` pixels
(the first steps on the most blurred: it reaches a few pixels of motion), each level with its
own appearance.

**The residual** of a sample ``s`` with surface point ``X_s`` is ``(I(proj(R X_s + t)) - g_r A_s
- o_r) / sigma`` (``A_s`` its appearance, ``g_r, o_r`` its region's light), Gauss-Newton through
the image's gradient and the projected vertices' Jacobian. Robust weights (Huber beyond
:attr:`PhotometricTerm.huber` sigmas) take out what the model's surface does not show: teeth
or the tongue where the lips part, the eyes' irises, a hand. Samples on triangles turned away
from the camera weigh 0 (a sample's visibility is its triangle's normal; occlusion by another
part of the face, e.g. the nose at a large yaw, is not tested: a depth buffer would).

Samples near one another see nearly the same blurred pixels: their errors are not independent.
Each sample weighs ``min(1, (spacing / (2 blur))^2)`` so that the term counts about one
independent measurement per blur-sized patch of skin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from myoface.analysis.terms import Estimate
from myoface.errors import MyofaceValueError
from myoface.facemesh import import_opencv

#: barycentric subdivision of each triangle: the samples at (i, j, k) / N, i + j + k = N, all
#: three >= 1 (inside the triangle): N = 4 gives 3 per triangle, ~2700 on the default face
SUBDIVISION = 4
#: the Gaussian blurs (pixels) of the coarse-to-fine levels, and how many of a frame's
#: Gauss-Newton steps each gets (the last level takes the rest)
BLUR_SCHEDULE_PX = (4.0, 2.0, 1.0)
STEPS_PER_LEVEL = (2, 2)
#: the lighting's regions: the face split at the head frame's x = 0 (left, right) and at this
#: height (mm, head frame; about the nose's tip)
LIGHT_SPLIT_Y_MM = -20.0
LIGHT_REGIONS = 4


def _cv2():
    return import_opencv("the photometric fit")


def grey(frame) -> np.ndarray:
    """A frame's brightness (H, W) float32, 0-255 (ITU-R BT.601 luma)."""
    img = np.asarray(frame)
    if img.ndim == 2:
        return img.astype(np.float32)
    return (
        _cv2()
        .cvtColor(np.ascontiguousarray(img[..., :3]), _cv2().COLOR_RGB2GRAY)
        .astype(np.float32)
    )


def blurred(image: np.ndarray, sigma_px: float) -> np.ndarray:
    return _cv2().GaussianBlur(image, (0, 0), float(sigma_px))


def _sample(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """``image`` (H, W) float32 bilinearly at ``uv`` (S, 2) pixels (x, y); outside: NaN."""
    cv2 = _cv2()
    m = np.ascontiguousarray(uv.reshape(1, -1, 2), dtype=np.float32)
    out = cv2.remap(image, m[..., 0], m[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                    borderValue=np.nan)  # fmt: skip
    return out.reshape(-1).astype(np.float64)


@dataclass(frozen=True)
class SurfaceSamples:
    """Sample points on a face mesh: ``tri`` (S, 3) the vertices of each sample's triangle,
    ``bary`` (S, 3) its barycentric coordinates, ``tri_index`` (S,) its triangle."""

    tri: np.ndarray
    bary: np.ndarray
    tri_index: np.ndarray

    @classmethod
    def on(cls, triangles: np.ndarray, subdivision: int = SUBDIVISION) -> SurfaceSamples:
        n = int(subdivision)
        if n < 3:
            raise MyofaceValueError(f"subdivision must be >= 3; got {subdivision}")
        b = (
            np.array(
                [(i, j, n - i - j) for i in range(1, n) for j in range(1, n - i)], dtype=np.float64
            )
            / n
        )
        tris = np.asarray(triangles, dtype=np.int64)
        k = len(b)
        return cls(np.repeat(tris, k, axis=0), np.tile(b, (len(tris), 1)),
                   np.repeat(np.arange(len(tris)), k))  # fmt: skip

    def points(self, vertices: np.ndarray) -> np.ndarray:
        """The samples' positions (S, 3) on ``vertices`` (V, 3)."""
        return np.einsum("sk,skd->sd", self.bary, vertices[self.tri])

    def __len__(self) -> int:
        return len(self.tri)


def facing(samples: SurfaceSamples, triangles, camera_points: np.ndarray) -> np.ndarray:
    """Each sample's facing (S,): the cosine between its triangle's normal and the direction
    to the camera, at the vertices' camera-frame positions ``camera_points`` (V, 3) (the
    mesh's triangles wind counter-clockwise seen from the front)."""
    t = np.asarray(triangles, dtype=np.int64)
    a, b, c = (camera_points[t[:, k]] for k in range(3))
    n = np.cross(b - a, c - a)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    centre = (a + b + c) / 3
    view = -centre / np.maximum(np.linalg.norm(centre, axis=1, keepdims=True), 1e-12)
    return (n * view).sum(1)[samples.tri_index]


@dataclass
class Appearance:
    """The person's appearance at the model's surface samples: for each blur level
    (:data:`BLUR_SCHEDULE_PX`), the calibration frame's brightness (S,) at the samples
    (NaN where the sample was not seen there), and the samples' light region (S,)."""

    samples: SurfaceSamples
    triangles: np.ndarray
    levels: tuple[float, ...]
    values: list
    region: np.ndarray
    spacing_px: float

    @classmethod
    def from_frame(cls, frame, face, camera, pose, shape, levels=BLUR_SCHEDULE_PX,
                   subdivision: int = SUBDIVISION) -> Appearance:  # fmt: skip
        """The appearance of ``frame`` (the calibration frame), the model's skin ``shape``
        (V, 3) mm head frame (the person's neutral) at ``pose`` through ``camera``."""
        samples = SurfaceSamples.on(face.triangles, subdivision)
        pc = pose.apply(shape)
        pts = samples.points(pc)
        uv = camera.project(pts)
        seen = facing(samples, face.triangles, pc) > 0.2
        img = grey(frame)
        values = []
        for s in levels:
            v = _sample(blurred(img, s), uv)
            v[~seen] = np.nan
            values.append(v)
        head = samples.points(np.asarray(shape, dtype=np.float64))
        region = (head[:, 0] > 0).astype(np.int64) + 2 * (head[:, 1] < LIGHT_SPLIT_Y_MM)
        # the samples' mean spacing on the image: the face's projected area over their count
        area = 0.0
        tri = np.asarray(face.triangles)
        uvv = camera.project(pc)
        e1, e2 = uvv[tri[:, 1]] - uvv[tri[:, 0]], uvv[tri[:, 2]] - uvv[tri[:, 0]]
        area = float(np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum() / 2)
        spacing = float(np.sqrt(area / max(len(samples), 1)))
        return cls(samples, tri, tuple(levels), values, region, spacing)


class PhotometricTerm:
    """The frame's pixels against the appearance at the model's surface samples (see the
    module's docstring). ``frame``: the RGB (or grey) frame; ``appearance``: the calibration
    frame's (:class:`Appearance`); ``sigma``: a sample's brightness error, grey levels (1 sd:
    the camera's noise and what the model's surface does not reproduce); ``huber``: robust
    beyond this many sigmas; ``weight``: the whole term's (1: as the module says)."""

    def __init__(self, frame, appearance: Appearance, camera, sigma: float = 8.0,
                 huber: float = 2.0, weight: float = 1.0):  # fmt: skip
        if not sigma > 0 or not huber > 0 or not weight >= 0:
            raise MyofaceValueError("the photometric term needs sigma > 0, huber > 0, weight >= 0")
        self.app = appearance
        self.camera = camera
        self.sigma = float(sigma)
        self.huber = float(huber)
        self.weight = float(weight)
        cv2 = _cv2()
        img = grey(frame)
        self._images = []
        for s in appearance.levels:
            b = blurred(img, s)
            gx = cv2.Sobel(b, cv2.CV_32F, 1, 0, ksize=3, scale=1 / 8)
            gy = cv2.Sobel(b, cv2.CV_32F, 0, 1, ksize=3, scale=1 / 8)
            self._images.append((b, gx, gy))
        self._step = 0
        self._level = 0
        self._w = None  # per sample: weight (visibility, independence, Huber), fixed over a step
        self._light = None  # (gain, offset) per region, fixed over a step

    def restart(self) -> None:
        """Start the coarse-to-fine schedule again (a new round of Gauss-Newton steps)."""
        self._step = 0
        self._w = None

    # -------------------------------------------------------------- the schedule
    def _level_for(self, step: int) -> int:
        k = 0
        for n in STEPS_PER_LEVEL:
            if step < n:
                return k
            step -= n
            k += 1
        return min(k, len(self._images) - 1)

    @property
    def settling(self) -> bool:
        """Whether the term is still on a coarse level (the solver is not done with it)."""
        return self._level_for(self._step) < len(self._images) - 1

    def advance(self) -> None:
        """Go to the next level at the next step's start."""
        here = self._level_for(self._step)
        while self._level_for(self._step) == here:
            self._step += 1

    def _uv(self, est: Estimate):
        pc = est.pose.apply(est.shape)
        return pc, self.camera.project(self.app.samples.points(pc))

    def _residual(self, uv, level, light):
        img = self._images[level][0]
        val = _sample(img, uv)
        a = self.app.values[level]
        g, o = light
        r = self.app.region
        return val - (g[r] * a + o[r])

    def prepare(self, est: Estimate) -> None:
        self._level = self._level_for(self._step)
        self._step += 1
        pc, uv = self._uv(est)
        a = self.app.values[self._level]
        val = _sample(self._images[self._level][0], uv)
        vis = facing(self.app.samples, self.app.triangles, pc) > 0.2
        ok = vis & np.isfinite(a) & np.isfinite(val)
        # the light: a gain and offset per region (least squares over the region's samples)
        g, o = np.ones(LIGHT_REGIONS), np.zeros(LIGHT_REGIONS)
        w_prev = None if self._w is None else self._w
        for k in range(LIGHT_REGIONS):
            m = ok & (self.app.region == k)
            if w_prev is not None:
                m &= w_prev > 0
            if m.sum() < 20:
                continue
            x, y = a[m], val[m]
            vx = float(x.var())
            if vx < 1e-6:
                continue
            gk = float(((x - x.mean()) * (y - y.mean())).mean() / vx)
            gk = float(np.clip(gk, 0.5, 2.0))
            g[k], o[k] = gk, float(y.mean() - gk * x.mean())
        self._light = (g, o)
        r = np.where(ok, val - (g[self.app.region] * a + o[self.app.region]), 0.0) / self.sigma
        blur = self.app.levels[self._level]
        indep = min(1.0, (self.app.spacing_px / (2.0 * blur)) ** 2)
        hub = np.where(np.abs(r) > self.huber, self.huber / np.maximum(np.abs(r), 1e-12), 1.0)
        self._w = np.where(ok, indep * hub * self.weight, 0.0)

    def _rows(self, est: Estimate):
        """The weighted rows' Jacobian (S, n) and residuals (S,) at ``est``."""
        free = est.free
        nf = len(free)
        n = 6 + nf
        rot = est.pose.rotation
        rx = est.shape @ rot.T  # R X (V, 3)
        pc = rx + est.pose.translation_mm
        dproj = self.camera.projection_jacobian(pc)  # (V, 2, 3)
        # dP/d(unknowns) per vertex (V, 3, n): omega x (R X) = -[RX]x omega, dt, R J dc
        dp = np.zeros((len(pc), 3, n))
        dp[:, 0, 1], dp[:, 0, 2] = rx[:, 2], -rx[:, 1]
        dp[:, 1, 0], dp[:, 1, 2] = -rx[:, 2], rx[:, 0]
        dp[:, 2, 0], dp[:, 2, 1] = rx[:, 1], -rx[:, 0]
        dp[:, 0, 3] = dp[:, 1, 4] = dp[:, 2, 5] = 1.0
        if nf:
            dp[:, :, 6:] = np.einsum("ij,vjf->vif", rot, est.jac[:, :, free])
        duv = np.einsum("vij,vjn->vin", dproj, dp)  # (V, 2, n)
        s = self.app.samples
        dsample = np.einsum("sk,skin->sin", s.bary, duv[s.tri])  # (S, 2, n)
        uv = self.camera.project(s.points(pc))
        _, gx, gy = self._images[self._level]
        g = np.column_stack([_sample(gx, uv), _sample(gy, uv)])
        g = np.nan_to_num(g)
        rows = np.einsum("si,sin->sn", g, dsample) / self.sigma
        res = np.nan_to_num(self._residual(uv, self._level, self._light)) / self.sigma
        return rows, res

    def normal_equations(self, est: Estimate):
        rows, res = self._rows(est)
        w = self._w
        h = rows.T @ (rows * w[:, None])
        b = -rows.T @ (w * res)
        return h, b

    def cost(self, est: Estimate) -> float:
        _, uv = self._uv(est)
        r = np.nan_to_num(self._residual(uv, self._level, self._light)) / self.sigma
        return float((self._w * r * r).sum())
