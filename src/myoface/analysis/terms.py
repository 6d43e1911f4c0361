"""The terms of the 3-D fit's energy: what each observation and each prior adds to one frame's
problem, ``E = sum_i E_i``, each term in units of its standard deviation (the shape of
model-based trackers such as Face2Face, Thies et al. 2016: photometric, landmark and prior
terms over one set of unknowns, solved by Gauss-Newton).

The unknowns of a step, at an :class:`Estimate` (a head pose and contractions, with the
model's skin there and its response to the contractions): a small rotation ``omega`` (3,
rad, applied on the left), a translation ``dt`` (3, mm) and the change of the free
contractions ``dc`` (F,). A term gives, at an estimate,

- :meth:`Term.normal_equations`: ``(H, b)`` with ``H = J^T J`` and ``b = -J^T r`` of its
  (weighted) residual rows ``r`` and their Jacobian ``J`` in the step's unknowns (for a term
  linear in the unknowns, such as the L1 prior, ``H = 0`` and ``b`` half its negative
  gradient), and
- :meth:`Term.cost`: its value (robust where it says so).

:func:`~myoface.analysis.solver.bounded_gauss_newton` sums them; adding an observation (a new
detector, optical flow, pixels) is adding a term. Terms:

- :class:`LandmarkTerm`: MediaPipe's 468 points (x, y in the image, z its relative depth),
  Huber-weighted; compiled (:mod:`myoface.analysis._fitkernels`) so that the (2-3 V) x (6 +
  F) Jacobian is never formed;
- :class:`OpticalFlowTerm`: the points optical flow tracked, where it is sure (in place of
  MediaPipe's x, y there);
- :class:`TemporalPrior`: the pose and each contraction change little from the last frame;
- :class:`MagnitudePrior`: a weak Gaussian on each contraction (about 0);
- :class:`SparsityPrior`: an L1 prior on the contractions (each in [0, 1], so it is linear).

Their weights (:class:`~myoface.analysis.weights.FitSettings`) say why each is what it is.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from myoface.analysis._fitkernels import landmark_cost, nearest_triangles, normal_equations
from myoface.analysis.camera import HeadPose, PinholeCamera, rotvec


@dataclass(frozen=True)
class Estimate:
    """Where a step starts (or a trial lands): ``pose``, ``contractions`` (M,), the skin there
    ``shape`` (V, 3) mm, head frame, its response ``jac`` (V, 3, M) mm per unit contraction,
    and ``free`` (F,): the contractions the step moves."""

    pose: HeadPose
    contractions: np.ndarray
    shape: np.ndarray
    jac: np.ndarray
    free: np.ndarray

    @property
    def n_unknowns(self) -> int:
        return 6 + len(self.free)


class Term(Protocol):
    """One term of the energy (see the module's docstring)."""

    def prepare(self, est: Estimate) -> None:
        """Called once per Gauss-Newton step at its start (a term may fix what it holds
        constant over the step, e.g. the pixels' size in mm)."""

    def normal_equations(self, est: Estimate) -> tuple[np.ndarray, np.ndarray]: ...

    def cost(self, est: Estimate) -> float: ...


def _zeros(est: Estimate) -> tuple[np.ndarray, np.ndarray]:
    n = est.n_unknowns
    return np.zeros((n, n)), np.zeros(n)


class LandmarkTerm:
    """MediaPipe's points against the model's vertices (point i is vertex i).

    Rows per vertex ``v``: its image position's residual ``(proj(R X_v + t) - p_v) k /
    sigma_xy`` (x, y; ``k`` mm per pixel at the head's depth, so the residual is in mm on the
    face, in sigmas), and, where the points carry a depth, ``(-z_v - k p_z,v - mean) /
    sigma_z`` (MediaPipe's depth is relative: its ``w``-weighted mean is removed). Each
    vertex's rows weigh ``w_v`` (:attr:`weights`: the face oval's points and points turned
    away weigh less, and the model's own error where muscles move the skin far), times
    Huber's weight of its 2-D residual beyond :attr:`huber` sigmas (iteratively reweighted
    at each step's start; the cost is Huber's loss).

    Parameters
    ----------
    points : (V, 3) x, y pixels (column, row) and z relative depth (pixels; NaN: not used).
    camera : PinholeCamera.
    weights : (V,) per-vertex weights ``w`` (fixed over the frame's steps).
    sigma_mm, depth_sigma_mm, huber : :class:`~myoface.analysis.weights.FitSettings`'
        ``landmark_sigma_mm``, ``depth_sigma_mm`` and ``huber``.
    xy_weights : (V,) a further weight of each vertex's x, y rows only (default 1): 0 where
        another term reads the point's position in the image (:class:`OpticalFlowTerm`),
        its depth row still read here.
    gain : None, or (g, ``base`` (V, 3) mm, head frame): the detector reads the skin's motion
        from ``base`` (the person's neutral) at gain ``g``: each point is compared with
        ``base + g (shape - base)`` posed and projected, not with the vertex (the head's
        pose read in full; :attr:`~myoface.analysis.weights.FitSettings.photo_landmark_gain`).
    """

    def __init__(self, points, camera: PinholeCamera, weights, sigma_mm: float,
                 depth_sigma_mm: float, huber: float, xy_weights=None,
                 gain=None):  # fmt: skip
        self.points = np.asarray(points, dtype=np.float64)
        self.camera = camera
        self.weights = np.asarray(weights, dtype=np.float64)
        n = len(self.points)
        self.xy_weights = (
            np.ones(n) if xy_weights is None else np.asarray(xy_weights, dtype=np.float64)
        )
        self.sigma_mm = float(sigma_mm)
        self.depth_sigma_mm = float(depth_sigma_mm)
        self.huber = float(huber)
        self.use_z = bool(np.isfinite(self.points[:, 2]).all())
        self.mm_per_px: float | None = None
        self.gain = None
        if gain is not None and float(gain[0]) != 1.0:
            self.gain = (float(gain[0]), np.asarray(gain[1], dtype=np.float64))
        self._seen = None  # (the estimate last read at the gain, and its reading)

    def pixel_mm(self, pose: HeadPose) -> float:
        """mm on the face per pixel at the head's depth."""
        return pixel_mm(self.camera, pose)

    def prepare(self, est: Estimate) -> None:
        self.mm_per_px = self.pixel_mm(est.pose)

    def _once(self, slot: str, est: Estimate, make) -> Estimate:
        """``make(est)``, kept in ``slot`` for the estimate last asked (a step asks for its
        normal equations and its cost alike)."""
        last = getattr(self, slot)
        if last is None or last[0] is not est:
            last = (est, make(est))
            setattr(self, slot, last)
        return last[1]

    def _as_seen(self, est: Estimate) -> Estimate:
        """``est`` as the detector reads it (:attr:`gain`): the skin's motion from the base
        scaled by ``g``, and its response with it; ``est`` itself without a gain."""
        if self.gain is None:
            return est
        g, base = self.gain
        return self._once(
            "_seen",
            est,
            lambda e: Estimate(
                e.pose, e.contractions, base + g * (e.shape - base), g * e.jac, e.free
            ),  # fmt: skip
        )

    def _kernel_args(self, est: Estimate):
        k = self.mm_per_px if self.mm_per_px is not None else self.pixel_mm(est.pose)
        cam = self.camera
        return (
            np.ascontiguousarray(est.pose.rotation),
            np.ascontiguousarray(est.pose.translation_mm, dtype=np.float64),
            est.shape,
            float(cam.focal_px),
            float(cam.cx),
            float(cam.cy),
            self.points,
            self.use_z,
            self.weights,
            self.xy_weights,
            k / self.sigma_mm,
            1.0 / self.depth_sigma_mm,
            k,
            self.huber,
        )

    def normal_equations(self, est: Estimate):
        est = self._as_seen(est)
        ka = self._kernel_args(est)
        return normal_equations(*ka[:3], est.jac, est.free, *ka[3:])

    def cost(self, est: Estimate) -> float:
        return float(landmark_cost(*self._kernel_args(self._as_seen(est))))

    def residuals(self, pose: HeadPose, shape: np.ndarray, k: float | None = None):
        """The weighted rows' residuals before the weights: xy (V, 2) and z (V,) in sigmas,
        the 2-D distance (V,) in sigmas (for Huber's weights) and whether z is used; ``k``
        mm per pixel (default: at ``pose``'s depth)."""
        k = self.pixel_mm(pose) if k is None else k
        pc = pose.apply(shape)
        uv = self.camera.project(pc)
        rxy = (uv - self.points[:, :2]) * (k / self.sigma_mm)
        if self.use_z:
            w = self.weights
            dz = -pc[:, 2] - k * self.points[:, 2]
            dz = dz - (w * dz).sum() / w.sum()
            rz = dz / self.depth_sigma_mm
        else:
            rz = np.zeros(len(self.points))
        return rxy, rz, np.linalg.norm(rxy, axis=1), self.use_z

    def huber_weights(self, dist: np.ndarray) -> np.ndarray:
        """Huber's weight (V,) of residuals ``dist`` (sigmas): 1 inside, h / r beyond."""
        h = self.huber
        return np.where(dist > h, h / np.maximum(dist, 1e-12), 1.0)


class OpticalFlowTerm(LandmarkTerm):
    """Points tracked by optical flow (:class:`~myoface.analysis.flow.FlowRefiner`) against
    the model's vertices: the x, y rows of :class:`LandmarkTerm` for the vertices the flow
    tracked (``tracked``; the others weigh 0), no depth rows. The flow reads an expression's
    motion more fully than MediaPipe (a real frame warped by a known field: 0.86-0.99 of the
    motion against MediaPipe's 0.49-0.66), so where it is sure it replaces MediaPipe's x, y
    (whose term then weighs those vertices' x, y at 0 and keeps their depth), with the same
    scatter (``sigma_mm``) and Huber threshold.

    What a patch tracker reads is not the motion at its point but the motion of its patch:
    translation-only Lucas-Kanade finds the one shift that best moves the whole window, about
    the mean of the skin's motion over the window's pixels. Where the motion peaks (a smile's
    mouth corner, the middle of a raised brow) that mean is short of the peak. With
    ``footprint`` (:func:`patch_footprint`: each tracked point's window, in the calibration
    frame, as weights over the model's vertices) the term compares the point with the
    model's own motion averaged over the same window (``base + F (shape - base)``, ``base``
    the person's neutral, head frame), not with its vertex: the model predicts what the
    tracker reads. Measured 2026-12-02 (``tools/flow_known_warp_stages.py``, the known-warp
    clips, head still): against the warp's motion at the points the anchored tracker reads
    0.90 of the mouth corners' motion and 0.97 of the brows', against the warp's motion
    averaged over its window 0.98 and 1.00 (0.98 over every point it keeps); the smile's and
    surprise's fields of the face model, interpolated smoothly (C1) between the vertices
    rather than linearly, average over an 11-px window to 0.90 of the corners' peak and
    0.92-0.98 of the brows' (linearly: 0.90, 0.89-0.96): the shortfall is the field's
    shape at the patch's scale, not the known warp's interpolation. Read at the vertex, the
    fit explained the shortfall with smaller contractions everywhere the muscles move the
    skin (the corners 0.80, the brows 0.87); with the footprint 0.88 and 0.93. On the
    sample video's real smile (``--flow``, the validated judge, explained / gain, without /
    with) the mouth corners 0.89 / 0.82 -> 0.90 / 0.84, brows 0.75 / 0.84 -> 0.71 / 0.90,
    lower lip 0.63 / 0.49 -> 0.59 / 0.46, overall 0.779 / 0.74 -> 0.775 / 0.75: the gains
    rise there too, and none passes 1.

    Parameters
    ----------
    xy : (V, 2) the tracked points, pixels (column, row); ``tracked`` (V,) bool: where the
        track is sure. ``camera``, ``weights``, ``sigma_mm``, ``huber``: as for
        :class:`LandmarkTerm`.
    footprint : None, or (sparse (V, V) rows summing to 1, ``base`` (V, 3) mm, head frame):
        each point's patch as weights over the vertices, and the shape the motion is
        measured from (the person's neutral).
    """

    def __init__(self, xy, tracked, camera: PinholeCamera, weights, sigma_mm: float,
                 huber: float, footprint=None):  # fmt: skip
        xy = np.asarray(xy, dtype=np.float64)
        pts = np.column_stack([xy[:, :2], np.full(len(xy), np.nan)])
        tracked = np.asarray(tracked, dtype=bool)
        w = np.asarray(weights, dtype=np.float64) * tracked
        super().__init__(pts, camera, w, sigma_mm, 1.0, huber)
        self.footprint = None
        self._rows = np.flatnonzero(tracked)
        if footprint is not None and len(self._rows):
            fmat, base = footprint
            sub = fmat[self._rows]  # (every row has an entry: its own vertex at least)
            self.footprint = (sub, np.asarray(base, dtype=np.float64))
            self._csr = (sub.indptr[:-1], sub.indices, sub.data[:, None])
        self._jac_of = None  # (the Jacobian last averaged, and its average: one per frame)
        self._jac_avg = None
        self._last = None  # (the estimate last averaged, and its average)

    def _averaged(self, est: Estimate) -> Estimate:
        """``est`` with each tracked vertex's skin and response averaged over its patch."""
        if self.footprint is None:
            return est
        return self._once("_last", est, self._average)

    def _average(self, est: Estimate) -> Estimate:
        fmat, base = self.footprint
        rows = self._rows
        shape = est.shape.copy()
        start, cols, vals = self._csr  # (the rows' products, without scipy's overhead)
        shape[rows] = base[rows] + np.add.reduceat(vals * (est.shape - base)[cols], start)
        if self._jac_of is not est.jac:
            m = est.jac.shape[2]
            jac = est.jac.copy()
            jac[rows] = (fmat @ est.jac.reshape(len(est.jac), -1)).reshape(-1, 3, m)
            self._jac_of, self._jac_avg = est.jac, np.ascontiguousarray(jac)
        return Estimate(est.pose, est.contractions, shape, self._jac_avg, est.free)

    def normal_equations(self, est: Estimate):
        return super().normal_equations(self._averaged(est))

    def cost(self, est: Estimate) -> float:
        return super().cost(self._averaged(est))


def patch_footprint(uv, depth, triangles, half: int, gap=None):
    """Each point's patch as weights over the mesh's vertices: sparse (V, V), row ``v`` the
    mean, over the ``(2 half + 1)^2`` pixels of the square window centred on ``uv[v]`` (V, 2)
    px (a tracker's template in the calibration frame), of the barycentric weights of the
    mesh's triangle (``triangles`` (T, 3), projected at ``uv``) under each pixel: the nearest
    (``depth`` (V,), distance from the camera) where triangles overlap. Pixels inside the
    polygon ``gap`` (K, 2) px (the mouth's gap, which the tracker masks) do not count. A
    point whose patch reaches off the mesh elsewhere (over an eye's opening, beyond the
    face's outline) keeps its own vertex (row ``v`` = e_v): there the patch's strongest
    texture is the opening's or the outline's edge, which moves with the margin, not as the
    skin's mean. Multiplying a field given at the vertices (the model's skin motion) by it
    averages the field, linearly interpolated over the triangles, over each patch."""
    from scipy import sparse

    uv = np.asarray(uv, dtype=np.float64)
    depth = np.asarray(depth, dtype=np.float64)
    tri = np.asarray(triangles, dtype=np.int64)
    n = len(uv)
    o = np.arange(-int(half), int(half) + 1, dtype=np.float64)
    off = np.stack(np.meshgrid(o, o), -1).reshape(-1, 2)
    pix = (uv[:, None, :] + off[None]).reshape(-1, 2)
    order = np.argsort(pix[:, 0])
    xs = pix[order, 0]
    a, b, c = uv[tri[:, 0]], uv[tri[:, 1]], uv[tri[:, 2]]
    lo, hi = np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c)
    i0 = np.searchsorted(xs, lo[:, 0], side="left")
    i1 = np.searchsorted(xs, hi[:, 0], side="right")
    owner, bary = nearest_triangles(
        pix, order, i0, i1, a, b, c, lo, hi, np.ascontiguousarray(depth[tri])
    )
    row = np.repeat(np.arange(n), len(off))
    on = owner >= 0
    masked = np.zeros(len(pix), dtype=bool) if gap is None else _inside(pix, gap)
    off_mesh = np.bincount(row[~on & ~masked], minlength=n)
    on &= (off_mesh == 0)[row] & ~masked
    count = np.bincount(row[on], minlength=n).astype(np.float64)
    r = np.repeat(row[on], 3)
    col = tri[owner[on]].ravel()
    val = (bary[on] / count[row[on]][:, None]).ravel()
    none = np.flatnonzero(count == 0)
    r = np.concatenate([r, none])
    col = np.concatenate([col, none])
    val = np.concatenate([val, np.ones(len(none))])
    return sparse.csr_matrix((val, (r, col)), shape=(n, n))


def _inside(pts, polygon) -> np.ndarray:
    """Which points (N, 2) are inside ``polygon`` (K, 2) (even-odd rule)."""
    poly = np.asarray(polygon, dtype=np.float64)
    x, y = pts[:, 0], pts[:, 1]
    out = np.zeros(len(pts), dtype=bool)
    for k in range(len(poly)):
        (x1, y1), (x2, y2) = poly[k - 1], poly[k]
        cross = (y1 > y) != (y2 > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xc = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
        out ^= cross & (x < xc)
    return out


def pixel_mm(camera: PinholeCamera, pose: HeadPose) -> float:
    """mm on the face per pixel at the head's depth (``pose``'s distance from the camera)."""
    return float(max(-pose.translation_mm[2], 1.0) / camera.focal_px)


class TemporalPrior:
    """The pose and each free contraction change from the previous frame's by about a
    plausible rate times the frame interval (1 sd): rows ``rotvec(R R_prev^T) / sigma_r``,
    ``(t - t_prev) / sigma_t`` and ``(c - c_prev) / sigma_c``. It makes an ill-posed frame
    (a side view that hides one half of the face) well-posed.

    ``prev``: the previous frame's fit (its ``pose`` and ``contractions``); ``dt_s``: the
    frame interval; ``rotation_rate_deg_per_s``, ``translation_rate_mm_per_s``,
    ``rate_per_s``: the rates (:class:`~myoface.analysis.weights.FitSettings`)."""

    def __init__(self, prev, dt_s: float, rotation_rate_deg_per_s: float,
                 translation_rate_mm_per_s: float, rate_per_s: float):  # fmt: skip
        self.prev = prev
        self.sigma_r = float(np.radians(rotation_rate_deg_per_s) * dt_s)
        self.sigma_t = float(translation_rate_mm_per_s * dt_s)
        self.sigma_c = float(rate_per_s * dt_s)
        self._at = None  # (the last estimate asked, its rotation and translation residuals)
        self._hess = None  # (the diagonal, the normal matrix)

    def prepare(self, est: Estimate) -> None:
        pass

    def _pose_residuals(self, est: Estimate):
        # (once per estimate: its normal equations and its cost both ask)
        at = self._at
        if at is not None and at[0] is est:
            return at[1], at[2]
        rv = rotvec(est.pose.rotation @ self.prev.pose.rotation.T)
        dtr = est.pose.translation_mm - self.prev.pose.translation_mm
        self._at = (est, rv, dtr)
        return rv, dtr

    def _diagonal(self, nf: int) -> np.ndarray:
        """Each row's weight squared: the normal equations' diagonal (the rows are the
        unknowns themselves over their sigmas)."""
        d = np.empty(6 + nf)
        d[:3] = 1.0 / self.sigma_r**2
        d[3:6] = 1.0 / self.sigma_t**2
        d[6:] = 1.0 / self.sigma_c**2
        return d

    def normal_equations(self, est: Estimate):
        # (the rows are the unknowns over their sigmas: A^T A is diagonal, the same matrix at
        # every step of a frame: made once, read only)
        free = est.free
        if self._hess is None or len(self._hess[0]) != len(free):
            d = self._diagonal(len(free))
            h = np.diag(d)
            h.setflags(write=False)
            self._hess = (d, h)
        d, h = self._hess
        rv, dtr = self._pose_residuals(est)
        r = np.empty(len(d))
        r[:3] = rv
        r[3:6] = dtr
        r[6:] = est.contractions[free] - self.prev.contractions[free]
        return h, -d * r

    def cost(self, est: Estimate) -> float:
        rv, dtr = self._pose_residuals(est)
        cost = float(rv @ rv) / self.sigma_r**2 + float(dtr @ dtr) / self.sigma_t**2
        if len(est.free):
            dc = est.contractions[est.free] - self.prev.contractions[est.free]
            cost += float(dc @ dc) / self.sigma_c**2
        return cost


class SymmetryPrior:
    """The two sides of the face contract alike, about: for each pair of muscles that mirror
    one another (``pairs``, model indices (P, 2): :func:`mirror_pairs`) whose both members
    are free, the difference ``d = c_l - c_r`` costs ``(d / sigma)^2``, or with ``scale``
    Cauchy's ``(scale / sigma)^2 log(1 + (d / scale)^2)``: quadratic for a difference well
    under ``scale``, growing only as its logarithm beyond, so that a one-sided action the
    frames show is hardly pulled (its normal equations weigh each pair by ``1 / (1 + (d /
    scale)^2)`` at the step's estimate, iteratively reweighted as Huber's weights are). Most
    expressions are bilateral, and where the head turns one side of the face is seen at a
    slant; without it the fit reads a symmetric action on the side it sees best and gives
    the other side's motion to a neighbouring muscle
    (:attr:`~myoface.analysis.weights.FitSettings.symmetry_sigma` has what it measured)."""

    def __init__(self, pairs, sigma: float, scale: float | None = None):
        self.pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
        self.sigma = float(sigma)
        self.scale = None if scale is None else float(scale)
        self._ne = None  # (the free set last asked, the pairs' positions in it, the matrix)

    def prepare(self, est: Estimate) -> None:
        pass

    def _positions(self, est: Estimate):
        """The pairs' positions among the unknowns (P', 2) (the pairs both of whose members
        are free) and, quadratic, the normal matrix (the same at every step of a frame: read
        only)."""
        if self._ne is None or self._ne[0] is not est.free:
            where = {int(m): 6 + k for k, m in enumerate(est.free)}
            pos = np.array(
                [(where[a], where[b]) for a, b in self.pairs if a in where and b in where],
                dtype=np.int64,
            ).reshape(-1, 2)
            h = None
            if self.scale is None:
                h = self._matrix(pos, np.ones(len(pos)), 6 + len(est.free))
                h.setflags(write=False)
            self._ne = (est.free, pos, h)
        return self._ne[1], self._ne[2]

    def _matrix(self, pos, w, n: int) -> np.ndarray:
        """The normal matrix (n, n) of the pairs ``pos`` weighing ``w`` (P',) each."""
        h = np.zeros((n, n))
        wk = w / self.sigma**2
        np.add.at(h, (pos[:, 0], pos[:, 0]), wk)
        np.add.at(h, (pos[:, 1], pos[:, 1]), wk)
        np.subtract.at(h, (pos[:, 0], pos[:, 1]), wk)
        np.subtract.at(h, (pos[:, 1], pos[:, 0]), wk)
        return h

    def _differences(self, est: Estimate, pos) -> np.ndarray:
        cf = est.contractions[est.free]
        return cf[pos[:, 0] - 6] - cf[pos[:, 1] - 6]

    def normal_equations(self, est: Estimate):
        pos, h = self._positions(est)
        n = 6 + len(est.free)
        d = self._differences(est, pos)
        w = np.ones(len(d)) if self.scale is None else 1.0 / (1.0 + (d / self.scale) ** 2)
        if h is None:  # (Cauchy's weights at this estimate)
            h = self._matrix(pos, w, n)
        b = np.zeros(n)
        g = w * d / self.sigma**2
        np.subtract.at(b, pos[:, 0], g)
        np.add.at(b, pos[:, 1], g)
        return h, b

    def cost(self, est: Estimate) -> float:
        pos, _ = self._positions(est)
        if not len(pos):
            return 0.0
        d = self._differences(est, pos)
        if self.scale is None:
            return float(d @ d) / self.sigma**2
        k = self.scale**2 / self.sigma**2
        return float(k * np.log1p((d / self.scale) ** 2).sum())


#: muscles that mirror one another but act apart (:func:`mirror_pairs` leaves them out): the
#: lateral pterygoids turn the mandible sideways one at a time (together they thrust it
#: forward)
NOT_MIRRORED = ("lateral_pterygoid",)


def mirror_pairs(ids) -> np.ndarray:
    """The pairs (P, 2) of indices into ``ids`` of muscles that mirror one another: the ids
    ``NAME_l`` and ``NAME_r`` (but :data:`NOT_MIRRORED`)."""
    ids = list(ids)
    index = {m: k for k, m in enumerate(ids)}
    out = [(k, index[m[:-2] + "_r"]) for k, m in enumerate(ids)
           if m.endswith("_l") and m[:-2] + "_r" in index
           and not m.startswith(NOT_MIRRORED)]  # fmt: skip
    return np.array(out, dtype=np.int64).reshape(-1, 2)


class MagnitudePrior:
    """A weak Gaussian prior on each free contraction about 0: rows ``c / sigma``."""

    def __init__(self, sigma: float):
        self.sigma = float(sigma)
        self._hess = None

    def prepare(self, est: Estimate) -> None:
        pass

    def normal_equations(self, est: Estimate):
        free = est.free
        n = 6 + len(free)
        if self._hess is None or len(self._hess) != n:  # (the same at every step: read only)
            h = np.zeros((n, n))
            idx = 6 + np.arange(len(free))
            h[idx, idx] = 1.0 / self.sigma**2
            h.setflags(write=False)
            self._hess = h
        b = np.zeros(n)
        b[6:] = est.contractions[free] * (-1.0 / self.sigma**2)
        return self._hess, b

    def cost(self, est: Estimate) -> float:
        cf = est.contractions[est.free]
        return float(cf @ cf) / self.sigma**2


class SparsityPrior:
    """An L1 prior on the free contractions, ``weight * sum(c)`` (they are in [0, 1], so it
    is linear): a muscle has to lower the rest of the energy by ``weight`` per unit before it
    is used. Between muscles whose pulls nearly coincide it gives the motion to the one that
    makes it with the least contraction.

    With ``knee`` (a contraction, > 0) it is the minimax concave penalty (C.-H. Zhang, "Nearly
    unbiased variable selection under minimax concave penalty", Ann. Statist. 38:894-942,
    2010): ``weight * (c - c^2 / (2 knee))`` up to the knee and ``weight * knee / 2`` past
    it. It starts as the L1 prior, so a muscle still has to earn its first contraction, and
    its pull fades to nothing at the knee: the L1 prior takes the same ``weight`` off every
    contraction however large, and so reads every motion short. Its normal equations carry
    the gradient only (its curvature is negative; the solver's steps are kept where they
    lower the whole energy).

    ``scale`` (M,): each muscle's weight is ``weight * scale[m]`` (the fit's
    :attr:`~myoface.analysis.weights.FitSettings.sparsity_reach`); None, all alike."""

    def __init__(self, weight: float, knee: float | None = None, scale=None):
        self.weight = float(weight)
        self.knee = None if knee is None else float(knee)
        #: (M,) each muscle's weight relative to ``weight`` (None: 1 for every muscle)
        self.scale = None if scale is None else np.asarray(scale, dtype=np.float64)
        self._ne = None  # (its normal equations: the same at every step, read only)

    def _weights(self, free) -> np.ndarray | float:
        return self.weight if self.scale is None else self.weight * self.scale[free]

    def prepare(self, est: Estimate) -> None:
        pass

    def normal_equations(self, est: Estimate):
        w = self._weights(est.free)
        if self.knee is not None:
            h, b = _zeros(est)
            cf = est.contractions[est.free]
            b[6:] = -0.5 * w * np.maximum(1.0 - cf / self.knee, 0.0)
            return h, b
        if self._ne is None or self._ne[0] is not est.free:
            h, b = _zeros(est)
            b[6:] = -0.5 * w
            h.setflags(write=False)
            b.setflags(write=False)
            self._ne = (est.free, h, b)
        return self._ne[1:]

    def cost(self, est: Estimate) -> float:
        cf = est.contractions[est.free]
        if self.knee is not None:
            k = self.knee
            part = np.where(cf < k, cf - cf * cf / (2 * k), k / 2)
        else:
            part = cf
        if self.scale is None:
            return self.weight * float(part.sum())
        return float(np.sum(self._weights(est.free) * part))
