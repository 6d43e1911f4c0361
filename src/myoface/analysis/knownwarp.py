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
  (2026-12-01), because no muscle moves the skin that way. Two constructions: the skin's x, y
  mapped by a 2-D similarity (:func:`expression_warp`: flat, the depth dropped), and its 3-D
  motion projected through a camera at the head's pose (:func:`projected_warp`: what a camera
  sees of a face's motion, which a flat field is not).

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


def projected_warp(points, shape0, shape1, camera, pose, **head) -> MeshWarp:
    """The :class:`MeshWarp` that moves a frame's landmarks ``points`` (N, 2+) pixels as a
    face's 3-D motion from ``shape0`` to ``shape1`` (N, 3) mm, head frame, is seen by
    ``camera`` (a :class:`~myoface.analysis.camera.PinholeCamera`) with the head at ``pose``
    (a :class:`~myoface.analysis.camera.HeadPose`): each point's shift is its vertex's
    projected motion, depth included. A 3-D motion seen through a pinhole does not move the
    image as its x, y do (:func:`expression_warp`'s field): a point off the camera's axis that
    moves in depth moves in the image too (a smile's corners, which move back 3.7 mm as they
    rise, show 8 % more motion so than their x, y; surprise's chin, which moves back 5-6 mm
    as the jaw drops below the axis, 29 % less: measured at the sample video's calibration
    pose, 2026-12-03), so that no motion of a face seen at that pose makes a flat field, and a
    fit, which must move a face, cannot match one. This field is one a face seen at ``pose``
    makes. ``head``: the similarity of the head's motion (``pivot`` defaults to the points'
    centre)."""
    pts = np.asarray(points, dtype=np.float64)[:, :2]
    s0, s1 = (np.asarray(s, dtype=np.float64).reshape(-1, 3) for s in (shape0, shape1))
    if not len(pts) == len(s0) == len(s1):
        raise MyofaceValueError(
            f"projected_warp needs one 3-D vertex per point; got {len(pts)} points, "
            f"{len(s0)} and {len(s1)} vertices"
        )
    shifts = camera.project(pose.apply(s1)) - camera.project(pose.apply(s0))
    head.setdefault("pivot", pts.mean(0))
    return MeshWarp(points=pts, shifts=shifts, **head)


# ------------------------------------------------------------------ an expression's look
#
# A warp moves the frame's pixels; a real expression also changes what they show. In the
# sample video's smile the lips part (the teeth and the dark of the mouth appear between
# them), the nasolabial folds deepen and the cheeks bulge, and the brows' raise folds the
# forehead: about 8 % of the face's textured patches stop looking as they did at calibration
# (:meth:`~myoface.analysis.photometric.PhotometricTerm.occlusion`'s test, 2026-12-01). A
# reader of pixels that assumes the neutral's look can read such a change as motion, or as
# motion resisted; a warp alone cannot show that. :func:`expression_look` paints the change
# on a warped frame where the warped face now is, so the motion stays the known answer and
# the look is what a real face adds.

#: MediaPipe's face mesh's inner lips, corner to corner (upper, lower), and points used below
INNER_LIP_UPPER = (78, 191, 80, 81, 82, 13, 312, 311, 310, 415, 308)
INNER_LIP_LOWER = (78, 95, 88, 178, 87, 14, 317, 402, 318, 324, 308)
NOSE_WINGS = (129, 358)
MOUTH_CORNERS = (61, 291)
EYES_OUTER = (33, 263)
BROWS = (70, 63, 105, 66, 107, 336, 296, 334, 293, 300)
GLABELLA, FOREHEAD_TOP = 9, 10
#: what shows between the lips where they have parted: the upper teeth (this share of the
#: gap's height from the upper lip, across the middle of the mouth) and the dark of the
#: mouth (RGB)
TEETH_SHARE = 0.55
TEETH_RGB = (205.0, 195.0, 180.0)
MOUTH_DARK_RGB = (40.0, 22.0, 22.0)
#: a fold: its line darkens the skin by this fraction, over a Gaussian profile of this width
#: (1 sd, IOD), and the skin beside it (the cheek's bulge) brightens by this fraction
FOLD_DARKEN = 0.3
FOLD_WIDTH_IOD = 0.018
FOLD_BULGE = 0.10
#: the cheeks' shading (a smile): each cheek bulges and turns its normals, so that under a
#: light from one side one cheek brightens and the other darkens by this fraction at its
#: centre (a Gaussian of this radius, IOD, centred this far below the eye and out from the
#: nose's wing: the sample video's smile's residuals against the calibration's look show
#: such a pair of broad patches, 15-30 grey levels)
CHEEK_SHADE = 0.10
CHEEK_RADIUS_IOD = 0.14
#: the forehead's lines (surprise): this many, between the brows and the forehead's top
FOREHEAD_LINES = (0.3, 0.5, 0.7)
FOREHEAD_DARKEN = 0.15
#: which look each expression adds (any other: the lips' gap only)
EXPRESSION_LOOKS = {
    "happiness": ("gap", "nasolabial", "cheeks"),
    "surprise": ("gap", "forehead"),
}


def _quadratic(a, c, b, n: int = 24) -> np.ndarray:
    """A quadratic Bezier from ``a`` to ``b`` with control point ``c`` (n, 2)."""
    t = np.linspace(0.0, 1.0, n)[:, None]
    return (1 - t) ** 2 * a + 2 * (1 - t) * t * c + t**2 * b


def _line_profile(shape_hw, lines, sigma_px: float) -> np.ndarray:
    """A Gaussian ridge (H, W) float32 of peak ~1 along the polylines ``lines`` (each (n, 2)
    pixels) of width ``sigma_px`` (1 sd)."""
    cv2 = _cv2()
    h, w = shape_hw
    ss = 4  # drawn at 4x sub-pixel precision (cv2's shift)
    m = np.zeros((h, w), np.float32)
    for ln in lines:
        q = np.round(np.asarray(ln) * (1 << ss)).astype(np.int32).reshape(-1, 1, 2)
        cv2.polylines(m, [q], False, 1.0, 1, cv2.LINE_AA, ss)
    s = max(float(sigma_px), 0.5)
    out = cv2.GaussianBlur(m, (0, 0), s)
    peak = 1.0 / (np.sqrt(2 * np.pi) * s)  # a 1-px line blurred
    return np.minimum(out / peak, 1.0)


#: a polygon's coverage of a pixel is sampled on this many points a side
COVERAGE_SUBSAMPLES = 4


def _coverage(polygon, shape_hw) -> np.ndarray:
    """How much of each pixel (H, W) float32, 0-1, the ``polygon`` (n, 2) pixels covers
    (:data:`COVERAGE_SUBSAMPLES` squared points a pixel: a polygon of no area covers none)."""
    from matplotlib.path import Path

    h, w = shape_hw
    out = np.zeros((h, w), np.float32)
    poly = np.asarray(polygon, dtype=np.float64)
    x0, y0 = np.maximum(np.floor(poly.min(0)).astype(int) - 1, 0)
    x1 = min(int(np.ceil(poly[:, 0].max())) + 2, w)
    y1 = min(int(np.ceil(poly[:, 1].max())) + 2, h)
    if x1 <= x0 or y1 <= y0:
        return out
    n = COVERAGE_SUBSAMPLES
    off = (np.arange(n) + 0.5) / n - 0.5  # (pixel centres at integer coordinates)
    ys = (np.arange(y0, y1)[:, None] + off[None, :]).ravel()
    xs = (np.arange(x0, x1)[:, None] + off[None, :]).ravel()
    gx, gy = np.meshgrid(xs, ys)
    inside = Path(poly).contains_points(np.column_stack([gx.ravel(), gy.ravel()]))
    cov = inside.reshape(y1 - y0, n, x1 - x0, n).mean((1, 3))
    out[y0:y1, x0:x1] = cov
    return out


def mouth_gap(points) -> np.ndarray:
    """The lips' gap of the landmarks ``points`` (468, 2+) pixels: the polygon (n, 2) between
    the inner lips' contours, upper then lower (corner to corner and back)."""
    p = np.asarray(points, dtype=np.float64)[:, :2]
    return np.vstack([p[list(INNER_LIP_UPPER)], p[list(INNER_LIP_LOWER)][::-1]])


def expression_look(image, points, expression: str, amount: float, iod: float | None = None):
    """``image`` (H, W, 3) uint8, the frame of a face whose landmarks are at ``points`` (468,
    2+) pixels (the warped frame's: :meth:`MeshWarp.moved`), with the look that
    ``expression`` adds at ``amount`` (0-1, its strength over time) painted on
    (:data:`EXPRESSION_LOOKS`): where the lips have parted (:func:`mouth_gap`: between the
    inner lips' contours) the upper teeth and the dark of the mouth (whatever ``amount``:
    the gap is the motion's); for a smile the nasolabial folds
    (from the nose's wings to beyond the mouth's corners) darkened with the cheek's bulge
    beside them brightened, and the cheeks' shading changed (one brighter, the other darker,
    as a light from one side shades a bulge); for surprise lines across the forehead. ``iod``: the
    inter-ocular distance (pixels; default the points' outer eye corners'). The motion is
    unchanged: only what the pixels show."""
    cv2 = _cv2()
    img = np.asarray(image)
    a = float(np.clip(amount, 0.0, 1.0))
    if a <= 0.0:
        return img.copy()
    p = np.asarray(points, dtype=np.float64)[:, :2]
    if iod is None:
        iod = float(np.linalg.norm(p[EYES_OUTER[1]] - p[EYES_OUTER[0]]))
    h, w = img.shape[:2]
    out = img.astype(np.float32)
    looks = EXPRESSION_LOOKS.get(expression, ("gap",))
    across = (p[EYES_OUTER[1]] - p[EYES_OUTER[0]]) / iod  # the face's x axis in the image
    sigma = FOLD_WIDTH_IOD * iod
    shade = np.ones((h, w), np.float32)
    if "nasolabial" in looks:
        lines, bulges = [], []
        for side, (wing, corner) in enumerate(zip(NOSE_WINGS, MOUTH_CORNERS, strict=True)):
            out_dir = across if side else -across
            down = np.array([-out_dir[1], out_dir[0]]) * (1 if side else -1)
            if down[1] < 0:
                down = -down
            start = p[wing] + 0.03 * iod * out_dir
            end = p[corner] + 0.07 * iod * out_dir + 0.08 * iod * down
            ctrl = 0.5 * (start + end) + 0.06 * iod * out_dir
            ln = _quadratic(start, ctrl, end)
            lines.append(ln)
            bulges.append(ln + 3.0 * sigma * out_dir)
        shade *= 1.0 - FOLD_DARKEN * a * _line_profile((h, w), lines, sigma)
        shade *= 1.0 + FOLD_BULGE * a * _line_profile((h, w), bulges, 2.0 * sigma)
    if "cheeks" in looks:
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        r2 = 2.0 * (CHEEK_RADIUS_IOD * iod) ** 2
        for sign, wing, eye in (
            (1.0, NOSE_WINGS[0], EYES_OUTER[0]),
            (-1.0, NOSE_WINGS[1], EYES_OUTER[1]),
        ):
            c = 0.5 * (p[wing] + p[eye])
            g = np.exp(-((xx - c[0]) ** 2 + (yy - c[1]) ** 2) / r2)
            shade *= 1.0 + sign * CHEEK_SHADE * a * g
    if "forehead" in looks:
        up = p[FOREHEAD_TOP] - p[GLABELLA]
        brows = p[list(BROWS)]
        order = np.argsort(brows @ across)
        lines = [brows[order] + k * up for k in FOREHEAD_LINES]
        shade *= 1.0 - FOREHEAD_DARKEN * a * _line_profile((h, w), lines, 0.7 * sigma)
    out *= shade[..., None]
    if "gap" in looks:
        # where the warp has parted the lips (the skin between the inner lips' contours is
        # the neutral's closed lips stretched): what shows there now is the upper teeth
        # across the middle of the mouth (TEETH_SHARE of the way down from the upper lip)
        # and the dark of the mouth below them and towards the corners
        mask = _coverage(mouth_gap(p), (h, w))
        ss = 4
        lines = []
        for contour in (INNER_LIP_UPPER, INNER_LIP_LOWER):
            ln = np.zeros((h, w), np.uint8)
            c = np.round(p[list(contour)] * (1 << ss)).astype(np.int32).reshape(-1, 1, 2)
            cv2.polylines(ln, [c], False, 255, 1, cv2.LINE_8, ss)
            lines.append(cv2.distanceTransform(255 - ln, cv2.DIST_L2, 3))
        frac = lines[0] / np.maximum(lines[0] + lines[1], 1e-6)  # 0 upper lip, 1 lower
        c0, c1 = p[INNER_LIP_UPPER[0]], p[INNER_LIP_UPPER[-1]]
        u = (c1 - c0) / max(float(np.linalg.norm(c1 - c0)) ** 2, 1e-9)
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        along = (xx - c0[0]) * u[0] + (yy - c0[1]) * u[1]  # 0..1 corner to corner
        middle = np.clip(1.0 - (np.abs(along - 0.5) / 0.32) ** 4, 0.0, 1.0)
        teeth = (middle * np.clip((TEETH_SHARE - frac) / 0.15 + 0.5, 0.0, 1.0))[..., None]
        colour = teeth * np.array(TEETH_RGB, np.float32) + (1 - teeth) * np.array(
            MOUTH_DARK_RGB, np.float32
        )
        out = mask[..., None] * colour + (1 - mask[..., None]) * out
    return np.clip(np.round(out), 0, 255).astype(img.dtype)
