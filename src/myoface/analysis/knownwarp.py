"""Known answers made from real frames: a frame warped by a known smooth displacement field
(the expression's regions moved by set amounts), with a few degrees and pixels of fake head
motion on top. The warped frames keep the real frame's texture, noise and lighting, and the
true motion of every point is known, so a reader of facial motion (a detector, an optical
flow, a judge of resynthesis) can be validated on them before it is trusted.

Two kinds of field:

- :class:`KnownWarp`: a sum of Gaussian bumps, one per moved point, each of ``radius`` pixels
  and a displacement (pixels) of its own (:func:`region_warp`): any smooth field, to validate a
  reader of motion on;
- :class:`MeshWarp`: the motion a face makes, the face model's own skin displacement at known
  contractions, mapped into the frame at its landmarks and interpolated smoothly between them
  (:func:`expression_warp`): a field the face model can reproduce, so that the whole analysis
  (what it observes and what it fits) can be judged against it, contractions included. A sum
  of bumps at the regions' points is not a motion any muscle makes: given the warped points
  exactly, the 3-D fit reproduced 0.4 of the lips' bump motion and 0.34 of the chin's
  (2026-12-01), because no muscle moves the skin that way.

Then the whole frame is moved by a similarity (rotation, scale and translation about the
face's centre: the head's motion in the image plane). A pixel ``x`` of the source frame lands
at ``y = S(x + d(x))``. The warped frame is sampled backward: for each ``y``, ``x`` is found by
fixed-point iteration of ``x = S^-1(y) - d(x)`` (the fields are smooth and small against their
scale, so it contracts) and the source is sampled there bilinearly (OpenCV's ``remap``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from myoface.errors import MyofaceValueError
from myoface.facemesh import import_opencv

#: fixed-point iterations of the backward map (the residual falls by the bumps' largest
#: gradient, |d'| < 0.3, each iteration: 1e-6 px after 12)
BACKWARD_ITERATIONS = 12
#: the backward map's grid step, pixels (interpolated between: the field is smooth)
GRID_PX = 4


def _cv2():
    return import_opencv("a known warp")


class _Warp:
    """What every known warp does with its ``displacement`` field (the expression's displacement) and its
    similarity (the head's motion in the image plane)."""

    rotation_deg: float
    scale: float
    translation_px: tuple
    pivot: np.ndarray

    def displacement(self, x: np.ndarray) -> np.ndarray:  # pragma: no cover (each warp has its own)
        raise NotImplementedError

    def _check_head(self) -> None:
        """The similarity's parameters checked, its pivot an array (frozen subclasses)."""
        if not self.scale > 0:
            raise MyofaceValueError(f"scale must be > 0; got {self.scale}")
        object.__setattr__(self, "pivot", np.asarray(self.pivot, dtype=np.float64).reshape(2))

    def _similarity(self) -> tuple[np.ndarray, np.ndarray]:
        return _similarity(self.rotation_deg, self.scale, self.translation_px, self.pivot)

    def moved(self, x: np.ndarray) -> np.ndarray:
        """Where the points ``x`` (N, 2) of the source frame are in the warped frame."""
        x = np.asarray(x, dtype=np.float64)
        a, b = self._similarity()
        return (x + self.displacement(x)) @ a.T + b

    def head_only(self, x: np.ndarray) -> np.ndarray:
        """Where the points ``x`` would be with the head's motion alone (no expression)."""
        a, b = self._similarity()
        return np.asarray(x, dtype=np.float64) @ a.T + b

    def apply(self, image: np.ndarray) -> np.ndarray:
        """The warped frame (same size and type as ``image``; :func:`_warp_image`)."""
        return _warp_image(image, self.displacement, *self._similarity())


@dataclass(frozen=True)
class KnownWarp(_Warp):
    """A known smooth warp of a frame (see the module's docstring).

    Attributes
    ----------
    centres : (K, 2) pixels (x, y): where each bump is centred (a point the warp moves).
    shifts : (K, 2) pixels: each bump's displacement at its centre.
    radius : float or (K,) pixels: the bumps' Gaussian radius (sigma).
    rotation_deg, scale, translation_px : the head's motion in the image plane, a similarity
        about ``pivot`` applied after the bumps (0, 1, (0, 0): none).
    pivot : (2,) pixels: the similarity's centre (e.g. the face's centre).
    """

    centres: np.ndarray
    shifts: np.ndarray
    radius: float | np.ndarray
    rotation_deg: float = 0.0
    scale: float = 1.0
    translation_px: tuple = (0.0, 0.0)
    pivot: np.ndarray = field(default_factory=lambda: np.zeros(2))

    def __post_init__(self):
        c = np.asarray(self.centres, dtype=np.float64).reshape(-1, 2)
        s = np.asarray(self.shifts, dtype=np.float64).reshape(-1, 2)
        r = np.broadcast_to(np.asarray(self.radius, dtype=np.float64), (len(c),))
        if len(c) != len(s) or not (np.isfinite(c).all() and np.isfinite(s).all()):
            raise MyofaceValueError("centres and shifts must be finite (K, 2) arrays alike")
        if not (r > 0).all():
            raise MyofaceValueError("the bumps' radius must be > 0 pixels")
        self._check_head()
        object.__setattr__(self, "centres", c)
        object.__setattr__(self, "shifts", s)
        object.__setattr__(self, "radius", r.copy())

    # ------------------------------------------------------------------ the field
    def displacement(self, x: np.ndarray) -> np.ndarray:
        """The expression's displacement d(x) (N, 2) pixels at points ``x`` (N, 2)."""
        return self.bumps(x)

    def bumps(self, x: np.ndarray) -> np.ndarray:
        """The expression's displacement d(x) (N, 2) pixels at points ``x`` (N, 2)."""
        x = np.asarray(x, dtype=np.float64)
        out = np.zeros_like(x)
        for c, s, r in zip(self.centres, self.shifts, self.radius, strict=True):
            w = np.exp(-((x - c) ** 2).sum(-1) / (2.0 * r * r))
            out += w[..., None] * s
        return out


def _similarity(rotation_deg, scale, translation_px, pivot) -> tuple[np.ndarray, np.ndarray]:
    """(A (2, 2), b (2,)) of ``S(x) = A x + b``, a similarity about ``pivot``."""
    t = np.radians(rotation_deg)
    a = scale * np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    b = pivot + np.asarray(translation_px, dtype=np.float64) - a @ pivot
    return a, b


def _grid(h: int, w: int) -> np.ndarray:
    """The backward map's nodes (gh, gw, 2) pixels (x, y), every :data:`GRID_PX`."""
    gh, gw = -(-h // GRID_PX) + 1, -(-w // GRID_PX) + 1
    yy, xx = np.mgrid[0:gh, 0:gw].astype(np.float64) * GRID_PX
    return np.stack([xx, yy], -1)


def _warp_image(image, field, a, b) -> np.ndarray:
    """``image`` warped by ``y = A (x + field(x)) + b`` (``field``: (N, 2) -> (N, 2) pixels). The backward map is solved on a grid
    of every :data:`GRID_PX` pixels and interpolated between (the fields are smooth on the
    scale of their features: 0.01 px off for a 3 px bump of 25 px radius)."""
    cv2 = _cv2()
    img = np.asarray(image)
    h, w = img.shape[:2]
    nodes = _grid(h, w)
    gh, gw = nodes.shape[:2]
    y = nodes.reshape(-1, 2)
    z = (y - b) @ np.linalg.inv(a).T  # S^-1(y)
    x = z.copy()
    for _ in range(BACKWARD_ITERATIONS):
        x = z - field(x)
    x = np.ascontiguousarray(x.reshape(gh, gw, 2), dtype=np.float32)
    # every pixel's source, interpolated between the grid's nodes (node (i, j) is pixel
    # (j, i) * GRID_PX)
    gy, gx = np.mgrid[0:h, 0:w].astype(np.float32) / GRID_PX
    mx = cv2.remap(x[..., 0], gx, gy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    my = cv2.remap(x[..., 1], gx, gy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)


def region_warp(points: np.ndarray, regions: dict, amounts: dict, radius_px: float,
                **head) -> KnownWarp:  # fmt: skip
    """A :class:`KnownWarp` that moves the points of ``regions`` ({name: point indices}) of
    ``points`` (N, 2+) pixels by ``amounts`` ({name: (dx, dy) pixels, or (M, 2) per point})
    with bumps of ``radius_px``; ``head``: :class:`KnownWarp`'s similarity (its ``pivot``
    defaults to the points' centre)."""
    pts = np.asarray(points, dtype=np.float64)[:, :2]
    centres, shifts = [], []
    for name, idx in regions.items():
        if name not in amounts:
            continue
        a = np.broadcast_to(np.asarray(amounts[name], dtype=np.float64), (len(idx), 2))
        centres.append(pts[list(idx)])
        shifts.append(a)
    if not centres:
        centres, shifts = [np.zeros((0, 2))], [np.zeros((0, 2))]
    head.setdefault("pivot", pts.mean(0))
    return KnownWarp(np.vstack(centres), np.vstack(shifts), radius_px, **head)


#: the mesh warp's field is pinned to 0 on a ring of this many points around the face ...
RING_POINTS = 48
#: ... this many times the landmarks' extent from their centre (the motion stays on the face)
RING_SCALE = 1.35


@dataclass(frozen=True)
class MeshWarp(_Warp):
    """A known warp whose field is given at points: ``shifts`` (N, 2) pixels at ``points``
    (N, 2) pixels (e.g. the face's landmarks moved as the face model moves its skin), zero on
    a ring around them (:data:`RING_POINTS` at :data:`RING_SCALE` times their extent) and
    beyond, and linear in between, over the Delaunay triangles of the points and the ring (exact
    at the points: ``moved(points)`` is ``points + shifts`` before the similarity); then the
    similarity, as :class:`KnownWarp`'s. Linear, not a spline: a thin-plate spline through the
    landmarks folds the frame where two points lie close together and move apart (the lips' 13
    and 14, 1.2 px apart on the sample video: the smile's spline had a Jacobian determinant of
    -6 between them), and the face there is then not a face's; a linear field folds only
    where a triangle turns over (:meth:`min_jacobian` says whether it does)."""

    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    shifts: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    rotation_deg: float = 0.0
    scale: float = 1.0
    translation_px: tuple = (0.0, 0.0)
    pivot: np.ndarray = field(default_factory=lambda: np.zeros(2))

    def __post_init__(self):
        from scipy.interpolate import LinearNDInterpolator
        from scipy.spatial import Delaunay

        p = np.asarray(self.points, dtype=np.float64).reshape(-1, 2)
        s = np.asarray(self.shifts, dtype=np.float64).reshape(-1, 2)
        if len(p) < 3 or len(p) != len(s) or not (np.isfinite(p).all() and np.isfinite(s).all()):
            raise MyofaceValueError("points and shifts must be finite (N >= 3, 2) arrays alike")
        self._check_head()
        c = (p.max(0) + p.min(0)) / 2
        half = (p.max(0) - p.min(0)) / 2 * RING_SCALE
        t = np.linspace(0, 2 * np.pi, RING_POINTS, endpoint=False)
        ring = c + half * np.column_stack([np.cos(t), np.sin(t)])
        nodes = np.vstack([p, ring])
        tri = Delaunay(nodes)
        vals = _unfold(nodes, np.vstack([s, np.zeros_like(ring)]), tri.simplices)
        s = vals[: len(p)]
        spline = LinearNDInterpolator(tri, vals, fill_value=0.0)
        object.__setattr__(self, "points", p)
        object.__setattr__(self, "shifts", s)
        object.__setattr__(self, "_spline", spline)

    def displacement(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        return self._spline(x.reshape(-1, 2)).reshape(x.shape)

    def min_jacobian(self) -> float:
        """The least Jacobian determinant of ``x -> x + d(x)`` over the field's triangles
        (> 0: the warp does not fold the frame)."""
        tri = self._spline.tri
        p, d = tri.points, self._spline.values
        return float((_signed_areas(p + d, tri.simplices) / _signed_areas(p, tri.simplices)).min())

    def apply(self, image: np.ndarray) -> np.ndarray:
        """The warped frame; the spline is evaluated once on the backward map's grid and
        interpolated bilinearly between its nodes while the map is solved (0.01 px of a
        smooth field)."""
        cv2 = _cv2()
        h, w = np.shape(image)[:2]
        nodes = _grid(h, w)
        grid = np.ascontiguousarray(self.displacement(nodes), dtype=np.float32)

        def on_grid(x):
            q = np.ascontiguousarray(x.reshape(1, -1, 2) / GRID_PX, dtype=np.float32)
            out = cv2.remap(grid, q[..., 0], q[..., 1], cv2.INTER_LINEAR,
                            borderMode=cv2.BORDER_REPLICATE)  # fmt: skip
            return out.reshape(-1, 2).astype(np.float64)

        return _warp_image(image, on_grid, *self._similarity())


#: a triangle of a mesh warp turned over or squeezed below this fraction of its area ...
MIN_AREA_RATIO = 0.2
#: ... has its vertices' shifts drawn together (up to this many rounds)
UNFOLD_ROUNDS = 100


def _signed_areas(x: np.ndarray, simplices: np.ndarray) -> np.ndarray:
    """Twice the signed area (T,) of each triangle ``simplices`` (T, 3) of points ``x``."""
    a, b, c = (simplices[:, k] for k in range(3))
    e1, e2 = x[b] - x[a], x[c] - x[a]
    return e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]


def _unfold(points, shifts, simplices) -> np.ndarray:
    """``shifts`` (N, 2) at ``points`` (N, 2) with no triangle of ``simplices`` turned over:
    where one would be (its area after the shift below :data:`MIN_AREA_RATIO` of before), its
    vertices' shifts are drawn halfway to their mean, round after round. Where two points lie
    close together and the face model moves them apart by more than their distance in the
    frame (the person's lips are closer than the model's), or together, the frame cannot show
    that motion without folding; the shifts that stay are the known answer.

    On the sample video's smile the shifts drawn in are the lips' (56 of 468 points, up to
    3.8 px, 2026-12-01): the face model's lips are 6 px apart at rest where the person's are
    1.3 px (closed), and the model's smile closes its gap, which on closed lips crosses them."""
    d = np.array(shifts, dtype=np.float64)
    a0 = _signed_areas(points, simplices)
    for _ in range(UNFOLD_ROUNDS):
        bad = np.flatnonzero(_signed_areas(points + d, simplices) < MIN_AREA_RATIO * a0)
        if not len(bad):
            break
        for t in bad:
            v = simplices[t]
            d[v] = 0.5 * d[v] + 0.5 * d[v].mean(0)
    return d


def expression_warp(points, model, contractions, state=None, **head):
    """The :class:`MeshWarp` that moves a frame's landmarks ``points`` (468, 2+) pixels
    (MediaPipe's face mesh: point i is the face model's vertex i) as ``model`` (a FaceModel in
    that topology) moves its skin at ``contractions`` (relaxed through its tissue from
    ``state``, default its rest state): the skin's displacement (x, y of the head frame; its
    depth is not seen by a frontal camera) mapped into the frame by the 2-D similarity of the
    model's neutral onto the points at the vertices no muscle moves
    (:func:`~myoface.analysis.weights.gauge_vertices`, the nose): the scale at which the 3-D
    fit's head frame is the image's, since the fit's person has the model's nose (its
    gauge). ``head``: the similarity of the head's motion (``pivot`` defaults to the points'
    centre). Returns (warp, the tissue's state)."""
    from myoface.analysis.weights import gauge_vertices

    pts = np.asarray(points, dtype=np.float64)[:, :2]
    if len(pts) != model.face.n_vertices:
        raise MyofaceValueError(
            f"expression_warp needs one point per vertex of the face model "
            f"({model.face.n_vertices}); got {len(pts)}"
        )
    rest = model.skin_vertices()
    res = model.relax(np.asarray(contractions, dtype=np.float64), state or model.rest_state())
    disp = model.skin_vertices(res.state) - rest
    flip = np.array([1.0, -1.0])  # head frame y up, image y down
    src = rest[:, :2] * flip
    g = gauge_vertices(model)
    src_c, dst_c = src[g] - src[g].mean(0), pts[g] - pts[g].mean(0)
    u, sv, vt = np.linalg.svd(dst_c.T @ src_c)
    d = np.diag([1.0, np.sign(np.linalg.det(u @ vt))])
    rot = u @ d @ vt
    s = float(np.trace(np.diag(sv) @ d) / (src_c**2).sum())
    shifts = s * (disp[:, :2] * flip) @ rot.T
    head.setdefault("pivot", pts.mean(0))
    return MeshWarp(points=pts, shifts=shifts, **head), res.state
