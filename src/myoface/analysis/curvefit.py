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
from scipy.optimize import lsq_linear

from myoface.analysis.estimate import RIDGE, skin_response
from myoface.errors import MyofaceValueError

#: closest-point / least-squares rounds per estimate (the feet move little after two)
ICP_ROUNDS = 3
#: a residual beyond this (mm) is down-weighted (Huber), so that a snake that lost part of its
#: feature pulls the fit less
HUBER_MM = 0.75


def closest_on_polyline(p: np.ndarray, q: np.ndarray, closed: bool):
    """The points of polyline ``q`` (M, 2) nearest to points ``p`` (N, 2).

    Returns ``(foot (N, 2), segment (N,), t (N,), normal (N, 2), at_end (N,) bool)``: the foot
    lies at ``q[seg] + t (q[seg + 1] - q[seg])``; ``normal`` is that segment's unit normal;
    ``at_end`` marks feet on an open polyline's end points (where the distance is not a normal
    distance)."""
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
        self.section_of = np.concatenate(sec)
        self.node_weight = np.concatenate(w)

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
        normal = np.zeros((n, 2))
        res = np.zeros(n)
        w = np.zeros(n)
        for s, name in enumerate(self.names):
            m = self.section_of == s
            cur = curves.get(name)
            if cur is None or not np.isfinite(cur).all():
                continue
            _, closed = self.sections[name]
            foot, _, _, nrm, at_end = closest_on_polyline(pred[m], cur, closed)
            normal[m] = nrm
            res[m] = ((foot - pred[m]) * nrm).sum(1) * self.mm_per_px
            w[m] = np.where(at_end, 0.0, self.node_weight[m])
        return normal, res, w

    def _solve(self, normal, res, w, lo, hi, jac=None):
        k = len(self.ids)
        jac = self.jac if jac is None else jac
        a = np.einsum("nd,ndk->nk", normal, jac) * self.mm_per_px
        r = np.abs(res)
        hub = np.where(r > HUBER_MM, HUBER_MM / np.maximum(r, 1e-12), 1.0)
        sw = np.sqrt(w * hub)
        a_aug = np.vstack([a * sw[:, None], np.sqrt(RIDGE) * np.eye(k)])
        b_aug = np.concatenate([res * sw, np.zeros(k)])
        return lsq_linear(a_aug, b_aug, bounds=(lo, hi), method="bvls").x

    def estimate(self, curves: dict, refine: int = 0) -> np.ndarray:
        """Contractions (K,) from the tracked ``curves`` ({name: (N, 2)} px, in the calibration
        frame's coordinates: the head's motion removed). ``refine`` rounds through the tissue
        follow the linear fit (one relax each)."""
        if self.p0 is None:
            raise MyofaceValueError("calibrate() first")
        k = len(self.ids)
        c = np.zeros(k)
        for _ in range(ICP_ROUNDS):
            pred = self.p0 + self.jac @ c
            normal, res, w = self.residuals(curves, pred)
            if w.sum() <= 0:
                return np.full(k, np.nan)
            step = self._solve(normal, res, w, -c, 1.0 - c)
            c = np.clip(c + step, 0.0, 1.0)
        jac = self.jac.copy()
        # secant pairs (contractions, predicted nodes): the rest state is one
        c_prev, p_prev = np.zeros(k), self.p0
        for _ in range(int(refine)):
            pred = self.predicted(self.relaxed_skin(c))
            # Broyden's update: the Jacobian made exact along the last step, so that the
            # stiffening tissue's smaller response is not overshot again (Nocedal & Wright,
            # eq. 11.27)
            dc = c - c_prev
            dd = float(dc @ dc)
            if dd > 1e-12:
                jac += np.multiply.outer((pred - p_prev) - jac @ dc, dc / dd)
            c_prev, p_prev = c.copy(), pred
            normal, res, w = self.residuals(curves, pred)
            step = self._solve(normal, res, w, -c, 1.0 - c, jac)
            c = np.clip(c + step, 0.0, 1.0)
        return c

    def relaxed_skin(self, c) -> np.ndarray:
        """The model's skin vertices (V, 3) relaxed (from its current state) at contractions
        ``c`` of the estimated muscles, every other muscle at rest."""
        fm = self.model
        full = np.zeros(len(fm.ids))
        full[[fm.ids.index(i) for i in self.ids]] = c
        self.state = fm.relax(full, self.state).state
        return fm.skin_vertices(self.state)

    def synthesis_step(self, c, pred, video: dict, synth: dict, synth_rest) -> np.ndarray:
        """The contractions after one analysis-by-synthesis step from ``c`` (see
        :mod:`myoface.analysis.synthesis`): ``pred`` are the nodes for the model relaxed at
        ``c``; ``video`` and ``synth`` the contours tracked on the real frame and on the model
        rendered at ``c``; ``synth_rest`` the residuals (mm, per node) of the contours tracked
        on the model rendered at rest (the tracker's bias on the calibration frame)."""
        normal, r_video, w = self.residuals(video, pred)
        _, r_synth, w_synth = self.residuals(synth, pred)
        res = r_video - (r_synth - np.asarray(synth_rest))
        c = np.asarray(c, dtype=np.float64)
        step = self._solve(normal, res, np.minimum(w, w_synth), -c, 1.0 - c)
        return np.clip(c + step, 0.0, 1.0)
