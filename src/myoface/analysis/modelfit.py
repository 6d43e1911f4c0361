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
- the points themselves first lose the detector's own offsets on this face at the frame's
  view (:meth:`ModelFit.set_offsets`, :class:`~myoface.analysis.landmarks.TrackerOffsets`:
  the person's model rendered neutral from each view and read by MediaPipe), which otherwise
  tilt the head: given the true skin, MediaPipe's points put a still frontal head 4.5 deg
  off in pitch on the head-motion loop's renders;
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

The terms (landmarks and priors) are in :mod:`~myoface.analysis.terms`, the solver that sums
them in :mod:`~myoface.analysis.solver`, the camera and the pose's conventions in
:mod:`~myoface.analysis.camera`; the tracker that runs this fit on a video is
:class:`~myoface.analysis.trackers.landmark_fit.FitTracker`.
"""

from __future__ import annotations

import time
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
from scipy import sparse
from scipy.sparse.linalg import splu

from myoface.analysis._fitkernels import vertex_normals
from myoface.analysis.au_prior import au_prior_terms
from myoface.analysis.camera import (
    HeadPose,
    PinholeCamera,
    check_points,
    initial_pose,
    rotation_angle_deg,
    rotmat,
    rotvec,
)
from myoface.analysis.estimate import skin_response
from myoface.analysis.landmarks import view_angles
from myoface.analysis.photometric import (
    COLOURLESS_SD,
    Appearance,
    ChannelTerms,
    PhotometricTerm,
    coarse_start,
    eye_rim_weight,
)
from myoface.analysis.solver import bounded_gauss_newton
from myoface.analysis.synthesis import LandmarkSynthesis
from myoface.analysis.terms import (
    Estimate,
    LandmarkTerm,
    MagnitudePrior,
    OpticalFlowTerm,
    SparsityPrior,
    SymmetryPrior,
    TemporalPrior,
    mirror_pairs,
    patch_footprint,
    pixel_mm,
)
from myoface.analysis.weights import (
    FitSettings,
    gauge_vertices,
    landmark_weights,
    laplacian,
    lid_gains,
    model_error_weights,
    offset_spread_weights,
)
from myoface.errors import MyofaceValueError
from myoface.face.personal import fit_similarity_3d
from myoface.tissue import RelaxWarning

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
#: ... at most this many frames around it (within the margin too): their noise averages out.
#: More of them, from further away, would show the neutral face from more directions where the
#: head turns, which the person's depth needs (a wrong depth under a turn reads as expression:
#: on the expression benchmark's rest frames the AU6, AU10 and AU12 readings follow the head's
#: pitch, r^2 0.75-0.78). But the scores are against the model's neutral, not the person's:
#: on the expression clip's first rest (the head turning) they wander 2.4-4.1 mm and the
#: lowest fall in an expression's offset, so 30 frames let in frames 22 and 25 of the first
#: smile's onset (measured 2026-12-04, 5 / 15 / 30: the degraded head-motion renders, head
#: moving, the default fit's worst RMSE 0.287 / 0.313 / 0.273, skin 1.44 / 1.44 / 1.37 mm, head
#: 1.85 / 1.84 / 1.71 deg; the expression clip's apex 0.562 / 0.562 / 0.479, rest 0.672 /
#: 0.672 / 0.793). Scored again against the person's neutral of these 5 frames, the expression
#: clip's first rest scores 0.2-1.6 mm and its first smile 2.7-3.9; the frames within 0.5 mm of
#: the least, up to 30 within 29 of the calibration frame, then calibrating again, gave the
#: expression clip apex 0.562, rest 0.750, the head-motion renders head still median RMSE
#: 0.126 -> 0.115, head 1.46 -> 1.41 deg, head moving the same (within 1 mm of the least:
#: head moving 0.280 / 0.165 / 1.40 mm / 1.67 deg, but the apex 0.490). Not taken yet: the
#: second scoring and the larger identity fit cost ~0.45 s once (6 ms a frame of the
#: benchmark's 72-frame clip, which would take the analysis below 0.25x of MediaPipe).
#: (2026-12-06: 12 frames for the eyes' sake, whose place in the head the calibration's
#: neutral sets: the gaze benchmark's three clips 4.24 / 3.55 / 4.39 -> 3.06 / 4.24 / 6.64
#: deg, each eye's mean misplacement in the image moved by up to 1 px either way,
#: ``tools/gaze_replay.py``: not a noise that more frames average out.)
CALIBRATION_FRAMES = 5
#: the detector's context (:meth:`ModelFit.measure_detector_context`): the steps of each
#: calibration frame's pose, and how far each step goes (past the pose its points give:
#: MediaPipe reads a change of the render's pose short, so a plain step goes about half way
#: to where the render and the frame are read alike; measured 2026-12-06 on the still head's
#: degraded frames: plain steps took the pitch 2.77 -> 1.44 -> 1.40 -> 0.87 -> 1.03 deg where
#: the render at the true pose gives 0.81)
CONTEXT_STEPS = 4
CONTEXT_OVERRELAX = 1.8
#: with the detector's offsets (:meth:`ModelFit.set_offsets`): each frame's expression is
#: scored on its points corrected at its view, the points the calibration then fits. Scored
#: on the raw points (before 2026-12-02), a turned frame's offsets (MediaPipe's chin and
#: jaw sliding along the outline) read as expression, and the neutral was taken from other
#: frames and views. Measured (issue 30, 2026-12-02; the expression benchmark's 356-frame
#: synthetic clip, head moving, degraded renders, MediaPipe): calibration frame 0 -> 15; at
#: rest the chin raiser AU17 read 0.44 -> 0.17 (corr with |yaw| 0.74 -> 0.55), AU23 0.27 ->
#: 0.25; worst RMSE (12 muscles + jaw) 0.316 -> 0.283, skin 1.39 -> 1.30 mm, head 1.54 ->
#: 1.60 deg. The neutral fitted to the true-pose-corrected points picks the same frame
#: (AU17 0.18 at rest): what is left is the table's and MediaPipe's error, not the choice.
#: (Those at e2115bd's muscles; at da930c9's it chose frame 18 and, alone, took the clip's
#: apex accuracy 0.49 -> 0.43 and rest 0.78 -> 0.70: see FitSettings.offset_spread.)
#: **Off** by default: at the released muscles (b5a2c3f) it chose frame 15 and, with
#: FitSettings.offset_spread 0, the expression benchmark read apex 0.40 and rest 0.81 against
#: 0.56 and 0.79 off; lower on both measurements made of the expressions, so the raw points
#: score the neutral until a choice of it is found that does not cost the expressions.
SCORE_CORRECTED = False

#: Gauss-Newton steps of each calibration frame's score fit (:meth:`ModelFit.calibrate`; the
#: frames' own fits take :attr:`FitSettings.iterations`): each starts from the previous
#: frame's, and the score only ranks frames against :data:`NEUTRAL_MARGIN_MM`. On
#: single_face.mp4's first 60 frames (2026-12-03) 3 steps move the scores by at most 0.09 mm
#: from 8 (the margin is 1 mm; the same frame chosen) and cost 5.3 ms of CPU a frame against 7.1.
SCORE_ITERATIONS = 3

#: the photometric fit's appearance registered on the landmarks of many neutral frames
#: (:func:`registration_frames`, :meth:`ModelFit._appearance_offset`), not on the calibration
#: frame's alone: what those got wrong there, every frame's pose inherits. Why (2026-12-04):
#: on the gaze benchmark's clip the photometric fit put both eyeballs 1-1.5 px low on every
#: frame (SD 0.5-0.7 px), as the calibration frame's landmarks had them there (0.9-1.2 px);
#: with the appearance taken at the true registration of that frame (an oracle: the pose
#: moved so that the eyeballs' centres land on the truth's) the gaze read 7.03 -> 2.98 deg.
#: Registered on up to 12 neutral frames' landmarks (tests/analysis/test_photometric.py holds
#: the mechanism to a known answer: the error left is the frames' mean landmark error),
#: measured against the appearance of the calibration frame alone (``--photometric``; the
#: gaze benchmark's clip and four more, gaze and camera seeds (7, 3), (11, 5), (23, 9),
#: (31, 1)): gaze 7.03, 3.79, 3.66, 3.55, 7.68 -> 3.36, 5.72, 5.55, 3.44, 4.50 deg (mean
#: 5.14 -> 4.51, worst 7.68 -> 5.72, median 3.79 -> 4.50: one frame's error is a lottery,
#: the frames' mean is MediaPipe's own bias at the eyes, about 1 px, which this does not
#: remove); the expression clip apex 0.698 -> 0.708, rest 0.655 -> 0.707; the degraded
#: head-motion renders, head moving: worst RMSE 0.248 -> 0.267, median 0.146 -> 0.127, skin
#: 0.948 -> 0.916 mm, head 1.146 -> 1.162 deg, worst correlation 0.31 -> 0.44; head still
#: the same to 0.01 (worst 0.194 -> 0.186); the known warps the same to 0.002 (their frames
#: near the calibration frame are the same frame); single_face.mp4's validated fidelity
#: 0.771 -> 0.762 (its chin 0.14 -> 0.05, the lower lip 0.57 -> 0.58). Its cost: a pose fit
#: by the pixels of each registration frame, once: 115 ms on the sample (11 frames).
#: Measured and not kept (2026-12-06): the appearance averaged over the registration frames
#: (each frame's pose fitted to its pixels against the calibration frame's appearance, its
#: own appearance taken there, each sample's albedo the mean over the frames that see it,
#: brightness under the calibration frame's shading: a template with the sensor's noise and
#: the codec's blocks of one frame averaged away). The degraded head-motion renders over
#: camera seeds 0, 1, 2, head moving: skin 0.894, 0.905, 0.835 -> 0.982, 0.713, 0.798 mm
#: (median 0.894 -> 0.798), head 0.711 -> 0.621 deg, median RMSE 0.103 -> 0.099, but the
#: worst correlation 0.487 -> 0.218, worst RMSE 0.199 -> 0.206; head still skin 0.629 ->
#: 0.660 mm, worst RMSE 0.172 -> 0.157: no better on the whole.
REGISTER_APPEARANCE = True
#: the frames that register the appearance: the calibration frame's neighbours within this
#: many frames (either side) whose scores are within :data:`NEUTRAL_MARGIN_MM` of the
#: lowest, at most :data:`REGISTRATION_MAX` of them spread evenly over those (MediaPipe's
#: errors on neighbouring frames are alike: frames farther apart average them). Not more
#: of them from further away (2026-12-07, :data:`REGISTRATION_MAX` 30 within 45 frames; the
#: gaze benchmark's three clips, ``tools/gaze_replay.py``-style recordings): the worse eye
#: 4.24 / 3.55 / 4.39 -> 4.37 / 6.15 / 6.41 deg (frames of other gazes and views register
#: the eyes worse, as the detector's context did: :meth:`ModelFit.measure_detector_context`)
REGISTRATION_SPAN = 29
REGISTRATION_MAX = 12

#: the appearance's pose refined by the parallax the registration frames show
#: (:meth:`ModelFit._appearance_parallax`). An appearance taken at a pose that is off by a
#: small rotation ``D`` reproduces the calibration frame exactly (its pixels are whatever that
#: pose projects the surface onto) but slides the texture over the skin, and the slide shows
#: wherever the head is seen from another view: the nose, the cheeks and the brows, at other
#: depths than the skin about them, land elsewhere than the slid texture says, and the fit
#: reads it as expression and as a turned head. So ``D`` (a turn about the neutral's centroid)
#: is the one under which the registration frames seen from the views farthest from the
#: calibration frame's are reproduced best: each such frame fitted by its pixels (pose and
#: contractions free, as a frame of the video is) and its photometric cost on the finest
#: level summed. The landmarks' registration (:meth:`ModelFit._appearance_offset`) is its
#: start: MediaPipe's bias is alike in every frame, so their mean keeps it; the parallax
#: does not.
#: Why (2026-12-05, ``bench.headmotion.run_headmotion``, the photometric fit, head moving):
#: with the appearance taken at the calibration frame's *true* pose (an oracle; clean renders
#: in ambient light) the rest frames' skin 0.38 -> 0.10 mm and the head 1.00 -> 0.39 deg;
#: with the appearance taken from a neutral render at each frame's own true pose instead
#: (another oracle: the view's change of look taken away too) the same, 0.06 mm: what the
#: turning head read as expression was the calibration pose's error, not the view's change
#: of look. With this search: the same clean renders in ambient light 0.38 -> 0.08 mm, head
#: 1.00 -> 0.41 deg; the degraded renders (the benchmark's) skin 1.06 -> 0.93 mm (its rest
#: frames 0.74 -> 0.42), head 1.25 -> 0.53 deg, worst correlation -0.02 -> 0.52, worst RMSE
#: 0.250 -> 0.238, median 0.113 -> 0.120; clean renders in the renderer's lights 0.91 ->
#: 0.78 mm, head 1.21 -> 0.84 deg (the yaw found short by the lights: 1.4 where ambient light
#: gives 2.3-2.7); the expression clip's fit skin 0.96 -> 0.90 mm, head 1.27 -> 0.91 deg. Head
#: still: no frame seen from another view, nothing done. About 1.7 s once (18-22 costs).
#: On the degraded renders the same oracle does not help (2026-12-06, camera seeds 0, 1, 2,
#: head moving; the calibration's pose 0.5-1.0 deg off in yaw): the appearance taken at the
#: calibration frame's true pose, after everything else as the fit has it, reads skin 1.01,
#: 1.04, 1.09 mm against 0.89, 0.91, 0.84, worst correlation -0.04 against 0.49 (median):
#: there the appearance's pose is not what holds the moving head's numbers (the camera's
#: degradation of the pixels is: ``bench/headmotion.py``'s docstring).
PARALLAX_REFINE = True
#: the registration frames it reads, those seen from the farthest views, at most this many,
#: and none seen within :data:`PARALLAX_MIN_DEG` of the calibration frame's view: a slide of a
#: degree moves the skin seen 2 degrees away by a few hundredths of a millimetre (on
#: single_face.mp4, whose frames are all within 2.5 degrees, a first search from 2 degrees
#: turned the pitch 2.5 degrees for a 1.6 % lower cost and took the validated fidelity from
#: 0.765 to 0.751)
PARALLAX_FRAMES = 4
PARALLAX_MIN_DEG = 8.0
#: the search: passes along one axis each (head frame: 1 yaw, 0 pitch), each the cost at
#: :data:`PARALLAX_SAMPLES` turns evenly over +-its half-range (deg) about the best turn so far
#: and a parabola fitted to them by least squares (each cost refits the frames: it is a bumpy
#: function of the turn, some tens of its units about a smooth one, and a parabola through
#: three costs a degree apart went astray). Its vertex is taken where it is a minimum within
#: the range and its standard error (the fit's residuals as the noise) is below
#: :data:`PARALLAX_MAX_SE_DEG`; where the lowest cost is at the range's end instead, the pass
#: is made again about that end (once). An axis is searched where the frames' views differ
#: across it by :data:`PARALLAX_MIN_DEG` (the yaw: their azimuths). Yaw only: the pitch and
#: the roll searched too (the pitch where the elevations differ) went wrong under the
#: renders' lights (degraded, head moving: the pitch's mean error 0.24 -> 1.07 deg with 11.5
#: deg of elevation between the views; the roll's 0.3 -> 0.8); in ambient light they were
#: found right. The lights' shading, which the shading model follows only to first order,
#: tells a vertical slide less well than the yaw's parallax does.
PARALLAX_PASSES = ((1, 4.0), (1, 2.0))
PARALLAX_SAMPLES = 9
PARALLAX_MAX_SE_DEG = 0.75

#: the detector's gain on an expression's motion (:meth:`ModelFit.landmark_gain`, with
#: :attr:`~myoface.analysis.weights.FitSettings.photo_landmark_gain` None): the prior (the
#: gain, and its weight in mm^2 of the model's motion squared, summed over the points: about
#: one frame of a full smile) and the range the estimate is held to
LANDMARK_GAIN_PRIOR = (0.6, 500.0)
LANDMARK_GAIN_RANGE = (0.3, 1.0)


#: the calibration reads MediaPipe's relative depth (its points' z) into the person's neutral
#: (:meth:`ModelFit._fit_identity`): True, False, or None (the default): only on a face that is not
#: the person's own, the generic face, which has no texture (a face made from the person's photo or
#: scan has one, and their depth). Off: the neutral and the calibration's poses are fitted to the
#: points' x, y only, and the neutral's depth is the model's, smoothed where x, y move it. Why not
#: on the person's own face: MediaPipe's z is a learned guess whose profile is tilted against the
#: face's true depth; fitted vertex by vertex (its weight is the only thing that holds the offset's
#: depth, and the smoothness prior does not see a linear field) it shears the neutral (on the
#: head-motion benchmark's own face, clean renders, head still: offset z = 0.010 y, offset y = 0.015
#: z, least squares over the vertices), and a face sheared so is, seen from the front, the same face
#: pitched: the head frame came out pitched by 1.17 deg (sd 0.13) over a clip whose head held still
#: (0.97 with the landmarks alone). Measured 2026-12-04 (on / off on one tree;
#: ``tools/pose_bias.py`` for the head's angles and the shear, the benchmarks' own functions for the
#: rest): clean renders, head still, photometric, the angles' bias (yaw, pitch) 0.18, 1.17 -> 0.57,
#: 0.40 deg, the head's RMS 0.69 -> 0.43 deg (landmarks alone: 0.02, 0.97 -> 0.40, 0.21; 0.78 ->
#: 0.61 deg, but median RMSE 0.128 -> 0.146); the degraded head-motion renders with the photometric
#: term, head moving, head 1.09 -> 0.88 deg, skin 0.95 -> 0.93 mm, median RMSE 0.127 -> 0.114 (head
#: still 1.52 -> 1.48 deg: a bias MediaPipe's x, y leave on the degraded renders, 2.4 deg of pitch,
#: stays); its gaze on five clips (the benchmark's and four more seeds) 3.61, 5.68, 4.78, 3.13, 5.27
#: -> 3.31, 5.10, 4.58, 2.99, 5.16 deg; the expression clip 0.729 / 0.776 -> 0.740 / 0.784; known
#: warps and single_face.mp4's fidelity the same (0.764 / 0.763). The default (landmarks): head
#: moving, head 1.85 -> 1.82 deg, median RMSE 0.178 -> 0.194, skin 1.44 -> 1.47 mm; gaze 4.30, 5.30,
#: 5.39, 4.80, 6.10 -> 4.28, 5.21, 5.40, 4.62, 5.62; the expression clip 0.604 / 0.672 -> 0.646 /
#: 0.664; known warps within 0.02, fidelity 0.783 -> 0.779. (MediaPipe's z left out of every frame's
#: fit too, ``FitSettings.depth_sigma_mm`` 1000: with the photometric term head moving 0.89 deg,
#: gaze 3.47, 4.87, 4.45, 3.02, 4.42, but single_face.mp4's fidelity 0.757, its brows' gain 0.83 ->
#: 0.76: not taken.) Why on the generic face: its depth is not the person's, and MediaPipe's z is
#: the only word on theirs; off there (the sample video, the generic face; the full benchmarks of
#: 16:20 UTC against 14:25), the sample's fidelity 0.783 -> 0.779, the codec's decoded fidelity
#: 0.665 -> 0.636 and its bytes against x264's 2.99 -> 2.92x, synth.smile_gain 0.825 -> 0.805, the
#: known warps' gain 0.456 -> 0.439.
IDENTITY_DEPTH: bool | None = None


def registers_appearance(settings) -> bool:
    """Whether a fit with ``settings`` registers its appearance on many frames
    (:data:`REGISTER_APPEARANCE`, with the photometric term)."""
    return bool(settings.photometric) and REGISTER_APPEARANCE


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
    #: with the photometric term: the share of the face's visible, textured patches that do
    #: not look as they did at calibration (an occluder; NaN without the term:
    #: :meth:`~myoface.analysis.photometric.PhotometricTerm.occlusion`)
    occlusion: float = float("nan")


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


def choose_calibration_frame(scores) -> int:
    """The calibration frame among frames scored by :meth:`ModelFit.score`: the scores are
    known to the tracker's scatter, so of the frames within :data:`NEUTRAL_MARGIN_MM` of the
    lowest, the earliest (a video starts neutral more often than it ends so)."""
    scores = np.asarray(scores, dtype=np.float64)
    best = np.nanmin(scores)
    return int(np.flatnonzero(scores <= best + NEUTRAL_MARGIN_MM)[0])


def calibration_frames(scores, index: int) -> list[int]:
    """The frames that calibrate with frame ``index``: itself first, then those within
    :data:`CALIBRATION_FRAMES` - 1 of it whose scores are within :data:`NEUTRAL_MARGIN_MM` of
    the lowest (their tracker noise averages out), the lowest first, at most
    :data:`CALIBRATION_FRAMES` in all; ``index`` alone where its score is not known."""
    scores = np.asarray(scores, dtype=np.float64)
    use = [int(index)]
    if np.isfinite(scores[index]):
        near = [
            k
            for k in np.argsort(np.where(np.isfinite(scores), scores, np.inf))
            if k != index
            and abs(k - index) <= CALIBRATION_FRAMES - 1
            and scores[k] <= np.nanmin(scores) + NEUTRAL_MARGIN_MM
        ]
        use += [int(k) for k in near[: CALIBRATION_FRAMES - 1]]
    return use


#: :func:`neutral_views`: at most this many frames (as :data:`REGISTRATION_MAX`)
NEUTRAL_VIEWS_MAX = REGISTRATION_MAX
#: ... each in a run of at least this many frames labelled neutral (a frame between an
#: expression's frames that its rule labels neutral is not taken)
NEUTRAL_VIEWS_RUN = 3


def neutral_views(labels, n: int = NEUTRAL_VIEWS_MAX) -> list[int]:
    """The frames of a first pass over a video to register the appearance on
    (:meth:`ModelFit.set_appearance`'s ``views``): of the frames whose ``labels`` (the
    expression reader's, per frame; ``""`` not measured) are ``"neutral"`` with the
    :data:`NEUTRAL_VIEWS_RUN` - 1 frames before them, at most ``n``, evenly spread over them
    in time (a moving head shows the face at rest from its views as the video goes).

    Why (2026-12-06, ``tools/expression_calibration.py --wide-registration``, six synthetic
    expression clips, the head moving): the appearance registered on the calibration
    window's frames, one view, leaves what that view cannot tell (MediaPipe's bias there) in
    every other view's reading; registered on a first pass's neutral frames spread over the
    clip, the rest frames read right went 85.6 -> 91.7 % and 77.9 -> 90.2 % (the benchmark's
    three clips / three held out), the apex frames 74.3 -> 75.3 % and 55.9 -> 60.8 %; the
    gaze on five clips (``tools/gaze_clips.py --wide-registration``: frames spread over the
    clip, blinks left out) worse on four, mean 6.27 -> 6.42 deg, the head's pitch better."""
    ok = [
        k
        for k in range(len(labels))
        if k >= NEUTRAL_VIEWS_RUN - 1
        and all(labels[j] == "neutral" for j in range(k - NEUTRAL_VIEWS_RUN + 1, k + 1))
    ]
    return spread_evenly(ok, n)


def spread_evenly(frames, n: int) -> list:
    """At most ``n`` of ``frames`` (in order), evenly spread over them: the first, the last
    and those between at equal steps of their positions."""
    frames = list(frames)
    if len(frames) <= n:
        return frames
    return sorted({frames[int(i)] for i in np.linspace(0, len(frames) - 1, n)})


def registration_frames(scores, index: int) -> list[int]:
    """The frames that register the photometric fit's appearance with calibration frame
    ``index`` (:meth:`ModelFit._appearance_offset`): itself first, then up to
    :data:`REGISTRATION_MAX` - 1 of the frames within :data:`REGISTRATION_SPAN` of it whose
    scores are within :data:`NEUTRAL_MARGIN_MM` of the lowest (neutral: their poses are
    fitted without contractions), evenly spaced in time; ``index`` alone where its score is
    not known."""
    scores = np.asarray(scores, dtype=np.float64)
    if not np.isfinite(scores[index]):
        return [int(index)]
    low = np.nanmin(scores) + NEUTRAL_MARGIN_MM
    near = [
        k
        for k in range(
            max(0, index - REGISTRATION_SPAN), min(len(scores), index + REGISTRATION_SPAN + 1)
        )
        if k != index and np.isfinite(scores[k]) and scores[k] <= low
    ]
    if len(near) > REGISTRATION_MAX - 1:
        pick = np.round(np.linspace(0, len(near) - 1, REGISTRATION_MAX - 1)).astype(int)
        near = [near[i] for i in pick]
    return [int(index)] + [int(k) for k in near]


def parabola_vertex(x, y) -> tuple[float, float] | None:
    """The minimum of the parabola fitted to ``(x, y)`` by least squares and its standard
    error (the delta method on the fit's covariance, the residuals' variance as the noise):
    ``(vertex, se)``, or None where the parabola has no minimum within ``x``'s range."""
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    a = np.column_stack([np.ones_like(x), x, x * x])
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    _, b, c = coef
    if not c > 0:
        return None
    v = -b / (2.0 * c)
    if not x.min() <= v <= x.max():
        return None
    dof = max(len(x) - 3, 1)
    s2 = float(((a @ coef - y) ** 2).sum()) / dof
    cov = s2 * np.linalg.pinv(a.T @ a)
    g = np.array([0.0, -1.0 / (2.0 * c), b / (2.0 * c * c)])  # d vertex / d (a, b, c)
    return float(v), float(np.sqrt(max(g @ cov @ g, 0.0)))


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
        # the model's own error grows with what its muscles do to the soft tissue; the jaw is
        # a rotation of bone that the chin's skin follows, so it does not count (with it, the
        # chin and lower lip, which the jaw moves ~22 mm, weighed 0.16 and the fit raised them
        # by 4.5 mm with the smile's zygomatici where the video's stayed or dropped); nor do
        # the lateral pterygoids, which turn the same bone sideways
        bone = set(model.muscles.bone_index)
        soft = [k for k in range(self.n_muscles) if k not in bone]
        #: the contractions the fit moves: all but the mandible's sideways turn, unless
        #: :attr:`FitSettings.jaw_sideways`
        sideways = set(model.muscles.mandible_index)
        self._fitted = np.array(
            [k for k in range(self.n_muscles) if self.settings.jaw_sideways or k not in sideways],
            dtype=np.int64,
        )
        self._soft = soft
        self.base_weights = landmark_weights(
            model.face, self.settings.oval_weight
        ) * model_error_weights(
            self.response[:, :, soft], self.settings.model_error, self.settings.landmark_sigma_mm
        )
        #: with the optical flow: MediaPipe's x, y where the flow did not track weigh this
        #: much more (:attr:`FitSettings.flow_landmark_error`)
        self._detector_weights = model_error_weights(
            self.response[:, :, soft], self.settings.flow_landmark_error,
            self.settings.landmark_sigma_mm,
        )  # fmt: skip
        self.identity_mm = np.zeros_like(self.neutral)
        #: the fit's own state of the model's tissue (each relax starts from the last)
        self.state = model.rest_state()
        self._c0 = np.zeros(self.n_muscles)  # contractions the tissue was last relaxed at
        self._d0 = np.zeros_like(self.neutral)  # ... and its skin displacement there
        self._prev: FrameFit | None = None
        #: the frame intervals from :attr:`_prev`'s frame to the next one fitted (1, or more
        #: after frames fitted and then not measured: :meth:`restore_frame_state`)
        self._prev_age = 1
        #: deferred relaxes (``fit(deferred=True)``): the response Broyden-corrected at the
        #: last relax, the relax running on the worker thread (contractions, future)
        self._jac: np.ndarray | None = None
        self._pending = None
        self._pending_fits = 0
        self._worker = None
        self._channel_pool = None  # (the photometric channels' steps side by side: ChannelTerms)
        self.calibration: Calibration | None = None
        #: what :meth:`calibrate` was last given: its landmarks, frame and scores
        self._calibration_input: tuple | None = None
        #: the person's appearance for the photometric term (:meth:`set_appearance`)
        self.appearance: Appearance | None = None
        #: ... and in the frame's redness (:attr:`FitSettings.photo_colour`)
        self.appearance_colour: Appearance | None = None
        #: the appearances of the face at rest seen from other views
        #: (:meth:`set_view_appearances`): ``[(head rotation (3, 3), appearance, its
        #: redness's)]``, the calibration's first; empty: the calibration's alone
        self.view_appearances: list = []
        #: the detector's offsets on this face by view (:meth:`set_offsets`), taken off the
        #: points of every frame (None: the points as given)
        self.offsets = None
        self._spread_w = None  # (:meth:`_offset_weights`)
        #: the optical flow's patches (:meth:`set_flow_footprint`): their half side (px;
        #: None: not set) and the weights made from the calibration
        self._footprint_half: int | None = None
        self._footprint_cache = None
        #: tissue relaxes that did not converge (see :meth:`_relax`)
        self.unconverged_relaxes = 0
        #: where the time goes (for the benchmark's breakdown): the fits' thread CPU (s) and
        #: count, the relaxes' thread CPU (s; on the worker when deferred) and count, and the
        #: wall time (s) fits waited for a deferred relax
        self.timings = {
            "fits": 0, "fit_cpu_s": 0.0, "relaxes": 0, "relax_cpu_s": 0.0, "relax_wait_s": 0.0,
            "photo_coarse_starts": 0,
        }  # fmt: skip
        #: the points of the last frame fitted with the photometric term (its schedule's start:
        #: :func:`~myoface.analysis.photometric.coarse_start`)
        self._photo_points = None
        #: {frame: its points} of the frames the appearance is registered on (:meth:`calibrate`)
        self._registration: dict = {}
        #: the detector's gain on this video's expression motion (:meth:`landmark_gain`): the
        #: sums over the frames fitted with the photometric term so far, and the last fit's
        self._gain_sums = (0.0, 0.0)
        self._gain_last = None
        self._gain_mask = None
        #: MediaPipe's points at gain 1 whatever :meth:`landmark_gain` says: in the appearance's
        #: parallax search (its frames are the neutral's, and at a gain below 1 the muscles took
        #: up the turn it searches for) and with analysis by synthesis (whose rounds take the
        #: detector's shortfall on the model's own render off the points)
        self._gain_one = False

    # -------------------------------------------------------------- public
    def lose_track(self) -> None:
        """Forget the previous frame (after frames without a face): the next fit starts from a
        closed-form pose and no temporal prior."""
        self._prev = None

    def frame_state(self) -> tuple:
        """What the next fit starts from (the previous frame's fit, how many frames back it
        is, and for the photometric term's schedule its points): :meth:`restore_frame_state`
        takes it back."""
        return self._prev, self._prev_age, self._photo_points, self._gain_sums

    def restore_frame_state(self, state: tuple) -> None:
        """The next fit starts from ``state`` (:meth:`frame_state`, taken before a frame that
        is then not measured, e.g. ``occluded``): from that frame's fit, its temporal prior
        as wide as the frames since then allow (the head moved on meanwhile: with the prior
        of one frame's interval the fit lagged the turning head further at each frame, and
        every frame after the first not measured was not measured either; 2026-12-04, the
        degraded head-motion renders with the photometric term), and the photometric term's
        schedule from its coarsest level unless the face has not moved since that frame's
        points (:func:`~myoface.analysis.photometric.coarse_start`)."""
        self._prev, age, self._photo_points, self._gain_sums = state
        self._prev_age = age + 1

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
        if self._worker is None:
            self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="myoface-fit")
        c = np.array(c, dtype=np.float64)
        self._pending = (c, self._worker.submit(self._relax, c))
        self._pending_fits = 0  # the fits since it started (:meth:`_collect_due`)

    def _collect_due(self) -> None:
        """:meth:`_collect` the deferred relax once :attr:`FitSettings.relax_lag` fits have
        been made since it started (the fits in between read the linearisation before it): the
        relax runs beside those fits instead of the next fit waiting for it, and which fit
        takes it up depends on the count alone, not on timing."""
        if self._pending is None:
            return
        if self._pending_fits >= self.settings.relax_lag:
            self._collect()
        else:
            self._pending_fits += 1

    def _collect(self) -> None:
        """Wait for the deferred relax, if any, and move the linearisation there: the response
        at rest Broyden-corrected along the step from the last relaxed point (as the second
        round of an immediate fit does)."""
        if self._pending is None:
            return
        c, fut = self._pending
        self._pending = None
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
        """Finish the deferred relax and stop its thread (and the photometric channels')."""
        if self._worker is not None:
            self._collect()
            self._worker.shutdown()
            self._worker = None
        if self._channel_pool is not None:
            self._channel_pool.shutdown()
            self._channel_pool = None

    def fit(
        self,
        points,
        synthesis: LandmarkSynthesis | None = None,
        deferred: bool = False,
        flow=None,
        image=None,
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
        next call waits for it first, so the results do not depend on timing.

        ``flow``: ``(xy (468, 2), tracked (468,) bool)``, the points optical flow tracked on
        this frame (:meth:`~myoface.analysis.flow.FlowRefiner.track`): an
        :class:`~myoface.analysis.terms.OpticalFlowTerm` reads the tracked ones in place of
        the landmarks' x, y there.

        ``image``: the frame itself (RGB), read by the photometric term
        (:class:`~myoface.analysis.photometric.PhotometricTerm`) against the calibration
        frame's appearance, once :meth:`set_appearance` has taken it (else not used)."""
        t0 = time.thread_time()
        photo = None
        if image is not None:
            self._nearest_view()
            # the schedule's coarsest level only where the face moved far since the last fit
            start = coarse_start(points, self._photo_points if self._prev is not None else None)
            # (the head's turn from the calibration's pose, or from the view whose appearance
            # it reads, set_view_appearances: the last frame's, else none known)
            turn = 0.0
            if self._prev is not None and self.calibration is not None:
                turn = rotation_angle_deg(self._prev.pose.rotation, self._view_rotation())
            photo = self.photometric_term(image, start, eye_rim_weight(turn))
            self._photo_points = np.asarray(points, dtype=np.float64)
            if photo is not None:
                self.timings["photo_coarse_starts"] += start == 0
        # the lid margins' edges (FitSettings.reads_lids) read on this frame's fits only
        self._lid_image = image if self.settings.reads_lids else None
        self._gain_one = synthesis is not None
        try:
            return self._fit_frame(points, synthesis, deferred, flow, photo, t0)
        finally:
            self._lid_image = None
            self._gain_one = False

    def lid_edge_term(self, image):
        """The lids' term of ``image`` (:func:`myoface.analysis.lidtemplate.lid_term`)."""
        from myoface.analysis.lidtemplate import lid_term

        return lid_term(self, image)

    def set_lid_reference(self, frame) -> None:
        """Take the calibration frame (after :meth:`calibrate`) as the lids' reference
        (:class:`~myoface.analysis.lidtemplate.LidTemplate`)."""
        from myoface.analysis.lidtemplate import LidTemplate

        self.lid_template = LidTemplate(
            self.model.face, self.neutral + self.identity_mm, frame, self.camera,
            self.calibration.pose,
        )  # fmt: skip

    def _fit_frame(self, points, synthesis, deferred, flow, photo, t0) -> FrameFit:
        """(:meth:`fit`'s body.)"""
        p = check_points(points, len(self.neutral))
        if flow is not None:
            flow = (np.asarray(flow[0], dtype=np.float64), np.asarray(flow[1], dtype=bool))
        prev = self._prev
        if self.offsets is not None and synthesis is None:
            p = self._corrected(p, None if prev is None else prev.pose)
        if deferred:
            self._collect_due()
        else:
            self._collect()
        refine = 0 if deferred else self.settings.refine
        start = None
        if photo is not None and prev is not None and self._prev_age > 1:
            # the last fit is frames back (the frames since were not measured): the
            # landmarks move the start to this frame first; the photometric steps, a few
            # pixels' reach, lost a head that had turned on meanwhile (2026-12-04, the
            # degraded head-motion renders: from a frame marked occluded on, every frame
            # diverged, MediaPipe's points ending up to 66 mm RMS from the fit)
            start = self._fit(p, prev, refine=0, flow=flow)
        res = self._fit(p, prev, refine=refine, flow=flow, photo=photo, start=start)
        if synthesis is not None:
            for _ in range(self.settings.synthesis_rounds):
                err = synthesis.tracker_error(self.shape(res.contractions), res.pose)
                if err is None:
                    break
                moved = None if flow is None else (flow[0] - err[:, :2], flow[1])
                res = self._fit(p - err, prev, refine=0, start=res, flow=moved, photo=photo)
        if self._gain_last is not None:
            dm, mm = self._gain_last
            self._gain_sums = (self._gain_sums[0] + dm, self._gain_sums[1] + mm)
        self._gain_last = None
        if (
            deferred
            and self.settings.refine > 0
            and self._pending is None
            and self._relax_due(res.contractions)
        ):
            self._relax_later(res.contractions)
        self._prev = res
        self._prev_age = 1
        self.timings["fits"] += 1
        self.timings["fit_cpu_s"] += time.thread_time() - t0  # (with immediate relaxes)
        return res

    def score(self, frames, synthesis: LandmarkSynthesis | None = None, on_scored=None):
        """Each frame's expression score (:meth:`calibrate`'s ranking of its candidate frames):
        returns ``(frames, scores)``, the frames as a list and their (T,) scores (NaN where
        ``frames`` gives None: no face). ``frames`` may be an iterator whose points are being
        detected meanwhile: each is scored as it comes, and ``on_scored(frames, scores)``
        (the lists so far) is called after each (:class:`FitTracker` starts measuring on a
        provisional choice there). Each frame's fit is started from the previous frame's
        (no temporal prior: each frame's score is its own), against the model's own neutral."""
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
                else:
                    q = check_points(pts, len(self.neutral))
                    if self.offsets is not None and synthesis is None and SCORE_CORRECTED:
                        # scored on the points the calibration will read (the detector's
                        # offsets at this view taken off), else a turned frame's offsets
                        # read as expression and the choice falls on the wrong frames
                        q = self._corrected(q, None if last is None else last.pose)
                    r = self._fit(
                        q, None, refine=0, start=last, rest=True, iterations=SCORE_ITERATIONS
                    )
                    last = r
                    disp = np.linalg.norm((flat @ r.contractions).reshape(-1, 3), axis=1)
                    scored.append(float(np.percentile(disp, NEUTRAL_PERCENTILE)))
                if on_scored is not None:
                    # (the scoring's neutral put back meanwhile: the callback may fit)
                    self.identity_mm = saved
                    try:
                        on_scored(got, scored)
                    finally:
                        self.identity_mm = np.zeros_like(self.neutral)
        finally:
            self.identity_mm = saved
        if not got:
            raise MyofaceValueError("calibrate() needs at least one frame")
        scores = np.array(scored, dtype=np.float64)
        if not np.isfinite(scores).any():
            raise MyofaceValueError("no face in any of the calibration frames")
        return got, scores

    def calibrate(
        self, frames, index: int | None = None, synthesis: LandmarkSynthesis | None = None,
        scores=None,
    ) -> Calibration:  # fmt: skip
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
        (:meth:`_gauge`); later frames measure expression relative to it. ``scores``: with
        ``index``, the frames' scores of an earlier calibration on them (its
        :attr:`Calibration.scores`), so that the same frames around it calibrate with it
        (without: the frame ``index`` alone).
        """
        if index is None:
            frames, scores = self.score(frames, synthesis)
            index = choose_calibration_frame(scores)
        else:
            frames = list(frames)
            if not frames:
                raise MyofaceValueError("calibrate() needs at least one frame")
            if scores is None or len(scores) != len(frames):
                scores = np.full(len(frames), np.nan)
            scores = np.asarray(scores, dtype=np.float64)
        if not 0 <= index < len(frames) or frames[index] is None:
            raise MyofaceValueError(f"calibration frame {index} has no face")
        use = calibration_frames(scores, index)
        # (kept to calibrate again with the detector's context: measure_detector_context)
        self._calibration_input = (frames, int(index), scores)
        pts = [check_points(frames[k], len(self.neutral)) for k in use]
        if self.offsets is not None and synthesis is None:
            pts = [self._corrected(p) for p in pts]
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
        self._registration = {}
        if registers_appearance(self.settings):  # (the frames its appearance is registered on)
            extra["registration"] = registration_frames(scores, index)
            for k in extra["registration"][1:]:
                p = check_points(frames[k], len(self.neutral))
                self._registration[k] = p if self.offsets is None else self._corrected(p)
        self.calibration = Calibration(index, scores, identity, pose, resid, extra)
        self._gain_sums, self._gain_last = (0.0, 0.0), None  # (a new neutral: a new start)
        return self.calibration

    def measure_detector_context(self, images) -> dict | None:
        """Measure what MediaPipe does on this video's frames beyond what the detector's
        offsets' table (:meth:`set_offsets`, a :class:`~myoface.analysis.landmarks.
        TrackerOffsets` of a face with its own texture) says, and calibrate again with it
        (after :meth:`calibrate`; ``images``: the frames given to it, by position, None where
        one was not kept). Returns what was measured (also the calibration's
        ``extra["detector_context"]``), or None where it is not done
        (:attr:`~myoface.analysis.weights.FitSettings.detector_context` off) or cannot be (no
        table, or no calibration frame's image).

        The table renders the person's model on the renderer's plain background; on a video
        the detector sees the face among its room, hair and neck, and places its points
        differently there. So on each calibration frame the model, at the person's neutral
        and the frame's pose, is rendered over the frame itself
        (:meth:`~myoface.analysis.synthesis.LandmarkSynthesis.tracker_error` with
        ``context``) and read by the detector: what it reports less the model's vertices is
        its error in that context. The frame's pose is found again from its points less that
        error (:data:`CONTEXT_STEPS` steps, each over-relaxed by :data:`CONTEXT_OVERRELAX`),
        and the error's excess over the table's at that pose, in the head frame, averaged over
        the calibration frames, is added to the table at every view
        (:meth:`~myoface.analysis.landmarks.TrackerOffsets.with_context`): the calibration and
        every later frame are corrected alike, so what the context does to the detector is not
        read as expression. (Only at the calibration's frames: a render and a detection a
        step, about 20 in all.)

        Measured 2026-12-06 (the benchmarks' personal face, degraded renders;
        ``tools/detector_context.py``). On the still head's frames 0, 10 and 20 MediaPipe's
        points are 3.8-4.1 px RMS from the true vertices and give the head pitched 5.1-5.6
        deg; less the table's offsets 1.8-2.4 px and 2.3-2.7 deg; less its error on the model
        rendered over the frame at the true pose 0.5-0.8 px and 0.2-0.8 deg. Against the same
        tree without it (medians over the benchmarks' camera seeds and clips):
        ``analysis.headmotion`` head still: head 1.76 -> 0.92 deg RMS, worst correlation
        0.12 -> 0.38, worst RMSE 0.176 -> 0.172, median RMSE 0.072 -> 0.077, skin 0.62 ->
        0.63 mm; head moving: worst RMSE 0.206 -> 0.199, worst correlation 0.38 -> 0.49,
        median RMSE 0.115 -> 0.103, skin 0.84 -> 0.89 mm, head 0.69 -> 0.71 deg;
        ``analysis.gaze_error_deg`` 6.56 -> 5.02 deg (clips 4.16 / 6.56 / 6.84 -> 5.02 / 5.89
        / 4.88); the expression benchmark's six clips, apex / rest read right, 65.1 / 81.8 ->
        66.8 / 81.9 %. On a real video (single_face.mp4 analysed with the person's face made
        from its first frame, ``myoface face from-photo``; the context measured 0.92 mm RMS,
        the calibration turned 0.78 deg by it): the validated fidelity 0.786 -> 0.794 (lower
        lip 0.57 -> 0.68, chin 0.11 -> 0.16, corners 0.91 -> 0.90, brows 0.71 -> 0.69, lids
        0.86 -> 0.86). Tried and not kept: the context's error taken off the calibration
        frames' points alone, not the later frames' (one seed: the moving head's poses 0.51
        -> 0.69 deg, its worst correlation 0.36 -> 0.30: the calibration and the frames after
        it corrected unlike); the context averaged over the appearance's registration frames
        too (up to 11, spread over a second: gaze 5.02 -> 6.52 deg, the moving head's worst
        RMSE 0.199 -> 0.218, its skin 0.89 -> 0.81 mm: frames of other gazes and views do
        not share one context); plain steps (3: the still head 1.08 deg, 6: 1.05); the model
        rendered with the gaze the reader finds on the frame (the eyes' contour moves with
        the gaze): one gaze clip 3.9 -> 8.8 deg, that reading not good enough to steer it;
        (2026-12-06) the render blurred before the detector reads it, as the camera blurs the
        frames (a Gaussian of 0.7 / 1.2 px; the benchmark's frames have 1 px and a texture at
        half resolution): the gaze benchmark's three clips 4.24 / 3.55 / 4.39 -> 3.64 / 3.75
        / 4.80 and 3.35 / 3.99 / 4.99 deg, each eye's mean misplacement in the image the same
        within 0.3 px (``tools/gaze_replay.py``).

        Off again on the tree of 2026-12-06, night (``analysis.headmotion``'s clip, camera seeds
        0, 1, 2, median; on / off): head moving, worst RMSE 0.149 / 0.160, median 0.101 / 0.115,
        worst correlation 0.51 / 0.44, skin 0.818 / 0.819 mm, head 0.72 / 0.67 deg; head still
        0.121 / 0.128, 0.069 / 0.072, 0.38 / 0.12, 0.589 / 0.569 mm, 0.91 / 1.74 deg: kept on.
        Where the background acts (the head-motion renders with only the cluttered background,
        ``tools/photometric_ablation.py headmotion --only background``): MediaPipe's points
        there, a 2-D similarity taken off, sit 0.8-1.4 px (median over the inner points) and
        1.4-4.2 px (the face's oval) from its points on the same renders without it, and the
        chin's muscles follow the turn (the mentalis 0.56 at a yaw of 30 deg where nothing
        moves; RMSE 0.20, correlation -0.02); with MediaPipe's points read on the renders
        without the background and the pixels with it (``--points-from clean``) the mentalis
        is 0.05 RMSE, the worst of the 12 muscles and the jaw 0.131 against 0.154. Not kept:
        the face oval's weight 0 or 0.05 (:attr:`~myoface.analysis.weights.FitSettings.
        oval_weight`; the mentalis 0.19-0.21); the frame shown to MediaPipe with everything
        outside its last frame's points' hull (grown 1.2, 1.5, 2 times about its centroid)
        made the renderer's background: background only, worst RMSE 0.154 -> 0.190, 0.091,
        0.141, skin 0.64 -> 1.07, 0.79, 0.64 mm; every part of the camera (seed 0) 0.166 ->
        0.166, 0.142, skin 0.81 -> 1.14, 0.85 mm: the detector reads a cut-out face as
        unlike the table's as the room."""
        from myoface.analysis.landmarks import TrackerOffsets, head_frame_offsets

        cal = self.calibration
        if cal is None:
            raise MyofaceValueError("measure_detector_context() needs a calibration first")
        table = self.offsets
        if (
            not self.settings.detector_context
            or not isinstance(table, TrackerOffsets)
            or self._calibration_input is None
        ):
            return None
        frames, index, scores = self._calibration_input
        plain = table.with_context(None)
        syn = plain.synthesis
        self.offsets = plain  # (the poses below from the table's points alone)
        base = self.neutral + self.identity_mm
        deltas = []
        try:
            for k in cal.extra.get("frames", [cal.index]):
                image = images[k] if k < len(images) else None
                if image is None or frames[k] is None:
                    continue
                p = check_points(frames[k], len(self.neutral))
                pose = self._pose_only(self._corrected(p), initial_pose(base, p, self.camera), base)
                err = None
                for _ in range(CONTEXT_STEPS):
                    at = pose
                    err = syn.tracker_error(base, at, context=image)
                    if err is None:
                        break
                    new = self._pose_only(p - err, at, base)
                    turn = rotvec(at.rotation.T @ new.rotation) * CONTEXT_OVERRELAX
                    pose = HeadPose(
                        at.rotation @ rotmat(turn),
                        at.translation_mm + CONTEXT_OVERRELAX * (new.translation_mm - at.translation_mm),
                    )  # fmt: skip
                if err is None:
                    continue
                # the error beyond the table's shift, as a head-frame offset, at the pose the
                # points less the error give (the last step's)
                shifted = plain.correct(p, pose, base)
                d = err[:, :2] - (p[:, :2] - shifted[:, :2])
                deltas.append(head_frame_offsets(d, pose, base, self.camera))
        finally:
            self.offsets = table
        if not deltas:
            return None
        before = cal.pose
        context = np.mean(deltas, axis=0)
        self.set_offsets(plain.with_context(context))
        self.calibrate(frames, index, scores=scores)
        info = {
            "frames": len(deltas),
            "context_rms_mm": round(float(np.sqrt((context**2).sum(axis=1).mean())), 4),
            "calibration_turned_deg": round(
                float(rotation_angle_deg(before.rotation, self.calibration.pose.rotation)), 4
            ),
        }
        self.calibration.extra["detector_context"] = info
        return info

    def set_appearance(self, frame, window=None, views=None) -> None:
        """Take the person's appearance from ``frame``, the calibration frame (after
        :meth:`calibrate`): the photometric term then reads every frame given to :meth:`fit`
        with its ``image`` against it. ``window``: the images of the frames given to
        :meth:`calibrate`, by position (None where one was not kept): the appearance is then
        registered on its ``extra["registration"]`` frames (:func:`registration_frames`,
        :meth:`_appearance_offset`), not on the calibration frame's landmarks alone, and then
        turned by the parallax of those seen from other views (:data:`PARALLAX_REFINE`,
        :meth:`_appearance_parallax`). ``views``: None, or neutral frames from anywhere in
        the video, ``{frame index: (landmarks (V, 3), image)}``, registered on in place of
        the window's (a first pass's frames labelled neutral, spread over the video:
        :func:`neutral_views`; the calibration window shows the face from one view, and what
        that view leaves unsaid is read at every other view as expression)."""
        if self.calibration is None:
            raise MyofaceValueError("set_appearance() needs a calibration first")
        cal = self.calibration
        pose = cal.pose
        self.view_appearances = []
        self._take_appearance(frame, pose)
        # (each registration frame kept, with the pose its landmarks give the neutral)
        if views is not None:
            seen = self._given_views(views)
            cal.extra["registration"] = [int(cal.index)] + [v[0] for v in seen]
        else:
            seen = self._registration_views(window) if window is not None else []
        if seen:
            offset = self._appearance_offset(seen)
            if offset is not None:
                # the calibration frame as the frames' landmarks place it on average
                rot, t = offset
                r2 = pose.rotation @ rot.T
                pose = HeadPose(r2, pose.translation_mm - r2 @ t)
                self._take_appearance(frame, pose)
                cal.extra["appearance_offset"] = {
                    "rotation_deg": [round(float(v), 4) for v in np.degrees(rotvec(rot))],
                    "translation_mm": [round(float(v), 4) for v in t],
                }
        if seen and PARALLAX_REFINE:
            self._appearance_parallax(frame, seen, pose)

    def set_view_appearances(self, views) -> None:
        """Read each frame against the face at rest as seen from the nearest of several views
        (after :meth:`set_appearance`): ``views``, ``[(image, pose)]``, frames of the face at
        rest seen from other views than the calibration frame's, each with its head pose
        (:class:`~myoface.analysis.camera.HeadPose`, e.g. the photometric fit's in a first
        pass over the video). Each view's appearance is taken as the calibration frame's is
        (:meth:`_take_appearance`, on the person's neutral at that pose), and each frame's
        photometric term then reads against the appearance of the view, the calibration's
        among them, nearest to the last frame's head rotation (:meth:`_nearest_view`).
        An empty ``views``: the calibration's appearance alone, as before.

        Why (2026-12-06, ``tools/expression_view_bank.py``; the expression benchmark's nine
        clips, degraded renders, the head moving +-30 deg): the calibration frame's appearance
        carried to another view is not what that view shows of the face at rest (the model's
        surface, the light's side, the eyeball behind the lids' margins are not the person's),
        and the fit reads the difference as expression. Given up to 12 of the clip's frames at
        rest (the truth's: an oracle of which frames are at rest), spread over its views, the
        rest frames read neutral went from 43-100 % to 93-100 % of every clip's, the apex
        frames read right 65.1 -> 74.0 % (the benchmark's six clips pooled) and 71.2 -> 72.2 %
        (three held out). Chosen from a first pass's own readings instead, the views include
        frames whose expression it missed, which the bank then takes for the face at rest
        (73.8 / 84.8 % on the six, but 66.0 / 73.0 against 71.2 / 67.3 on the held-out three;
        docs/expressions.md, "The face at rest from its views"): not yet in the analysis.

        On the head-motion renders (2026-12-07; the truth's frames at rest at least 8 deg
        apart, 3, 6 and 87, yaw 9-18 deg, each at its true pose: an oracle of the views and
        their poses; the benchmark's analysis otherwise; skin mm at rest / in expressions,
        head deg): clean renders 0.36 / 0.57, 0.90 -> 0.17 / 0.55, 0.48, and with
        :attr:`~myoface.analysis.weights.FitSettings.photo_model_error` 0.25 beside it 0.19 /
        0.56, 0.38, the worst RMSE 0.098 -> 0.100, the paper's frontalis parts' gain 0.77-0.87
        -> 0.83-0.99 (the moving skin weighed more without the rest frames paying); but on the
        degraded renders (camera seeds 0 / 1) 0.24 / 0.87 -> 0.25 / 1.07 and 0.13 / 1.03 (the
        default's 0.83 mm overall on seed 1 -> 0.95), with 0.25 as well 0.44 / 1.07 (seed 0):
        the rest frames as good or better, the expressions' worse: the views were taken at
        the true poses, and the fit's own are off by its calibration's error (0.5-2.2 deg of
        yaw at those frames; the calibration's appearance is registered on the fit's poses).
        Taken at the poses a first pass of the fit gives those frames (the same frames),
        clean 0.09 / 0.55, the worst RMSE 0.109; degraded, camera seeds 0 / 1 / 2 (the
        default's in brackets): worst RMSE 0.179 / 0.126 / 0.149 (0.166 / 0.132 / 0.149),
        median RMSE 0.086 / 0.092 / 0.096 (0.100 / - / -), skin 0.83 / 0.78 / 0.74 mm (0.81 /
        0.83 / 0.82; at rest 0.18 / 0.20 / 0.18), head 0.66 / 0.68 / 0.64 deg (median 0.72):
        the views help where their poses are the fit's own, a little, with the frames at rest
        known. With :attr:`~myoface.analysis.weights.FitSettings.photo_model_error` 0.25 as
        well, worse (worst 0.122 / 0.189 / 0.194, skin 0.78 / 0.86 / 0.84 mm). Chosen from
        the first pass's readings instead (frames whose five-frame neighbourhood reads every
        contraction under 0.25, none under 0.1 anywhere, the least expressive first, 8 deg
        apart): seed 0 took frame 75 (fear's onset, truth 0.44, read as rest) and read worse
        (worst 0.194, skin 0.99 mm, correlation 0.38), seeds 1 and 2 (their views all at
        rest) better (0.140 / 0.132, skin 0.74 / 0.73 mm) but for the worst correlation
        (0.34 / 0.29 against 0.49 / 0.51): the medians 0.140 / 0.102 / 0.34 / 0.741 / 0.75
        against the default's 0.149 / 0.101 / 0.51 / 0.818 / 0.72. Which frames are at rest
        is still the open part."""
        if self.appearance is None or self.calibration is None:
            raise MyofaceValueError("set_view_appearances() needs set_appearance() first")
        first = (
            self.view_appearances[0]
            if self.view_appearances
            else (self.calibration.pose.rotation, self.appearance, self.appearance_colour)
        )
        bank = [first]
        for image, pose in views:
            self._take_appearance(image, pose)
            bank.append((np.asarray(pose.rotation, dtype=np.float64), self.appearance,
                         self.appearance_colour))  # fmt: skip
        self.appearance, self.appearance_colour = first[1], first[2]
        self.view_appearances = bank if len(bank) > 1 else []

    def _nearest_view(self) -> None:
        """Take the appearance of the view (:attr:`view_appearances`) nearest in head
        rotation to the last frame's (the calibration's before the first)."""
        if not self.view_appearances:
            return
        ref = (self._prev if self._prev is not None else self.calibration).pose.rotation
        k = int(np.argmin([rotation_angle_deg(ref, r) for r, _, _ in self.view_appearances]))
        _, self.appearance, self.appearance_colour = self.view_appearances[k]

    def _view_rotation(self) -> np.ndarray:
        """The head rotation of the view whose appearance the fit reads (the calibration's
        unless :meth:`set_view_appearances` gave others)."""
        for r, app, _ in self.view_appearances:
            if app is self.appearance:
                return r
        return self.calibration.pose.rotation

    def _take_appearance(self, frame, pose) -> None:
        """The appearance (and the redness's) of ``frame`` seen at ``pose``
        (:meth:`set_appearance`)."""
        self.appearance = Appearance.from_frame(
            frame, self.model.face, self.camera, pose, self.neutral + self.identity_mm,
        )  # fmt: skip
        # the samples weigh less where the muscles move the skin (FitSettings.photo_model_error)
        s = self.settings
        per_vertex = model_error_weights(
            self.model_response[:, :, self._soft], s.photo_model_error, s.landmark_sigma_mm
        )
        own = self.appearance.samples.matrix(len(per_vertex)) @ per_vertex
        prior = self.appearance.prior
        self.appearance.prior = own if prior is None else prior * own
        self.appearance_colour = None
        if s.photo_colour:
            self.appearance_colour = Appearance.from_frame(
                frame, self.model.face, self.camera, pose, self.neutral + self.identity_mm,
                channel="redness",
            )  # fmt: skip
            if not np.nanstd(self.appearance_colour.values[-1]) >= COLOURLESS_SD:
                self.appearance_colour = None  # (a grey video: its redness says nothing)
            else:
                prior = self.appearance_colour.prior
                self.appearance_colour.prior = own if prior is None else prior * own

    def _registration_views(self, window) -> list:
        """The registration frames whose images ``window`` kept (by position), each as
        ``(k, points, image, pose)``: its landmarks' pose of the person's neutral."""
        kept = [
            (k, p, window[k] if k < len(window) else None) for k, p in self._registration.items()
        ]
        return self._posed_views([v for v in kept if v[2] is not None])

    def _given_views(self, views) -> list:
        """:meth:`_registration_views` of the frames ``views`` ({index: (landmarks,
        image)}, in their order; the calibration frame's own left out: it is the one being
        registered), their landmarks corrected as the calibration's are."""
        out = []
        for k, (points, image) in sorted(views.items()):
            if int(k) == self.calibration.index or points is None or image is None:
                continue
            p = check_points(points, len(self.neutral))
            out.append((int(k), p if self.offsets is None else self._corrected(p), image))
        return self._posed_views(out)

    def _posed_views(self, frames) -> list:
        """``(k, points, image)`` as ``(k, points, image, pose)``, the pose the points give
        the person's neutral."""
        base = self.neutral + self.identity_mm
        return [
            (k, p, image, self._pose_only(p, initial_pose(base, p, self.camera), base))
            for k, p, image in frames
        ]

    def _appearance_offset(self, views) -> tuple[np.ndarray, np.ndarray] | None:
        """How far the appearance, taken at the calibration frame's pose, sits from where
        the registration frames' landmarks put it on average: a rigid motion of the head frame
        (rotation (3, 3), translation (3,) mm; None with fewer than two frames). An appearance
        taken at a pose that is off by ``D`` (the calibration frame's landmark error) makes
        the photometric fit find every frame's pose off by the same ``D``: it reproduces the
        frame's pixels with the texture slid on the skin. So each registration frame ``k``
        (neutral) is fitted by its landmarks and by its pixels against that appearance (the
        pose alone), and ``P_landmarks(k)^-1 P_pixels(k)`` is one reading of ``D`` with the
        error of frame ``k``'s landmarks (the calibration frame's own reads the identity: its
        error is the one to find); their mean (rotation vectors and translations averaged)
        reads it with the frames' errors averaged. ``views``: :meth:`_registration_views`."""
        base = self.neutral + self.identity_mm
        zeros = np.zeros(self.n_muscles)
        jac0 = np.zeros((len(base), 3, self.n_muscles))
        rvecs, ts = [np.zeros(3)], [np.zeros(3)]  # (the calibration frame's: the identity)
        for _, p, image, lm in views:
            px, _, _, _ = self._gauss_newton(
                p, lm, zeros, zeros, np.zeros_like(base), jac0, base, None,
                free=np.zeros(0, dtype=np.int64), photo=self.photometric_term(image),
                iterations=self.settings.photo_iterations,
            )  # fmt: skip
            rvecs.append(rotvec(lm.rotation.T @ px.rotation))
            ts.append(lm.rotation.T @ (px.translation_mm - lm.translation_mm))
        if len(rvecs) < 2:
            return None
        return rotmat(np.mean(rvecs, axis=0)), np.mean(ts, axis=0)

    def _appearance_parallax(self, frame, registration, pose) -> None:
        """The appearance taken again from ``frame`` at ``pose`` turned by the rotation about
        the person's neutral's centroid under which the registration frames seen from the
        farthest views are reproduced best (:data:`PARALLAX_REFINE`); recorded in the
        calibration's ``extra["appearance_parallax"]``. Unchanged where no registration frame
        is seen from :data:`PARALLAX_MIN_DEG` or more away. ``registration``:
        :meth:`_registration_views`."""
        cal = self.calibration
        base = self.neutral + self.identity_mm
        centre = base.mean(axis=0)
        views = [(rotation_angle_deg(lm.rotation, cal.pose.rotation), k, p, image, lm)
                 for k, p, image, lm in registration]  # fmt: skip
        views = sorted((v for v in views if v[0] >= PARALLAX_MIN_DEG), key=lambda v: -v[0])
        views = views[:PARALLAX_FRAMES]
        # (an axis is searched where the views differ across it: the yaw where the frames
        # are seen from other azimuths, the pitch from other elevations)
        here = np.array(view_angles(cal.pose))
        spread = np.zeros(3)
        for v in views:
            az, el = np.abs(np.array(view_angles(v[4])) - here)
            spread = np.maximum(spread, [el, az, 0.0])
        passes = [(a, h) for a, h in PARALLAX_PASSES if spread[a] >= PARALLAX_MIN_DEG]
        if not passes:
            return
        zeros = np.zeros(self.n_muscles)
        response = np.ascontiguousarray(self.response)

        def turned(d):
            r = rotmat(d)
            return HeadPose(pose.rotation @ r, pose.rotation @ (centre - r @ centre)
                            + pose.translation_mm)  # fmt: skip

        def cost(d) -> float:
            self._take_appearance(frame, turned(d))
            total = 0.0
            for _, _, p, image, lm in views:
                # (the points at gain 1: these frames are the neutral's views, and at a gain
                # below 1 the muscles took up the turn searched for)
                self._gain_one = True
                try:
                    px, c, _, _ = self._gauss_newton(
                        p, lm, zeros, zeros, np.zeros_like(base), response, base, None,
                        photo=self.photometric_term(image, foreshortening=False),
                    )  # fmt: skip
                finally:
                    self._gain_one = False
                # (each sample in full: weights that moved with the turn tried
                # (photometric.FORESHORTENING_POWER, from the appearance's pose) would bias
                # the costs compared)
                total += self._photo_cost(
                    image, px, base + _linear(response, c), foreshortening=False
                )
            return total

        d = np.zeros(3)
        known = {}  # (the costs evaluated, by turn)

        def at(trial) -> float:
            key = tuple(np.round(np.degrees(trial), 6))
            if key not in known:
                known[key] = cost(trial)
            return known[key]

        found: list = []  # (per pass: its axis, vertex and standard error, deg, or None)
        for axis, half in passes:
            turns = np.linspace(-half, half, PARALLAX_SAMPLES)
            moved = 0.0  # (the pass made again about its range's end: how far, deg)
            for again in (False, True):
                e = []
                for x in turns:
                    trial = d.copy()
                    trial[axis] += np.radians(x)
                    e.append(at(trial))
                vertex = parabola_vertex(turns, np.asarray(e))
                low = int(np.argmin(e))
                if vertex is None and not again and low in (0, len(turns) - 1):
                    moved = float(turns[low])  # (the minimum lies beyond: once more there)
                    d[axis] += np.radians(moved)
                    continue
                break
            found.append([axis, None if vertex is None else [round(v, 3) for v in vertex]])
            if vertex is not None and vertex[1] <= PARALLAX_MAX_SE_DEG:
                d[axis] += np.radians(vertex[0])
            else:
                d[axis] -= np.radians(moved)  # (none found: the pass leaves the turn as it was)
        n = len(known)
        self._take_appearance(frame, turned(d))
        cal.extra["appearance_parallax"] = {
            "rotation_deg": [round(float(v), 4) for v in np.degrees(d)],
            "frames": [int(v[1]) for v in views],
            "views_deg": [round(float(v[0]), 2) for v in views],
            "view_spread_deg": {
                "azimuth": round(float(spread[1]), 2),
                "elevation": round(float(spread[0]), 2),
            },
            "vertex_and_se_deg": found,
            "evaluations": n,
        }

    def _photo_cost(self, image, pose, shape, foreshortening: bool = True) -> float:
        """The photometric terms' cost of ``image`` on their finest level at ``pose`` and
        skin ``shape`` (V, 3) mm, head frame (``foreshortening``: :meth:`photometric_term`'s)."""
        est = Estimate(pose, np.zeros(self.n_muscles), shape,
                       np.zeros((len(shape), 3, self.n_muscles)), np.zeros(0, dtype=np.int64))  # fmt: skip
        total = 0.0
        for t in self.photometric_term(image, foreshortening=foreshortening):
            while t.settling:
                t.advance()
            t.prepare(est)
            total += t.cost(est)
        return total

    def set_offsets(self, offsets) -> None:
        """Take the detector's offsets on this face off every frame's points from now on
        (``offsets``: :class:`~myoface.analysis.landmarks.TrackerOffsets`, or None: not);
        before :meth:`calibrate`, so that the calibration reads corrected points too. Not
        with analysis by synthesis (which measures the offsets at each frame's estimate)."""
        self.offsets = offsets
        self._spread_w = None

    def _corrected(self, p, pose: HeadPose | None = None) -> np.ndarray:
        """``p`` with :attr:`offsets` taken off at ``pose`` (the previous frame's; without
        one, the pose of the person's neutral fitted to ``p``, then to the points corrected
        there)."""
        base = self.neutral + self.identity_mm
        if pose is None:
            pose = self._pose_only(p, initial_pose(base, p, self.camera), base)
            pose = self._pose_only(self.offsets.correct(p, pose, base), pose, base)
        return self.offsets.correct(p, pose, base)

    def photometric_term(self, image, start_level: int = 0, eye_weight: float = 1.0,
                         foreshortening: bool = True) -> list[PhotometricTerm] | None:  # fmt: skip
        """The photometric terms of ``image``: its brightness, and its redness with
        :attr:`FitSettings.photo_colour` (None without an image or an appearance); their
        coarse-to-fine schedule from ``start_level`` (:func:`~myoface.analysis.photometric.
        coarse_start`), the eyes' rim samples weighing ``eye_weight``
        (:func:`~myoface.analysis.photometric.eye_rim_weight`), the samples weighed by their
        foreshortening's change since calibration or not (``foreshortening``,
        :data:`~myoface.analysis.photometric.FORESHORTENING_POWER`)."""
        if image is None or self.appearance is None:
            return None
        s = self.settings
        kw = {"start_level": start_level, "eye_weight": eye_weight,
              "foreshortening": foreshortening}  # fmt: skip
        out = [PhotometricTerm(image, self.appearance, self.camera, s.photo_sigma, s.photo_huber,
                               **kw)]  # fmt: skip
        if self.appearance_colour is not None:  # (the same samples: the brightness's geometry)
            out.append(
                PhotometricTerm(image, self.appearance_colour, self.camera,
                                s.photo_colour_sigma, s.photo_huber, channel="redness",
                                peer=out[0], **kw)
            )  # fmt: skip
        return out

    def _sparsity_scale(self) -> np.ndarray | None:
        """Each muscle's share of the sparsity prior (:attr:`FitSettings.sparsity_reach`):
        its reach (the skin's motion per unit contraction: the norm over the vertices of
        the model's response) over the median reach of the fitted muscles, to that power; None
        at 0 (every muscle alike)."""
        p = self.settings.sparsity_reach
        if not p:
            return None
        reach = np.sqrt((self.model_response**2).sum(axis=(0, 1)))
        return (reach / np.median(reach[self._fitted])) ** p

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
        return pixel_mm(self.camera, pose)

    def _weights(self, pose: HeadPose, shape: np.ndarray) -> np.ndarray:
        """Base weights times visibility: points whose surface turns away from the camera
        weigh less (MediaPipe guesses them)."""
        tri = self.model.face.triangles
        n = vertex_normals(np.ascontiguousarray(shape, dtype=np.float64), tri) @ pose.rotation.T
        p = pose.apply(shape)
        view = -p / np.maximum(np.linalg.norm(p, axis=1, keepdims=True), 1e-9)
        cos = (n * view).sum(1)
        return self.base_weights * np.clip(cos / 0.3, 0.05, 1.0) * self._offset_weights(pose)

    def _offset_weights(self, pose: HeadPose):
        """The weights (V,) of the detector's offsets' own error
        (:attr:`FitSettings.offset_spread`, :func:`offset_spread_weights`), measured once,
        at the distance of the first pose they are asked at; 1 without offsets."""
        s = self.settings
        if self.offsets is None or not s.offset_spread > 0:
            return 1.0
        if self._spread_w is None:
            self._spread_w = offset_spread_weights(
                self.offsets.spread(pose), s.offset_spread, s.landmark_sigma_mm
            )
        return self._spread_w

    def landmark_term(self, points, weights, gain: float = 1.0, xy_weights=None) -> LandmarkTerm:
        """The landmark term of ``points`` (V, 3) with per-vertex ``weights`` (V,), the
        detector reading the skin's motion from the person's neutral at ``gain``
        (:class:`~myoface.analysis.terms.LandmarkTerm`)."""
        s = self.settings
        return LandmarkTerm(
            points,
            self.camera,
            weights,
            s.landmark_sigma_mm,
            s.depth_sigma_mm,
            s.huber,
            xy_weights=xy_weights,
            gain=None if gain == 1.0 else (gain, self.neutral + self.identity_mm),
        )

    def terms(self, points, weights, prev: FrameFit | None, flow=None, photo=None) -> list:
        """One frame's energy: the temporal prior to ``prev`` (when there is one), the
        magnitude and the sparsity priors, the landmarks, and the points the optical flow
        tracked (``flow``: ``(xy, tracked)``; in place of the landmarks' x, y where tracked)
        (:mod:`myoface.analysis.terms`)."""
        s = self.settings
        out: list = []
        if prev is not None:
            # (the frames since prev: more than one after frames not measured)
            age = self._prev_age if prev is self._prev else 1
            out.append(
                TemporalPrior(
                    prev,
                    age / self.fps,
                    s.rotation_rate_deg_per_s,
                    s.translation_rate_mm_per_s,
                    s.rate_per_s if photo is None else s.photo_rate_per_s,
                )  # fmt: skip
            )
        out += [
            MagnitudePrior(s.magnitude_sigma),
            SparsityPrior(s.sparsity, s.sparsity_knee, self._sparsity_scale()),
        ]
        if s.symmetry_sigma is not None:
            out.append(
                SymmetryPrior(mirror_pairs(self.model.ids), s.symmetry_sigma, s.symmetry_scale)
            )
        out += au_prior_terms(self.model.ids, s)  # the AU table's span (analysis.au_prior)
        if getattr(self, "_lid_image", None) is not None:  # (FitSettings.reads_lids)
            lid = self.lid_edge_term(self._lid_image)
            out.append(lid)
            weights = lid.landmark_weights(weights)  # (MediaPipe's lid points where read)
        # (the observations last: the priors' normal equations are summed first, then theirs)
        if photo is not None:
            # the pixels read the motion; MediaPipe's points stay as a weak term (they find
            # the face and keep the fit from a wrong minimum of the pixels)
            for t in photo:
                t.restart()
            if len(photo) > 1:  # (the channels' steps side by side: ChannelTerms)
                if self._channel_pool is None:
                    self._channel_pool = ThreadPoolExecutor(
                        max_workers=len(photo) - 1, thread_name_prefix="myoface-photo"
                    )
                out.append(ChannelTerms(photo, self._channel_pool))
            else:
                out += photo
            weights = weights * s.photo_landmark_weight
        gain = self.landmark_gain() if photo is not None and not self._gain_one else 1.0
        if flow is None:
            out.append(self.landmark_term(points, weights, gain))
            return out
        xy, tracked = flow
        out.append(
            self.landmark_term(
                points, weights, gain, xy_weights=(1.0 - tracked) * self._detector_weights
            )
        )
        out.append(
            OpticalFlowTerm(
                xy,
                tracked,
                self.camera,
                weights,
                s.landmark_sigma_mm,
                s.huber,
                footprint=self._footprint(),
            )  # fmt: skip
        )
        return out

    def set_flow_footprint(self, half: int | None) -> None:
        """The optical flow's points are read by patches ``2 half + 1`` px a side, centred
        where the calibrated neutral puts each vertex on the calibration frame (the
        model-anchored tracker's templates, :class:`~myoface.analysis.modelflow.ModelFlow`,
        which calls this): the flow's term then compares each point with the model's motion
        averaged over its patch (:class:`~myoface.analysis.terms.OpticalFlowTerm`,
        :attr:`FitSettings.flow_footprint`). None: with its vertex."""
        self._footprint_half = None if half is None else int(half)
        self._footprint_cache = None

    def _footprint(self):
        """(:class:`~myoface.analysis.terms.OpticalFlowTerm`'s ``footprint``: made once a
        calibration, :func:`~myoface.analysis.terms.patch_footprint`; None when not set.)"""
        half = self._footprint_half
        cal = self.calibration
        if half is None or cal is None or not self.settings.flow_footprint:
            return None
        cache = self._footprint_cache
        if cache is None or cache[0] is not cal:
            base = self.neutral + self.identity_mm
            pc = cal.pose.apply(base)
            uv = self.camera.project(pc)
            gap = _mouth_gap(self.model.face)
            fmat = patch_footprint(
                uv, -pc[:, 2], self.model.face.triangles, half, None if gap is None else uv[gap]
            )
            cache = (cal, (fmat, base))
            self._footprint_cache = cache
        return cache[1]

    def _fit(self, p, prev: FrameFit | None, refine: int, start: FrameFit | None = None,
             rest: bool = False, flow=None, photo=None, iterations=None):  # fmt: skip
        """The bounded Gauss-Newton fit of one frame (see the module's docstring), with the
        temporal prior to ``prev``, started from ``start`` (default: ``prev``; without
        either from a closed-form pose and no contraction). ``rest``: with the model
        linearised at rest (as a fit from nothing is) rather than where the tissue was last
        relaxed. ``flow``: as for :meth:`fit`."""
        m = self.n_muscles
        base = self.neutral + self.identity_mm
        seen = p  # where the frame's points are, the flow's where it tracked them
        if flow is not None:
            seen = p.copy()
            seen[flow[1], :2] = flow[0][flow[1]]
        start = prev if start is None else start
        if start is None:
            pose = initial_pose(base, seen, self.camera)
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
            pose, c, it, conv = self._gauss_newton(
                p,
                pose,
                c,
                c0,
                d0,
                jac,
                base,
                prev,
                flow=flow,
                photo=photo,
                iterations=iterations,
            )
            total_it += it
        shape = base + d0 + _linear(jac, c - c0)
        k = self._pixel_mm(pose)
        uv = self.camera.project(pose.apply(shape))
        resid = float(np.sqrt(((uv - seen[:, :2]) ** 2).sum(1).mean()) * k)
        occlusion = float("nan")
        if photo is not None:
            # (the brightness's patches: the redness of skin is nearly uniform)
            occlusion = photo[0].occlusion(Estimate(pose, c, shape, jac, np.arange(m)))
            if not self._gain_one:  # (analysis by synthesis: its rounds' fits not counted)
                self._gain_last = self._gain_stats(p, pose, base, uv, k)
        return FrameFit(c, pose, resid, total_it, conv, occlusion)

    def landmark_gain(self) -> float:
        """The detector's gain on the skin's motion under the photometric term
        (:attr:`FitSettings.photo_landmark_gain`; None there: this video's, estimated from the
        frames fitted so far, :data:`LANDMARK_GAIN_PRIOR` until they show expression)."""
        g = self.settings.photo_landmark_gain
        if g is not None:
            return float(g)
        dm, mm = self._gain_sums
        prior, weight = LANDMARK_GAIN_PRIOR
        return float(np.clip((dm + prior * weight) / (mm + weight), *LANDMARK_GAIN_RANGE))

    def _gain_stats(self, p, pose, base, uv, k) -> tuple[float, float]:
        """One fit's sums for :meth:`landmark_gain`: the detector's motion from the person's
        neutral (at the fitted pose) against the model's, both in the image (mm on the face),
        over the points that are neither the face's oval nor the lids'."""
        if self._gain_mask is None:
            mask = landmark_weights(self.model.face, 0.0) > 0
            for _, verts in lid_gains(self.model, base).values():
                mask[verts] = False
            self._gain_mask = mask
        j = self._gain_mask
        uv0 = self.camera.project(pose.apply(base[j]))
        mod = (uv[j] - uv0) * k
        det = (p[j, :2] - uv0) * k
        return float((det * mod).sum()), float((mod * mod).sum())

    def _gauss_newton(self, p, pose, c, c0, d0, jac, base, prev, free=None, flow=None,
                      photo=None, iterations=None):  # fmt: skip
        """One frame's energy (:meth:`terms`, visibility from the starting pose) minimised by
        :func:`~myoface.analysis.solver.bounded_gauss_newton` from ``pose``, ``c`` with the
        forward model ``base + d0 + jac (c - c0)``; only the contractions ``free`` move.
        Returns (pose, contractions, steps, converged)."""
        free = self._fitted if free is None else np.asarray(free, dtype=np.int64)
        jac = np.ascontiguousarray(jac)

        def forward(cc):
            return base + d0 + _linear(jac, cc - c0)

        w0 = self._weights(pose, forward(c))
        terms = self.terms(p, w0, prev, flow, photo)
        if iterations is not None:
            steps = int(iterations)
        elif photo is not None:  # (FitSettings.photo_iterations: the photometric fit's)
            # (less the steps of the coarse levels a schedule skips: photometric.coarse_start)
            steps = self.settings.photo_iterations - min(t._first_step() for t in photo)
        else:
            steps = self.settings.iterations
        return bounded_gauss_newton(terms, forward, jac, pose, c, free, steps)

    def _fit_identity(self, frames):
        """The poses and a smooth identity offset (V, 3) shared by the landmark ``frames``, every
        contraction at zero; then what the offset left of the frames' mean residual (in the
        image plane) is added to it, so that the neutral reproduces the calibration frames.
        Their z too only where :data:`IDENTITY_DEPTH` says (the generic face)."""
        s = self.settings
        nv = len(self.neutral)
        ident = np.zeros_like(self.neutral)
        if not self._reads_identity_depth():  # (the points' x, y only: IDENTITY_DEPTH)
            frames = [np.column_stack([p[:, :2], np.full(len(p), np.nan)]) for p in frames]
        poses = [initial_pose(self.neutral, p, self.camera) for p in frames]
        lap = laplacian(self.model.face)
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
                    term = self.landmark_term(p, w0)
                    rxy, rz, dist, use_z = term.residuals(pose, base, k)
                    w = w0 * term.huber_weights(dist)
                    hb, rhs = self._offset_blocks(pose, base, k, w, rxy, rz, use_z)
                    blocks += hb
                    g = g + rhs
                diag = sparse.bsr_matrix(
                    (blocks, np.arange(nv), np.arange(nv + 1)), shape=(3 * nv, 3 * nv)
                )
                h = (reg + diag).tocsc()
                ident = ident + _solve_spd(h, g).reshape(-1, 3)
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

    def _reads_identity_depth(self) -> bool:
        """Whether the calibration reads MediaPipe's depth into the neutral
        (:data:`IDENTITY_DEPTH`; by default only on a face without the person's texture)."""
        if IDENTITY_DEPTH is None:
            return self.model.face.texture is None
        return bool(IDENTITY_DEPTH)

    def _gauge(self, ident, poses):
        """The identity offset with no rigid motion in it: the rotation and translation that
        best map the person's neutral onto the model's (least squares over
        :func:`gauge_vertices`, which no muscle moves) moved from the offset into the poses.
        The points the camera sees are unchanged; the head frame is then the one in which
        the person's rigid points sit where the model's do, rather than wherever the
        offset's regularisation left it. On the head-motion closed loop (2026-12-01) it took
        the head angles' RMS error from 1.80 to 1.28 degrees with the head still and from
        2.99 to 2.79 with it moving (analysis.fidelity 0.870, was 0.872)."""
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
        dproj = self.camera.projection_jacobian(pose.apply(shape))
        jxy = np.einsum("vij,jk->vik", dproj, pose.rotation) * (k / s.landmark_sigma_mm)
        h = np.einsum("vji,vjk->vik", jxy, jxy) * w[:, None, None]
        g = -np.einsum("vji,vj->vi", jxy, rxy) * w[:, None]
        if use_z:
            # (the mean removal couples the points weakly; it is left out of the Jacobian)
            jz = -pose.rotation[2] / s.depth_sigma_mm
            h += w[:, None, None] * np.outer(jz, jz)[None]
            g -= (w * rz)[:, None] * jz[None]
        return h, g.ravel()


def _solve_spd(h, g: np.ndarray) -> np.ndarray:
    """``h^-1 g`` for a sparse symmetric positive definite ``h`` (CSC): SuperLU in its
    symmetric mode (a minimum-degree ordering of ``h + h^T``, the diagonal as pivots), which
    the identity's normal equations (a mesh Laplacian plus 3 x 3 blocks) factor in about half
    the time of :func:`scipy.sparse.linalg.spsolve`'s general ordering (measured 2026-12-04 on
    the sample video's calibration, 1404 unknowns: 3.6 against 6.8 ms a solve, the solutions
    within 1e-14 of each other)."""
    lu = splu(h, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
              options={"SymmetricMode": True})  # fmt: skip
    return lu.solve(g)


def _mouth_gap(face):
    """The mouth's gap's polygon's vertices (upper inner margin, then the lower one back), as
    the anchored tracker masks it (None for a face without the lips' margins)."""
    from myoface.face.lips import inner_lip_margins

    m = inner_lip_margins(face)
    return None if m is None else np.concatenate([m[0], m[1][::-1]])


def _linear(jac: np.ndarray, dc: np.ndarray) -> np.ndarray:
    """``jac @ dc`` (V, 3) for a response ``jac`` (V, 3, M) and contractions ``dc`` (M,), as
    one matrix-vector product (numpy's stacked matmul of (V, 3, M) by (M,) loops over V)."""
    m = jac.shape[2]
    return (np.ascontiguousarray(jac).reshape(-1, m) @ dc).reshape(-1, 3)
