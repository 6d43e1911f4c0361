"""The receiver's picture: the calibration frame moved by the person's model
(:class:`PictureModel`), what ``myoface decode`` shows and what animates a still photo
(``myoface synth --in-photo``).

A frame's parameters (:class:`~myoface.codec.params.FrameParams`: head pose, contractions,
gaze) drive the model; the model's skin, posed and seen through the camera, is projected now
and at calibration, and the calibration picture is warped by that motion, piecewise affinely
over the projected triangles (:mod:`myoface.codec.warp`; one :func:`cv2.remap` of the
picture). The warp is continued outside the face by rings of nodes around the face's rim that
move with the head (hair, ears, neck: the head's rigid motion), then with less of it, then not
at all: the picture's border and everything far from the head stay still. Nearer the head, the
person is told from the background once, in the calibration frame (GrabCut,
:func:`person_mask`): the warped person is laid over a still background plate, filled where the
head was (:func:`fill_rows`), so the room behind a turning head is not dragged along.

What the picture cannot supply is the model's:

- the inside of the mouth: where the lips part more than at calibration, the model's mouth
  (cavity, teeth, tongue; :class:`~myoface.render.Renderer`, the jaw's pose) rendered through
  the same camera shows through the opening, faded in with the opening (the calibration's own
  mouth at the calibration's opening);
- the eyelids: the lid skin is skin (the model's lids, :mod:`myoface.muscles.lids`, close the
  opening): a blink draws the calibration's lid over the eye;
- the eyes turned by gaze: each eyeball is a cap of nodes on the model's eyeball sphere, its
  material points turned by the gaze now and at calibration, so the iris of the calibration
  picture moves across the eye; the eyeball's part under the lids at calibration (never seen)
  is filled with the sclera's colour.

What the warp cannot show of the frame's look, the stream's appearance terms carry
(:data:`~myoface.codec.params.APPEARANCE_FIELDS`, format version 2), applied on the warped
picture (:meth:`PictureModel.apply_appearance`): the inside of the mouth's luma gain and
offset (the person's teeth are brighter than the model's cavity), and the face's shading, a
gain over the face and smooth bumps of light on it (a webcam's exposure, a head turning under
lights, an expression's shading). The encoder fits them on each frame against this picture
(:meth:`PictureModel.estimate_appearance`).

The physics per frame is the synthesis' (:mod:`myoface.synth`): the tissue relaxed at the
frame's contractions, warm-started from the previous frame's (``physics="relax"``); or, for a
fixed cost (the default: real time), the tissue's linear response to each muscle and its
tabulated response to the jaw, summed, computed once per model and made exact at the
calibration (``physics="linear"``, :func:`tissue_response`; the lids and the lips' contact
with the teeth are applied on it as on the relaxed skin).

Image coordinates are (x, y) = (column, row), pixels, pixel centres at half-integers (the
camera's, :class:`~myoface.analysis.camera.PinholeCamera`); the head frame and the camera
frame are the analysis' (:mod:`myoface.analysis.camera`); mm.

A still photo has no camera: :func:`photo_setup` aligns the model to the face MediaPipe found
in it, as ``myoface face from-photo`` does, and makes its camera (a far pinhole, nearly
orthographic, as the alignment's similarity is) and its calibration parameters
(:mod:`myoface.codec.photo` animates a photo with it).
"""

from __future__ import annotations

import time
import warnings
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from myoface.analysis.camera import PinholeCamera
from myoface.analysis.potentials import LUMA_601
from myoface.codec.params import (
    APPEARANCE_LIMITS,
    N_APPEARANCE,
    N_SHADING_BUMPS,
    FrameParams,
)
from myoface.codec.warp import raster_warp
from myoface.errors import MyofaceValueError

#: the luma's weights (BT.601), float32 as the picture's arithmetic
LUMA = np.asarray(LUMA_601, dtype=np.float32)

__all__ = [
    "PHYSICS",
    "PictureModel",
    "PictureStats",
    "fill_holes",
    "fill_rows",
    "person_mask",
    "photo_setup",
    "tissue_response",
]

PHYSICS = ("linear", "relax")

#: labels of the warp's layers in :attr:`PictureModel.last_label`
LABEL_STILL, LABEL_AROUND, LABEL_EYE, LABEL_MOUTH, LABEL_SKIN = 0, 1, 2, 3, 4

#: the seed of OpenCV's random generator for each GrabCut (:func:`person_mask`); 0 gives
#: ``cv::RNG``'s default state (0xFFFFFFFF), a fresh process', so every segmentation is that one
GRABCUT_SEED = 0

#: the rings of nodes around the face's rim (:class:`PictureModel`): each ring is the rim
#: scaled by ``scale`` about its centre in the head frame (x, y), ``back_mm`` behind it (the
#: head's sides curve away from the camera), and moves with ``weight`` of the head's motion
#: (1: rigidly with the head; 0: still). Above the mouth's level the rings carry the hair and
#: the ears; below it (the neck, the shoulders, which follow the head less) the weights of the
#: outer rings are ``below`` instead
RINGS = (
    # scale, back_mm, weight, below
    (1.30, 15.0, 1.0, 0.6),
    (1.75, 35.0, 0.55, 0.15),
    (2.50, 60.0, 0.0, 0.0),
)
#: ... the second ring's weight above the mouth when the person is told from the background
#: (:func:`person_mask`): the head and its hair move as one, the background behind them
#: staying still whatever the warp does there
SEGMENTED_RING2_WEIGHT = 1.0
#: the person is told from the background by GrabCut (Rother, Kolmogorov & Blake 2004,
#: OpenCV's :func:`cv2.grabCut`) at this scale of the picture, in this many iterations: the
#: face (inside the rim) is the person, the second ring's outline and a band below the chin
#: may be, everything beyond the third ring is background
SEGMENT_SCALE, SEGMENT_ITERATIONS = 0.5, 4
#: the background behind the head (what shows where it moves away) is made down to this
#: many face widths below the chin (the neck); the body below is its own background
SEGMENT_NECK = 0.35
#: ... within this many face widths of the face's centre line (the neck; beside it the
#: shoulders, which stay)
SEGMENT_NECK_HALF_WIDTH = 0.4
#: the head's outline is widened by this many pixels (see :func:`person_mask`)
SEGMENT_MARGIN_PX = 4
#: the mask's edge is softened outwards over this many pixels (a Gaussian's sigma)
SEGMENT_SOFT_PX = 1.5
#: as an eye closes, its margin's source in the picture moves this far (px) out of the
#: opening, times the share of the opening's area gone: the lids drawn over the eye read lid
#: skin, not the thin band of white that the margin's points leave inside the opening
#: (MediaPipe's points lie a little inside the lashes). At calibration (the calibration's
#: opening) nothing moves: the warp stays the identity
LID_SOURCE_SHIFT_PX = 2.0
#: nodes on the picture's border every this many pixels (still)
BORDER_STEP_PX = 64
#: the eyeball's cap of nodes reaches this far (degrees) from the eye's forward direction
CAP_DEG = 125.0
#: ... in this many rings of this many nodes each (the cap turned by a gaze of up to 45
#: degrees still covers the eyeball's whole visible disc; its far side is hidden by depth)
CAP_RINGS, CAP_SEGMENTS = 10, 20
#: a point of the cap whose normal's cosine with the way to the camera was at most this at
#: calibration was not seen there (0: the sphere's far side; the cap's rings, 12.5 degrees
#: apart, put the last seen one at 87.5: the calibration's pixels are left as they were)
CAP_SEEN_COS = 0.0
#: the model's mouth is shown through lips parted more than at calibration: faded in from
#: ``MOUTH_FADE_MM[0]`` to ``MOUTH_FADE_MM[1]`` of extra mean gap between the inner lip
#: margins (mm; below it the calibration's own mouth is stretched, a dark line at closed lips)
MOUTH_FADE_MM = (0.3, 1.5)
#: the model's mouth is softened by a Gaussian of this sigma (px of the picture): a camera's
#: optics and a video codec blur the picture's own lips and teeth about as much
MOUTH_SOFT_PX = 0.7
#: the mouth's edge is feathered over this many pixels (a Gaussian of this sigma)
MOUTH_FEATHER_PX = 1.0
#: the model's mouth is rendered at this scale of the picture (its inside has no fine detail;
#: the render's cost is its pixels), unless that would make it less than this many pixels high
MOUTH_RENDER_SCALE, MOUTH_RENDER_MIN_PX = 0.5, 180
#: ... only the face around the mouth: within this many of the mouth's half widths of its
#: centre across and up (an ellipse in the rest head frame)
MOUTH_PART = (1.6, 1.2)
#: the mouth's inside is at least this share of the lips' colour (the render's cavity is
#: lit by the model's lights only, near black in its depth: a hole, not a mouth)
MOUTH_AMBIENT = 0.3
#: the render's brightness is matched to the picture's lips by a gain within these bounds
#: (never brighter: the model's white teeth, brightened, were saturated on the sample)
MOUTH_GAIN = (0.5, 1.0)
#: the sclera's colour is the mean of the brightest share of the calibration's eye opening
SCLERA_SHARE = 0.3
#: the atlas' eye patches have this many pixels of margin around the eyeball's projection
ATLAS_MARGIN_PX = 4
#: a still picture's pinhole: this far (mm) from the head, a focal length that gives the
#: alignment's pixels per mm there; at 10 m the perspective moves a face's points by under
#: 0.5% of their distance from its centre (under a pixel for a face 200 px wide)
PHOTO_DISTANCE_MM = 10_000.0
#: :class:`PictureStats` keeps the times of this many renders (a long stream's last ones)
STATS_FRAMES = 10_000
#: equilibrium tolerance (mm) of the per-frame relax (the synthesis')
RELAX_TOL_MM = 2e-2
#: the shading basis' bumps (:meth:`PictureModel.apply_appearance`): Gaussians of this sigma
#: (a share of the face's width, at the face's distance), centred on face vertices picked
#: farthest apart (in the rest face's x, y) among those off the rim
SHADING_SIGMA_FACE = 0.15
#: the shading is faded out from the face's edge over this many pixels (a Gaussian's sigma
#: over the face's layers): no step at the rim
SHADING_FEATHER_PX = 4.0
#: the encoder's fits (:meth:`PictureModel.estimate_appearance`): the inside of the mouth
#: needs this many pixels; its gain and offset are pulled towards 1 and 0 by a ridge of this
#: share of the data's weight; the shading reads every this-many-th pixel of the skin, its
#: bumps pulled towards 0 by this ridge (per pixel), each pixel's log ratio clipped to this
#: (log2: misplaced edges are not light)
APPEARANCE_MIN_MOUTH_PX = 12
#: ... the inside of the mouth under its terms takes the face's colour at this share of its
#: saturation (teeth and the mouth's shade are a warm white and grey, not skin)
MOUTH_TINT_SATURATION = 0.6
APPEARANCE_MOUTH_RIDGE = 0.01
#: ... the mouth's gain (log2) the encoder sends is within these bounds (the format allows
#: +-2): below 1 the gain flattens the model's teeth against its cavity, and the fit, on the
#: luma alone, takes it down to its bound (x0.25) with the offset lifting the mouth to a flat
#: grey: nearer in luma to a person's wide bright teeth than narrow teeth in a dark cavity, but
#: no longer a mouth to whoever watches (docs/codec-format.md, "the encoder's fit")
APPEARANCE_MOUTH_GAIN_LOG2 = (-0.5, 2.0)
APPEARANCE_SHADING_STRIDE = 2
APPEARANCE_SHADING_RIDGE = 0.02
APPEARANCE_LOG_CLIP = 0.5


@dataclass
class PictureStats:
    """Wall times (ms) of the last :data:`STATS_FRAMES` :meth:`PictureModel.render` calls:
    the physics, the warp's geometry and raster, the remap over the background, the mouth,
    the whole; and the relaxes that did not converge."""

    physics_ms: deque = field(default_factory=lambda: deque(maxlen=STATS_FRAMES))
    warp_ms: deque = field(default_factory=lambda: deque(maxlen=STATS_FRAMES))
    remap_ms: deque = field(default_factory=lambda: deque(maxlen=STATS_FRAMES))
    mouth_ms: deque = field(default_factory=lambda: deque(maxlen=STATS_FRAMES))
    total_ms: deque = field(default_factory=lambda: deque(maxlen=STATS_FRAMES))
    unconverged: int = 0


def _rim_and_openings(face):
    from myoface.render.dressing import find_openings

    loops = face.boundary_loops
    if not loops:
        raise MyofaceValueError("the face model's mesh has no boundary: no rim to warp around")
    rim = np.asarray(max(loops, key=len), dtype=np.int64)
    openings = {op.name: np.asarray(op.loop, dtype=np.int64) for op in find_openings(face)}
    return rim, openings


def _cap_mesh():
    """Unit directions (n, 3) of an eyeball's cap about +z and its triangles."""
    th = np.deg2rad(np.linspace(0.0, CAP_DEG, CAP_RINGS + 1)[1:])
    ph = np.linspace(0.0, 2 * np.pi, CAP_SEGMENTS, endpoint=False)
    dirs = [np.array([0.0, 0.0, 1.0])]
    for t in th:
        for p in ph:
            dirs.append([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])
    tris = []
    s = CAP_SEGMENTS
    for j in range(s):
        tris.append((0, 1 + j, 1 + (j + 1) % s))
    for r in range(CAP_RINGS - 1):
        a0, b0 = 1 + r * s, 1 + (r + 1) * s
        for j in range(s):
            j1 = (j + 1) % s
            tris.append((a0 + j, b0 + j, b0 + j1))
            tris.append((a0 + j, b0 + j1, a0 + j1))
    return np.array(dirs, dtype=np.float64), np.array(tris, dtype=np.int64)


def _area(pts: np.ndarray) -> float:
    """The area (px^2) of the polygon ``pts`` (K, 2) (shoelace; either orientation)."""
    x, y = pts[:, 0], pts[:, 1]
    return 0.5 * abs(float(x @ np.roll(y, -1) - y @ np.roll(x, -1)))


def _fan(loop: np.ndarray, center: int) -> np.ndarray:
    k = len(loop)
    return np.column_stack([loop, np.roll(loop, -1), np.full(k, center)]).astype(np.int64)


def _polygon_mask(shape, pts: np.ndarray) -> np.ndarray:
    import cv2

    m = np.zeros(shape, np.uint8)
    poly = np.round((np.asarray(pts) - 0.5) * 16).astype(np.int32)
    cv2.fillPoly(m, [poly], 1, lineType=cv2.LINE_8, shift=4)
    return m.astype(bool)


def _gaze_matrix(yaw: float, pitch: float) -> np.ndarray:
    from myoface.render.renderer import MAX_GAZE_RAD, gaze_rotation

    lim = float(MAX_GAZE_RAD)
    return gaze_rotation((float(np.clip(yaw, -lim, lim)), float(np.clip(pitch, -lim, lim))))


class PictureModel:
    """The calibration frame moved by the person's model (see the module's docstring).

    Parameters
    ----------
    model : FaceModel — the person's model (:mod:`myoface.model`); its rest skin is the
        person's neutral (the better it matches the picture, the better the warp follows it).
    camera : PinholeCamera — the picture's camera (:mod:`myoface.analysis.camera`).
    calibration_frame : (H, W, 3) uint8 RGB — the picture.
    calibration : FrameParams — the parameters at that picture (its pose, its contractions,
        its gaze; NaN gaze: straight ahead).
    physics : {"linear", "relax"} — the tissue's responses summed (default: a fixed cost
        of about 2 ms a frame; on the sample photo's performance, ``codec.picture_fps``, the
        frames' largest vertex error against the relaxed tissue is 0.65 px at the median and
        4.3 px at a full surprise's forehead), or the tissue relaxed per frame (exact; 5-20 ms
        a frame on a loaded 2-core machine, what a real-time decoder cannot always spend).
    segment : bool — tell the person from the background in the calibration frame
        (:func:`person_mask`, about half a second at 640x360), so that the background behind
        a moving head stays still (default); without it, the background near the head moves
        with the warp's rings.

    :meth:`render` keeps the tissue's state from one call to the next (a warm start), and the
    last gaze read of each eye (an eye not read, e.g. closed, holds it): a PictureModel is
    one receiver's, not to be shared between threads.
    """

    def __init__(self, model, camera: PinholeCamera, calibration_frame, calibration: FrameParams,
                 *, physics: str = "linear", segment: bool = True):  # fmt: skip
        import cv2

        if physics not in PHYSICS:
            raise MyofaceValueError(f"physics must be one of {PHYSICS}; got {physics!r}")
        frame = np.asarray(calibration_frame)
        if (
            frame.ndim != 3
            or frame.shape[2] != 3
            or frame.dtype != np.uint8
            or min(frame.shape[:2]) < 2
        ):
            raise MyofaceValueError(
                "the calibration frame must be an (H, W, 3) uint8 RGB image of at least 2x2 "
                f"pixels; got {frame.dtype} {frame.shape}"
            )
        if not isinstance(camera, PinholeCamera):
            raise MyofaceValueError(
                f"camera must be a PinholeCamera (myoface.analysis.camera); got {type(camera).__name__}"
            )
        self.model = model
        self.camera = camera
        self.physics = physics
        self.height, self.width = frame.shape[:2]
        h, w = self.height, self.width
        self.calibration = self._check(calibration)
        self.stats = PictureStats()
        face = model.face
        nv = face.n_vertices
        self._rim, self._openings = _rim_and_openings(face)
        self._face_tris = np.ascontiguousarray(face.triangles, dtype=np.int64)

        # ---- the skin at calibration
        cal = self.calibration
        self._c_cal = cal.contractions.copy()
        self._state_cal = self._relaxed(cal.contractions, model.rest_state())
        self._state = self._state_cal
        self._settled = self._state_cal
        self._skin_cal = model.skin_vertices(self._state_cal)
        if physics == "linear":
            self._response, self._jaw_table = tissue_response(model)
            # the linear model made exact at the calibration: its error there, carried
            self._x_fix = np.array(self._state_cal.x[:nv]) - self._linear_x(cal.contractions)

        # ---- the nodes: skin, rings, border, fan centres, eye caps
        rim3 = self._skin_cal[self._rim]
        centre = rim3.mean(axis=0)
        mouth_loop = self._openings.get("mouth")
        mouth_y = (
            float(self._skin_cal[mouth_loop, 1].mean()) if mouth_loop is not None else centre[1]
        )
        rings = []
        below = rim3[:, 1] < mouth_y
        for scale, back, _wt, _wt_below in RINGS:
            p = rim3.copy()
            p[:, :2] = centre[:2] + scale * (rim3[:, :2] - centre[:2])
            p[:, 2] -= back
            rings.append(p)
        self._ring3 = np.concatenate(rings)
        cal_pose = cal.pose
        ring_cal = camera.project(cal_pose.apply(self._ring3))
        skin_cal_px = camera.project(cal_pose.apply(self._skin_cal))
        k = len(self._rim)
        #: the person (1) against the background (0), (H, W) float32 in [0, 1], from the
        #: calibration frame (:func:`person_mask`); None when not segmented
        self.person = None
        self._plate = None
        if segment:
            self.person, plate = person_mask(
                frame, skin_cal_px[self._rim], ring_cal[k : 2 * k], ring_cal[2 * k :]
            )
            if plate is not None:  # RGBA, as the warped canvas
                self._plate = np.ascontiguousarray(
                    np.dstack([plate, np.full((h, w), 255, np.uint8)])
                )
        weights = []
        for j, (_scale, _back, wt, wt_below) in enumerate(RINGS):
            if j == 1 and self.person is not None:
                wt = SEGMENTED_RING2_WEIGHT
            weights.append(np.where(below, wt_below, wt))
        self._ring_w = np.concatenate(weights)
        # the border's nodes, those inside the second ring's outline dropped (they would
        # pin the moving head to the frame's edge)
        bx = np.unique(np.r_[np.arange(0, w, BORDER_STEP_PX), w])
        by = np.unique(np.r_[np.arange(0, h, BORDER_STEP_PX), h])
        border = np.concatenate([
            np.column_stack([bx, np.zeros_like(bx)]), np.column_stack([bx, np.full_like(bx, h)]),
            np.column_stack([np.zeros_like(by), by]), np.column_stack([np.full_like(by, w), by]),
        ]).astype(np.float64)  # fmt: skip
        border = np.unique(border, axis=0)
        from matplotlib.path import Path as MplPath

        outline2 = MplPath(ring_cal[k : 2 * k])
        border = border[~outline2.contains_points(border)]
        self._n_ring = len(self._ring3)
        self._i_ring = nv
        self._i_border = nv + self._n_ring
        self._i_fans = self._i_border + len(border)
        fan_names = [n for n in ("mouth", "eye_l", "eye_r") if n in self._openings]
        self._fan_centre = {n: self._i_fans + j for j, n in enumerate(fan_names)}
        self._i_caps = self._i_fans + len(fan_names)
        cap_dirs, cap_tris = _cap_mesh()
        self._cap_dirs = cap_dirs
        self._eyes = []  # (name, loop, centre (3,), first node, gaze index)
        from myoface.face.eyes import EYE_RADIUS_MM, eyeball_center

        self._eye_radius = EYE_RADIUS_MM
        first = self._i_caps
        for name, gi in (("eye_l", 0), ("eye_r", 1)):
            if name not in self._openings:
                continue
            c = eyeball_center(face.vertices, self._openings[name])
            self._eyes.append((name, self._openings[name], c, first, gi))
            first += len(cap_dirs)
        self._n_nodes = first
        n = self._n_nodes

        # ---- the source positions (the calibration's) and the still nodes' destinations
        self._src = np.zeros((n, 2))
        self._src[:nv] = skin_cal_px
        self._src[self._i_ring : self._i_border] = ring_cal
        self._src[self._i_border : self._i_fans] = border
        for name, j in self._fan_centre.items():
            self._src[j] = skin_cal_px[self._openings[name]].mean(axis=0)
        g_cal = np.nan_to_num(cal.gaze.reshape(2, 2), nan=0.0)
        self._gaze_cal = g_cal.copy()
        self._gaze_last = g_cal.copy()
        for _, _, c, i0, gi in self._eyes:
            pts = cal_pose.apply(c + self._eye_radius * cap_dirs @ _gaze_matrix(*g_cal[gi]).T)
            xy = camera.project(pts)
            # the eyeball's part the calibration did not see (turned away from the camera):
            # its source is just outside the eyeball's outline, where the atlas has the
            # sclera's colour (on the sphere's far side it would read the front's pixels)
            centre = cal_pose.apply(c[None])[0]
            normal = (pts - centre) / self._eye_radius
            seen = -(normal * pts).sum(axis=1) / np.linalg.norm(pts, axis=1) > CAP_SEEN_COS
            cxy = camera.project(centre[None])[0]
            r_px = camera.focal_px * self._eye_radius / max(-centre[2], 1e-6)
            out = xy - cxy
            out /= np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-9)
            xy[~seen] = cxy + (r_px + 1.5) * out[~seen]
            self._src[i0 : i0 + len(cap_dirs)] = xy
        self._dst = np.zeros((n, 2))
        self._depth = np.zeros(n)

        # ---- the triangles: around the face (a Delaunay triangulation of the rim, the rings
        # and the border at calibration, without the face inside the rim), the fans, the caps
        from scipy.spatial import Delaunay

        around_nodes = np.r_[self._rim, np.arange(self._i_ring, self._i_fans)]
        tri = Delaunay(self._src[around_nodes]).simplices
        tri = around_nodes[tri]
        cen = self._src[tri].mean(axis=1)
        inside = MplPath(skin_cal_px[self._rim]).contains_points(cen)
        tri = tri[~inside]
        weight = np.zeros(n)
        weight[: self._i_ring] = 1.0
        weight[self._i_ring : self._i_border] = self._ring_w
        weight[self._i_fans :] = 1.0
        moving = weight[tri].max(axis=1) > 0
        self._around_tris = np.ascontiguousarray(tri[moving])
        #: the nodes whose triangles the warp moves: outside their box it is the identity
        self._moving_nodes = np.union1d(
            np.unique(self._around_tris), np.r_[np.arange(nv), np.arange(self._i_fans, n)]
        )
        self._node_weight = weight
        self._fan_tris = {
            name: _fan(self._openings[name], j) for name, j in self._fan_centre.items()
        }
        self._cap_tris = [cap_tris + e[3] for e in self._eyes]
        # the eyes' margins: their calibration area on screen, and the outward shift their
        # source takes as the eye closes (see :data:`LID_SOURCE_SHIFT_PX`)
        self._margins = []
        for _name, loop, _c, _i0, _gi in self._eyes:
            pts = self._src[loop]
            out = pts - pts.mean(axis=0)
            out /= np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-9)
            self._margins.append((loop, pts.copy(), _area(pts), LID_SOURCE_SHIFT_PX * out))

        # ---- the source picture: the frame, and beside it the eyes' patches with the
        # eyeball's unseen part filled with the sclera's colour
        self._frame = np.ascontiguousarray(frame)
        patches, self._atlas_shift = [], []
        x_at = w
        for _name, loop, _c, i0, _gi in self._eyes:
            cap_px = self._src[i0 : i0 + len(cap_dirs)]
            x0 = int(np.floor(cap_px[:, 0].min())) - ATLAS_MARGIN_PX
            y0 = int(np.floor(cap_px[:, 1].min())) - ATLAS_MARGIN_PX
            x1 = int(np.ceil(cap_px[:, 0].max())) + ATLAS_MARGIN_PX
            y1 = int(np.ceil(cap_px[:, 1].max())) + ATLAS_MARGIN_PX
            pw, ph = max(x1 - x0, 1), max(y1 - y0, 1)
            if pw > w or ph > h:  # an eye larger than the picture: no patch
                self._atlas_shift.append((0.0, 0.0))
                continue
            ys = np.clip(np.arange(y0, y1), 0, h - 1)
            xs = np.clip(np.arange(x0, x1), 0, w - 1)
            patch = frame[ys][:, xs].copy()
            opening = _polygon_mask((ph, pw), skin_cal_px[loop] - [x0, y0])
            seen = patch[opening].reshape(-1, 3).astype(np.float64)
            if len(seen) >= 4:
                bright = seen.sum(axis=1)
                top = bright >= np.quantile(bright, 1.0 - SCLERA_SHARE)
                sclera = seen[top].mean(axis=0)
            else:
                sclera = np.array([200.0, 190.0, 180.0])
            # the picture kept a little beyond the opening (the warp's edge pixels read it),
            # the sclera's colour faded in outside
            keep = cv2.dilate(opening.astype(np.uint8), np.ones((3, 3), np.uint8))
            soft = np.maximum(cv2.GaussianBlur(keep.astype(np.float32), (0, 0), 1.0), keep)
            soft = soft[:, :, None]
            patch = (soft * patch + (1 - soft) * sclera).round().astype(np.uint8)
            patches.append((patch, x_at))
            self._atlas_shift.append((float(x_at - x0), float(-y0)))
            x_at += pw
        nch = 3 if self.person is None else 4
        canvas = np.zeros((h, x_at, nch), np.uint8)
        canvas[:, :w, :3] = frame
        if self.person is not None:  # the person's mask rides in the fourth channel
            canvas[:, :w, 3] = np.round(self.person * 255).astype(np.uint8)
            canvas[:, w:, 3] = 255
        for patch, xa in patches:
            canvas[: patch.shape[0], xa : xa + patch.shape[1], :3] = patch
        self._canvas = np.ascontiguousarray(canvas)
        if x_at > 32767:
            raise MyofaceValueError(f"the picture is too wide to warp ({w} px)")

        # ---- buffers
        ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
        self._ident_x, self._ident_y = xs, ys
        self._map_x = np.empty((h, w), np.float32)
        self._map_y = np.empty((h, w), np.float32)
        self._label = np.empty((h, w), np.uint8)
        self._zbuf = np.empty((h, w), np.float32)
        #: the layer each pixel of the last render came from (``LABEL_*``)
        self.last_label = self._label
        self._mouth_renderer = None
        lm = face.landmarks
        up = np.asarray(lm.get("lip_upper_inner", ()), dtype=np.int64)
        lo = np.asarray(lm.get("lip_lower_inner", ()), dtype=np.int64)
        pairs = [(a, b) for a, b in zip(up, lo, strict=False) if a != b]
        self._lip_pairs = (
            np.array(pairs, dtype=np.int64).T if pairs and len(up) == len(lo) else None
        )
        self._gap_cal = self._lip_gap(self._skin_cal)
        self._shade_nodes = _shading_nodes(self._skin_cal, self._rim, N_SHADING_BUMPS)
        #: the colour of the mouth's inside under its appearance terms: the calibration
        #: picture's face (inside the rim), normalised to luma 1, desaturated
        #: (:data:`MOUTH_TINT_SATURATION`)
        face_px = frame[_polygon_mask((h, w), skin_cal_px[self._rim])].astype(np.float64)
        tint = face_px.mean(axis=0) if len(face_px) else np.full(3, 128.0)
        tint = tint / max(float(tint @ LUMA), 1.0)
        tint = 1.0 + MOUTH_TINT_SATURATION * (tint - 1.0)
        self._tint = tint.astype(np.float32) if np.isfinite(tint).all() else np.ones(3, np.float32)
        self._face_width_mm = float(np.ptp(self._skin_cal[:, 0]))
        if "mouth" in self._openings and model.dentition is not None:
            self._renderer()  # built now: not a stall at the first frame that opens the lips

    def face_outline(self) -> np.ndarray:
        """The face's rim (K, 2) px (x, y) in the calibration frame, where the model put it."""
        return self._src[self._rim].copy()

    # ------------------------------------------------------------------ checks
    def _check(self, params) -> FrameParams:
        if not isinstance(params, FrameParams):
            raise MyofaceValueError(f"params must be a FrameParams; got {type(params).__name__}")
        m = self.model.n_muscles
        if params.contractions.shape != (m,):
            raise MyofaceValueError(
                f"params.contractions must have {m} entries (the model's ids); got "
                f"{params.contractions.shape[0]}"
            )
        rot, t = params.rotation, params.translation
        if not (np.isfinite(rot).all() and np.isfinite(t).all()) or not np.allclose(
            rot @ rot.T, np.eye(3), atol=1e-5
        ):
            raise MyofaceValueError("params.rotation must be a finite rotation matrix and "
                                    "params.translation finite (mm)")  # fmt: skip
        if not t[2] < 0:
            raise MyofaceValueError(
                f"the head must be in front of the camera (translation z < 0 mm); got {t[2]:g}"
            )
        return params

    # ------------------------------------------------------------------ physics
    def _relaxed(self, c, state):
        from myoface.tissue import RelaxWarning

        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", RelaxWarning)
            res = self.model.relax(c, state, tol_mm=RELAX_TOL_MM)
        ok = res.converged and not any(issubclass(x.category, RelaxWarning) for x in caught)
        if not ok and hasattr(self, "stats"):
            self.stats.unconverged += 1
        return res.state

    def skin(self, contractions) -> np.ndarray:
        """The model's skin (V, 3) mm, head frame, at ``contractions`` (M,): relaxed from the
        last call's state (``physics="relax"``) or the linear response about the calibration
        (``"linear"``), the lids and the lips' contact applied."""
        model = self.model
        c = model.validate(contractions)
        if np.array_equal(c, self._c_cal):
            self._state = self._state_cal
            return self._skin_cal
        if self.physics == "relax":
            if not (self._state is self._settled and np.array_equal(c, self._state.contractions)):
                self._state = self._relaxed(c, self._state)
                self._settled = self._state
            return model.skin_vertices(self._state)
        from myoface.model import FaceState

        x = np.array(self._state_cal.x)
        nv = model.face.n_vertices
        x[:nv] = self._linear_x(c) + self._x_fix
        self._state = FaceState(x, self._state_cal.v, c)
        return model.skin_vertices(self._state)

    def _linear_x(self, c) -> np.ndarray:
        """The tissue's skin nodes (V, 3) mm at ``c`` by :func:`tissue_response`: the rest
        plus each muscle's response times its contraction plus the jaw's displacement at its
        opening (interpolated in the table)."""
        model = self.model
        j = model.muscles.jaw_index
        soft = np.array(c, dtype=np.float64)
        x = np.array(model.tissue.rest_positions[: model.face.n_vertices])
        if j is not None:
            x += _interp_table(self._jaw_table, float(soft[j]))
            soft[j] = 0.0
        return x + self._response @ soft

    def _lip_gap(self, skin) -> float:
        if self._lip_pairs is None:
            return 0.0
        a, b = self._lip_pairs
        return float((skin[a, 1] - skin[b, 1]).mean())

    # ------------------------------------------------------------------ render
    def render(self, params: FrameParams) -> np.ndarray:
        """The picture (H, W, 3) uint8 RGB at ``params`` (the calibration frame's size)."""
        import cv2

        t0 = time.perf_counter()
        p = self._check(params)
        skin = self.skin(p.contractions)
        t1 = time.perf_counter()
        dst, depth = self._dst, self._depth
        pose = p.pose
        cam = self.camera
        nv = self.model.face.n_vertices
        cam_pts = pose.apply(skin)
        dst[:nv] = cam.project(cam_pts)
        depth[:nv] = -cam_pts[:, 2]
        ring_now = cam.project(pose.apply(self._ring3))
        s = slice(self._i_ring, self._i_border)
        dst[s] = self._src[s] + self._ring_w[:, None] * (ring_now - self._src[s])
        dst[self._i_border : self._i_fans] = self._src[self._i_border : self._i_fans]
        for loop, src0, area0, shift in self._margins:
            shut = 1.0 - _area(dst[loop]) / area0 if area0 > 1.0 else 0.0
            self._src[loop] = src0 + float(np.clip(shut, 0.0, 1.0)) * shift
        for name, j in self._fan_centre.items():
            dst[j] = dst[self._openings[name]].mean(axis=0)
        g_now = p.gaze.reshape(2, 2)
        for _, _, c, i0, gi in self._eyes:
            g = g_now[gi]
            if not np.isfinite(g).all():
                other = g_now[1 - gi]
                g = other if np.isfinite(other).all() else self._gaze_last[gi]
            self._gaze_last[gi] = g
            pts = pose.apply(c + self._eye_radius * self._cap_dirs @ _gaze_matrix(*g).T)
            dst[i0 : i0 + len(self._cap_dirs)] = cam.project(pts)
            depth[i0 : i0 + len(self._cap_dirs)] = -pts[:, 2]
        # the box the warp moves anything in (outside it the picture is the frame itself)
        h, w = self.height, self.width
        moving = self._moving_nodes
        both = np.concatenate([dst[moving], self._src[moving]])
        x0, y0 = np.maximum(np.floor(both.min(axis=0)).astype(int) - 1, 0)
        x1, y1 = np.ceil(both.max(axis=0)).astype(int) + 2
        x1, y1 = min(int(x1), w), min(int(y1), h)
        box = (slice(y0, max(y1, y0)), slice(x0, max(x1, x0)))
        mx, my, lab, zb = self._map_x, self._map_y, self._label, self._zbuf
        mx[box] = self._ident_x[box]
        my[box] = self._ident_y[box]
        lab.fill(LABEL_STILL)
        src = self._src
        raster_warp(
            dst, src, depth, self._around_tris, mx, my, lab, LABEL_AROUND, zb, False, 0.0, 0.0
        )
        for name in ("eye_l", "eye_r"):
            if name in self._fan_tris:
                raster_warp(dst, src, depth, self._fan_tris[name], mx, my, lab, LABEL_EYE, zb,
                            False, 0.0, 0.0)  # fmt: skip
        zb.fill(np.inf)
        for (_, _, _, _, _), tris, (dx, dy) in zip(self._eyes, self._cap_tris, self._atlas_shift,
                                                   strict=True):  # fmt: skip
            raster_warp(dst, src, depth, tris, mx, my, lab, LABEL_EYE, zb, True, dx, dy)
        if "mouth" in self._fan_tris:
            raster_warp(dst, src, depth, self._fan_tris["mouth"], mx, my, lab, LABEL_MOUTH, zb,
                        False, 0.0, 0.0)  # fmt: skip
        zb.fill(np.inf)
        raster_warp(dst, src, depth, self._face_tris, mx, my, lab, LABEL_SKIN, zb, True, 0.0, 0.0)
        t2 = time.perf_counter()
        out = self._frame.copy()
        if x1 > x0 and y1 > y0:
            warped = cv2.remap(
                self._canvas, mx[box], my[box], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
            )
            if self._plate is None:
                out[box] = warped
            else:  # the warped person over the still background
                a = warped[:, :, 3].astype(np.float32) * (1.0 / 255.0)
                mixed = cv2.blendLinear(warped, self._plate[box], a, 1.0 - a)
                out[box] = cv2.cvtColor(mixed, cv2.COLOR_RGBA2RGB)
        t3 = time.perf_counter()
        self._mouth(out, skin, p, dst)
        self.apply_appearance(out, p.appearance)
        t4 = time.perf_counter()
        st = self.stats
        st.physics_ms.append((t1 - t0) * 1e3)
        st.warp_ms.append((t2 - t1) * 1e3)
        st.remap_ms.append((t3 - t2) * 1e3)
        st.mouth_ms.append((t4 - t3) * 1e3)
        st.total_ms.append((t4 - t0) * 1e3)
        return out

    # ------------------------------------------------------------------ appearance
    def _shading_basis(self, box):
        """The shading bumps over ``box`` of the last render, separably: (bh, K) along the
        rows and (K, bw) along the columns (a bump is their outer product)."""
        nodes = self._shade_nodes
        c = self._dst[nodes]
        depth = float(np.median(self._depth[nodes]))
        sigma = SHADING_SIGMA_FACE * self._face_width_mm * self.camera.focal_px / max(depth, 1.0)
        ys = np.arange(box[0].start, box[0].stop) + 0.5
        xs = np.arange(box[1].start, box[1].stop) + 0.5
        k = -0.5 / max(sigma, 1.0) ** 2
        ey = np.exp(k * (ys[:, None] - c[None, :, 1]) ** 2)
        ex = np.exp(k * (xs[None, :] - c[:, 0, None]) ** 2)
        return ey, ex

    def _face_weight(self, lab) -> np.ndarray:
        """Where the shading applies: the face's layers of the last render (skin, eyes,
        mouth) in ``lab``, faded out over :data:`SHADING_FEATHER_PX` (nothing beyond them)."""
        import cv2

        face = (lab >= LABEL_EYE).astype(np.float32)  # (eye, mouth, skin)
        soft = cv2.GaussianBlur(face, (0, 0), SHADING_FEATHER_PX, borderType=cv2.BORDER_CONSTANT)
        return soft * face

    @staticmethod
    def _mouth_feather(lab) -> np.ndarray:
        """The mouth's layer in ``lab``, feathered (a Gaussian of :data:`MOUTH_FEATHER_PX`)."""
        import cv2

        m = (lab == LABEL_MOUTH).astype(np.float32)
        return cv2.GaussianBlur(m, (0, 0), MOUTH_FEATHER_PX, borderType=cv2.BORDER_CONSTANT)

    @staticmethod
    def _mouth_pivot(rgb, soft) -> np.float32:
        """The luma (BT.601) about which the mouth's gain acts: the mean of ``rgb`` (the
        render without the terms) over the mouth's feathered layer ``soft`` (so that the gain
        and the offset are apart: contrast and level)."""
        w = float(soft.sum())
        return np.float32(float((rgb @ LUMA * soft).sum()) / w if w > 0 else 0.0)

    def _part_box(self, nodes, pad: int):
        """The box (rows, cols) of the last render's ``nodes`` (their destinations), ``pad``
        pixels wider, within the picture."""
        d = self._dst[nodes]
        x0, y0 = np.maximum(np.floor(d.min(axis=0)).astype(int) - pad, 0)
        x1, y1 = np.ceil(d.max(axis=0)).astype(int) + pad + 1
        x1, y1 = min(int(x1), self.width), min(int(y1), self.height)
        return slice(y0, max(y0, y1)), slice(x0, max(x0, x1))

    def _face_box(self):
        """The box of the face's layers in the last render (its skin, the eyes' caps)."""
        nv = self.model.face.n_vertices
        return self._part_box(np.r_[np.arange(nv), np.arange(self._i_caps, self._n_nodes)], 2)

    def _mouth_box(self):
        """The box of the mouth's layer in the last render, with room for its feather."""
        pad = int(np.ceil(4 * MOUTH_FEATHER_PX)) + 1
        return self._part_box(self._openings["mouth"], pad)

    def apply_appearance(self, img: np.ndarray, appearance) -> np.ndarray:
        """The appearance terms ``appearance`` (:data:`~myoface.codec.params.APPEARANCE_FIELDS`)
        applied in place to ``img`` (H, W, 3) uint8, the last render's picture: the inside of
        the mouth (the mouth's layer, feathered): its luma ``y`` becomes
        ``y + (2**gain - 1) (y - c) + offset`` (``c``: :meth:`_mouth_pivot`, the layer's mean
        luma), the change added in the colour of the calibration picture's face (its mean,
        normalised to luma 1, desaturated) over the render's own colours; then the face's
        shading, ``y * 2**(w (g + sum_k a_k bump_k))`` (``w``: :meth:`_face_weight`).
        Returns ``img``."""

        a = np.asarray(appearance, dtype=np.float64)
        if (a[0] or a[1]) and "mouth" in self._openings:
            box = self._mouth_box()
            lab = self._label[box]
            if lab.size and (lab == LABEL_MOUTH).any():
                soft = self._mouth_feather(lab)
                f = img[box].astype(np.float32)
                c = self._mouth_pivot(f, soft)
                g1 = np.float32(2.0 ** a[0] - 1.0)
                y = f @ LUMA
                # the luma's change added in the colour of the person's face (the model's
                # render has the model's colours: its cavity brightened alone turned
                # grey-blue; the teeth replaced by the face's colour at their new luma turned
                # peach): the luma moves by s (y' - y), the render's own colours kept under it
                dy = g1 * (y - c) + np.float32(a[1])
                f = f + (soft * dy)[:, :, None] * self._tint
                img[box] = np.clip(f + 0.5, 0, 255).astype(np.uint8)
        if a[2:].any():
            box = self._face_box()
            lab = self._label[box]
            if lab.size:
                ey, ex = self._shading_basis(box)
                e = (a[2] + (ey * a[3:]) @ ex).astype(np.float32)
                gain = np.exp2(e * self._face_weight(lab))
                f = img[box].astype(np.float32) * gain[:, :, None]
                img[box] = np.clip(f + 0.5, 0, 255).astype(np.uint8)
        return img

    def estimate_appearance(self, base: np.ndarray, frame: np.ndarray) -> np.ndarray:
        """The appearance terms (:data:`~myoface.codec.params.N_APPEARANCE`,) that bring
        ``base`` (the last render, with none) nearest to ``frame`` (H, W, 3) uint8, the
        input (the encoder's fit, on the luma, BT.601): the face's shading by least squares
        of the log ratio of the frame's to the render's on the skin (every
        :data:`APPEARANCE_SHADING_STRIDE`-th pixel; a ridge towards 0), then the inside of the
        mouth's gain and offset on the mouth's layer, against the frame over that shading
        (a ridge towards gain 1, offset 0; the gain within :data:`APPEARANCE_MOUTH_GAIN_LOG2`,
        the offset fitted again at its bound: the mouth's contrast kept). Each within its
        bound (:data:`~myoface.codec.params.APPEARANCE_LIMITS`)."""
        a = np.zeros(N_APPEARANCE)
        frame = np.asarray(frame)
        box = self._face_box()
        lab = self._label[box]
        if lab.size == 0:
            return a
        ey, ex = self._shading_basis(box)
        st = APPEARANCE_SHADING_STRIDE
        sk = (lab == LABEL_SKIN)[::st, ::st]
        if sk.sum() >= 4 * (N_SHADING_BUMPS + 1):
            yb = base[box][::st, ::st][sk].astype(np.float32) @ LUMA
            yr = frame[box][::st, ::st][sk].astype(np.float32) @ LUMA
            rows, cols = np.nonzero(sk)
            b = ey[::st][rows] * ex[:, ::st][:, cols].T  # (n, K)
            # (as applied: the exponent times the face's weight)
            w = self._face_weight(lab)[::st, ::st][sk].astype(np.float64)
            basis = np.column_stack([np.ones(len(rows)), b]) * w[:, None]
            t = np.clip(np.log2((yr + 1.0) / (yb + 1.0)), -APPEARANCE_LOG_CLIP, APPEARANCE_LOG_CLIP)
            ridge = APPEARANCE_SHADING_RIDGE * len(rows) * np.r_[0.0, np.ones(N_SHADING_BUMPS)]
            a[2:] = np.linalg.solve(basis.T @ basis + np.diag(ridge + 1e-9), basis.T @ t)
        if "mouth" in self._openings:
            mb = self._mouth_box()
            lab_m = self._label[mb]
            if int((lab_m == LABEL_MOUTH).sum()) >= APPEARANCE_MIN_MOUTH_PX:
                # the terms as they are applied: y + s ((gain - 1) (y - c) + offset) ~ r, s
                # the mouth's feathered layer, c its pivot (least squares in gain - 1, offset)
                s = self._mouth_feather(lab_m)
                c = float(self._mouth_pivot(base[mb].astype(np.float32), s))
                on = s > 0.05
                s = s[on].astype(np.float64)
                y = base[mb][on].astype(np.float64) @ LUMA
                r = frame[mb][on].astype(np.float64) @ LUMA
                if a[2:].any():  # (the shading multiplies the mouth's terms: / it)
                    ey_m, ex_m = self._shading_basis(mb)
                    e = a[2] + (ey_m * a[3:]) @ ex_m
                    r = r / np.exp2(e * self._face_weight(lab_m))[on]
                u = np.column_stack([s * (y - c), s])
                ata = u.T @ u
                ridge = APPEARANCE_MOUTH_RIDGE * np.diag(ata)
                g1, o = np.linalg.solve(ata + np.diag(ridge + 1e-9), u.T @ (r - y))
                lo, hi = APPEARANCE_MOUTH_GAIN_LOG2
                g = float(np.clip(np.log2(max(1.0 + float(g1), 1e-3)), lo, hi))
                if g != np.log2(max(1.0 + float(g1), 1e-3)):  # at a bound: the offset for it
                    res = r - y - (2.0**g - 1.0) * u[:, 0]
                    o = float(s @ res) / (float(s @ s) * (1.0 + APPEARANCE_MOUTH_RIDGE) + 1e-9)
                a[0] = g
                a[1] = o
        lim = np.asarray(APPEARANCE_LIMITS)
        return np.clip(a, -lim, lim)

    def mouth_alpha(self, skin) -> float:
        """How much of the model's rendered mouth shows through the lips of ``skin`` (V, 3):
        0 at the calibration's lip gap, 1 from :data:`MOUTH_FADE_MM` [1] mm more."""
        extra = self._lip_gap(skin) - self._gap_cal
        lo, hi = MOUTH_FADE_MM
        return float(np.clip((extra - lo) / (hi - lo), 0.0, 1.0))

    def _mouth(self, out, skin, p: FrameParams, dst) -> None:
        """The model's mouth rendered into ``out`` where the lips part (see the module)."""
        import cv2

        if "mouth" not in self._openings or self.model.dentition is None:
            return
        alpha = self.mouth_alpha(skin)
        if alpha <= 0:
            return
        h, w = self.height, self.width
        loop = dst[self._openings["mouth"]]
        pad = 3
        x0 = max(int(np.floor(loop[:, 0].min())) - pad, 0)
        x1 = min(int(np.ceil(loop[:, 0].max())) + pad, w)
        y0 = max(int(np.floor(loop[:, 1].min())) - pad, 0)
        y1 = min(int(np.ceil(loop[:, 1].max())) + pad, h)
        if x0 >= x1 or y0 >= y1:
            return
        mask = (self._label[y0:y1, x0:x1] == LABEL_MOUTH).astype(np.float32)
        if not mask.any():
            return
        r, (dx, dy), k, keep = self._renderer()
        img = r.render(
            skin[keep], pose=(p.rotation, p.translation), jaw=self.model.jaw_pose(self._state)
        )
        # the render's pixel under each pixel of the box (its camera k times smaller)
        rh, rw = img.shape[:2]
        gx = ((np.arange(x0, x1) + 0.5 - dx) - 0.5 * w) * k + 0.5 * rw - 0.5
        gy = ((np.arange(y0, y1) + 0.5 - dy) - 0.5 * h) * k + 0.5 * rh - 0.5
        mx, my = np.meshgrid(gx.astype(np.float32), gy.astype(np.float32))
        crop = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        # as a camera would see it: the model's crisp gaps between the teeth softened
        crop = cv2.GaussianBlur(crop.astype(np.float32), (0, 0), MOUTH_SOFT_PX)
        region = out[y0:y1, x0:x1].astype(np.float32)
        # the render's light matched to the picture's: the brightness of the lips around the
        # opening in the picture over the render's (one grey gain: the colours are the model's)
        lips = (self._label[y0:y1, x0:x1] == LABEL_SKIN) & (mask == 0)
        if lips.sum() >= 8:
            lip_rgb = region[lips].mean(axis=0)
            gain = float(lip_rgb.mean()) / max(float(crop[lips].mean()), 1.0)
            crop *= float(np.clip(gain, *MOUTH_GAIN))
            # the inside is lit a little by the light the lips and teeth scatter into it
            np.maximum(crop, MOUTH_AMBIENT * lip_rgb, out=crop)
        soft = cv2.GaussianBlur(mask, (0, 0), MOUTH_FEATHER_PX) * mask
        a = (alpha * soft)[:, :, None]
        out[y0:y1, x0:x1] = np.clip(a * crop + (1 - a) * region + 0.5, 0, 255).astype(np.uint8)

    def _renderer(self):
        """The model's renderer through this camera (built on first use), the shift (px) of
        the camera's principal point from the picture's centre, and the render's scale."""
        if self._mouth_renderer is None:
            from myoface.render import Camera, Renderer

            cam = self.camera
            h, w = self.height, self.width
            k = MOUTH_RENDER_SCALE if h >= MOUTH_RENDER_MIN_PX / MOUTH_RENDER_SCALE else 1.0
            hs, ws = max(int(round(h * k)), 8), max(int(round(w * k)), 8)
            k = hs / h  # the render's pixels per the picture's (square pixels)
            fov = float(np.degrees(2 * np.arctan(0.5 * h / cam.focal_px)))
            rc = Camera(np.zeros(3), np.array([0.0, 0.0, -1.0]), (0.0, 1.0, 0.0), ws, hs,
                        max(fov, 0.1))  # fmt: skip
            # the skin's texture is the picture itself, where the calibration projects it:
            # the render's lips are the person's, and its light is matched on them
            nv = self.model.face.n_vertices
            xy = self._src[:nv]
            uv = np.column_stack([xy[:, 0] / w, 1.0 - xy[:, 1] / h])
            face, keep = _mouth_face(self.model.face, uv, self._frame)
            r = Renderer(face, rc, ssaa=1, wrinkles=False)
            shift = (cam.cx - 0.5 * w, cam.cy - 0.5 * h)
            self._mouth_renderer = (r, shift, k, keep)
        return self._mouth_renderer


def _shading_nodes(skin: np.ndarray, rim: np.ndarray, k: int) -> np.ndarray:
    """``k`` vertices of ``skin`` (V, 3) mm, head frame, off the ``rim``, picked farthest
    apart in x, y from the one nearest the face's centre (deterministic: the encoder and the
    decoder pick the same)."""
    ok = np.ones(len(skin), bool)
    ok[rim] = False
    cand = np.flatnonzero(ok)
    pts = skin[cand, :2]
    first = int(np.argmin(((pts - pts.mean(axis=0)) ** 2).sum(axis=1)))
    picked = [first]
    d = ((pts - pts[first]) ** 2).sum(axis=1)
    for _ in range(k - 1):
        i = int(np.argmax(d))
        picked.append(i)
        d = np.minimum(d, ((pts - pts[i]) ** 2).sum(axis=1))
    return cand[np.array(picked, dtype=np.int64)]


def _mouth_face(face, uv: np.ndarray, texture: np.ndarray):
    """The part of ``face`` around the mouth (its triangles within :data:`MOUTH_PART` of
    the mouth's half width from its centre, rest head frame x, y), what the mouth's render
    draws (the rest of the face is the picture's), with its lip landmark groups, textured by
    ``texture`` at ``uv`` (V, 2) (the face's vertices'); and the indices of its vertices in
    ``face``. The whole face when the part would not hold the lips.
    """
    from myoface.face import FaceMesh
    from myoface.face.teeth import LIP_GROUPS

    lm = face.landmarks
    everything = FaceMesh(face.vertices, face.triangles, uv, texture, lm, name=face.name)
    if not all(g in lm for g in LIP_GROUPS):
        return everything, np.arange(face.n_vertices)
    lips = np.unique(np.concatenate([np.asarray(lm[g]) for g in LIP_GROUPS]))
    v = face.vertices
    m = v[lips, :2].mean(axis=0)
    half = 0.5 * float(np.ptp(v[lips, 0]))
    rx, ry = MOUTH_PART
    inside = ((v[:, 0] - m[0]) / (rx * half)) ** 2 + ((v[:, 1] - m[1]) / (ry * half)) ** 2 <= 1
    tris = face.triangles[inside[face.triangles].all(axis=1)]
    keep = np.unique(tris)
    if not np.isin(lips, keep).all():
        return everything, np.arange(face.n_vertices)
    new = np.full(face.n_vertices, -1, np.int64)
    new[keep] = np.arange(len(keep))
    groups = {g: new[np.asarray(lm[g])] for g in LIP_GROUPS}
    part = FaceMesh(v[keep], new[tris], uv[keep], texture, groups, name=f"{face.name} mouth")
    return part, keep


# ---------------------------------------------------------------------- the physics

#: the tissue's response to each muscle is read at this contraction (the analysis' probe)
RESPONSE_PROBE = 0.5
#: the jaw's displacement of the skin is tabulated at these openings and interpolated (it is
#: a rotation of the bone: far from linear over its range)
JAW_TABLE = (0.0, 0.25, 0.5, 0.75, 1.0)


def tissue_response(model):
    """The tissue's skin nodes' displacement (V, 3, M) mm per unit contraction of each
    muscle (the jaw's column zero), each relaxed from rest at :data:`RESPONSE_PROBE` (as the
    analysis' response, :func:`myoface.analysis.estimate.skin_response`, but of the tissue, the
    lids and the lips' contact left out), and the jaw's displacement at each opening of
    :data:`JAW_TABLE` ((J, V, 3) mm): what ``physics="linear"`` sums. (A quadratic in each
    contraction, through c = 1/2 and 1, took twice the relaxes for 0.62 px against 0.65 px on
    the sample photo's sequence: the error left is the muscles' interplay, not each one's.) Computed once per model (:meth:`~myoface.model.FaceModel.memo`;
    a relax per muscle and per opening). The lids and the lips' contact are not in it: they
    are applied on the sum as on a relaxed skin (:meth:`~myoface.model.FaceModel.skin_vertices`)."""

    def compute():
        nv = model.face.n_vertices
        rest = model.tissue.rest_positions[:nv]
        j = model.muscles.jaw_index
        resp = np.zeros((nv, 3, model.n_muscles))
        for k, mid in enumerate(model.ids):
            if k == j:
                continue
            x = model.relax({mid: RESPONSE_PROBE}, tol_mm=RELAX_TOL_MM).state.x[:nv]
            resp[:, :, k] = (x - rest) / RESPONSE_PROBE
        table = np.zeros((len(JAW_TABLE), nv, 3))
        if j is not None:
            for i, a in enumerate(JAW_TABLE):
                if a > 0:
                    x = model.relax({model.ids[j]: a}, tol_mm=RELAX_TOL_MM).state.x[:nv]
                    table[i] = x - rest
        resp.flags.writeable = False
        table.flags.writeable = False
        return resp, table

    return model.memo(("picture.tissue_response", RESPONSE_PROBE, JAW_TABLE), compute)


def _interp_table(table: np.ndarray, a: float) -> np.ndarray:
    grid = np.asarray(JAW_TABLE)
    i = int(np.clip(np.searchsorted(grid, a) - 1, 0, len(grid) - 2))
    t = float(np.clip((a - grid[i]) / (grid[i + 1] - grid[i]), 0.0, 1.0))
    return (1 - t) * table[i] + t * table[i + 1]


# ---------------------------------------------------------------------- the person


def person_mask(frame: np.ndarray, rim_px, ring2_px, ring3_px):
    """The person in ``frame`` (H, W, 3) uint8 against the background, from the face's rim
    and the rings around it projected in it ((K, 2) px each): GrabCut (:func:`cv2.grabCut`,
    at :data:`SEGMENT_SCALE`) with the inside of the rim the person, the second ring's outline
    and a band below the chin (the neck, the body) probably the person, the rest inside the
    third ring probably background, beyond it background.

    Returns (mask, plate): ``mask`` (H, W) float32 in [0, 1], 1 on the person and softened
    outwards by :data:`SEGMENT_SOFT_PX` (so that it is 1 wherever the hard mask is), and
    ``plate`` (H, W, 3) uint8, the frame with the head's pixels (down to :data:`SEGMENT_NECK`
    below the chin) filled from the background beside them (:func:`fill_rows`; what shows
    where the head moves away); (None, None) when GrabCut finds no background."""
    import cv2

    h, w = frame.shape[:2]
    k = SEGMENT_SCALE
    hs, ws = max(int(round(h * k)), 8), max(int(round(w * k)), 8)
    sx, sy = ws / w, hs / h
    small = cv2.resize(frame, (ws, hs), interpolation=cv2.INTER_AREA)
    init = np.full((hs, ws), cv2.GC_BGD, np.uint8)

    def fill(poly, value):
        pts = np.round(np.asarray(poly) * [sx, sy] - 0.5).astype(np.int32)
        cv2.fillPoly(init, [pts], int(value))

    rim = np.asarray(rim_px, dtype=np.float64)
    c = rim.mean(axis=0)
    fw = float(np.ptp(rim[:, 0]))
    chin = float(rim[:, 1].max())
    # the neck under the chin, widening to the shoulders
    top, low = chin + 0.15 * fw, chin + 0.45 * fw
    body = np.array([[c[0] - 0.35 * fw, chin], [c[0] + 0.35 * fw, chin],
                     [c[0] + 0.45 * fw, top], [c[0] + 1.6 * fw, low], [c[0] + 1.6 * fw, h],
                     [c[0] - 1.6 * fw, h], [c[0] - 1.6 * fw, low], [c[0] - 0.45 * fw, top]])  # fmt: skip
    fill(ring3_px, cv2.GC_PR_BGD)
    fill(ring2_px, cv2.GC_PR_FGD)
    fill(body, cv2.GC_PR_FGD)
    fill(rim, cv2.GC_FGD)
    if not (init == cv2.GC_BGD).any() and not (init == cv2.GC_PR_BGD).any():
        return None, None
    bgd, fgd = np.zeros((1, 65)), np.zeros((1, 65))
    # GrabCut seeds its colour models by k-means from OpenCV's per-thread random generator:
    # without a fixed seed a second picture model in one process (a second decoder, the
    # encoder's own) segments the same frame differently from the first, and the outline's
    # pixels decode up to ~160 grey levels apart. The seed is OpenCV's own initial state, so
    # a fresh process segments exactly as before.
    cv2.setRNGSeed(GRABCUT_SEED)
    try:
        cv2.grabCut(
            cv2.cvtColor(small, cv2.COLOR_RGB2BGR), init, None, bgd, fgd, SEGMENT_ITERATIONS,
            cv2.GC_INIT_WITH_MASK,
        )  # fmt: skip
    except cv2.error:  # a degenerate picture (one colour): no model of either side
        return None, None
    fg_small = ((init == cv2.GC_FGD) | (init == cv2.GC_PR_FGD)).astype(np.float32)
    hard = cv2.resize(fg_small, (w, h), interpolation=cv2.INTER_LINEAR) >= 0.5
    hard |= _polygon_mask((h, w), rim)  # the face is the person, whatever GrabCut says
    if int(hard.sum()) >= h * w - 16:  # no background found: nothing to keep still
        return None, None
    # the plate: the head's pixels (down to the collar; the body below hardly moves, it stays
    # itself) filled from the background around them
    head = hard.copy()
    head[min(max(int(chin + SEGMENT_NECK * fw), 0), h) :] = False
    xs = np.arange(w) + 0.5
    beside = np.abs(xs - c[0]) > SEGMENT_NECK_HALF_WIDTH * fw  # the shoulders, not the neck
    head[max(int(chin), 0) :, beside] = False
    # GrabCut's outline leaves the hair's finest wisps out: the head's hole, and the person
    # with it, reach SEGMENT_MARGIN_PX beyond it (the wisps move with the head, not left
    # behind as a ghost of its outline; a thin band of the background moves with them)
    d = 2 * SEGMENT_MARGIN_PX + 1
    hole = cv2.dilate(head.astype(np.uint8), np.ones((d, d), np.uint8)).astype(bool)
    plate = frame.copy()
    plate[hole] = fill_rows(frame, ~(hole | hard))[hole]  # from the background alone
    person = hard | hole
    soft = cv2.GaussianBlur(person.astype(np.float32), (0, 0), SEGMENT_SOFT_PX)
    mask = np.maximum(soft, person.astype(np.float32))
    return mask.astype(np.float32), plate


def _fill_along_rows(img: np.ndarray, known: np.ndarray):
    """Each unknown pixel of ``img`` (H, W, C) float32 interpolated linearly between the
    nearest known pixels left and right on its row (the one there where a side has none), and
    its distance (px) to the nearer of them (inf on a row without any)."""
    h, w = known.shape
    cols = np.arange(w)
    left = np.maximum.accumulate(np.where(known, cols, -1), axis=1)
    right = np.minimum.accumulate(np.where(known, cols, w)[:, ::-1], axis=1)[:, ::-1]
    rows = np.arange(h)[:, None]
    has_l, has_r = left >= 0, right < w
    vl = img[rows, np.clip(left, 0, w - 1)]
    vr = img[rows, np.clip(right, 0, w - 1)]
    span = np.maximum(right - left, 1).astype(np.float32)
    t = np.clip((cols[None, :] - left) / span, 0.0, 1.0)[:, :, None]
    both = (has_l & has_r)[:, :, None]
    out = np.where(both, (1 - t) * vl + t * vr, np.where(has_l[:, :, None], vl, vr))
    dist = np.minimum(np.where(has_l, cols - left, np.inf), np.where(has_r, right - cols, np.inf))
    return out, dist.astype(np.float32)


def fill_rows(image: np.ndarray, known: np.ndarray) -> np.ndarray:
    """``image`` (H, W, 3) uint8 with its pixels outside ``known`` (H, W) bool filled from
    the known pixels on the same row and the same column: each direction's linear
    interpolation between the nearest known pixels on either side, weighed by the inverse of
    its distance to them (near a hole's side its row decides, near its top its column), then
    softened inside the holes (a Gaussian of 1.5 px). Behind a head, the background beside and
    above it is what is most likely there: a door's edges, a wall's colour, continued, not a
    blend of the whole room's. The known pixels unchanged; :func:`fill_holes` where neither
    direction has a known pixel. Returns a new uint8 image."""
    import cv2

    img = image.astype(np.float32)
    by_row, d_row = _fill_along_rows(img, known)
    by_col, d_col = _fill_along_rows(img.transpose(1, 0, 2), known.T)
    by_col, d_col = by_col.transpose(1, 0, 2), d_col.T
    w_row = np.where(np.isfinite(d_row), 1.0 / np.maximum(d_row, 1.0), 0.0)[:, :, None]
    w_col = np.where(np.isfinite(d_col), 1.0 / np.maximum(d_col, 1.0), 0.0)[:, :, None]
    total = w_row + w_col
    out = (w_row * by_row + w_col * by_col) / np.maximum(total, 1e-12)
    none = total[:, :, 0] == 0
    if none.any():
        out[none] = fill_holes(image, known)[none]
    soft = cv2.GaussianBlur(out.astype(np.float32), (0, 0), 1.5)
    out = np.where(known[:, :, None], img, soft)
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)


def fill_holes(image: np.ndarray, known: np.ndarray) -> np.ndarray:
    """``image`` (H, W, 3) uint8 with its pixels outside ``known`` (H, W) bool filled smoothly
    from the known ones around them (push-pull: the known pixels averaged over a pyramid of
    halvings, each level filled from the coarser one; Gortler et al., "The Lumigraph", 1996);
    the known pixels unchanged. Returns a new uint8 image."""
    import cv2

    c = image.astype(np.float32) * known[:, :, None]
    wt = known.astype(np.float32)
    levels = [(c, wt)]
    while min(c.shape[:2]) > 1:
        size = (max(c.shape[1] // 2, 1), max(c.shape[0] // 2, 1))
        c = cv2.resize(c, size, interpolation=cv2.INTER_AREA)
        wt = cv2.resize(wt, size, interpolation=cv2.INTER_AREA)
        levels.append((c, wt))
    c, wt = levels[-1]
    filled = c / np.maximum(wt, 1e-6)[:, :, None]
    for c, wt in reversed(levels[:-1]):
        up = cv2.resize(filled, (c.shape[1], c.shape[0]), interpolation=cv2.INTER_LINEAR)
        a = np.clip(wt, 0.0, 1.0)[:, :, None]
        filled = a * (c / np.maximum(wt, 1e-6)[:, :, None]) + (1 - a) * up
    out = np.clip(filled + 0.5, 0, 255).astype(np.uint8)
    out[known] = image[known]
    return out


# ---------------------------------------------------------------------- a still photo


def photo_setup(model, points: np.ndarray, width: int, height: int):
    """The camera and the calibration parameters of a still picture ``width`` x ``height``
    in which the face's 468 points (MediaPipe's, (468, 3) x, y px, z relative depth px;
    the default topology, as ``model``'s) were found: the similarity that takes the model's
    rest skin onto them (:func:`~myoface.face.personal.fit_similarity_3d`, as ``myoface face
    from-photo`` aligns the generic face), read as a pinhole :data:`PHOTO_DISTANCE_MM` away
    whose focal length gives the similarity's scale there. Returns (PinholeCamera,
    FrameParams at rest with the eyes straight ahead)."""
    from myoface.face.personal import fit_similarity_3d

    pts = np.asarray(points, dtype=np.float64)
    nv = model.face.n_vertices
    if pts.shape != (nv, 3) or not np.isfinite(pts).all():
        raise MyofaceValueError(
            f"the photo's face points must be finite ({nv}, 3) (the model's topology); got "
            f"shape {pts.shape}"
        )
    found = np.column_stack([pts[:, 0], -pts[:, 1], -pts[:, 2]])  # +y up, +z to the camera
    s, r, t = fit_similarity_3d(model.skin_vertices(), found)
    if not s > 0:
        raise MyofaceValueError("the photo's face points are degenerate: cannot place the model")
    d = PHOTO_DISTANCE_MM
    cx, cy = 0.5 * width, 0.5 * height
    cam = PinholeCamera(float(s * d), cx, cy)
    # pixel x = cx + s P_x (P_z ~ -d): P_x = (r X)_x + (t_x - cx) / s; y likewise, flipped
    trans = np.array([(t[0] - cx) / s, (t[1] + cy) / s, -d])
    params = FrameParams(r, trans, np.zeros(model.n_muscles), np.zeros(4))
    return cam, params
