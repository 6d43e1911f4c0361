"""Jaw rotation: a hinge axis, and how much each part of the face follows the mandible.

The jaw opens by rotating the bone nodes of the lower face about a hinge axis through the
temporomandibular joints (T&W 1993, Section III-C: "plus jaw rotation"). A smooth weight
w in [0, 1] per skin vertex says how much of the rotation a point follows: 1 on the chin and
the lower lip, 0 on the upper lip, the nose and everything above; in between it is harmonic
over the mesh (the solution of the graph Laplace equation with those values held), so the
cheeks stretch smoothly. Rotating a point by ``w * angle`` (not blending positions) keeps
every point on its arc around the hinge.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components

from myoface.errors import MyofaceValueError
from myoface.face.mesh import unique_edges


def rotate_about_axis(
    points: np.ndarray, pivot: np.ndarray, axis: np.ndarray, angles_rad
) -> np.ndarray:
    """Rotate ``points`` (N, 3) about the line through ``pivot`` along ``axis`` (right-handed).

    ``angles_rad`` is a scalar or one angle per point (N,). Rodrigues' formula.
    """
    p = np.asarray(points, dtype=np.float64)
    k = np.asarray(axis, dtype=np.float64)
    k = k / np.linalg.norm(k)
    th = np.broadcast_to(np.asarray(angles_rad, dtype=np.float64), (len(p),))[:, None]
    r = p - pivot
    c, s = np.cos(th), np.sin(th)
    rot = r * c + np.cross(k, r) * s + np.outer(r @ k, k) * (1.0 - c)
    return rot + pivot


def harmonic_weights(
    n_vertices: int, triangles: np.ndarray, ones: np.ndarray, zeros: np.ndarray
) -> np.ndarray:
    """Harmonic interpolation (V,) over the mesh graph of 1 at ``ones`` and 0 at ``zeros``.

    Vertices in a connected component without any constraint get 0.
    """
    ones = np.unique(np.asarray(ones, dtype=np.int64))
    zeros = np.setdiff1d(np.asarray(zeros, dtype=np.int64), ones)
    if len(ones) == 0:
        raise MyofaceValueError("harmonic weights need at least one vertex held at 1")
    e = unique_edges(triangles)
    n = n_vertices
    a = sp.coo_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])))
    a = sp.csr_matrix(a, shape=(n, n))
    lap = sp.diags(np.asarray(a.sum(axis=1)).ravel()) - a
    w = np.zeros(n)
    w[ones] = 1.0
    fixed = np.zeros(n, dtype=bool)
    fixed[ones] = True
    fixed[zeros] = True
    # components without constraints would make the system singular: hold them at 0
    n_comp, label = connected_components(a, directed=False)
    constrained = np.zeros(n_comp, dtype=bool)
    constrained[label[fixed]] = True
    fixed |= ~constrained[label]
    free = np.flatnonzero(~fixed)
    if len(free):
        lff = lap[free][:, free].tocsc()
        rhs = -(lap[free][:, np.flatnonzero(fixed)] @ w[fixed])
        w[free] = spla.spsolve(lff, rhs)
    return np.clip(w, 0.0, 1.0)


@dataclass(frozen=True)
class Jaw:
    """The jaw: hinge and per-vertex following weights.

    Attributes
    ----------
    hinge_point : (3,) mm — a point on the hinge axis (between the two condyles).
    hinge_axis : (3,) — unit axis; a positive rotation opens the mouth (right-handed).
    max_angle_rad : float — the rotation at contraction 1 of the ``"jaw"`` control.
    weights : (V,) float in [0, 1] — how much of the rotation each skin vertex follows.
    """

    hinge_point: np.ndarray
    hinge_axis: np.ndarray
    max_angle_rad: float
    weights: np.ndarray

    def __post_init__(self):
        hp = np.asarray(self.hinge_point, dtype=np.float64)
        ax = np.asarray(self.hinge_axis, dtype=np.float64)
        if hp.shape != (3,) or ax.shape != (3,) or not np.isfinite(np.r_[hp, ax]).all():
            raise MyofaceValueError("jaw hinge_point and hinge_axis must be finite 3-vectors")
        if np.linalg.norm(ax) < 1e-9:
            raise MyofaceValueError("jaw hinge_axis must be non-zero")
        if not 0 < float(self.max_angle_rad) <= np.pi / 2:
            raise MyofaceValueError(
                f"jaw max_angle_rad must be in (0, pi/2]; got {self.max_angle_rad}"
            )
        w = np.asarray(self.weights, dtype=np.float64)
        if w.ndim != 1 or not np.isfinite(w).all() or w.min() < 0 or w.max() > 1:
            raise MyofaceValueError("jaw weights must be a finite (V,) array in [0, 1]")
        object.__setattr__(self, "hinge_point", hp)
        object.__setattr__(self, "hinge_axis", ax / np.linalg.norm(ax))
        object.__setattr__(self, "weights", w)

    def rotate(self, points: np.ndarray, weights: np.ndarray, opening: float) -> np.ndarray:
        """Positions of ``points`` (N, 3) when the jaw control is ``opening`` in [0, 1]."""
        angles = float(opening) * self.max_angle_rad * np.asarray(weights)
        out = np.array(points, dtype=np.float64)
        m = angles != 0  # points that do not follow the jaw stay bit-for-bit where they are
        out[m] = rotate_about_axis(out[m], self.hinge_point, self.hinge_axis, angles[m])
        return out

    def mirror_error_mm(self) -> float:
        """Distance of the hinge from the mid-sagittal plane plus the axis' tilt (for tests)."""
        return float(abs(self.hinge_point[0]) + abs(abs(self.hinge_axis[0]) - 1.0))
