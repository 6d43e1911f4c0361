"""From fiducial points in the head frame to muscle contractions and jaw rotation.

Two estimators, both working in the image (x-y) plane of an orthographic frontal view, as the
paper does (Terzopoulos & Waters 1993, Section V-F):

``"paper"``
    each muscle independently: the displacement of its fiducial point from the neutral frame,
    projected on the muscle's direction in the x-y plane, divided by the displacement that a unit
    contraction gives there — the inverse of eq. (5) with b_ij of the fiducial. The jaw from the
    drop of the chin's mean position.

``"model"`` (default; beyond the paper)
    all muscles jointly, through the physics: the skin response of the face model to each unit
    contraction (measured once by relaxing the tissue, the columns of a Jacobian J) predicts the
    fiducial displacements d ~ J c; c is the bounded least-squares solution (0 <= c <= 1) with a
    small ridge term. Muscles act on several fiducials at once and their tissue coupling is
    accounted for, which the independent inversion ignores.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import lsq_linear

from myoface.errors import MyofaceValueError

#: contraction at which the skin response is probed (the response is nearly linear below it)
PROBE_CONTRACTION = 0.5
#: ridge weight (mm^2 per unit contraction^2): keeps muscles that no fiducial sees at 0
RIDGE = 1e-3
METHODS = ("model", "paper")


def skin_response(model, ids) -> np.ndarray:
    """The skin's displacement per unit contraction of each muscle in ``ids`` (V, 3, K), mm:
    the tissue relaxed from rest at :data:`PROBE_CONTRACTION` of one muscle at a time.

    Depends only on the model and the muscles, so it is computed once per model
    (:meth:`~myoface.model.FaceModel.memo`): a second analysis in the same session does not
    relax the tissue again. Read-only."""

    def compute():
        rest = model.skin_vertices()
        cols = [
            (model.skin_vertices(model.relax({mid: PROBE_CONTRACTION}).state) - rest)
            / PROBE_CONTRACTION
            for mid in ids
        ]
        resp = np.stack(cols, axis=-1)
        resp.flags.writeable = False
        return resp

    return model.memo(("response", tuple(ids)), compute)


@dataclass(frozen=True)
class Fiducial:
    """A fiducial point: a name and the skin vertex of the face model it stands for (or a
    tuple of vertices whose mean it stands for, e.g. a contour's centroid)."""

    name: str
    vertex: int | tuple

    @property
    def vertex_list(self) -> tuple:
        return tuple(self.vertex) if isinstance(self.vertex, tuple | list) else (self.vertex,)


def paper_fiducials(face) -> list[Fiducial]:
    """The paper's 11 fiducial points on a face with the default landmark groups.

    Inner, centre and outer point of each eyebrow; the two ends of the upper lip; the uppermost
    point of each nasolabial furrow; the chin (its boss centre).
    """
    out = []
    for side in "lr":
        brow = face.landmark(f"eyebrow_{side}")  # ordered inner -> outer
        for name, idx in zip(("inner", "centre", "outer"), (0, len(brow) // 2, -1), strict=True):
            out.append(Fiducial(f"brow_{name}_{side}", int(brow[idx])))
    for side in "lr":
        out.append(Fiducial(f"mouth_corner_{side}", int(face.landmark(f"mouth_corner_{side}")[0])))
    for side in "lr":
        nl = face.landmark(f"nasolabial_{side}")
        top = nl[int(np.argmax(face.vertices[nl, 1]))]
        out.append(Fiducial(f"nasolabial_top_{side}", int(top)))
    chin = face.landmark("chin_boss")
    out.append(Fiducial("chin", int(chin[len(chin) // 2])))
    return out


class ContractionEstimator:
    """Estimates contractions from fiducial displacements (head frame, x-y plane, mm).

    Parameters
    ----------
    model : FaceModel — the model whose muscles are estimated (never changed: the estimator
        keeps its own state).
    fiducials : list of Fiducial
    muscle_ids : the muscles to estimate (default: all of the model's, jaw included);
        the others are held at 0.
    """

    def __init__(self, model, fiducials: list[Fiducial], muscle_ids=None):
        self.model = model
        #: this estimator's own state of the model (its refinements relax from it)
        self.state = model.rest_state()
        self.fiducials = list(fiducials)
        ids = list(model.ids if muscle_ids is None else muscle_ids)
        for i in ids:
            model.muscles.index(i)  # validates
        self.ids = tuple(ids)
        nv = model.face.n_vertices
        self.weights = np.zeros((len(self.fiducials), nv))  # fiducial = weights @ skin
        for i, f in enumerate(self.fiducials):
            vl = f.vertex_list
            self.weights[i, list(vl)] = 1.0 / len(vl)
        self.vertices = np.array([f.vertex_list[0] for f in self.fiducials])
        self.jacobian = self._probe()  # (F, 2, K)

    def positions(self, skin: np.ndarray) -> np.ndarray:
        """Fiducial positions (F, 2) (x-y plane, mm) of skin vertices (V, 3)."""
        return self.weights @ skin[:, :2]

    def _probe(self) -> np.ndarray:
        resp = skin_response(self.model, self.ids)  # (V, 3, K)
        return np.einsum("fv,vdk->fdk", self.weights, resp[:, :2])

    def _solve(self, a, b, lo, hi):
        k = len(self.ids)
        a_aug = np.vstack([a, np.sqrt(RIDGE) * np.eye(k)])
        b_aug = np.concatenate([b, np.zeros(k)])
        return lsq_linear(a_aug, b_aug, bounds=(lo, hi), method="bvls").x

    def estimate(
        self, displacements: np.ndarray, valid: np.ndarray | None = None, refine: int = 0
    ) -> np.ndarray:
        """Contractions (K,) in :attr:`ids` order from fiducial displacements (F, 2) mm.

        ``valid`` (F,) bool masks fiducials that could not be measured in this frame.
        ``refine`` > 0 runs that many Gauss-Newton corrections through the real (nonlinear)
        model: relax at the estimate, compare its fiducials with the measured ones, correct with
        the Jacobian (one tissue relax each, from the model's current state).
        Returns NaN for every muscle when fewer than two fiducials are valid.
        """
        d = np.asarray(displacements, dtype=np.float64)
        if d.shape != (len(self.fiducials), 2):
            raise MyofaceValueError(
                f"displacements must have shape ({len(self.fiducials)}, 2); got {d.shape}"
            )
        ok = np.isfinite(d).all(axis=1)
        if valid is not None:
            ok &= np.asarray(valid, dtype=bool)
        if ok.sum() < 2:
            return np.full(len(self.ids), np.nan)
        a = self.jacobian[ok].reshape(-1, len(self.ids))
        c = np.clip(self._solve(a, d[ok].reshape(-1), 0.0, 1.0), 0.0, 1.0)
        fm = self.model
        rest = self.positions(fm.face.vertices)
        for _ in range(int(refine)):
            full = np.zeros(len(fm.ids))
            full[[fm.ids.index(i) for i in self.ids]] = c
            self.state = fm.relax(full, self.state).state
            pred = self.positions(fm.skin_vertices(self.state)) - rest
            step = self._solve(a, (d - pred)[ok].reshape(-1), -c, 1.0 - c)
            c = np.clip(c + step, 0.0, 1.0)
        return c

    def estimate_paper(self, displacements: np.ndarray, assignment: dict[str, str]) -> np.ndarray:
        """The paper's independent inversion: muscle id -> the fiducial name it reads.

        c_i = (d_f . u_i) / |J_fi| with u_i the unit direction of the unit-contraction response
        J_fi of muscle i at fiducial f (x-y plane), clipped to [0, 1]; NaN when unmeasured.
        """
        d = np.asarray(displacements, dtype=np.float64)
        names = [f.name for f in self.fiducials]
        out = np.zeros(len(self.ids))
        for mid, fname in assignment.items():
            i = self.ids.index(mid)
            f = names.index(fname)
            j = self.jacobian[f, :, i]
            n = np.linalg.norm(j)
            if n < 1e-9:
                raise MyofaceValueError(f"muscle {mid} does not move fiducial {fname}")
            out[i] = np.clip((d[f] @ j) / (n * n), 0.0, 1.0) if np.isfinite(d[f]).all() else np.nan
        return out


#: the paper's reading of each estimated muscle from one fiducial (Section V-F)
PAPER_ASSIGNMENT = {
    **{f"frontalis_inner_{s}": f"brow_inner_{s}" for s in "lr"},
    **{f"frontalis_major_{s}": f"brow_centre_{s}" for s in "lr"},
    **{f"frontalis_outer_{s}": f"brow_outer_{s}" for s in "lr"},
    **{f"zygomaticus_major_{s}": f"mouth_corner_{s}" for s in "lr"},
    **{f"depressor_labii_inferioris_{s}": f"mouth_corner_{s}" for s in "lr"},
    **{f"levator_labii_superioris_alaeque_nasi_{s}": f"nasolabial_top_{s}" for s in "lr"},
    "jaw": "chin",
}
