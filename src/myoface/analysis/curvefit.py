"""Contractions from whole contours: the model's skin curves fitted to the tracked snakes.

Beyond the paper. Terzopoulos & Waters (1993, Section V-F) read each muscle off one fiducial
point of a contour (an end, a top, a centroid). Snake nodes slide along the edges they sit on, so
such points are only as good as the geometric rule that picks them, and at the end of a contour
that rule is ill-posed along the contour: a brow's outermost point moves up and down its
vertical end as the snake rounds it, and an open contour's top moves as the snake's ends
retract. Here every node of the calibration frame's contours is attached to the point of the
face model's landmark curve nearest to it; the model predicts where that point goes for
contractions ``c`` (linearly through the skin's response to each muscle, then through the
tissue itself); and ``c`` minimises the distances, measured along the tracked contour's normal,
from the predicted points to the tracked contour (point-to-curve, as in the "point-to-plane"
variant of iterative closest points, Chen & Medioni 1992). The component along the contour,
which the image does not determine, is never used.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from myoface.analysis.estimate import RIDGE, skin_response
from myoface.errors import MyofaceSimulationError, MyofaceValueError

#: closest-point / least-squares rounds per estimate (the feet move little after two)
ICP_ROUNDS = 3
#: a residual beyond this (mm) is down-weighted (Huber), so that a snake that lost part of its
#: feature pulls the fit less
HUBER_MM = 0.75
#: ``estimate(deferred=True)`` relaxes the tissue on the worker thread only when the estimate is
#: within this (contraction, every muscle) of the last relaxed point; a larger step is
#: corrected through the tissue at once. The lag costs accuracy where the tissue stiffens:
#: measured on ramps (tests/analysis/test_curvefit.py), errors up to 0.03 at 0.07 per frame
#: and 0.08 at 0.15 per frame (0.01 relaxing at once); on the sample video the less
#: determined muscles (depressor, levator) jump by 0.1-0.2 between frames, so a smaller
#: threshold would relax on the main thread on most frames
DEFER_STEP = 0.25
#: a round through the tissue is skipped when the estimate is within this (contraction, every
#: muscle) of the contractions the tissue was last relaxed at: the model linearised there (a
#: secant Jacobian, kept from frame to frame) is then exact to about 1e-3 mm
RELAX_STEP = 0.02


@njit(cache=True, nogil=True, inline="always")
def _closest_one(px, py, q, lo, hi, closed):
    """The segment (index into ``q``) and parameter of the point of polyline ``q[lo:hi]``
    nearest to (px, py)."""
    m = hi - lo
    ns = m if closed else m - 1
    best = np.inf
    bk = 0
    bt = 0.0
    for k in range(ns):
        k1 = k + 1 if k + 1 < m else 0
        ax, ay = q[lo + k, 0], q[lo + k, 1]
        bx, by = q[lo + k1, 0] - ax, q[lo + k1, 1] - ay
        l2 = max(bx * bx + by * by, 1e-18)
        tk = ((px - ax) * bx + (py - ay) * by) / l2
        tk = min(max(tk, 0.0), 1.0)
        dx = px - (ax + tk * bx)
        dy = py - (ay + tk * by)
        d2 = dx * dx + dy * dy
        if d2 < best:
            best, bk, bt = d2, k, tk
    return bk, bt


@njit(cache=True, nogil=True, inline="always")
def _foot(q, lo, hi, closed, bk, bt):
    """The foot, the unit normal and whether it is an open polyline's end."""
    m = hi - lo
    ns = m if closed else m - 1
    k1 = bk + 1 if bk + 1 < m else 0
    bx, by = q[lo + k1, 0] - q[lo + bk, 0], q[lo + k1, 1] - q[lo + bk, 1]
    ln = np.sqrt(max(bx * bx + by * by, 1e-18))
    fx = q[lo + bk, 0] + bt * bx
    fy = q[lo + bk, 1] + bt * by
    end = (not closed) and ((bk == 0 and bt <= 0.0) or (bk == ns - 1 and bt >= 1.0))
    return fx, fy, -by / ln, bx / ln, end


@njit(cache=True, nogil=True)
def _closest_kernel(p, q, closed, foot, seg, t, normal, at_end):
    for i in range(p.shape[0]):
        bk, bt = _closest_one(p[i, 0], p[i, 1], q, 0, q.shape[0], closed)
        fx, fy, nx, ny, end = _foot(q, 0, q.shape[0], closed, bk, bt)
        foot[i, 0], foot[i, 1] = fx, fy
        normal[i, 0], normal[i, 1] = nx, ny
        seg[i], t[i], at_end[i] = bk, bt, end


@njit(cache=True, nogil=True)
def _signed_distances(p, sec, q, off, closed, present, normal, dist, at_end):
    """For each point ``p[i]`` of section ``sec[i]``: the normal of that section's polyline
    ``q[off[s]:off[s + 1]]`` at the nearest point, the signed distance to it along the normal,
    and whether it is an open end (sections not ``present``: at_end True, 0 elsewhere)."""
    for i in range(p.shape[0]):
        s = sec[i]
        if not present[s]:
            normal[i, 0] = normal[i, 1] = dist[i] = 0.0
            at_end[i] = True
            continue
        lo, hi = off[s], off[s + 1]
        bk, bt = _closest_one(p[i, 0], p[i, 1], q, lo, hi, closed[s])
        fx, fy, nx, ny, end = _foot(q, lo, hi, closed[s], bk, bt)
        normal[i, 0], normal[i, 1] = nx, ny
        dist[i] = (fx - p[i, 0]) * nx + (fy - p[i, 1]) * ny
        at_end[i] = end


def closest_on_polyline(p: np.ndarray, q: np.ndarray, closed: bool):
    """The points of polyline ``q`` (M, 2) nearest to points ``p`` (N, 2).

    Returns ``(foot (N, 2), segment (N,), t (N,), normal (N, 2), at_end (N,) bool)``: the foot
    lies at ``q[seg] + t (q[seg + 1] - q[seg])``; ``normal`` is that segment's unit normal;
    ``at_end`` marks feet on an open polyline's end points (where the distance is not a normal
    distance). Compiled; :func:`closest_on_polyline_numpy` is the reference."""
    q = np.ascontiguousarray(q, dtype=np.float64)
    if len(q) < 2:
        raise MyofaceValueError("a polyline needs at least 2 points")
    p = np.ascontiguousarray(p, dtype=np.float64).reshape(-1, 2)
    n = len(p)
    foot, normal = np.empty((n, 2)), np.empty((n, 2))
    seg, t, at_end = np.empty(n, np.int64), np.empty(n), np.empty(n, np.bool_)
    _closest_kernel(p, q, bool(closed), foot, seg, t, normal, at_end)
    return foot, seg, t, normal, at_end


def closest_on_polyline_numpy(p: np.ndarray, q: np.ndarray, closed: bool):
    """:func:`closest_on_polyline` in plain numpy (the reference of the tests)."""
    q = np.asarray(q, dtype=np.float64)
    if len(q) < 2:
        raise MyofaceValueError("a polyline needs at least 2 points")
    a = q
    b = np.roll(q, -1, axis=0) if closed else q[1:]
    if not closed:
        a = q[:-1]
    ab = b - a
    l2 = np.maximum((ab * ab).sum(1), 1e-18)
    rel = p[:, None, :] - a[None]
    t = np.clip((rel * ab[None]).sum(-1) / l2, 0.0, 1.0)
    foot_all = a[None] + t[..., None] * ab[None]
    d2 = ((p[:, None, :] - foot_all) ** 2).sum(-1)
    k = np.argmin(d2, axis=1)
    rows = np.arange(len(p))
    foot = foot_all[rows, k]
    tk = t[rows, k]
    tan = ab[k] / np.sqrt(l2[k])[:, None]
    normal = np.stack([-tan[:, 1], tan[:, 0]], axis=1)
    at_end = np.zeros(len(p), dtype=bool)
    if not closed:
        at_end = ((k == 0) & (tk <= 0.0)) | ((k == len(ab) - 1) & (tk >= 1.0))
    return foot, k, tk, normal, at_end


def bounded_least_squares(a: np.ndarray, b: np.ndarray, lo, hi, ridge: float = 0.0):
    """``x`` minimising ``|a x - b|^2 + ridge |x|^2`` with ``lo <= x <= hi`` (``a`` (N, K),
    ``b`` (N,); ``lo <= 0 <= hi``): the primal active-set method on the normal equations
    (Nocedal & Wright 2006, Algorithm 16.3), exact after finitely many steps. For the few
    unknowns here (K ~ 13) it takes microseconds where scipy's BVLS takes milliseconds; the
    tests hold it against ``scipy.optimize.lsq_linear``, which it falls back to should the
    normal equations be too ill-conditioned for it (a non-finite result)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    k = a.shape[1]
    h = a.T @ a + ridge * np.eye(k)
    g = a.T @ b
    lo = np.broadcast_to(np.asarray(lo, dtype=np.float64), g.shape)
    hi = np.broadcast_to(np.asarray(hi, dtype=np.float64), g.shape)
    # Jacobi scaling (x = s y): unknowns whose columns differ in size by orders of magnitude
    # condition the normal equations no worse than their correlation does
    s = 1.0 / np.sqrt(np.maximum(np.diag(h), 1e-300))
    y = _box_qp(
        np.ascontiguousarray(h * np.outer(s, s)),
        g * s,
        np.ascontiguousarray(lo / s),
        np.ascontiguousarray(hi / s),
    )
    x = np.clip(y * s, lo, hi)
    if not np.isfinite(x).all():
        from scipy.optimize import lsq_linear

        aug = np.vstack([a, np.sqrt(ridge) * np.eye(k)])
        x = lsq_linear(aug, np.concatenate([b, np.zeros(k)]), (lo, hi), method="bvls").x
    return x


@njit(cache=True, nogil=True)
def _cholesky_solve(a, b):
    """Solve a x = b for a small symmetric positive definite ``a`` (in place of ``a``)."""
    n = a.shape[0]
    for j in range(n):
        d = a[j, j]
        for m in range(j):
            d -= a[j, m] * a[j, m]
        d = np.sqrt(max(d, 1e-300))
        a[j, j] = d
        for i in range(j + 1, n):
            v = a[i, j]
            for m in range(j):
                v -= a[i, m] * a[j, m]
            a[i, j] = v / d
    y = b.copy()
    for i in range(n):
        for m in range(i):
            y[i] -= a[i, m] * y[m]
        y[i] /= a[i, i]
    for i in range(n - 1, -1, -1):
        for m in range(i + 1, n):
            y[i] -= a[m, i] * y[m]
        y[i] /= a[i, i]
    return y


@njit(cache=True, nogil=True)
def _box_qp(h, g, lo, hi):
    """Minimise 0.5 x'Hx - g'x on lo <= x <= hi (H symmetric positive definite)."""
    k = g.shape[0]
    x = np.minimum(np.maximum(np.zeros(k), lo), hi)
    fixed = np.zeros(k, np.bool_)  # the working set: variables held on a bound
    scale = 1e-300
    for i in range(k):
        scale = max(scale, abs(h[i, i]))
    z = np.empty(k)
    for _ in range(10 * k + 10):
        idx = np.nonzero(~fixed)[0]
        nf = idx.shape[0]
        z[:] = x
        if nf > 0:
            a = np.empty((nf, nf))
            b = np.empty(nf)
            for i in range(nf):
                s = g[idx[i]]
                for j in range(k):
                    if fixed[j]:
                        s -= h[idx[i], j] * x[j]
                b[i] = s
                for j in range(nf):
                    a[i, j] = h[idx[i], idx[j]]
            sol = _cholesky_solve(a, b)
            for i in range(nf):
                z[idx[i]] = sol[i]
        # the free variables that z puts outside the box, and the step's first bound
        alpha = 1.0
        block = -1
        for i in range(k):
            if fixed[i]:
                continue
            tol = 1e-12 * (1.0 + abs(x[i]))
            d = z[i] - x[i]
            if z[i] < lo[i] - tol and d < 0:
                lim = (lo[i] - x[i]) / d
            elif z[i] > hi[i] + tol and d > 0:
                lim = (hi[i] - x[i]) / d
            else:
                continue
            if block < 0 or lim < alpha:
                alpha = min(max(lim, 0.0), 1.0)
                block = i
        if block < 0:
            for i in range(k):
                x[i] = min(max(z[i], lo[i]), hi[i])
            # a held variable is released when the gradient pulls it into the box
            best, j = 0.0, -1
            xmax = 0.0
            for i in range(k):
                xmax = max(xmax, abs(x[i]))
            for i in range(k):
                if not fixed[i]:
                    continue
                gi = -g[i]
                for m in range(k):
                    gi += h[i, m] * x[m]
                pull = -gi if x[i] <= lo[i] else (gi if x[i] >= hi[i] else 0.0)
                if pull > best:
                    best, j = pull, i
            if j < 0 or best <= 1e-12 * scale * (1.0 + xmax):
                return x
            fixed[j] = False
            continue
        for i in range(k):
            x[i] = min(max(x[i] + alpha * (z[i] - x[i]), lo[i]), hi[i])
        x[block] = lo[block] if z[block] < x[block] else hi[block]
        fixed[block] = True
    return x


class CurveEstimator:
    """Contractions from tracked contours by fitting the model's skin curves to them.

    Parameters
    ----------
    model : FaceModel.
    sections : {name: (vertex indices of the model's curve, closed)}.
    muscle_ids : the muscles to estimate.
    """

    def __init__(self, model, sections: dict, muscle_ids):
        self.model = model
        #: this estimator's own state of the model (each relax starts from the last one's)
        self.state = model.rest_state()
        self.ids = tuple(muscle_ids)
        flip = np.array([1.0, -1.0])  # image-like model coordinates: y points down
        self.response = skin_response(model, self.ids)[:, :2] * flip[None, :, None]  # (V,2,K)
        self.rest = model.face.vertices[:, :2] * flip
        self.sections = {
            k: (np.asarray(v, dtype=np.int64), bool(c)) for k, (v, c) in sections.items()
        }
        self.names: list[str] = []
        self.p0 = None
        #: the model linearised where the tissue was last relaxed: (contractions, the attached
        #: nodes predicted there (N, 2) px, secant Jacobian (N, 2, K) px per contraction)
        self.linearisation = None
        self.warm = True
        self._worker = None  # a thread for deferred relaxes (estimate(deferred=True))
        self._pending = None  # the relax under way on it
        #: {section: RMS distance (mm) across it from the model's curve} of the last estimate
        self.last_residuals = {}

    def calibrate(self, curves: dict, matrix: np.ndarray, offset: np.ndarray) -> None:
        """Attach the nodes of the calibration frame's ``curves`` ({name: (N, 2) px}) to the
        model's curves. ``px = matrix @ mm + offset`` maps the model's image-like coordinates
        (x, -y), mm, to the image."""
        self.matrix = np.asarray(matrix, dtype=np.float64).reshape(2, 2)
        self.offset = np.asarray(offset, dtype=np.float64).reshape(2)
        self.mm_per_px = 1.0 / np.sqrt(abs(np.linalg.det(self.matrix)))
        p0, jac, ia, ib, ta, sec, w = [], [], [], [], [], [], []
        self.names = [n for n in curves if n in self.sections]
        if not self.names:
            raise MyofaceValueError("no tracked contour has a model curve")
        for s, name in enumerate(self.names):
            verts, closed = self.sections[name]
            model_px = self.rest[verts] @ self.matrix.T + self.offset
            pts = np.asarray(curves[name], dtype=np.float64)
            _, k, t, _, _ = closest_on_polyline(pts, model_px, closed)
            a = verts[k]
            b = verts[(k + 1) % len(verts)] if closed else verts[np.minimum(k + 1, len(verts) - 1)]
            resp = (1 - t)[:, None, None] * self.response[a] + t[:, None, None] * self.response[b]
            jac.append(np.einsum("ij,njk->nik", self.matrix, resp))
            p0.append(pts)
            ia.append(a)
            ib.append(b)
            ta.append(t)
            sec.append(np.full(len(pts), s))
            # each node stands for the curve length around it (mm)
            q = (
                np.vstack([pts[-1:], pts, pts[:1]])
                if closed
                else np.vstack([pts[:1], pts, pts[-1:]])
            )
            seg = np.linalg.norm(np.diff(q, axis=0), axis=1)
            w.append(0.5 * (seg[:-1] + seg[1:]) * self.mm_per_px)
        self.p0 = np.concatenate(p0)
        self.jac = np.concatenate(jac)  # (N, 2, K) px per unit contraction
        self.ia, self.ib, self.ta = np.concatenate(ia), np.concatenate(ib), np.concatenate(ta)
        self.section_of = np.concatenate(sec).astype(np.int64)
        self.node_weight = np.concatenate(w)
        self._closed = np.array([self.sections[n][1] for n in self.names], dtype=np.bool_)
        self._column_norms = np.linalg.norm(self.jac, axis=(0, 1)) + 1e-9
        self.linearisation = (np.zeros(len(self.ids)), self.p0.copy(), self.jac.copy())

    def predict(self, c) -> np.ndarray:
        """The attached nodes (N, 2) px for contractions ``c`` by the model linearised where
        the tissue was last relaxed (no relax)."""
        self._collect()
        c_r, p_r, jac = self.linearisation
        return p_r + jac @ (np.asarray(c, dtype=np.float64) - c_r)

    def predicted(self, skin: np.ndarray) -> np.ndarray:
        """The attached nodes (N, 2) px for skin vertices ``skin`` (V, 3) of the model."""
        xy = skin[:, :2] * np.array([1.0, -1.0]) - self.rest
        u = (1 - self.ta)[:, None] * xy[self.ia] + self.ta[:, None] * xy[self.ib]
        return self.p0 + u @ self.matrix.T

    def residuals(self, curves: dict, pred: np.ndarray):
        """Per node: the normal of ``curves`` ({name: (N, 2) px}) at its foot, the signed
        distance n . (foot - pred) in mm from ``pred`` (the nodes, (N, 2) px) along it, and the
        weight (0 where a contour is missing or the node is past an open contour's end)."""
        n = len(pred)
        qs, off, present = [], [0], np.zeros(len(self.names), dtype=np.bool_)
        for s, name in enumerate(self.names):
            cur = curves.get(name)
            if cur is not None and len(cur) >= 2 and np.isfinite(cur).all():
                qs.append(np.asarray(cur, dtype=np.float64))
                present[s] = True
            off.append(off[-1] + (len(qs[-1]) if present[s] else 0))
        normal = np.zeros((n, 2))
        res = np.zeros(n)
        at_end = np.ones(n, dtype=np.bool_)
        if qs:
            _signed_distances(
                np.ascontiguousarray(pred, dtype=np.float64),
                self.section_of,
                np.ascontiguousarray(np.concatenate(qs)),
                np.asarray(off, dtype=np.int64),
                self._closed,
                present,
                normal,
                res,
                at_end,
            )
        res *= self.mm_per_px
        w = np.where(at_end, 0.0, self.node_weight)
        return normal, res, w

    def _solve(self, normal, res, w, lo, hi, jac=None):
        jac = self.jac if jac is None else jac
        a = np.einsum("nd,ndk->nk", normal, jac) * self.mm_per_px
        r = np.abs(res)
        hub = np.where(r > HUBER_MM, HUBER_MM / np.maximum(r, 1e-12), 1.0)
        sw = np.sqrt(w * hub)
        return bounded_least_squares(a * sw[:, None], res * sw, lo, hi, RIDGE)

    def estimate(
        self, curves: dict, refine: int = 0, deferred: bool = False, rounds: int = ICP_ROUNDS
    ) -> np.ndarray:
        """Contractions (K,) from the tracked ``curves`` ({name: (N, 2)} px, in the calibration
        frame's coordinates: the head's motion removed).

        The fit starts from the model linearised where the tissue was last relaxed (at first
        the rest state; in a video, a recent frame's estimate: :attr:`linearisation`). Up to
        ``refine`` rounds through the tissue follow (one relax each, and Broyden's update of
        the Jacobian along the step, Nocedal & Wright 2006, eq. 11.27, so that the stiffening
        tissue's smaller response is not overshot again); a round is skipped once the
        estimate is within :data:`RELAX_STEP` of where the tissue was relaxed.

        ``deferred=True`` (a video, frame after frame): when the estimate is within
        :data:`DEFER_STEP` of where the tissue was last relaxed, it is the fit of the model
        linearised there, and the tissue is relaxed at it (when ``refine`` > 0 and it moved
        by more than :data:`RELAX_STEP`) on a second thread while the caller goes on tracking
        the next frame; the next call starts from there. A larger step is refined at once. The
        relax is awaited before anything that needs it, so the results do not depend on
        timing. ``rounds``: closest-point / least-squares rounds of the linear fit."""
        if self.p0 is None:
            raise MyofaceValueError("calibrate() first")
        self._collect()
        k = len(self.ids)
        if not self.warm:
            self.linearisation = (np.zeros(k), self.p0.copy(), self.jac.copy())
        c_r, p_r, jac = self.linearisation
        c = c_r.copy()
        for _ in range(max(int(rounds), 1)):
            pred = p_r + jac @ (c - c_r)
            normal, res, w = self.residuals(curves, pred)
            if w.sum() <= 0:
                return np.full(k, np.nan)
            c_before = c
            step = self._solve(normal, res, w, -c, 1.0 - c, jac)
            c = np.clip(c + step, 0.0, 1.0)
        if deferred and np.abs(c - c_r).max() <= DEFER_STEP:
            # the residuals after the last step, with its feet and normals (the linear model)
            moved = np.einsum("nd,ndk,k->n", normal, jac, c - c_before) * self.mm_per_px
            self.last_residuals = self._rms_by_section(res - moved, w)
            if int(refine) > 0 and np.abs(c - c_r).max() > RELAX_STEP:
                self._relax_later(c)
            return c
        for _ in range(int(refine)):
            if np.abs(c - self.linearisation[0]).max() <= RELAX_STEP:
                break
            pred = self.predicted(self.relaxed_skin(c))
            self.relinearise(c, pred)
            normal, res, w = self.residuals(curves, pred)
            step = self._solve(normal, res, w, -c, 1.0 - c, self.linearisation[2])
            c = np.clip(c + step, 0.0, 1.0)
        self.last_residuals = self._section_rms(curves, self.predict(c))
        return c

    def relinearise(self, c, pred: np.ndarray) -> None:
        """Move :attr:`linearisation` to contractions ``c``, where the tissue was relaxed and
        put the attached nodes at ``pred`` (N, 2) px. Broyden's update makes the Jacobian
        exact along the step from the last point (Nocedal & Wright 2006, eq. 11.27), so that
        the stiffening tissue's smaller response is not overshot again; steps shorter than
        half of :data:`RELAX_STEP` leave it as it is (the relax's tolerance would dominate
        the difference)."""
        c = np.array(c, dtype=np.float64)
        pred = np.asarray(pred, dtype=np.float64)
        c_r, p_r, jac = self.linearisation
        dc = c - c_r
        if np.abs(dc).max() > 0.5 * RELAX_STEP:
            jac = jac + np.multiply.outer((pred - p_r) - jac @ dc, dc / float(dc @ dc))
            # the tissue stiffens: a muscle's response never grows far beyond the one at rest.
            # A secant that says otherwise (a relax that found another equilibrium) is
            # dropped for the response at rest
            if (
                not np.isfinite(jac).all()
                or (np.linalg.norm(jac, axis=(0, 1)) > 3.0 * self._column_norms).any()
            ):
                jac = self.jac.copy()
        self.linearisation = (c, pred, jac)

    def _section_rms(self, curves: dict, pred: np.ndarray) -> dict:
        _, res, w = self.residuals(curves, pred)
        return self._rms_by_section(res, w)

    def _rms_by_section(self, res: np.ndarray, w: np.ndarray) -> dict:
        out = {}
        for s, name in enumerate(self.names):
            m = (self.section_of == s) & (w > 0)
            if m.any():  # (w is 0 on the sections missing from the curves)
                out[name] = float(np.sqrt(np.average(res[m] ** 2, weights=w[m])))
        return out

    def _relax_later(self, c) -> None:
        """Relax the tissue at ``c`` on the worker thread; :meth:`_collect` moves the
        linearisation there."""
        from concurrent.futures import ThreadPoolExecutor

        if self._worker is None:
            self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="myoface-relax")
        c = np.array(c, dtype=np.float64)
        self._pending = self._worker.submit(lambda: (c, self.predicted(self._relaxed(c))))

    def _collect(self) -> None:
        """Wait for the relax on the worker thread, if any, and move the linearisation to it."""
        if self._pending is not None:
            fut, self._pending = self._pending, None
            self.relinearise(*fut.result())

    def close(self) -> None:
        """Wait for any relax under way and stop the worker thread."""
        try:
            self._collect()
        finally:
            if self._worker is not None:
                self._worker.shutdown()
                self._worker = None

    def relaxed_skin(self, c) -> np.ndarray:
        """The model's skin vertices (V, 3) relaxed (from its current state) at contractions
        ``c`` of the estimated muscles, every other muscle at rest."""
        self._collect()
        return self._relaxed(c)

    def _relaxed(self, c) -> np.ndarray:
        fm = self.model
        full = np.zeros(len(fm.ids))
        full[[fm.ids.index(i) for i in self.ids]] = c
        try:
            self.state = fm.relax(full, self.state).state
        except MyofaceSimulationError:
            # a start far from the new equilibrium (a jump of the estimate) can defeat the
            # solver where the rest state does not: start again from there
            self.state = fm.relax(full, fm.rest_state()).state
        return fm.skin_vertices(self.state)

    def synthesis_step(self, c, pred, video: dict, synth: dict, synth_rest) -> np.ndarray:
        """The contractions after one analysis-by-synthesis step from ``c`` (see
        :mod:`myoface.analysis.synthesis`): ``pred`` are the nodes for the model relaxed at
        ``c``; ``video`` and ``synth`` the contours tracked on the real frame and on the model
        rendered at ``c``; ``synth_rest`` the residuals (mm, per node) of the contours tracked
        on the model rendered at rest (the tracker's bias on the calibration frame)."""
        self._collect()
        normal, r_video, w = self.residuals(video, pred)
        _, r_synth, w_synth = self.residuals(synth, pred)
        res = r_video - (r_synth - np.asarray(synth_rest))
        c = np.asarray(c, dtype=np.float64)
        jac = self.linearisation[2] if self.linearisation is not None else None
        step = self._solve(normal, res, np.minimum(w, w_synth), -c, 1.0 - c, jac)
        return np.clip(c + step, 0.0, 1.0)
