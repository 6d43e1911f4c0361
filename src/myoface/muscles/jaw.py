"""The jaw: a hinge that turns and slides, and how much each part of the face follows the mandible.

The jaw opens by rotating the bone nodes of the lower face about a hinge axis through the
temporomandibular joints (T&W 1993, Section III-C: "plus jaw rotation") and, as a real jaw
does, in two phases (the classical account of mouth opening): first the condyles turn in
their fossae (a hinge, ``hinge_angle_rad`` per unit of the control), then, from the control
``translation_from`` on, they also slide forward and down the articular eminence (``slide_mm``
at full opening) while the mandible turns further, to ``max_angle_rad`` at full opening. With
``t = ((c - translation_from) / (1 - translation_from)) ** SLIDE_POWER`` for the control
``c`` past ``translation_from`` (0 before):

    angle(c) = hinge_angle_rad * c + (max_angle_rad - hinge_angle_rad) * t
    slide(c) = slide_mm * t

A relaxed opening is a pure rotation; a maximal one adds the condylar translation and the
rotation it allows (Travers et al. 2000; Ferrario et al. 2005: at maximal opening about three
quarters of the incisors' motion is rotation). Without the two optional parameters the jaw is
the paper's hinge, ``angle = c * max_angle_rad``.

A smooth weight w in [0, 1] per skin vertex says how much of the motion a point follows: 1 on
the chin and the lower lip, 0 on the upper lip, the nose and everything above; in between it is
harmonic over the mesh (the solution of the graph Laplace equation with those values held), so
the cheeks stretch smoothly. A point is rotated by ``w * angle`` about the hinge (not blended
between positions: it stays on its arc) and then moved by ``w`` times the slide.

References: Terzopoulos & Waters 1993, Section III-C; K. H. Travers, P. H. Buschang,
H. Hayasaki, G. S. Throckmorton, "Associations between incisor and mandibular condylar
movements during maximum mouth opening in humans", Arch. Oral Biol. 45:267-275, 2000;
V. F. Ferrario, C. Sforza, N. Lovecchio, F. Mian, "Quantification of translational and gliding
components in human temporomandibular joint during mouth opening", Arch. Oral Biol.
50:507-515, 2005.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components

from myoface.errors import MyofaceValueError
from myoface.face.mesh import unique_edges

#: the translation phase grows as its progress to this power: it starts smoothly (no kink in
#: the motion where it begins) and ends at the full slide. Our choice.
SLIDE_POWER = 2.0


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
    """The jaw: hinge, condylar slide and per-vertex following weights.

    Attributes
    ----------
    hinge_point : (3,) mm — a point on the hinge axis (between the two condyles), at rest.
    hinge_axis : (3,) — unit axis; a positive rotation opens the mouth (right-handed).
    max_angle_rad : float — the rotation at contraction 1 of the ``"jaw"`` control.
    weights : (V,) float in [0, 1] — how much of the motion each skin vertex follows.
    slide_mm : (3,) mm — the condyles' translation (head frame) at contraction 1. Default:
        none (a pure hinge).
    hinge_angle_rad : float — the hinge phase's rotation per unit of the control (rad), at
        most ``max_angle_rad`` (default: ``max_angle_rad``, a linear rotation).
    translation_from : float in [0, 1) — the control where the translation phase starts
        (default 0).
    """

    hinge_point: np.ndarray
    hinge_axis: np.ndarray
    max_angle_rad: float
    weights: np.ndarray
    slide_mm: np.ndarray | None = None
    hinge_angle_rad: float | None = None
    translation_from: float = 0.0

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
        sl = np.zeros(3) if self.slide_mm is None else np.asarray(self.slide_mm, dtype=np.float64)
        if sl.shape != (3,) or not np.isfinite(sl).all():
            raise MyofaceValueError(f"jaw slide_mm must be a finite 3-vector (mm); got {sl}")
        object.__setattr__(self, "slide_mm", sl)
        hinge = self.max_angle_rad if self.hinge_angle_rad is None else self.hinge_angle_rad
        if not 0 < float(hinge) <= float(self.max_angle_rad):
            raise MyofaceValueError(
                f"jaw hinge_angle_rad must be in (0, max_angle_rad = {self.max_angle_rad}]; "
                f"got {hinge}"
            )
        object.__setattr__(self, "hinge_angle_rad", float(hinge))
        if not 0 <= float(self.translation_from) < 1:
            raise MyofaceValueError(
                f"jaw translation_from must be in [0, 1); got {self.translation_from}"
            )

    def translation_phase(self, opening: float) -> float:
        """How far (0-1) the translation phase has gone at jaw control ``opening`` in [0, 1]."""
        k = float(self.translation_from)
        return (max(float(opening) - k, 0.0) / (1.0 - k)) ** SLIDE_POWER

    def angle_rad(self, opening: float) -> float:
        """The mandible's rotation (rad) at jaw control ``opening`` in [0, 1]."""
        h = self.hinge_angle_rad
        return h * float(opening) + (self.max_angle_rad - h) * self.translation_phase(opening)

    def slide(self, opening: float) -> np.ndarray:
        """The condyles' translation (3,) mm at jaw control ``opening`` in [0, 1]."""
        return self.translation_phase(opening) * self.slide_mm

    def pose(self, opening: float) -> tuple[np.ndarray, np.ndarray]:
        """The mandible's rigid motion from rest at ``opening``: ``(rotation (3, 3),
        translation (3,) mm)``, ``x -> rotation @ x + translation`` (what a point of weight 1
        and the lower teeth follow)."""
        rot = rotate_about_axis(np.eye(3), np.zeros(3), self.hinge_axis, self.angle_rad(opening))
        rot = rot.T  # rows of the rotated identity -> the rotation matrix
        return rot, self.hinge_point - rot @ self.hinge_point + self.slide(opening)

    def rotate(self, points: np.ndarray, weights: np.ndarray, opening: float) -> np.ndarray:
        """Positions of ``points`` (N, 3) mm when the jaw control is ``opening`` in [0, 1]:
        each rotated by its weight times the angle about the hinge, then moved by its weight
        times the condylar slide (weights (N,) in [0, 1])."""
        w = np.asarray(weights, dtype=np.float64)
        angles = self.angle_rad(opening) * w
        out = np.array(points, dtype=np.float64)
        m = angles != 0  # points that do not follow the jaw stay bit-for-bit where they are
        out[m] = rotate_about_axis(out[m], self.hinge_point, self.hinge_axis, angles[m])
        sl = self.slide(opening)
        if np.any(sl != 0):
            out[m] += w[m, None] * sl
        return out

    def mirror_error_mm(self) -> float:
        """Distance of the hinge from the mid-sagittal plane plus the axis' tilt (for tests)."""
        return float(abs(self.hinge_point[0]) + abs(abs(self.hinge_axis[0]) - 1.0))
