"""The 3-D fit of the whole face model to each frame's landmarks: head pose + every muscle.

Beyond the paper. Terzopoulos & Waters (1993, Section V-C) read the face in a 2-D head frame
because their subject faced the camera; a head that turns moves every feature by more than the
muscles do. Here the face model itself is posed in 3-D in front of a pinhole camera and fitted
to MediaPipe's 468 points (the topology of the default face: point i *is* vertex i).

Unknowns per frame: the head's rotation (3) and translation (3) in the camera frame, and the
contraction of every muscle of the model and the jaw (M), each in [0, 1]. The forward model is

    skin(c) = neutral + identity + D(c),    D(c) ~ D(c0) + J (c - c0)

with ``identity`` the person's own neutral (a smooth per-vertex offset fitted on the calibration
frame, :meth:`ModelFit.calibrate`), ``D(c0)`` the tissue's displacement at the last contractions
the tissue was relaxed at (the previous frame's), and ``J`` the skin's response to each unit
contraction (:func:`~myoface.analysis.estimate.skin_response`, once per model), made exact along
each step through the tissue by Broyden's update (as :mod:`~myoface.analysis.curvefit` does). A
frame is solved by bounded Gauss-Newton (Levenberg's damping on a rejected step): each step is a
bounded linear least-squares problem in (rotation, translation, contractions) with the
contractions kept in [0, 1]; ``refine`` relaxes of the tissue at the estimate follow, each
followed by Gauss-Newton steps with the corrected model. The fit owns its
:class:`~myoface.model.FaceState`; the caller's model is never changed.

The weights (:class:`FitSettings`) are those of a maximum a posteriori estimate with every term
in units of its standard deviation:

- landmark x, y: MediaPipe's scatter about the true vertex, in mm on the face (pixels times
  depth over focal length), so that the priors weigh the same whatever the face's size in the
  image; the face oval's points (which MediaPipe slides along the silhouette as the head turns)
  and points turned away from the camera weigh less; a Huber weight takes out outliers;
- landmark z: MediaPipe's relative depth, mean removed (it has no absolute depth), with a
  larger deviation (monocular depth is its weakest coordinate);
- temporal: each contraction and the pose may change from the previous frame by about a
  plausible rate times the frame interval (the prior that makes an ill-posed frame, e.g. a
  side view that hides one half of the face, well-posed);
- magnitude: a weak Gaussian prior on each contraction, and a sparsity (L1) prior: a muscle
  has to explain a little of the landmarks' motion before it is used. Between muscles whose
  pulls nearly coincide (:func:`confounded_muscles`, e.g. risorius and buccinator) the L1
  prior gives the motion to the one that produces it with the least contraction, and keeps
  that choice from frame to frame; such muscles are judged by the skin they produce.

Camera frame (:class:`HeadPose`): x right, y up, z towards the viewer (the head frame's axes
when the face looks into the camera), the camera at the origin looking along -z; the head frame
maps into it by ``P = R X + t``. Angles: ``R = Ry(yaw) Rx(pitch) Rz(roll)`` (intrinsic y-x-z):
yaw > 0 turns the face towards the subject's left (the image's right), pitch > 0 nods it down,
roll > 0 tilts its top towards the subject's right (counter-clockwise in the image).
"""

from __future__ import annotations

import collections
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import sparse
from scipy.optimize import lsq_linear
from scipy.sparse.linalg import spsolve
from scipy.spatial.transform import Rotation

from myoface.analysis.contractions_csv import POSE_COLUMNS as _POSE_COLUMNS
from myoface.errors import MyofaceValueError

#: the vertical field of view assumed for a video whose camera is not known: a typical webcam
#: or phone front camera (60-78 degrees diagonal) on a 16:9 or 4:3 frame
DEFAULT_FOV_DEG = 45.0
#: seconds at the start of a video searched for the most neutral frame to calibrate on
CALIBRATION_WINDOW_S = 2.0
#: rounds of (pose, identity) alternation when calibrating
IDENTITY_ROUNDS = 4
#: a frame's expression score: this percentile of its vertices' displacement (mm) by the
#: contractions fitted against the model's neutral (an expression moves a part of the face)
NEUTRAL_PERCENTILE = 90
#: the scores are known to within this (mm): MediaPipe's points on identical neutral frames
#: score up to ~1 mm apart. The earliest frame within it of the lowest score
#: calibrates, with ...
NEUTRAL_MARGIN_MM = 1.0
#: ... at most this many frames around it (within the margin too): their noise averages out
CALIBRATION_FRAMES = 5
#: Euler axis order of the head angles (scipy's: upper case = intrinsic)
EULER_ORDER = "YXZ"
#: a frame's Gauss-Newton iterations stop once a step is below all of these: head rotation
#: (rad; 0.006 degrees), head translation (mm) and contraction. Each is far below what the
#: landmarks resolve (MediaPipe's ~1 mm scatter moves a contraction by a few hundredths);
#: tolerances ten times tighter took a third more iterations on single_face.mp4 for the same
#: analysis.fidelity (0.694 against 0.693)
STEP_TOL_RAD = 1e-4
STEP_TOL_MM = 1e-2
STEP_TOL_CONTRACTION = 5e-3


@dataclass(frozen=True)
class FitSettings:
    """The fit's weights, each a standard deviation of the term it scales.

    Attributes
    ----------
    landmark_sigma_mm : MediaPipe's scatter of a point about its vertex in the image plane, mm
        on the face (measured on faces rendered by myoface: median 1.2 mm frontal, ~2 mm at
        30 degrees of yaw).
    depth_sigma_mm : the same for MediaPipe's relative depth z: about a linear fit to the true
        depth it scatters by 1.3-2.2 mm, but it follows a turning head less than x and y do
        (on the closed loop, weighing it like x, y / 3 made the skin error 1.5 mm, like
        x, y / 10 1.1 mm), so it only keeps the depth of the pose from being ill-posed.
    oval_weight : weight of the face oval's points (the mesh's outer rim), which MediaPipe
        puts on the face's silhouette, not on fixed skin, as the head turns.
    model_error : the model's own error at a point, as a fraction of the largest skin
        displacement any one muscle (or the jaw) makes there at full contraction
        (:func:`model_error_weights`): a point the muscles move far (lips, cheeks, chin) is
        known less well than one no muscle moves (eye corners, nose bridge), because the
        model's muscles and tissue are an approximation of the person's. Without it, what an
        expression moves that the model cannot (a broad smile's cheeks bulging up and out)
        is explained by moving the head: on the sample video's smile the head rose ~1.2 mm
        against its eye corners and nose bridge, the chin then seemed to drop, and the jaw
        opened 0.13 rad behind closed teeth. 0: every point is known to
        :attr:`landmark_sigma_mm`.
    rate_per_s : temporal prior: a contraction changes by about this much per second (1 sd);
        a fast expression goes from 0 to 1 in a quarter of a second.
    rotation_rate_deg_per_s, translation_rate_mm_per_s : the same for the head pose (weak: a
        head turns fast; they only keep a frame with too few points well-posed).
    magnitude_sigma : Gaussian prior on each contraction (about 0).
    sparsity : L1 prior, in squared standard deviations of the landmarks per unit contraction:
        a muscle must lower the landmark cost by this much per unit before it is used.
    huber : a landmark residual beyond this many sigmas weighs less (Huber). What the model
        cannot make (a broad smile's cheeks, a person's own way of moving) leaves residuals
        of a few sigmas at many points at once; weighed in full they pull the head pose and
        the other muscles. On single_face.mp4 (2026-12-01): 3.0 gave analysis.fidelity 0.703
        and synth.smile_gain 0.672, 1.5 0.765 and 0.709 (the synthetic closed loop unchanged
        within its tolerance).
    tracking : MediaPipe's face mesh in its tracking (video) mode, which finds each frame's
        face from the last frame's points, instead of detecting it on every frame (image
        mode; the default). Tracking costs ~3 ms less CPU a frame (5.5 vs 8.5 on the sample
        video), but it is biased where the face changes shape fast: on single_face.mp4's smile
        it puts the chin 3.1 mm and the lower lip 4.1 mm lower than detection does (the
        tracked box lags the opening mouth, as other trackers' users report, e.g. OpenFace
        issue 552, MediaPipe issue 2990), and the fit then opens the jaw and pulls the lower
        lip down while the chin rises. Detected on every frame, the points scatter a little
        more; the fit's temporal prior takes that out.
    flow : refine MediaPipe's points by optical flow (:mod:`myoface.analysis.flow`: each
        point tracked by Lucas-Kanade from the first frame with a face, kept where the track
        is sure), because MediaPipe reads an expression's motion short. Off by default: it
        helps where the skin's texture moves with the skin and the face keeps its look, and
        hurt on the real video we have. Measured 2026-12-01 (BENCHMARKS.md; the flow on /
        off): on the head-motion closed loop, head still, skin error 0.34 / 1.03 mm, median
        RMSE 0.045 / 0.100, worst correlation 0.99 / 0.61; head moving, skin 1.26 / 1.53 mm,
        head angles 1.58 / 2.79 degrees, worst RMSE 0.38 / 0.31. On single_face.mp4,
        analysis.fidelity 0.84-0.85 / 0.87 and synth.smile_gain 0.72 / 0.79: on a real smile the flow follows
        the cheek's skin beside the mouth corner, which moves less than the corner MediaPipe
        finds on the input and on the resynthesis. It costs ~7 ms a frame (head still) to
        ~17 ms (head turning), on the detector's thread.
    iterations : Gauss-Newton steps per frame (fewer when converged).
    refine : relaxes of the tissue per frame at the estimate (0: the linear response only).
    relax_step_mm : with the relax deferred (a video, :meth:`ModelFit.fit` ``deferred=True``):
        the tissue is relaxed again only once the skin the estimate makes has moved this far
        (mm, at any vertex, by the linear model) from where the tissue was last relaxed; in
        between, the model's response Broyden-corrected at the last relax stands in for the
        tissue. Its error grows with the square of the step: a frame behind on a ramp that
        moves the lips several mm a frame it is ~0.1 mm RMS (test_fitkernels), a tenth of
        :attr:`landmark_sigma_mm`. A relax costs more CPU than MediaPipe on a frame, and
        MediaPipe's scatter moves the estimate's skin by ~1 mm from frame to frame. On
        single_face.mp4: 0 (a relax whenever the estimate moves) 72 relaxes, analysis.fidelity
        0.694; 0.5 mm 59, 0.697; 1 mm 40, 0.694; 2 mm 26, 0.703.
    synthesis_rounds : rounds of analysis by synthesis per frame (and at calibration) when the
        fit is given a :class:`LandmarkSynthesis`.
    """

    landmark_sigma_mm: float = 1.0
    depth_sigma_mm: float = 10.0
    oval_weight: float = 0.2
    model_error: float = 0.1
    rate_per_s: float = 4.0
    rotation_rate_deg_per_s: float = 180.0
    translation_rate_mm_per_s: float = 300.0
    magnitude_sigma: float = 1.0
    sparsity: float = 4.0
    huber: float = 1.5
    tracking: bool = False
    flow: bool = False
    iterations: int = 8
    refine: int = 1
    relax_step_mm: float = 2.0
    #: with a :class:`LandmarkSynthesis`: rounds of analysis by synthesis per frame
    synthesis_rounds: int = 2
    #: identity offset (calibration): the difference of neighbouring vertices' offsets (mm, 1
    #: sd) and the offset itself (mm, 1 sd)
    identity_edge_sigma_mm: float = 1.0
    identity_sigma_mm: float = 10.0


# ------------------------------------------------------------------ camera and pose


@dataclass(frozen=True)
class PinholeCamera:
    """A pinhole camera's intrinsics: focal length and principal point, pixels; image (x, y) =
    (column, row)."""

    focal_px: float
    cx: float
    cy: float

    def __post_init__(self):
        vals = (self.focal_px, self.cx, self.cy)
        if not all(np.isfinite(v) for v in vals) or not self.focal_px > 0:
            raise MyofaceValueError(
                f"a camera needs a finite focal length > 0 px and principal point; got {vals}"
            )

    @classmethod
    def for_image(cls, width: int, height: int, fov_deg: float = DEFAULT_FOV_DEG):
        """The camera of a ``width`` x ``height`` image with vertical field of view
        ``fov_deg`` and the principal point at the image's centre."""
        if not 1 <= fov_deg <= 170:
            raise MyofaceValueError(f"fov_deg must be in [1, 170]; got {fov_deg}")
        f = 0.5 * height / np.tan(np.radians(fov_deg) / 2)
        return cls(float(f), 0.5 * width, 0.5 * height)

    @classmethod
    def from_camera(cls, camera):
        """The intrinsics of a (perspective) :class:`~myoface.render.Camera`."""
        if camera.orthographic:
            raise MyofaceValueError("the fit needs a perspective camera (fov_deg), not ortho")
        return cls(float(camera.focal_px), 0.5 * camera.width, 0.5 * camera.height)

    def project(self, p: np.ndarray) -> np.ndarray:
        """Camera-frame points (N, 3) mm -> (N, 2) pixels (x, y)."""
        d = np.maximum(-p[:, 2], 1e-6)
        return np.column_stack(
            [self.cx + self.focal_px * p[:, 0] / d, self.cy - self.focal_px * p[:, 1] / d]
        )


@dataclass(frozen=True)
class HeadPose:
    """The head frame in the camera frame: ``P = rotation @ X + translation_mm``."""

    rotation: np.ndarray
    translation_mm: np.ndarray

    @classmethod
    def from_euler(cls, yaw_deg=0.0, pitch_deg=0.0, roll_deg=0.0, translation_mm=(0, 0, -600)):
        r = Rotation.from_euler(EULER_ORDER, [yaw_deg, pitch_deg, roll_deg], degrees=True)
        return cls(r.as_matrix(), np.asarray(translation_mm, dtype=np.float64))

    @property
    def angles_deg(self) -> np.ndarray:
        """(yaw, pitch, roll) degrees."""
        return Rotation.from_matrix(self.rotation).as_euler(EULER_ORDER, degrees=True)

    def apply(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(x) @ self.rotation.T + self.translation_mm

    def columns(self) -> dict[str, float]:
        """The CSV's pose columns: angles (deg) and the head frame's origin in the camera frame
        (x right, y up, mm; ``head_tz_mm`` its distance in front of the camera)."""
        yaw, pitch, roll = self.angles_deg
        tx, ty, tz = self.translation_mm
        return {
            "head_yaw_deg": float(yaw),
            "head_pitch_deg": float(pitch),
            "head_roll_deg": float(roll),
            "head_tx_mm": float(tx),
            "head_ty_mm": float(ty),
            "head_tz_mm": float(-tz),
        }

    @classmethod
    def from_columns(cls, row: dict) -> HeadPose:
        """The inverse of :meth:`columns`."""
        return cls.from_euler(
            row["head_yaw_deg"],
            row["head_pitch_deg"],
            row["head_roll_deg"],
            (row["head_tx_mm"], row["head_ty_mm"], -row["head_tz_mm"]),
        )


#: the CSV columns of a pose, in order (defined with the CSV's other columns)
POSE_COLUMNS = _POSE_COLUMNS


def _check_points(points, n: int) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[0] != n or p.shape[1] not in (2, 3) or not np.isfinite(p).all():
        raise MyofaceValueError(
            f"landmarks must be finite ({n}, 3) points (x, y px; z relative depth px); got "
            f"shape {p.shape}"
        )
    if p.shape[1] == 2:
        p = np.column_stack([p, np.full(n, np.nan)])
    return p


def initial_pose(shape: np.ndarray, points: np.ndarray, camera: PinholeCamera) -> HeadPose:
    """A closed-form pose of ``shape`` (V, 3) mm, head frame, for ``points`` (V, 3) (x, y px,
    z relative depth px): the weak-perspective similarity (Umeyama 1991) between the shape and
    the points, its scale read as focal length over depth."""
    from myoface.face.personal import fit_similarity_3d

    p = np.asarray(points, dtype=np.float64)
    z = p[:, 2] if np.isfinite(p[:, 2]).all() else np.zeros(len(p))
    dst = np.column_stack([p[:, 0] - camera.cx, camera.cy - p[:, 1], -z])
    s, r, t = fit_similarity_3d(shape, dst)
    if not s > 0:
        raise MyofaceValueError("degenerate landmarks: cannot place the head")
    d = camera.focal_px / s
    # the shape's centroid projects to where the points' centroid is, at depth d
    c = shape.mean(axis=0)
    pc = s * r @ c + t  # px, at the centroid
    centroid_cam = np.array([pc[0] * d / camera.focal_px, pc[1] * d / camera.focal_px, -d])
    return HeadPose(r, centroid_cam - r @ c)


# ------------------------------------------------------------------ the model's structure


def landmark_weights(face, oval_weight: float = FitSettings.oval_weight) -> np.ndarray:
    """Per-vertex base weights (V,): 1, ``oval_weight`` on the face oval (the mesh's outer
    boundary loop, which MediaPipe places on the silhouette)."""
    w = np.ones(face.n_vertices)
    loops = face.boundary_loops
    if loops:
        w[loops[0]] = oval_weight
    return w


def model_error_weights(response, model_error: float = FitSettings.model_error,
                        sigma_mm: float = FitSettings.landmark_sigma_mm) -> np.ndarray:  # fmt: skip
    """Per-vertex weights (V,) for the model's own error (:attr:`FitSettings.model_error`):
    ``1 / (1 + (model_error * e / sigma_mm)^2)`` with ``e`` the largest displacement (mm) any
    one muscle's full contraction makes at the vertex (``response`` (V, 3, M): mm per unit
    contraction, :func:`~myoface.analysis.estimate.skin_response`). That is the landmark's
    variance ``sigma_mm^2`` grown by the model's ``(model_error * e)^2``: 1 where no muscle
    moves the skin, about 0.5 where a muscle moves it ``sigma_mm / model_error`` (10 mm by
    default)."""
    if not model_error >= 0:
        raise MyofaceValueError(f"model_error must be >= 0; got {model_error}")
    r = np.asarray(response, dtype=np.float64)
    e = np.linalg.norm(r, axis=1).max(axis=1) if r.shape[2] else np.zeros(len(r))
    return 1.0 / (1.0 + (model_error * e / sigma_mm) ** 2)


#: the person's eye opening over the model's (:func:`lid_gains`) is kept within these bounds: a
#: tracker that finds an eye closed (or wide open) at calibration should not rescale its lids
#: beyond what faces differ by
LID_GAIN_RANGE = (0.5, 2.0)


def lid_gains(model, shape) -> dict[int, tuple[float, np.ndarray]]:
    """How much further the lids of ``shape`` (V, 3) mm, head frame (the person's neutral),
    move than the model's for the same contraction: ``{muscle index: (gain, vertices)}`` for
    each lid muscle (:mod:`myoface.muscles.lids`), ``gain`` the eye's opening (mean height of
    the upper margin over the lower, between the canthi) in ``shape`` over the model's, within
    :data:`LID_GAIN_RANGE`, and ``vertices`` those the lids move.

    A lid muscle's contraction is a fraction of the eye's own opening (at 1 the margins meet),
    so its skin displacement is proportional to the opening: the model's response, measured on
    the model's eyes, is the person's divided by this gain."""
    lids = getattr(model, "eyelids", None)
    out: dict[int, tuple[float, np.ndarray]] = {}
    if lids is None:
        return out
    rest = model.skin_vertices()
    shape = np.asarray(shape, dtype=np.float64)
    for eye in lids.eyes.values():

        def opening(x, eye=eye):
            up, lo = eye.upper[1:-1], eye.lower[1:-1]
            return float(x[up, 1].mean() - x[lo, 1].mean())

        ref = opening(rest)
        if not ref > 0:
            continue
        gain = float(np.clip(opening(shape) / ref, *LID_GAIN_RANGE))
        for i in (eye.raise_i, eye.close_i):
            if i is not None:
                out[int(i)] = (gain, np.asarray(eye.vertices))
    return out


def confounded_muscles(model, threshold: float = 0.95, ids=None) -> list[tuple[str, float, str]]:
    """Muscles the skin alone cannot tell apart from the others: ``(muscle, R2, nearest)``, R2
    the share of the muscle's skin response (every vertex, x, y, z) that the other muscles'
    responses explain (a variance inflation of 1 / (1 - R2)), ``nearest`` the muscle whose
    response is most like its own; sorted, most confounded first."""
    from myoface.analysis.estimate import skin_response

    ids = tuple(model.ids if ids is None else ids)
    a = skin_response(model, ids).reshape(-1, len(ids))
    g = a.T @ a
    gi = np.linalg.pinv(g)
    r2 = 1.0 - 1.0 / np.maximum(np.diag(g) * np.diag(gi), 1.0)
    norm = np.linalg.norm(a, axis=0)
    cos = g / np.maximum(np.outer(norm, norm), 1e-12)
    np.fill_diagonal(cos, -np.inf)
    out = [(ids[i], float(r2[i]), ids[int(np.argmax(cos[i]))]) for i in range(len(ids))]
    return sorted([o for o in out if o[1] >= threshold], key=lambda o: -o[1])


def gauge_vertices(model) -> np.ndarray:
    """The vertices whose fit defines the head frame of a person's neutral (see
    :meth:`ModelFit._gauge`): those no muscle moves
    (:func:`~myoface.analysis.landmarks.rigid_vertices`: the nose's bridge and body)."""
    from myoface.analysis.landmarks import rigid_vertices

    return np.asarray(rigid_vertices(model))


def _laplacian(face) -> sparse.csr_matrix:
    """The mesh graph's Laplacian (V, V): sum over edges of (e_a - e_b)(e_a - e_b)^T."""
    e = face.edges
    n = face.n_vertices
    rows = np.concatenate([e[:, 0], e[:, 1], e[:, 0], e[:, 1]])
    cols = np.concatenate([e[:, 0], e[:, 1], e[:, 1], e[:, 0]])
    vals = np.concatenate([np.ones(2 * len(e)), -np.ones(2 * len(e))])
    return sparse.csr_matrix((vals, (rows, cols)), shape=(n, n))


# ------------------------------------------------------------------ results


@dataclass
class FrameFit:
    """One frame's fit.

    Attributes
    ----------
    contractions : (M,) in [0, 1], over the model's ids (jaw last).
    pose : HeadPose.
    residual_mm : RMS distance (mm on the face, image plane) of the landmarks from the fitted
        model's vertices.
    iterations : Gauss-Newton steps taken.
    converged : whether the last step was below tolerance.
    """

    contractions: np.ndarray
    pose: HeadPose
    residual_mm: float
    iterations: int
    converged: bool


@dataclass
class Calibration:
    """What :meth:`ModelFit.calibrate` found.

    Attributes
    ----------
    index : position (in the sequence given) of the calibration frame.
    scores : (T,) per candidate frame, the RMS skin displacement (mm) of the contractions
        fitted against the model's own neutral (NaN without a face); the lowest is chosen.
    identity_mm : (V, 3) the person's neutral minus the model's, head frame.
    pose : the calibration frame's head pose.
    residual_mm : landmark RMS (mm) after the identity fit.
    """

    index: int
    scores: np.ndarray
    identity_mm: np.ndarray
    pose: HeadPose
    residual_mm: float
    extra: dict = field(default_factory=dict)


# ------------------------------------------------------------------ the fit


class ModelFit:
    """The face model fitted to landmark frames in 3-D (see the module's docstring).

    Parameters
    ----------
    model : FaceModel in the default (MediaPipe) topology; never changed.
    camera : PinholeCamera of the frames.
    settings : FitSettings (default: the documented defaults).
    fps : the video's frame rate (the temporal prior scales with the frame interval).

    Use :meth:`calibrate` once (optional: without it the model's own neutral is the person's),
    then :meth:`fit` on each frame in order; :meth:`lose_track` after frames without a face.
    """

    def __init__(self, model, camera: PinholeCamera, settings: FitSettings | None = None,
                 fps: float = 30.0):  # fmt: skip
        from myoface.analysis.estimate import skin_response

        if model.face.n_vertices != 468:
            raise MyofaceValueError(
                "the 3-D fit needs a face model in MediaPipe's 468-point topology (the default "
                f"face); this one has {model.face.n_vertices} vertices"
            )
        if not fps > 0:
            raise MyofaceValueError(f"fps must be > 0; got {fps}")
        self.model = model
        self.camera = camera
        self.settings = settings or FitSettings()
        self.fps = float(fps)
        self.ids = tuple(model.ids)
        self.n_muscles = len(self.ids)
        self.neutral = model.skin_vertices()
        #: the model's skin response (V, 3, M) mm per unit contraction, and the fit's: the
        #: same with the lids' scaled to the person's eye opening at calibration
        #: (:func:`lid_gains`; their extra part is :attr:`lid_extra`)
        self.model_response = skin_response(model, self.ids)
        self.response = self.model_response
        self.lid_extra = np.zeros_like(self.model_response)
        self.base_weights = landmark_weights(
            model.face, self.settings.oval_weight
        ) * model_error_weights(
            self.response, self.settings.model_error, self.settings.landmark_sigma_mm
        )
        self.identity_mm = np.zeros_like(self.neutral)
        #: the fit's own state of the model's tissue (each relax starts from the last)
        self.state = model.rest_state()
        self._c0 = np.zeros(self.n_muscles)  # contractions the tissue was last relaxed at
        self._d0 = np.zeros_like(self.neutral)  # ... and its skin displacement there
        self._prev: FrameFit | None = None
        #: deferred relaxes (``fit(deferred=True)``): the response Broyden-corrected at the
        #: last relax, the relax running on the worker thread (contractions, future)
        self._jac: np.ndarray | None = None
        self._pending = None
        self._worker = None
        self.calibration: Calibration | None = None
        #: tissue relaxes that did not converge (see :meth:`_relax`)
        self.unconverged_relaxes = 0
        #: where the time goes (for the benchmark's breakdown): the fits' thread CPU (s) and
        #: count, the relaxes' thread CPU (s; on the worker when deferred) and count, and the
        #: wall time (s) fits waited for a deferred relax
        self.timings = {
            "fits": 0, "fit_cpu_s": 0.0, "relaxes": 0, "relax_cpu_s": 0.0, "relax_wait_s": 0.0,
        }  # fmt: skip

    # -------------------------------------------------------------- public
    def lose_track(self) -> None:
        """Forget the previous frame (after frames without a face): the next fit starts from a
        closed-form pose and no temporal prior."""
        self._prev = None

    def skin(self, contractions=None) -> np.ndarray:
        """The person's skin (V, 3) mm, head frame, at ``contractions`` (default: neutral),
        relaxed through the tissue from the fit's state."""
        c = np.zeros(self.n_muscles) if contractions is None else np.asarray(contractions)
        self._collect()
        disp = self._relax(c) if np.any(c) else 0.0
        return self.neutral + self.identity_mm + disp

    def _relax(self, c) -> np.ndarray:
        """Relax the fit's state at ``c``; the skin's displacement (V, 3) mm. A relax that
        does not converge is counted (:attr:`unconverged_relaxes`), not raised: the fit
        corrects its linear model with whatever the tissue reached."""
        import time
        import warnings

        from myoface.tissue import RelaxWarning

        t0 = time.thread_time()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", RelaxWarning)
            res = self.model.relax(c, self.state)
        if not res.converged or any(issubclass(w.category, RelaxWarning) for w in caught):
            self.unconverged_relaxes += 1
        self.state = res.state
        disp = self.model.skin_vertices(self.state) - self.neutral
        out = disp + self.lid_extra @ np.asarray(c, dtype=np.float64)
        self.timings["relaxes"] += 1
        self.timings["relax_cpu_s"] += time.thread_time() - t0
        return out

    def shape(self, contractions) -> np.ndarray:
        """The fit's forward model (V, 3) mm, head frame, at ``contractions``: the person's
        neutral plus the displacement at the tissue's last relax, continued linearly."""
        c = np.asarray(contractions, dtype=np.float64)
        jac = self.response if self._jac is None else self._jac
        return self.neutral + self.identity_mm + self._d0 + _linear(jac, c - self._c0)

    def _relax_due(self, c) -> bool:
        """Whether the tissue is to be relaxed (deferred) at ``c``: once the skin the linear
        model gives there has moved :attr:`FitSettings.relax_step_mm` from where the tissue
        was last relaxed (at any vertex)."""
        dc = np.asarray(c, dtype=np.float64) - self._c0
        if np.abs(dc).max() <= 1e-6:
            return False
        jac = self.response if self._jac is None else self._jac
        step = _linear(jac, dc)
        return bool(np.sqrt((step**2).sum(1).max()) > self.settings.relax_step_mm)

    def _relax_later(self, c) -> None:
        """Relax the tissue at ``c`` on the worker thread (:meth:`_collect` takes it up)."""
        from concurrent.futures import ThreadPoolExecutor

        if self._worker is None:
            self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="myoface-fit")
        c = np.array(c, dtype=np.float64)
        self._pending = (c, self._worker.submit(self._relax, c))

    def _collect(self) -> None:
        """Wait for the deferred relax, if any, and move the linearisation there: the response
        at rest Broyden-corrected along the step from the last relaxed point (as the second
        round of an immediate fit does)."""
        if self._pending is None:
            return
        c, fut = self._pending
        self._pending = None
        import time

        t0 = time.perf_counter()
        d_new = fut.result()
        self.timings["relax_wait_s"] += time.perf_counter() - t0
        jac = self.response.copy()
        dc = c - self._c0
        dd = float(dc @ dc)
        if dd > 1e-10:
            jac += np.multiply.outer((d_new - self._d0) - _linear(jac, dc), dc / dd)
        self._c0, self._d0, self._jac = c, d_new, jac

    def close(self) -> None:
        """Finish the deferred relax and stop its thread."""
        if self._worker is not None:
            self._collect()
            self._worker.shutdown()
            self._worker = None

    def fit(
        self, points, synthesis: LandmarkSynthesis | None = None, deferred: bool = False
    ) -> FrameFit:
        """Fit one frame's landmarks (468, 3): x, y pixels (column, row), z MediaPipe's relative
        depth (pixels; NaN or a (468, 2) array: not used). Warm-started from the previous
        frame; the result becomes the next frame's prior.

        ``synthesis``: analysis by synthesis (:class:`LandmarkSynthesis`):
        :attr:`FitSettings.synthesis_rounds` times, the model is rendered at the estimate, the
        tracker run on the render, and its error there (what it reports less where the model's
        vertices are) taken off the landmarks before they are fitted again.

        ``deferred=True`` (a video, frame after frame): no round through the tissue in this
        call; the frame is fitted with the model linearised where the tissue was last relaxed
        (an earlier frame's estimate), and the tissue is relaxed at this frame's estimate on a
        second thread while the caller goes on (e.g. fits the next frame), once the
        estimate's skin has moved :attr:`FitSettings.relax_step_mm` since the last relax. The
        next call waits for it first, so the results do not depend on timing."""
        import time

        t0 = time.thread_time()
        p = _check_points(points, len(self.neutral))
        prev = self._prev
        self._collect()
        refine = 0 if deferred else self.settings.refine
        res = self._fit(p, prev, refine=refine)
        if synthesis is not None:
            for _ in range(self.settings.synthesis_rounds):
                err = synthesis.tracker_error(self.shape(res.contractions), res.pose)
                if err is None:
                    break
                res = self._fit(p - err, prev, refine=0, start=res)
        if deferred and self.settings.refine > 0 and self._relax_due(res.contractions):
            self._relax_later(res.contractions)
        self._prev = res
        self.timings["fits"] += 1
        self.timings["fit_cpu_s"] += time.thread_time() - t0  # (with immediate relaxes)
        return res

    def calibrate(
        self, frames, index: int | None = None, synthesis: LandmarkSynthesis | None = None
    ) -> Calibration:
        """Measure the person's own neutral.

        ``frames``: a sequence of landmark arrays (468, 3), or None where no face was found
        (e.g. the first :data:`CALIBRATION_WINDOW_S` seconds of a video). ``index`` picks the
        calibration frame; by default it is the most neutral one: the frame whose contractions,
        fitted against the model's own neutral, displace the skin least (the
        :data:`NEUTRAL_PERCENTILE` th percentile over the vertices), or rather the earliest
        whose score is within :data:`NEUTRAL_MARGIN_MM` of the least (the tracker's scatter;
        a video starts neutral more often than not). On that frame and up to :data:`CALIBRATION_FRAMES` around it
        within the margin too, the head poses and a per-vertex offset of the neutral
        (regularised to be smooth: :attr:`FitSettings.identity_edge_sigma_mm`; the residual
        in the image plane then added, so that the neutral reproduces them) are fitted with
        every contraction at zero, the offset's rigid part moved into the poses
        (:meth:`_gauge`); later frames measure expression relative to it.
        """
        if index is None:
            # scored as they come (``frames`` may be an iterator whose points are being
            # detected meanwhile), each frame's fit started from the previous frame's
            # (no temporal prior: each frame's score is its own)
            saved = self.identity_mm
            self.identity_mm = np.zeros_like(self.neutral)
            flat = self.response.reshape(-1, self.n_muscles)
            got, scored, last = [], [], None
            try:
                for pts in frames:
                    got.append(pts)
                    if pts is None:
                        scored.append(np.nan)
                        last = None
                        continue
                    r = self._fit(
                        _check_points(pts, len(self.neutral)), None, refine=0, start=last,
                        rest=True,
                    )  # fmt: skip
                    last = r
                    disp = np.linalg.norm((flat @ r.contractions).reshape(-1, 3), axis=1)
                    scored.append(float(np.percentile(disp, NEUTRAL_PERCENTILE)))
            finally:
                self.identity_mm = saved
            frames = got
            if not frames:
                raise MyofaceValueError("calibrate() needs at least one frame")
            scores = np.array(scored, dtype=np.float64)
            if not np.isfinite(scores).any():
                raise MyofaceValueError("no face in any of the calibration frames")
            # the scores are known to the tracker's scatter: of the frames within it of the
            # lowest, the earliest (a video starts neutral more often than it ends so)
            best = np.nanmin(scores)
            index = int(np.flatnonzero(scores <= best + NEUTRAL_MARGIN_MM)[0])
        else:
            frames = list(frames)
            if not frames:
                raise MyofaceValueError("calibrate() needs at least one frame")
            scores = np.full(len(frames), np.nan)
        if not 0 <= index < len(frames) or frames[index] is None:
            raise MyofaceValueError(f"calibration frame {index} has no face")
        use = [index]
        if np.isfinite(scores[index]):
            # the frames around it nearly as neutral calibrate with it (their tracker noise
            # averages out): within NEUTRAL_MARGIN_MM of the lowest score, the lowest first
            near = [
                k
                for k in np.argsort(np.where(np.isfinite(scores), scores, np.inf))
                if k != index
                and abs(k - index) <= CALIBRATION_FRAMES - 1
                and scores[k] <= np.nanmin(scores) + NEUTRAL_MARGIN_MM
            ]
            use += [int(k) for k in near[: CALIBRATION_FRAMES - 1]]
        pts = [_check_points(frames[k], len(self.neutral)) for k in use]
        identity, poses, resid = self._fit_identity(pts)
        if synthesis is not None:
            # the tracker's own error on the neutral, rendered, is not the person's shape
            for _ in range(self.settings.synthesis_rounds):
                errs = [synthesis.tracker_error(self.neutral + identity, q) for q in poses]
                if any(e is None for e in errs):
                    break
                identity, poses, resid = self._fit_identity(
                    [p - e for p, e in zip(pts, errs, strict=True)]
                )
        pose = poses[0]
        self.identity_mm = identity
        self._prev = None
        gains = self._scale_lids(self.neutral + identity)
        extra = {"frames": use, "lid_gains": gains}
        self.calibration = Calibration(index, scores, identity, pose, resid, extra)
        return self.calibration

    def _scale_lids(self, shape) -> dict[str, float]:
        """Scale the lid muscles' response to the eye openings of ``shape`` (the person's
        neutral; :func:`lid_gains`): the fit then reads a lid's contraction as the fraction of
        the person's own opening that it closes (or opens), which is what it means on any
        face the contractions drive. Returns {muscle id: gain}."""
        extra = np.zeros_like(self.model_response)
        gains = lid_gains(self.model, shape)
        for i, (g, verts) in gains.items():
            extra[verts, :, i] = (g - 1.0) * self.model_response[verts, :, i]
        self._collect()
        self.lid_extra = extra
        self.response = self.model_response + extra
        # the linearisation starts again from rest with the new response
        self.state = self.model.rest_state()
        self._c0 = np.zeros(self.n_muscles)
        self._d0 = np.zeros_like(self.neutral)
        self._jac = None
        return {self.ids[i]: round(g, 4) for i, (g, _) in gains.items()}

    # -------------------------------------------------------------- internals
    def _pixel_mm(self, pose: HeadPose) -> float:
        """mm on the face per pixel at the head's depth."""
        return float(max(-pose.translation_mm[2], 1.0) / self.camera.focal_px)

    def _weights(self, pose: HeadPose, shape: np.ndarray) -> np.ndarray:
        """Base weights times visibility: points whose surface turns away from the camera
        weigh less (MediaPipe guesses them)."""
        from myoface.analysis._fitkernels import vertex_normals

        tri = self.model.face.triangles
        n = vertex_normals(np.ascontiguousarray(shape, dtype=np.float64), tri) @ pose.rotation.T
        p = pose.apply(shape)
        view = -p / np.maximum(np.linalg.norm(p, axis=1, keepdims=True), 1e-9)
        cos = (n * view).sum(1)
        return self.base_weights * np.clip(cos / 0.3, 0.05, 1.0)

    def _residuals(self, p, pose, shape, w, k):
        """Weighted residuals (normalised by their sigmas): xy (V, 2), z (V,) and the points'
        2-D distance in sigmas (V,) (for the Huber weights)."""
        s = self.settings
        cam = self.camera
        pc = pose.apply(shape)
        uv = cam.project(pc)
        rxy = (uv - p[:, :2]) * (k / s.landmark_sigma_mm)
        use_z = np.isfinite(p[:, 2]).all()
        if use_z:
            dz = -pc[:, 2] - k * p[:, 2]
            dz = dz - (w * dz).sum() / w.sum()
            rz = dz / s.depth_sigma_mm
        else:
            rz = np.zeros(len(p))
        return rxy, rz, np.linalg.norm(rxy, axis=1), use_z

    def _jacobians(self, pose, shape, dshape_dc, k, w, use_z):
        """Rows of the weighted landmark residuals with respect to (omega (3), dt (3), dc)."""
        s = self.settings
        f = self.camera.focal_px
        y = shape @ pose.rotation.T  # R X
        pc = y + pose.translation_mm
        d = np.maximum(-pc[:, 2], 1e-6)
        # d(u, v)/dP (V, 2, 3)
        dproj = np.zeros((len(pc), 2, 3))
        dproj[:, 0, 0] = f / d
        dproj[:, 0, 2] = f * pc[:, 0] / d**2
        dproj[:, 1, 1] = -f / d
        dproj[:, 1, 2] = -f * pc[:, 1] / d**2
        # dP/dx (V, 3, 6 + K): omega -> -[y]_x, t -> I, c -> R J
        nk = 0 if dshape_dc is None else dshape_dc.shape[2]
        dp = np.zeros((len(pc), 3, 6 + nk))
        dp[:, 0, 1], dp[:, 0, 2] = y[:, 2], -y[:, 1]
        dp[:, 1, 0], dp[:, 1, 2] = -y[:, 2], y[:, 0]
        dp[:, 2, 0], dp[:, 2, 1] = y[:, 1], -y[:, 0]
        dp[:, :, 3:6] = np.eye(3)
        if nk:
            dp[:, :, 6:] = np.einsum("ij,vjk->vik", pose.rotation, dshape_dc)
        sw = np.sqrt(w)
        jxy = np.einsum("vij,vjk->vik", dproj, dp) * (k / s.landmark_sigma_mm)
        jxy *= sw[:, None, None]
        rows = [jxy.reshape(-1, 6 + nk)]
        if use_z:
            jz = -dp[:, 2, :] / s.depth_sigma_mm
            jz = jz - (w[:, None] * jz).sum(0) / w.sum()
            rows.append(jz * sw[:, None])
        return np.vstack(rows)

    def _fit(self, p, prev: FrameFit | None, refine: int, start: FrameFit | None = None,
             rest: bool = False):  # fmt: skip
        """The bounded Gauss-Newton fit of one frame (see the module's docstring), with the
        temporal prior to ``prev``, started from ``start`` (default: ``prev``; without
        either from a closed-form pose and no contraction). ``rest``: with the model
        linearised at rest (as a fit from nothing is) rather than where the tissue was last
        relaxed."""
        m = self.n_muscles
        base = self.neutral + self.identity_mm
        start = prev if start is None else start
        if start is None:
            pose = initial_pose(base, p, self.camera)
            c = np.zeros(m)
        else:
            pose, c = start.pose, start.contractions.copy()
        if start is None or rest:
            c0, d0 = np.zeros(m), np.zeros_like(base)
            jac = self.response.copy()
        else:
            c0, d0 = self._c0, self._d0
            jac = (self.response if self._jac is None else self._jac).copy()
        total_it, conv = 0, False
        for rnd in range(int(refine) + 1):
            if rnd > 0:
                if np.abs(c - c0).max() < 1e-6:
                    break  # the tissue is already relaxed at the estimate
                # through the tissue: relax at the estimate, Broyden-correct the response
                d_new = self._relax(c)
                dc = c - c0
                dd = float(dc @ dc)
                if dd > 1e-10:
                    miss = (d_new - d0) - _linear(jac, dc)
                    jac += np.multiply.outer(miss, dc / dd)
                c0, d0 = c.copy(), d_new
                self._c0, self._d0, self._jac = c0, d0, None
            pose, c, it, conv = self._gauss_newton(p, pose, c, c0, d0, jac, base, prev)
            total_it += it
        shape = base + d0 + _linear(jac, c - c0)
        k = self._pixel_mm(pose)
        uv = self.camera.project(pose.apply(shape))
        resid = float(np.sqrt(((uv - p[:, :2]) ** 2).sum(1).mean()) * k)
        return FrameFit(c, pose, resid, total_it, conv)

    def _prior_rows(self, pose, c, prev, free):
        """Prior rows (A, b) in the step (omega, dt, dc[free]) and the L1 gradient."""
        s = self.settings
        nf = len(free)
        rows_a, rows_b = [], []
        dt = 1.0 / self.fps
        if prev is not None:
            sig_r = np.radians(s.rotation_rate_deg_per_s) * dt
            sig_t = s.translation_rate_mm_per_s * dt
            rv = rotvec(pose.rotation @ prev.pose.rotation.T)
            a = np.zeros((6, 6 + nf))
            a[:3, :3] = np.eye(3) / sig_r
            a[3:, 3:6] = np.eye(3) / sig_t
            rows_a.append(a)
            rows_b.append(
                np.concatenate(
                    [-rv / sig_r, -(pose.translation_mm - prev.pose.translation_mm) / sig_t]
                )
            )
            if nf:
                sig_c = s.rate_per_s * dt
                a = np.zeros((nf, 6 + nf))
                a[:, 6:] = np.eye(nf) / sig_c
                rows_a.append(a)
                rows_b.append(-(c[free] - prev.contractions[free]) / sig_c)
        if nf:
            a = np.zeros((nf, 6 + nf))
            a[:, 6:] = np.eye(nf) / s.magnitude_sigma
            rows_a.append(a)
            rows_b.append(-c[free] / s.magnitude_sigma)
        g = np.zeros(6 + nf)
        g[6:] = s.sparsity
        if not rows_a:
            return np.zeros((0, 6 + nf)), np.zeros(0), g
        return np.vstack(rows_a), np.concatenate(rows_b), g

    def _cost(self, p, pose, c, shape, w, k, prev, free):
        """The objective: Huber loss of the weighted landmark residuals + the priors (the
        reference; the fit evaluates the same with :meth:`_fast_cost`)."""
        rxy, rz, dist, _ = self._residuals(p, pose, shape, w, k)
        h = self.settings.huber
        # Huber's loss of the 2-D distance (r^2 inside, 2 h r - h^2 beyond); z takes its weight
        rho = np.where(dist <= h, dist**2, 2 * h * dist - h * h)
        cost = float((w * rho).sum() + (w * self._huber(dist) * rz**2).sum())
        _, b, g = self._prior_rows(pose, c, prev, free)
        return cost + float((b**2).sum()) + float(g[6:] @ c[free])

    def _kernel_args(self, p, pose, shape, w, k):
        """The arguments the compiled kernels (:mod:`myoface.analysis._fitkernels`) share."""
        s, cam = self.settings, self.camera
        use_z = bool(np.isfinite(p[:, 2]).all())
        return (
            np.ascontiguousarray(pose.rotation),
            np.ascontiguousarray(pose.translation_mm, dtype=np.float64),
            shape,
            float(cam.focal_px),
            float(cam.cx),
            float(cam.cy),
            p,
            use_z,
            w,
            k / s.landmark_sigma_mm,
            1.0 / s.depth_sigma_mm,
            k,
            float(s.huber),
        )

    def _fast_cost(self, p, pose, c, shape, w, k, prev, free):
        """:meth:`_cost`, its landmark part compiled and its prior part without the rows."""
        from myoface.analysis._fitkernels import landmark_cost

        cost = landmark_cost(*self._kernel_args(p, pose, shape, w, k))
        return cost + self._prior_cost(pose, c, prev, free)

    def _prior_cost(self, pose, c, prev, free) -> float:
        """``|b|^2 + g . c[free]`` of :meth:`_prior_rows` without forming its rows."""
        s = self.settings
        cost = 0.0
        if prev is not None:
            dt = 1.0 / self.fps
            sig_r = np.radians(s.rotation_rate_deg_per_s) * dt
            sig_t = s.translation_rate_mm_per_s * dt
            rv = rotvec(pose.rotation @ prev.pose.rotation.T)
            dtr = pose.translation_mm - prev.pose.translation_mm
            cost += float(rv @ rv) / sig_r**2 + float(dtr @ dtr) / sig_t**2
            if len(free):
                dc = c[free] - prev.contractions[free]
                cost += float(dc @ dc) / (s.rate_per_s * dt) ** 2
        if len(free):
            cf = c[free]
            cost += float(cf @ cf) / s.magnitude_sigma**2 + s.sparsity * float(cf.sum())
        return cost

    def _huber(self, r):
        h = self.settings.huber
        return np.where(r > h, h / np.maximum(r, 1e-12), 1.0)

    def _gauss_newton(self, p, pose, c, c0, d0, jac, base, prev, free=None):
        """Bounded Gauss-Newton / Levenberg-Marquardt on one frame from ``pose``, ``c`` with
        the forward model ``base + d0 + jac (c - c0)``; only the contractions ``free`` move.
        Returns (pose, contractions, steps, converged)."""
        from myoface.analysis._fitkernels import box_qp, normal_equations

        s = self.settings
        free = np.arange(self.n_muscles) if free is None else np.asarray(free, dtype=np.int64)
        jac = np.ascontiguousarray(jac)
        c = c.copy()
        lam = 1e-3
        conv = False
        it = 0
        shape = base + d0 + _linear(jac, c - c0)
        w0 = self._weights(pose, shape)  # (visibility from the frame's starting pose)
        while it < s.iterations:
            it += 1
            shape = base + d0 + _linear(jac, c - c0)
            k = self._pixel_mm(pose)
            # the normal equations of the Huber-reweighted landmark rows (what
            # _residuals and _jacobians define), accumulated vertex by vertex, compiled
            ka = self._kernel_args(p, pose, shape, w0, k)
            h_lm, b_lm = normal_equations(*ka[:3], jac, free, *ka[3:])
            a_p, b_p, g = self._prior_rows(pose, c, prev, free)
            hess = h_lm + a_p.T @ a_p
            rhs = b_lm + a_p.T @ b_p - 0.5 * g
            cost0 = self._fast_cost(p, pose, c, shape, w0, k, prev, free)
            lo = np.concatenate([np.full(6, -np.inf), -c[free]])
            hi = np.concatenate([np.full(6, np.inf), 1.0 - c[free]])
            dg = np.maximum(np.diag(hess), 1e-12)
            for _ in range(6):
                # Levenberg: damp each unknown in proportion to its curvature; the bounded
                # step by the active-set method (the reference: _bounded_normal's BVLS)
                step = box_qp(hess + np.diag(lam * dg), rhs, lo, hi)
                new_pose = HeadPose(
                    rotmat(step[:3]) @ pose.rotation, pose.translation_mm + step[3:6]
                )
                new_c = c.copy()
                new_c[free] = np.clip(c[free] + step[6:], 0.0, 1.0)
                new_shape = base + d0 + _linear(jac, new_c - c0)
                cost1 = self._fast_cost(p, new_pose, new_c, new_shape, w0, k, prev, free)
                if cost1 <= cost0 + 1e-9 * abs(cost0):
                    lam = max(lam / 10, 1e-7)
                    break
                lam *= 10
            else:
                conv = True  # no step lowers the cost: at a minimum (to rounding)
                break
            pose, c = new_pose, new_c
            small = (
                np.abs(step[:3]).max() < STEP_TOL_RAD
                and np.abs(step[3:6]).max() < STEP_TOL_MM
                and (len(free) == 0 or np.abs(step[6:]).max() < STEP_TOL_CONTRACTION)
            )
            if small:
                conv = True
                break
        return pose, c, it, conv

    def _fit_identity(self, frames):
        """The poses and a smooth identity offset (V, 3) shared by the landmark ``frames``, every
        contraction at zero; then what the offset left of the frames' mean residual (in the
        image plane) is added to it, so that the neutral reproduces the calibration frames."""
        s = self.settings
        nv = len(self.neutral)
        ident = np.zeros_like(self.neutral)
        poses = [initial_pose(self.neutral, p, self.camera) for p in frames]
        lap = _laplacian(self.model.face)
        reg = sparse.kron(
            lap / s.identity_edge_sigma_mm**2 + sparse.eye(nv) / s.identity_sigma_mm**2,
            sparse.eye(3),
        ).tocsr()
        for _ in range(IDENTITY_ROUNDS):
            base = self.neutral + ident
            poses = [self._pose_only(p, q, base) for p, q in zip(frames, poses, strict=True)]
            # the offset, poses fixed: a sparse linear least-squares problem (Gauss-Newton)
            for _ in range(2):
                base = self.neutral + ident
                blocks, g = np.zeros((nv, 3, 3)), -(reg @ ident.ravel())
                for p, pose in zip(frames, poses, strict=True):
                    k = self._pixel_mm(pose)
                    w0 = self._weights(pose, base)
                    rxy, rz, dist, use_z = self._residuals(p, pose, base, w0, k)
                    w = w0 * self._huber(dist)
                    hb, rhs = self._offset_blocks(pose, base, k, w, rxy, rz, use_z)
                    blocks += hb
                    g = g + rhs
                diag = sparse.bsr_matrix(
                    (blocks, np.arange(nv), np.arange(nv + 1)), shape=(3 * nv, 3 * nv)
                )
                h = (reg + diag).tocsc()
                ident = ident + spsolve(h, g).reshape(-1, 3)
        # the residual left in the image plane: into the offset, perpendicular to the view
        base = self.neutral + ident
        rest = np.zeros_like(ident)
        for p, pose in zip(frames, poses, strict=True):
            pc = pose.apply(base)
            d = -pc[:, 2] / self.camera.focal_px
            du = p[:, :2] - self.camera.project(pc)
            rest += np.column_stack([du[:, 0] * d, -du[:, 1] * d, np.zeros(nv)]) @ pose.rotation
        ident = ident + rest / len(frames)
        ident, poses = self._gauge(ident, poses)
        base = self.neutral + ident
        poses = [self._pose_only(p, q, base) for p, q in zip(frames, poses, strict=True)]
        resid = []
        for p, pose in zip(frames, poses, strict=True):
            uv = self.camera.project(pose.apply(base))
            resid.append(np.sqrt(((uv - p[:, :2]) ** 2).sum(1).mean()) * self._pixel_mm(pose))
        return ident, poses, float(np.mean(resid))

    def _gauge(self, ident, poses):
        """The identity offset with no rigid motion in it: the rotation and translation that
        best map the person's neutral onto the model's (least squares over
        :func:`gauge_vertices`, which no muscle moves) moved from the offset into the poses.
        The points the camera sees are unchanged; the head frame is then the one in which
        the person's rigid points sit where the model's do, rather than wherever the
        offset's regularisation left it. On the head-motion closed loop (2026-12-01) it took
        the head angles' RMS error from 1.80 to 1.28 degrees with the head still and from
        2.99 to 2.79 with it moving (analysis.fidelity 0.870, was 0.872)."""
        from myoface.face.personal import fit_similarity_3d

        idx = gauge_vertices(self.model)
        base = self.neutral + ident
        _, rot, t = fit_similarity_3d(base[idx], self.neutral[idx], scale=False)  # base -> neutral
        new_base = base @ rot.T + t
        out = []
        for q in poses:  # P = R_q base + t_q = (R_q rot^T) new_base + (t_q - R_q rot^T t)
            r2 = q.rotation @ rot.T
            out.append(HeadPose(r2, q.translation_mm - r2 @ t))
        return new_base - self.neutral, out

    def _pose_only(self, p, pose, base):
        jac0 = np.zeros((len(base), 3, self.n_muscles))
        zeros = np.zeros(self.n_muscles)
        pose, _, _, _ = self._gauss_newton(
            p, pose, zeros, zeros, np.zeros_like(base), jac0, base, None,
            free=np.zeros(0, dtype=np.int64),
        )  # fmt: skip
        return pose

    def _offset_blocks(self, pose, shape, k, w, rxy, rz, use_z):
        """Per vertex, the 3x3 normal-equation block (V, 3, 3) and right-hand side (3 V,) of
        the weighted landmark residuals with respect to its offset (head frame)."""
        s = self.settings
        f = self.camera.focal_px
        pc = pose.apply(shape)
        d = np.maximum(-pc[:, 2], 1e-6)
        dproj = np.zeros((len(pc), 2, 3))
        dproj[:, 0, 0] = f / d
        dproj[:, 0, 2] = f * pc[:, 0] / d**2
        dproj[:, 1, 1] = -f / d
        dproj[:, 1, 2] = -f * pc[:, 1] / d**2
        jxy = np.einsum("vij,jk->vik", dproj, pose.rotation) * (k / s.landmark_sigma_mm)
        h = np.einsum("vji,vjk->vik", jxy, jxy) * w[:, None, None]
        g = -np.einsum("vji,vj->vi", jxy, rxy) * w[:, None]
        if use_z:
            # (the mean removal couples the points weakly; it is left out of the Jacobian)
            jz = -pose.rotation[2] / s.depth_sigma_mm
            h += w[:, None, None] * np.outer(jz, jz)[None]
            g -= (w * rz)[:, None] * jz[None]
        return h, g.ravel()


def _linear(jac: np.ndarray, dc: np.ndarray) -> np.ndarray:
    """``jac @ dc`` (V, 3) for a response ``jac`` (V, 3, M) and contractions ``dc`` (M,), as
    one matrix-vector product (numpy's stacked matmul of (V, 3, M) by (M,) loops over V)."""
    m = jac.shape[2]
    return (np.ascontiguousarray(jac).reshape(-1, m) @ dc).reshape(-1, 3)


def _bounded_normal(hess, rhs, lo, hi):
    """``argmin x^T hess x / 2 - rhs . x`` (times 2: ``|r x - r^-T rhs|^2``, ``hess = r^T r``)
    with ``lo <= x <= hi``: a bounded least-squares problem on the Cholesky factor."""
    from scipy.linalg import cho_factor, solve_triangular

    r, _ = cho_factor(hess, lower=False)
    r = np.triu(r)
    y = solve_triangular(r, rhs, trans="T")
    return lsq_linear(r, y, bounds=(lo, hi), method="bvls").x


def rotvec(rot: np.ndarray) -> np.ndarray:
    """The rotation vector (3,) rad of a rotation matrix (the logarithm map)."""
    cos = np.clip((np.trace(rot) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(cos)
    axis = np.array([rot[2, 1] - rot[1, 2], rot[0, 2] - rot[2, 0], rot[1, 0] - rot[0, 1]])
    if angle < 1e-6:
        return 0.5 * axis
    if angle > np.pi - 1e-6:
        return Rotation.from_matrix(rot).as_rotvec()
    return axis * (angle / (2.0 * np.sin(angle)))


def rotmat(v: np.ndarray) -> np.ndarray:
    """The rotation matrix of a rotation vector (Rodrigues' formula)."""
    angle = float(np.linalg.norm(v))
    k = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    if angle < 1e-9:
        return np.eye(3) + k
    k /= angle
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


# ------------------------------------------------------------------ analysis by synthesis


class LandmarkSynthesis:
    """The tracker's own error, measured on the model: the person's face rendered at the fit's
    estimate (head pose and skin) by the fit's camera, and MediaPipe run on the render; what it
    reports there less where the model's vertices are is its error at that configuration
    (MediaPipe under-reads expressions and turns of the head), taken off the real frame's
    landmarks (:meth:`ModelFit.fit`). At the truth the correction is exact up to how well the
    render looks like the frame; the fit then converges to where the tracker sees the model as
    it sees the video.

    Parameters
    ----------
    face : FaceMesh with the person's texture (e.g. ``face from-photo``'s, or
        :meth:`from_frame`), in the default topology.
    camera : PinholeCamera of the frames, principal point at the image's centre.
    size : (width, height) of the frames, pixels.
    detector : as for :class:`FitAnalyzer` (default: MediaPipe's face mesh, in the mode
        ``tracking`` says: the synthetic frames are observed like the real ones).
    tracking : :attr:`FitSettings.tracking` of the fit.
    """

    def __init__(self, face, camera: PinholeCamera, size, detector=None, tracking=False):
        from myoface.render import Camera, Renderer

        w, h = (int(v) for v in size)
        if abs(camera.cx - 0.5 * w) > 1 or abs(camera.cy - 0.5 * h) > 1:
            raise MyofaceValueError("synthesis needs the principal point at the image's centre")
        fov = float(np.degrees(2 * np.arctan(0.5 * h / camera.focal_px)))
        cam = Camera(np.zeros(3), np.array([0.0, 0.0, -1.0]), width=w, height=h, fov_deg=fov)
        self.camera = camera
        self.renderer = Renderer(face, cam)
        self._own_detector = detector is None
        if detector is None:
            from myoface.analysis.landmarks import FaceMeshDetector

            detector = FaceMeshDetector(video=tracking)
        self.detector = detector

    @classmethod
    def from_frame(cls, face, camera: PinholeCamera, frame, shape, pose: HeadPose, **kw):
        """With ``frame`` (H, W, 3) as the texture: each vertex of ``shape`` (V, 3) mm, head
        frame, where ``pose`` puts it in the frame (for a face without a texture of the
        person, e.g. the default face: the calibration frame, shading and all)."""
        from myoface.face import FaceMesh

        img = np.asarray(frame)
        h, w = img.shape[:2]
        uv = camera.project(pose.apply(shape))
        uv = np.column_stack([uv[:, 0] / w, 1.0 - uv[:, 1] / h])
        textured = FaceMesh(face.vertices, face.triangles, uv, img, face.landmarks, name=face.name)
        return cls(textured, camera, (w, h), **kw)

    def tracker_error(self, skin: np.ndarray, pose: HeadPose) -> np.ndarray | None:
        """(V, 3): the tracker's points on the model rendered with ``skin`` (V, 3) mm, head
        frame, at ``pose``, less the model's own (x, y pixels; z relative depth, pixels, up to
        a constant); None when the tracker finds no face in the render."""
        img = self.renderer.render(skin, pose=(pose.rotation, pose.translation_mm))
        q = self.detector.detect(img)
        if q is None:
            return None
        pc = pose.apply(skin)
        uv = self.camera.project(pc)
        z = -pc[:, 2] * self.camera.focal_px / max(-pose.translation_mm[2], 1.0)
        err = np.column_stack([q[:, :2] - uv, q[:, 2] - z])
        err[:, 2] -= err[:, 2].mean()
        return err

    def close(self) -> None:
        self.detector.close()


# ------------------------------------------------------------------ the landmark tracker's analyzer

#: how the landmark tracker's contractions are estimated: the 3-D fit (default), the 3-D fit
#: with analysis by synthesis (:class:`LandmarkSynthesis`), or the paper's 2-D head frame and
#: 12 muscles (:class:`~myoface.analysis.landmarks.LandmarkAnalyzer`)
LANDMARK_ESTIMATORS = ("fit", "fit-synthesis", "paper")
#: a frame whose landmarks stay farther than this (mm RMS) from the fitted model is not
#: measured (``quality="misfit"``): MediaPipe lost the face, or the face is not the model's
MISFIT_RMS_MM = 6.0


@dataclass
class FitMeasurement:
    """One frame of the 3-D fit, in the shape of
    :class:`~myoface.analysis.pipeline.FrameMeasurement` (index, time, quality, contractions
    over the analyzer's ids, contours for the overlay) plus the head ``pose`` and the fit's
    ``residual_mm``; :meth:`head_cells` gives its CSV columns (:data:`HEAD_COLUMNS`)."""

    index: int
    time_s: float
    quality: str
    contractions: np.ndarray
    pose: HeadPose | None
    residual_mm: float
    contours: dict = field(repr=False, default_factory=dict)
    iterations: int = 0

    #: the CSV's columns after the muscles and the jaw angle
    HEAD_COLUMNS = (*POSE_COLUMNS, "residual_mm")

    @property
    def head_shift_px(self) -> np.ndarray:  # (the 2-D head frame's fields: not measured)
        return np.full(2, np.nan)

    head_scale = float("nan")
    head_rot_rad = float("nan")

    def head_cells(self) -> list[str]:
        """The values of :data:`HEAD_COLUMNS` as CSV cells (empty when not measured)."""
        if self.pose is None:
            return [""] * len(self.HEAD_COLUMNS)
        vals = [*self.pose.columns().values(), self.residual_mm]
        return ["" if not np.isfinite(v) else f"{v:.3f}" for v in vals]


#: ``FitAnalyzer.measure``'s default: the frame is observed (its landmarks detected) there
_NOT_OBSERVED = object()


class FitAnalyzer:
    """The landmark tracker with the 3-D fit: MediaPipe's face mesh on every frame (detection
    on each, or tracking with :attr:`FitSettings.tracking`), :class:`ModelFit` on its points.
    ``measure(frame, index, time_s)`` returns a :class:`FitMeasurement`; frames without a face
    are ``quality="no_face"`` (the next face starts the fit afresh).

    Parameters
    ----------
    model : FaceModel in the default topology (never changed).
    fps : the video's frame rate.
    camera : PinholeCamera, or None: a vertical field of view of :data:`DEFAULT_FOV_DEG` on the
        first frame's size.
    settings : FitSettings.
    detector : an object with ``detect(frame) -> (468, 3) | None`` and ``close()`` (default:
        MediaPipe's face mesh, in the mode :attr:`FitSettings.tracking` says).
    synthesis : analysis by synthesis (:class:`LandmarkSynthesis`, made at calibration): the
        face model's own texture if it has one (e.g. ``face from-photo``), else the
        calibration frame.
    deferred_relax : relax the tissue at a frame's estimate on a second thread while the
        next frame is fitted, once its skin has moved :attr:`FitSettings.relax_step_mm` since
        the last relax (:meth:`ModelFit.fit` ``deferred=True``; what a video analysis does,
        :func:`make_fit_analyzer`), instead of a second fitting round through it.

    :func:`~myoface.analysis.pipeline.measure_frames` runs :meth:`observe` (MediaPipe) on a
    worker thread ahead of :meth:`measure` (the fit), and takes the frames the calibration
    decoded from :meth:`replay`.
    """

    tracker = "landmarks"
    method = "fit"

    def __init__(self, model, fps: float = 30.0, camera: PinholeCamera | None = None,
                 settings: FitSettings | None = None, detector=None,
                 synthesis: bool = False, deferred_relax: bool = False):  # fmt: skip
        from myoface.analysis.sections import SECTIONS, section_vertices

        if model.face.n_vertices != 468:
            raise MyofaceValueError(
                "the landmark tracker needs a face model with MediaPipe's 468-point topology "
                f"(the default face); this one has {model.face.n_vertices} vertices"
            )
        self.model = model
        self.ids = tuple(model.ids)
        self.settings = settings or FitSettings()
        self.refine = self.settings.refine
        self.fps = float(fps)
        self._camera = camera
        self.fit: ModelFit | None = None
        self._sections = {s: section_vertices(model.face, s) for s in SECTIONS}
        self._own_detector = detector is None
        if detector is None:
            from myoface.analysis.landmarks import _import_mediapipe

            _import_mediapipe()  # (fails now, with the pip command, if it is not installed)
        #: the detector; made when first needed (the calibration hands its own over)
        self._detector = detector
        #: {frame index: landmarks or None} of the calibration frames, taken by measure()
        self._detected: dict = {}
        #: relax the tissue on a second thread while the next frame is fitted
        #: (:meth:`ModelFit.fit`'s ``deferred``; the tissue then lags the estimate)
        self.deferred_relax = bool(deferred_relax)
        self.calibration: Calibration | None = None
        self.calibration_frame: int | None = None
        self.use_synthesis = bool(synthesis)
        self.synthesis: LandmarkSynthesis | None = None
        #: where the time goes (for the benchmark's breakdown): the calibration's wall time
        #: (s; its MediaPipe, scores and identity fit), and the detector's wall time (s) and
        #: count on the frames after it (on the thread that runs :meth:`observe`)
        self.timings = {"calibration_s": 0.0, "detections": 0, "detect_s": 0.0}
        #: the calibration's decoded frames and the rest of its decode (:meth:`replay`)
        self._replay = None
        #: the frames the calibration took (:meth:`calibrate`)
        self.calibration_images: list = []

    @property
    def detector(self):
        """The landmark detector (MediaPipe's face mesh unless one was given)."""
        if self._detector is None:
            self._detector = self._new_detector()
        return self._detector

    def _new_detector(self):
        """MediaPipe's face mesh in the mode :attr:`FitSettings.tracking` says, its points
        refined by optical flow (:class:`~myoface.analysis.flow.FlowDetector`) when
        :attr:`FitSettings.flow`."""
        from myoface.analysis.landmarks import FaceMeshDetector

        det = FaceMeshDetector(video=self.settings.tracking)
        if self.settings.flow:
            from myoface.analysis.flow import FlowDetector

            return FlowDetector(det)
        return det

    @property
    def mm_per_px(self) -> float | None:
        """mm on the face per pixel at the calibration frame's head distance."""
        if self.calibration is None or self.fit is None:
            return None
        return self.fit._pixel_mm(self.calibration.pose)

    def _ensure_fit(self, shape) -> ModelFit:
        if self.fit is None:
            h, w = shape[:2]
            cam = self._camera or PinholeCamera.for_image(w, h)
            self.fit = ModelFit(self.model, cam, self.settings, fps=self.fps)
        return self.fit

    def calibrate(self, frames, calibration_frame: int | None = None, first_index: int = 0,
                  window: int | None = None):  # fmt: skip
        """Calibrate on ``frames`` (an iterable of RGB frames, or None for a frame without a
        face: the first :data:`CALIBRATION_WINDOW_S` s of the video, from its frame
        ``first_index``): the most neutral one, or the frame ``calibration_frame`` (an index
        into the video). Runs MediaPipe as the analysis does (:attr:`FitSettings.tracking`:
        its two modes place the points a little differently); with the analyzer's
        own detector, the analysis then goes on with this one and takes these frames' points
        from the calibration instead of detecting them again (it starts on the first of
        them). ``window``: ``frames`` are the video's frames from ``first_index`` on, of
        which those up to ``window`` frames after the first with a face are taken (none
        after them: an iterator can go on from there); an error when no frame has a face.
        Returns the calibration frame's index in the video; :attr:`calibration_images` are
        the frames taken (None for those before the first face)."""
        import itertools
        import time

        from myoface.analysis.landmarks import detect_ahead

        t_start = time.perf_counter()
        # the frames up to the first there is (its size makes the fit's camera); the rest are
        # taken as they come (``frames`` may be decoding meanwhile), on the detector's thread
        frames = iter(frames)
        head: list = []
        for frame in frames:
            head.append(frame)
            if frame is not None:
                break
        if not head or head[-1] is None:
            _close(frames)
            raise MyofaceValueError("the video has no frames to calibrate on")
        self._ensure_fit(np.shape(head[-1]))
        images: list = []
        points: list = []
        first_face: list = []  # the index of the first frame with a face, once there is one
        det = self._new_detector()
        end = object()

        def source():
            # (runs on the detector's thread, which detects each frame before taking the next)
            it = itertools.chain(head, frames)
            k = 0
            while window is None or not first_face or k - first_face[0] < window:
                frame = next(it, end)
                if frame is end:
                    break
                images.append(frame)
                yield k, frame
                k += 1
            if window is not None and not first_face:
                raise MyofaceValueError(
                    f"no face found in the {k} frames of the video (MediaPipe face mesh)"
                )

        def detect(item):
            k, frame = item
            pts = None if frame is None else det.detect(frame)  # (None: no face)
            if pts is not None and not first_face:
                first_face.append(k)
            if pts is None and not first_face and window is not None:
                images[k] = None  # (not kept: the search for a face may be long)
            return pts

        def detected():
            # MediaPipe on a worker thread a few frames ahead while each frame is scored
            # (ModelFit.calibrate takes the points as they come)
            for _, pts in detect_ahead(source(), detect):
                points.append(pts)
                yield pts

        stream = detected()
        try:
            if calibration_frame is None:
                self.calibration = self.fit.calibrate(stream, None)
            else:
                for _ in stream:
                    pass
        except BaseException:
            stream.close()  # (stops the detector's thread before the detector closes)
            det.close()
            raise
        # the analysis goes on with this detector, and takes the calibration frames' points
        # from it rather than detecting them twice: the same points a detector tracking from
        # the first of these frames gives (the analysis starts there)
        if self._own_detector:
            if self._detector is not None:
                self._detector.close()
            self._detector = det
            self._detected = {first_index + k: pts for k, pts in enumerate(points)}
        else:
            det.close()
        if calibration_frame is not None:
            idx = int(calibration_frame) - first_index
            if not 0 <= idx < len(points):
                raise MyofaceValueError(
                    f"calibration frame {calibration_frame} is outside the frames given"
                )
            if points[idx] is None:
                raise MyofaceValueError(f"no face found on calibration frame {calibration_frame}")
            self.calibration = self.fit.calibrate(points, idx)
        if self.use_synthesis:
            cal = self.calibration
            fit = self.fit
            frame = images[cal.index]
            size = (np.shape(frame)[1], np.shape(frame)[0])
            if self.model.face.texture is not None:
                self.synthesis = LandmarkSynthesis(
                    self.model.face, fit.camera, size, tracking=self.settings.tracking
                )
            else:
                shape = fit.neutral + fit.identity_mm
                self.synthesis = LandmarkSynthesis.from_frame(
                    self.model.face, fit.camera, frame, shape, cal.pose,
                    tracking=self.settings.tracking,
                )  # fmt: skip
            self.calibration = fit.calibrate(points, cal.index, synthesis=self.synthesis)
            self.calibration.scores = cal.scores
        self.calibration_frame = first_index + self.calibration.index
        self.calibration_images = images
        self.timings["calibration_s"] += time.perf_counter() - t_start
        return self.calibration_frame

    def observe(self, frame, index: int = 0):
        """The frame's landmarks (468, 3) or None without a face: the calibration's (frames
        it detected), else detected. Called once per frame, in order; may run on another
        thread than :meth:`measure` (:func:`~myoface.analysis.pipeline.measure_frames`
        runs it ahead), which takes its result as ``observation``."""
        if index in self._detected:
            return self._detected.pop(index)
        import time

        self._detected.clear()  # (past the calibration frames: the detector tracks from here)
        t0 = time.perf_counter()
        pts = self.detector.detect(frame)
        self.timings["detections"] += 1
        self.timings["detect_s"] += time.perf_counter() - t0
        return pts

    def measure(self, frame, index: int = 0, time_s: float = 0.0,
                observation=_NOT_OBSERVED) -> FitMeasurement:  # fmt: skip
        """The frame's measurement; ``observation``: its :meth:`observe` (default: observed
        here)."""
        fit = self._ensure_fit(np.shape(frame))
        pts = self.observe(frame, index) if observation is _NOT_OBSERVED else observation
        nan = np.full(len(self.ids), np.nan)
        if pts is None:
            fit.lose_track()
            return FitMeasurement(index, time_s, "no_face", nan, None, float("nan"))
        try:
            r = fit.fit(pts, self.synthesis, deferred=self.deferred_relax)
        except (np.linalg.LinAlgError, MyofaceValueError):
            fit.lose_track()
            return FitMeasurement(index, time_s, "fit_failed", nan, None, float("nan"))
        uv = fit.camera.project(r.pose.apply(fit.shape(r.contractions)))
        contours = {s: uv[v] for s, v in self._sections.items()}
        if not r.residual_mm <= MISFIT_RMS_MM:
            fit.lose_track()
            return FitMeasurement(
                index, time_s, "misfit", nan, r.pose, r.residual_mm, contours, r.iterations
            )
        return FitMeasurement(
            index, time_s, "ok", r.contractions, r.pose, r.residual_mm, contours, r.iterations
        )

    def describe(self) -> dict:
        """For analysis.json: the estimator, the calibration, the camera and the weights."""
        from dataclasses import asdict

        out = {
            "estimator": "fit-synthesis" if self.use_synthesis else "fit",
            "fit_settings": asdict(self.settings),
        }
        refiner = getattr(self._detector, "refiner", None)
        if refiner is not None:
            # the optical flow's points (FitSettings.flow): tracked from the first frame,
            # from the previous frame, or left at MediaPipe's
            out["optical_flow_points"] = dict(refiner.stats)
        if self.fit is not None:
            cam = self.fit.camera
            out["camera"] = {"focal_px": cam.focal_px, "cx": cam.cx, "cy": cam.cy}
            out["unconverged_relaxes"] = self.fit.unconverged_relaxes
        if self.calibration is not None:
            cal = self.calibration
            out["calibration_frame"] = self.calibration_frame
            out["calibration"] = {
                "scores_mm": [
                    None if not np.isfinite(v) else round(float(v), 4) for v in cal.scores
                ],  # fmt: skip
                "frames_used": [
                    self.calibration_frame - cal.index + k for k in cal.extra["frames"]
                ],
                "identity_rms_mm": float(np.sqrt((cal.identity_mm**2).sum(1).mean())),
                "residual_mm": cal.residual_mm,
                "lid_gains": cal.extra.get("lid_gains", {}),
                "pose": cal.pose.columns(),
            }
        return out

    def _keep_for_replay(self, video, first: int, frames: list, rest) -> None:
        """Keep the calibration's decoded ``frames`` (``video``'s from ``first`` on) and the
        iterator ``rest`` of the frames after them, for :meth:`replay` (a frame before the
        first face was not kept: then the frames are decoded again)."""
        self._drop_replay()
        if any(f is None for f in frames):
            _close(rest)
            return
        self._replay = (video, int(first), collections.deque(frames), rest)

    def _drop_replay(self) -> None:
        r, self._replay = self._replay, None
        if r is not None:
            _close(r[3])

    def replay(self, video, start: int):
        """``(index, frame)`` for ``video``'s frames from ``start`` on without decoding the
        calibration's frames again (kept from its pass) and going on with its decode; None
        when there is nothing to replay for that video and start (then the caller decodes).
        Once: the kept frames are handed over (and released as they are taken)."""
        r, self._replay = self._replay, None
        if r is None:
            return None
        kept_video, first, frames, rest = r
        if kept_video is not video or first != int(start):
            _close(rest)
            return None

        def frames_from():
            try:
                k = first
                while frames:
                    yield k, frames.popleft()
                    k += 1
                for frame in rest:
                    yield k, frame
                    k += 1
            finally:
                frames.clear()
                _close(rest)

        return frames_from()

    def close(self) -> None:
        self._drop_replay()
        if self.fit is not None:
            self.fit.close()
        if self._detector is not None:
            self._detector.close()
        if self.synthesis is not None:
            self.synthesis.close()


def _close(iterator) -> None:
    """Close ``iterator`` if it is a generator (stops a decoder's thread)."""
    close = getattr(iterator, "close", None)
    if close is not None:
        close()


def make_fit_analyzer(model, video, calibration_frame: int | None = None, refine=None,
                      settings: FitSettings | None = None, synthesis: bool = False):  # fmt: skip
    """The :class:`FitAnalyzer` for ``video`` (a :class:`~myoface.analysis.video.Video`),
    calibrated, how (text), and the frame the analysis starts on.

    ``calibration_frame=None``: the most neutral frame of the first
    :data:`CALIBRATION_WINDOW_S` s from the first frame with a face, and the analysis starts
    at frame 0; a number: that frame, where the analysis then starts. ``refine``: relaxes of
    the tissue per frame (default :attr:`FitSettings.refine`). ``synthesis``: analysis by
    synthesis (see :class:`FitAnalyzer`).
    """
    import itertools

    settings = settings or FitSettings()
    if refine is not None:
        settings = replace(settings, refine=int(refine))
    fps = float(video.fps) if video.fps and video.fps > 0 else 30.0
    an = FitAnalyzer(model, fps=fps, settings=settings, synthesis=synthesis, deferred_relax=True)
    what = "the 3-D fit" + (" with analysis by synthesis" if synthesis else "")
    try:
        if calibration_frame is None:
            first, window = 0, max(1, int(round(CALIBRATION_WINDOW_S * fps)))
            live = iter(video)
            try:
                # decoded, searched for the first face and detected as the calibration takes
                # them, MediaPipe from the first frame
                cal = an.calibrate(live, window=window)
            except BaseException:
                _close(live)
                raise
            # the analysis takes these decoded frames again, then goes on decoding from
            # where the calibration stopped, instead of decoding them twice
            an._keep_for_replay(video, 0, an.calibration_images, live)
            an.calibration_images = []
            start = 0
            how = (
                f"MediaPipe face mesh on every frame, {what}; calibrated on frame {cal}, "
                f"the most neutral of the first {CALIBRATION_WINDOW_S:g} s"
            )
        else:
            first = int(calibration_frame)
            frames = list(itertools.islice(video, first, first + 1))
            if not frames:
                raise MyofaceValueError(f"the video has no frame {first}")
            cal = an.calibrate(frames, first, first_index=first)
            start = first
            how = f"MediaPipe face mesh on every frame, {what}; calibrated on frame {cal}"
    except BaseException:
        an.close()
        raise
    return an, how, start


def read_head_poses(path) -> list:
    """The head poses of a contractions CSV written with the 3-D fit (its
    :data:`POSE_COLUMNS`): one :class:`HeadPose` per row, None where the row has none (no face
    found)."""
    import csv
    from pathlib import Path

    from myoface._io import read_text
    from myoface.errors import MyofaceFormatError

    p = Path(path)
    rows = list(csv.DictReader(read_text(p, "contractions CSV").splitlines()))
    missing = [c for c in POSE_COLUMNS if not rows or c not in rows[0]]
    if missing:
        raise MyofaceFormatError(
            f"{p}: no head pose columns ({', '.join(missing)}); they are written by "
            "myoface analyze --tracker landmarks (the 3-D fit)"
        )
    out = []
    for k, r in enumerate(rows):
        cells = [(r.get(c) or "").strip() for c in POSE_COLUMNS]
        if not all(cells):
            out.append(None)
            continue
        try:
            vals = {c: float(v) for c, v in zip(POSE_COLUMNS, cells, strict=True)}
        except ValueError:
            raise MyofaceFormatError(
                f"{p}: row {k + 2}: a head pose cell is not a number"
            ) from None
        if not all(np.isfinite(v) for v in vals.values()):
            raise MyofaceFormatError(f"{p}: row {k + 2}: a head pose cell is not finite")
        out.append(HeadPose.from_columns(vals))
    return out


def display_poses(poses) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(rotation, translation mm)`` per row of ``poses`` (:func:`read_head_poses`) for
    :meth:`~myoface.render.Renderer.render`: the head's orientation as the camera saw it, and
    its translation from its median position (so that a renderer framing the face at rest
    keeps it in view while it moves as in the video); rows without a pose hold the last one."""
    known = [p for p in poses if p is not None]
    ref = np.median([p.translation_mm for p in known], axis=0) if known else np.zeros(3)
    out, last = [], (np.eye(3), np.zeros(3))
    for p in poses:
        if p is not None:
            last = (p.rotation, p.translation_mm - ref)
        out.append(last)
    return out
