"""The 3-D fit's weights: what each term of its energy is worth (:class:`FitSettings`, every
weight a standard deviation, with the measurements that set it) and the per-vertex weights and
structure the face model gives (the face oval, the model's own error, the lids' gains, the
muscles the skin cannot tell apart, the vertices no muscle moves)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse

from myoface.analysis.estimate import skin_response
from myoface.analysis.landmarks import rigid_vertices
from myoface.errors import MyofaceValueError


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
        x, y / 10 1.1 mm), so it only keeps the depth of the pose from being ill-posed. The
        calibration does not read it into the person's neutral
        (:data:`~myoface.analysis.modelfit.IDENTITY_DEPTH`: its tilt pitched the head frame).
    oval_weight : weight of the face oval's points (the mesh's outer rim), which MediaPipe
        puts on the face's silhouette, not on fixed skin, as the head turns. What is behind
        the head moves more of MediaPipe's points than the oval's (2026-12-07, evening; the
        degraded head-motion renders, head moving, camera seed 1, the same frames with and
        without the cluttered room): after a similarity transform, its points move 0.88 px
        (median), the oval's 2-2.8 and the ring just inside it 1.8-2.3, and the chin's inner
        points (175, 396, 171, 199, 200, 428, 208) shift along the mentalis' response: with
        the room the mentalis reads 1.0 with the head turned 30 deg where the truth is 0
        (RMSE 0.395, gain 2.0 on seed 1; 0.376 on seed 2; 0.053 on seed 0), without it 0.078.
        The points, not the pixels: MediaPipe's points from the frames without the room and
        the pixels from those with it, 0.167; the other way round, 0.675. Measured and not
        kept (seeds 1 / 2, worst RMSE, worst correlation, skin mm against 0.146 / 0.138, 0.35 /
        0.44, 0.74 / 0.76): the oval at 0.02, mentalis unchanged (0.392); the ring next to the
        oval at 0.5 (and seed 0: 0.136 / 0.139 / 0.165, 0.81 / 0.29 / 0.52, 0.70 / 0.69 /
        0.84; the six expression clips 0.733 / 0.904 against 0.748 / 0.892; gaze 4.52 deg
        against 4.05) or 0.2 (0.134 / 0.156 / 0.158, skin 0.71 / 0.83 / 0.79), mentalis
        0.37-0.47; every point weighed by ``d^2 / (d^2 + r^2)`` of its distance ``d`` from the
        projected oval, ``r`` 0.08 of the face's width: mentalis 0.11 / 0.18, worst RMSE 0.133
        / 0.127, skin 0.72 / 0.72, but the depressor labii inferioris, which the same chin
        points read, 0.42 / 0.55 -> 0.30 / 0.11 in correlation (the worst correlation 0.17 /
        0.08); ``r`` 0.04: mentalis 0.14 / 0.43, skin 0.68 / 0.80. (The renders' face has no
        neck: the room meets the chin directly, where a person's neck would be.)
        Nor the room taken away before MediaPipe looks (2026-12-08; a new install, whose
        numbers for the same commit were, seeds 0 / 1 / 2 head moving: worst RMSE 0.143 /
        0.153 / 0.138, median 0.080 / 0.113 / 0.091, worst correlation 0.11 / 0.50 / 0.40,
        skin 0.80 / 0.92 / 0.73 mm, head 0.50 / 1.07 / 0.62 deg; head still, median 0.061
        / 0.069 / 0.064, worst correlation 0.61 / 0.78 / 0.41, skin 0.50 / 0.56 / 0.68 mm):
        each frame shown to MediaPipe with everything outside its last frame's face oval (the
        oval's hull grown by 15 % about its centre, a 4 px feathered edge) blurred by a
        Gaussian of 25 px. Moving: worst 0.130 / 0.106 / 0.130, median 0.083 / 0.086 / 0.097,
        worst correlation 0.09 / 0.49 / 0.35, skin 0.80 / 0.81 / 0.73 mm, head 0.71 / 0.84 /
        0.64 deg, the mentalis of seed 2 0.35 -> 0.11; still: median 0.071 / 0.072 / 0.070,
        worst correlation 0.51 / 0.68 / 0.12, skin 0.56 / 0.60 / 0.55 mm. The hull grown by 8
        % or filled with the face's mean colour (seed 1): worst 0.125 / 0.114, mentalis
        0.22 / 0.20. With the detector's offsets (:attr:`tracker_offsets`) and their context
        (:attr:`detector_context`) read on renders masked the same way, about the model's own
        projected vertices, so that the correction is of the detector as the frames show it:
        moving 0.205 / 0.198 / 0.137, median 0.127 / 0.101 / 0.092, skin 1.13 / 1.00 / 0.80
        mm. The chin's false reading goes where the room is taken away, the pose and the
        still head's readings pay for it, and the consistent correction is worse: not kept.
    model_error : the model's own error at a point, as a fraction of the largest skin
        displacement any one muscle makes there at full contraction
        (:func:`model_error_weights`): a point the muscles move far (lips, cheeks, chin) is
        known less well than one no muscle moves (eye corners, nose bridge), because the
        model's muscles and tissue are an approximation of the person's. Without it, what an
        expression moves that the model cannot (a broad smile's cheeks bulging up and out)
        is explained by moving the head: on the sample video's smile the head rose ~1.2 mm
        against its eye corners and nose bridge, the chin then seemed to drop, and the jaw
        opened 0.13 rad behind closed teeth. The jaw does not count: it turns the mandible,
        which the chin's skin follows closely; counted, it made the chin and the lower lip
        (moved ~22 mm by the open jaw) weigh 0.16, and on the sample video's smile the fit
        then let the zygomatici raise the chin 4.5 mm and the lower lip 6 mm, where the video's
        chin stayed and its lower lip dropped as the lips parted (analysis.fidelity 0.18 with
        the jaw counted, 0.34 without; 2026-12-01). 0: every point is known to
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
        more; the fit's temporal prior takes that out. Measured again with the validated
        judges (2026-12-03, ``myoface bench --only analysis.fidelity`` and
        ``--only analysis.known_warp_gain``, tracking against detecting): on single_face.mp4
        the fidelity 0.707 against 0.783 (the lower lip 0.86 against 0.61 explained, gain 0.94
        against 0.48, but the chin -0.81 against 0.17, the corners 0.85 against 0.89, the
        brows 0.71 against 0.73, the lids 0.71 against 0.84); with ``--flow`` 0.783 against
        0.790; on the known warps (head still / moving) the brows 0.47 / 0.43 against 0.61 /
        0.59, the lids 0.43 / 0.37 against 0.62 / 0.61, the corners 0.64 / 0.62 against 0.59
        / 0.60, the lips 0.55 / 0.59 against 0.47 / 0.51, leak 0.25-0.27 against 0.20-0.21.
        Still off. Again with the photometric term the default (2026-12-07, tracking against
        detecting; ``tools/photometric_ablation.py``): single_face.mp4's fidelity 0.780
        against 0.778 (the lower lip 0.69 against 0.61, the chin -0.04 against 0.08); the
        known warps' worst gain 0.89 against 0.90 and the leak 0.054-0.058 against
        0.046-0.047; the degraded head-motion render (camera seed 0, head moving) worst RMSE
        0.110 against 0.166, median 0.089 against 0.100, but the worst correlation 0.48
        against 0.65 and the skin 0.892 against 0.811 mm (its rest frames 0.59 against
        0.24); the expression benchmark's clip apex / rest 0.531 / 0.698 against 0.698 /
        0.914; the pass over the sample 7 % faster (five alternating passes, 0.184x against
        0.170x MediaPipe). The rest read as expression costs more than the time saved:
        still off.
    flow : read the points optical flow tracks as a term of the fit's own
        (:class:`~myoface.analysis.terms.OpticalFlowTerm`), because MediaPipe reads an
        expression's motion short. Since 2026-12-02 the points come from
        :mod:`myoface.analysis.modelflow` (each read against the calibration frame, its
        template warped by the model's predicted pose and skin; that module and
        :mod:`myoface.bench.headmotion` / :mod:`myoface.bench.knownwarp` have its numbers;
        it costs ~3.3 ms of CPU a frame on the fit's thread and ~0.8 on the detector's, and
        the fit ~1 ms more with its term: ``tools/flow_compare.py fps`` 2026-12-02, process
        CPU 19.1 ms a frame against the default's 14.0, frames a second 0.188x MediaPipe's
        against 0.256x, in the same run; off by default for that). What follows is the
        earlier tracker's (:mod:`myoface.analysis.flow`, ``FitTracker(flow_method=
        "chained")``: each point tracked by Lucas-Kanade from the first frame with a face,
        else from the previous frame, used where the track is sure, in place of MediaPipe's
        x, y). Off by default: it
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
    #: (2026-12-06, night, the degraded head-motion renders, head moving, camera seeds 0, 1,
    #: 2, median worst RMSE / median RMSE / worst correlation / skin mm / head deg: 10:
    #: 0.156 / 0.108 / 0.52 / 0.827 / 0.72 against 0.149 / 0.101 / 0.51 / 0.818 / 0.72.)
    magnitude_sigma: float = 1.0
    #: (The same night, seed 0 alone: 0 gives 0.188 / 0.139 / 0.40 / 1.059 / 0.49 and 2
    #: 0.154 / 0.108 / 0.31 / 0.919 / 0.47 against 0.166 / 0.100 / 0.65 / 0.811 / 0.72; the
    #: corrugators 0.20 and 0.18 against 0.20: docs/expressions.md, "Which stage holds AU4
    #: and AU5".)
    sparsity: float = 4.0
    huber: float = 1.5
    tracking: bool = False
    flow: bool = False
    #: with :attr:`flow` (the model-anchored tracker): each tracked point compared with the
    #: model's motion averaged over the tracker's patch, not with its vertex (a patch
    #: tracker reads its window's mean motion, short of a peak's;
    #: :class:`~myoface.analysis.terms.OpticalFlowTerm` has why and what was measured).
    #: Known warps, head still (``tools/flow_known_warp_stages.py real``, 2026-12-02, off /
    #: on): mouth corners' gain 0.80 / 0.88, brows 0.87 / 0.93, lids 0.92 / 0.97, lips 0.98
    #: / 1.01, chin 0.94 / 0.97, explained >= 0.92, leak 0.058 / 0.040; head moving corners
    #: 0.80 / 0.88, brows 0.87 / 0.93. A point whose patch reaches over an eye's opening or
    #: past the face's outline keeps its vertex (:func:`~myoface.analysis.terms.
    #: patch_footprint`): averaged over the skin there, the lids read 0.80 (the patch's
    #: texture is the lid margin's edge, which moves with the margin). On single_face.mp4
    #: (``myoface bench --only analysis.fidelity``, the ``--flow`` row, off / on) overall
    #: 0.779 / 0.775: mouth corners 0.89 / 0.90, lower lip 0.63 / 0.59, brows 0.75 / 0.71,
    #: lids 0.37 / 0.40, chin 0.30 / 0.27; the gains rise (corners 0.82 / 0.84, brows 0.84 /
    #: 0.90): the real brows move further with it but their explained fraction falls, not
    #: yet understood. The head-motion renders' anchored-flow fit (90 frames) unchanged
    #: within the worst muscle's rounding: still worst RMSE 0.150 / 0.138, skin 0.80 / 0.79
    #: mm; moving 0.314 / 0.333, skin 1.28 / 1.30 mm, head 1.61 / 1.61 deg
    flow_footprint: bool = True
    #: with :attr:`flow` (the optical flow's points in the fit): MediaPipe's x, y at the
    #: points the flow did not track get a further error of this fraction of the largest
    #: displacement one muscle makes there (:func:`model_error_weights` with this in place of
    #: :attr:`model_error`: 1 where no muscle moves the skin, 0.2 at the mouth corners,
    #: ~0.35 at the brows). Why: MediaPipe's error on an expression is not scatter but a
    #: shortfall in proportion to the motion (it reads 0.49-0.66 of a known warp's motion,
    #: issue 30), and the motion at a point is bounded by what the muscles do there: 0.2 is
    #: that shortfall (~0.45) times a typical expression's contraction (~0.5). Where the
    #: flow reads the neighbours fully, MediaPipe's short reading of the lips' margins
    #: (never tracked) and of the points the flow drops pulled the muscles back: a weak term
    #: there, as the issue asks, and a full one where the skin does not move (the head's
    #: pose). Measured 2026-12-02 (0 / 0.2, both with :attr:`flow_footprint`): known warps
    #: (``tools/flow_known_warp_stages.py real``, head still) mouth corners' gain 0.88 /
    #: 0.91, lips 1.01 / 1.06, brows 0.93 / 0.92, lids 0.97 / 0.95, chin 0.97 / 1.02, leak
    #: 0.040 / 0.042; the head-motion renders' anchored-flow fit (16 frames, quick)
    #: head still worst RMSE 0.173 / 0.169, skin 0.80 / 0.79 mm; moving 0.284 / 0.295,
    #: median 0.165 / 0.150, skin 1.47 / 1.55 mm, head 2.12 / 2.11 deg (the flow keeps
    #: fewer points there, and the moving points it drops are MediaPipe's, weaker now);
    #: tests/analysis/test_flow_gain.py's smile with the lips left to MediaPipe at half the
    #: motion: the skin's gain 0.87 / 0.96 (every point tracked: 0.99 either way). **Off** (0: MediaPipe's x, y weigh as without
    #: the flow) because it does not carry over to a real smile: on single_face.mp4 with
    #: ``--flow`` (the validated judge, explained / gain, footprint on; 0 / 0.2) the mouth
    #: corners 0.90 / 0.84 -> 0.90 / 0.77, lower lip 0.59 / 0.46 -> 0.66 / 0.50, brows 0.71
    #: / 0.90 -> 0.72 / 0.85, chin 0.27 / 0.35 -> 0.30 / 0.37, overall 0.775 -> 0.786: at the
    #: real smile's apex the flow drops the corners' own patches (teeth, stretched lips, the
    #: folds) and MediaPipe's point is then the corner's only reading; weaker, the corner
    #: follows the cheek's skin beside it, which moves less. On the known warps with the
    #: look the expressions add (the teeth and the mouth's dark, the folds) the lips' gain
    #: went 1.08 -> 1.19 and the chin's 1.05 -> 1.12 (``analysis.known_warp_gain``'s full
    #: run). Weaker only where the flow reads the neighbours and not the point is what to
    #: try next.
    flow_landmark_error: float = 0.0
    iterations: int = 8
    refine: int = 1
    relax_step_mm: float = 2.0
    #: with the relax deferred: the fits made with the earlier linearisation while a relax
    #: runs on the second thread (0: the next fit waits for it). A relax costs more than a
    #: fit, so with 0 the fit's thread waits for most of each one. Measured 2026-12-03 on
    #: single_face.mp4 (2 cores): the fit's wait for relaxes 3.2 ms a frame with 0, 0.9-1.3
    #: with 1, ~0 with 2 (11 relaxes instead of 17: none starts while one runs);
    #: analysis.fidelity 0.779 (0) / 0.783 (2); on the test ramp with exact points (a smile
    #: and the jaw at 0.07 a frame) the skin's worst frame 0.12 / 0.17 / 0.27 mm RMS for 0 /
    #: 1 / 2, against MediaPipe's scatter of :attr:`landmark_sigma_mm`.
    relax_lag: int = 2
    #: with a :class:`LandmarkSynthesis`: rounds of analysis by synthesis per frame
    synthesis_rounds: int = 2
    #: the photometric term (:mod:`myoface.analysis.photometric`): read the frame's pixels
    #: against the calibration frame's appearance; a sample's brightness error (grey levels,
    #: 1 sd) and its Huber threshold (sigmas); MediaPipe's points then weigh this much.
    #: On by default since 2026-12-05 (``myoface analyze``; ``--no-photometric`` for the fit
    #: on MediaPipe's points alone): it measured best on every known answer (the known warps'
    #: gains 0.80-1.01 against 0.46-0.62, the degraded head-motion renders' skin 0.93 against
    #: 1.40 mm and head 0.53 against 1.63 deg, the expression clip 0.69 / 0.67 against 0.57 /
    #: 0.68), at 0.98 of the points' validated fidelity on the sample video (0.765 against
    #: 0.783) and about 0.65 of their frames a second (README, "The default analysis reads the
    #: pixels"; BENCHMARKS.md, 2026-12-05 10:45 UTC). Without a frame given (:meth:`~myoface.analysis.modelfit.ModelFit.fit`'s
    #: ``image``) a fit reads the points alone either way.
    photometric: bool = True
    #: (Measured 2026-12-06 against 8, the degraded head-motion renders, head moving, camera
    #: seeds 0, 1, 2: 5.6 worst RMSE 0.166, 0.132, 0.149 -> 0.142, 0.188, 0.194, skin 0.81,
    #: 0.83, 0.82 -> 0.71, 0.93, 0.85 mm; 4 -> 0.165, 0.269, 0.256 and 0.68, 1.02, 0.96 mm,
    #: though the corrugators' RMSE 0.20 -> 0.12-0.15: the pixels weighing more read the
    #: camera's noise as muscle. On the six expression clips pooled, apex / rest (the
    #: benchmark's value the lower), 0.696 / 0.885 -> 0.745 / 0.829 (5.6) and 0.812 / 0.756
    #: (4): the AUs held back are read, and as many that are not there at rest; per clip the
    #: rest frames fall to 0.63-0.65 on two of them. One trade between the two benchmarks'
    #: numbers, no gain on both: not taken.)
    photo_sigma: float = 8.0
    #: (Huber's threshold, in :attr:`photo_sigma`: a sample's residual beyond it weighs
    #: ``huber / |r|``. Measured 2026-12-08 against 2, on the install whose default numbers
    #: are BENCHMARKS.md's of that day; the degraded head-motion renders, seeds 0 / 1 / 2,
    #: head moving, worst RMSE, median RMSE, skin mm, the paper's muscles' median gain,
    #: the default 0.143 / 0.153 / 0.138, 0.080 / 0.113 / 0.091, 0.80 / 0.92 / 0.73, 0.86 /
    #: 0.76 / 0.81. 1: 0.120 / 0.178 / 0.131, 0.071 / 0.094 / 0.078, 0.74 / 0.80 / 0.71,
    #: 0.74 / 0.69 / 0.72 (the median RMSE and the skin better on every seed, the head the
    #: same); head still, median 0.068 / 0.075 / 0.065 against 0.061 / 0.069 / 0.064, worst
    #: correlation 0.53 / 0.67 / 0.40 against 0.61 / 0.78 / 0.41, skin 0.49 / 0.50 / 0.60
    #: against 0.50 / 0.56 / 0.68 mm; the known warps' worst gain 0.91 (still) and 0.93
    #: (moving), leak 0.040; single_face.mp4's fidelity 0.780 (chin 0.11); the gaze's three
    #: clips 4.39 / 4.46 / 3.72 against 4.59 / 4.04 / 3.67 deg; but the six expression clips
    #: pooled, apex / rest, 0.637 / 0.931 against 0.748 / 0.865: a residual that weighs less
    #: beyond 8 grey levels reads less of every change of look, the turning head's and the
    #: expression's alike, and the gain falls. 0.5: the gain 0.39-0.56, worst RMSE 0.18-0.23.
    #: 4: 0.141 / 0.127 / 0.146, 0.091 / 0.097 / 0.102, 0.84 / 0.85 / 0.76 mm. With the moving
    #: skin's pixels weighing more to give the gain back (1, :attr:`photo_model_error` 0.2):
    #: the expression clips 0.778 / 0.825 (one clip's rest frames 0.66), the renders head
    #: moving 0.170 / 0.135 / 0.146, 0.088 / 0.102 / 0.103, 0.87 / 0.88 / 0.69 mm: the trade
    #: of :attr:`photo_model_error`'s comment again. Kept at 2.)
    photo_huber: float = 2.0
    #: (MediaPipe's points under the photometric term: they read 0.5-0.7 of an expression's
    #: motion, so they pull the fit's gains down, but they keep it from the pixels' wrong
    #: minima where the model's appearance is least like the frame. Measured 2026-12-04 with
    #: the redness, 0.1 / 0.03 / 0.01: the known warps (head still, plain) mouth corners' gain
    #: 0.84 / - / 0.90, brows 0.81 / - / 0.86, eyelids 0.88 / - / 0.93, leak 0.107 / - / 0.090;
    #: but single_face.mp4's validated fidelity 0.771 / 0.726 / 0.689 (mouth corners' gain
    #: 0.84 / 0.73 / 0.69), the degraded head-motion renders, head moving, skin 0.95 / 1.00 /
    #: 1.05 mm, head 1.14 / 1.20 / 1.24 deg, worst RMSE 0.248 / 0.277 / 0.297; head still skin
    #: 0.65 / 0.70 / 0.76 mm: the real smile and the renders a camera degraded lose more than
    #: the clean known warps gain. Kept at 0.1.)
    #: (Again 2026-12-06, night, on the degraded head-motion renders over camera seeds 0, 1,
    #: 2, the median; head moving: worst RMSE, median RMSE, worst correlation, skin mm,
    #: head deg; the default 0.149, 0.101, 0.51, 0.818, 0.72: 0.03: 0.168, 0.101,
    #: 0.54, 0.839, 0.66, head still 0.113, 0.064, 0.47, 0.606 mm against 0.121, 0.069, 0.38,
    #: 0.589; 0.05: 0.159, 0.103, 0.54, 0.826, 0.63 and still 0.116, 0.069, 0.42, 0.596: each
    #: seed moves more than the medians do (0.03: worst RMSE 0.115, 0.272, 0.168). Kept.)
    photo_landmark_weight: float = 0.1
    #: with :attr:`photometric`: the gain at which MediaPipe reads the skin's motion from the
    #: person's neutral (its points compared with ``neutral + g (skin - neutral)``, posed and
    #: projected: :class:`~myoface.analysis.terms.LandmarkTerm`'s ``gain``; the head's pose
    #: read in full). None (the default): this video's, estimated as it is analysed
    #: (:meth:`~myoface.analysis.modelfit.ModelFit.landmark_gain`: the least-squares slope of
    #: the detector's motion on the fitted model's, in the image, over every frame fitted so
    #: far, from 0.6 until the frames show expression; held to 0.3-1). 1: MediaPipe's points
    #: taken at their word, as before 2026-12-05. Why: a detector that reads part of the
    #: motion (0.49-0.66 of a known warp's on real frames, issue 30) pulled the pixels' reading
    #: short by as much as the points weigh, wherever both read the skin; how much it reads is
    #: the detector's and the face's, not a constant: the estimate came out 0.61-0.64 on the
    #: known-warp clips, 0.58 / 0.69 on the degraded head-motion renders (head moving / still)
    #: and 0.83 on single_face.mp4's real smile, whose look (the teeth, the lips' shape)
    #: MediaPipe reads as well as its motion (its mouth corners at 1.18 of the validated
    #: reader's motion there; ``myoface bench --only analysis.fidelity``'s ``stages``). The
    #: fit reaches a fixed point at the detector's true gain (the pixels weigh more than the
    #: points: each frame's estimate moves the fit's by a small fraction of its error).
    #: Measured with :attr:`photo_rate_per_s` (below; ``tools/photometric_ablation.py warp |
    #: headmotion | video | expression --set ...``, the benchmarks' own clips).
    #: (Again 2026-12-06, night, on the degraded head-motion renders over camera seeds 0, 1,
    #: 2, the median; head moving: worst RMSE, median RMSE, worst correlation, skin mm,
    #: head deg; the default 0.149, 0.101, 0.51, 0.818, 0.72: 1: 0.165, 0.097, 0.52,
    #: 0.832, 0.72. Kept.)
    photo_landmark_gain: float | None = None
    #: with :attr:`photometric`: the temporal prior's rate (in place of :attr:`rate_per_s`,
    #: which stays the points' fit's: there it takes out MediaPipe's scatter from frame to
    #: frame). The pixels read a frame with far less scatter than the points, and at 4 / s the
    #: prior held back every rise and fall: an expression that rises in 0.2 s (the known-warp
    #: clips, a posed smile) was read with a lag, and short. 8: a contraction changes by 0.27
    #: a frame at 30 frames/s (1 sd). Measured 2026-12-05 (gain 1 and rate 4, as before /
    #: gain estimated, rate 4 / gain 0.6, rate 8 / the two defaults, gain estimated and rate
    #: 8): the known warps' worst gain 0.803 / 0.875 / 0.901 / 0.897 (head still, mouth
    #: corners), explained >= 0.948 / 0.961 / 0.975 / 0.971, leak 0.110 / 0.086 / 0.060 /
    #: 0.060; the degraded head-motion renders, head moving, worst RMSE 0.238 / 0.223 / 0.220
    #: / 0.224, median 0.120 / 0.109 / 0.118 / 0.117, worst correlation 0.52 / 0.25 / 0.28 /
    #: 0.24, skin 0.93 / 0.98 / 0.98 / 0.98 mm, head 0.53 / 0.53 / 0.52 / 0.53 deg; head
    #: still skin 0.70 / 0.70 / 0.65 / 0.66 mm, median RMSE 0.092 / 0.099 / 0.101 / 0.099;
    #: single_face.mp4's validated fidelity 0.765 / 0.752 / 0.766 / 0.766, its mouth
    #: corners' gain 0.81 / 0.82 / 0.87 / 0.87; the expression clip (apex / rest) 0.69 / 0.67,
    #: 0.69 / 0.68, -, 0.75 / 0.81 (rate 8 alone 0.73 / 0.71; the defaults 0.76 / 0.84, and 0.76 / 0.81
    #: in BENCHMARKS.md's full runs of 13:37 and 14:23 UTC, once the appearance's parallax search read the
    #: points at gain 1, :meth:`~myoface.analysis.
    #: modelfit.ModelFit.landmark_gain`, the rest the same to 0.002; the other columns were
    #: measured before that). Rate 12 with the gain
    #: estimated: the same known warps (0.895), the expression clip 0.77 / 0.76. Not taken:
    #: one gain per point (each drawn to the face's; known warps 0.891, expression clip 0.79 /
    #: 0.76), sparsity 2 (known warps 0.908, but the moving head's skin 1.15 mm, median RMSE
    #: 0.148), :attr:`photo_model_error` 0.35 (0.897; skin 1.21 mm).
    #: (Again 2026-12-06, night, on the degraded head-motion renders over camera seeds 0, 1,
    #: 2, the median; head moving: worst RMSE, median RMSE, worst correlation, skin mm,
    #: head deg; the default 0.149, 0.101, 0.51, 0.818, 0.72: 30: 0.147, 0.105, 0.53,
    #: 0.811, 0.72: the same; the errors are not the prior's lag. Kept.)
    photo_rate_per_s: float = 8.0
    #: with :attr:`photometric`: the frame's redness (``R - G``) read as a second channel
    #: (:func:`~myoface.analysis.photometric.redness`), against the calibration frame's,
    #: and its sample's error (grey levels of ``R - G``, 1 sd). Where it shows: the lips'
    #: border (red against the skin's paler red) and the lips against the teeth and the
    #: mouth's dark, which the brightness shows faintly. Its sigma is the brightness's
    #: (:attr:`photo_sigma`) in proportion to the two channels' residual spreads at the fit on
    #: single_face.mp4 (robust sd over the finest level's samples, median over the frames:
    #: brightness 6.7, redness 2.9 grey levels; 8 x 2.9 / 6.7 = 3.5): the redness is less
    #: shaded, so what the model's surface does not reproduce of it is smaller. Measured
    #: 2026-12-04 (off / on; ``myoface analyze single_face.mp4 --photometric --report`` and
    #: the ``--photometric`` rows of the benchmarks' details): single_face.mp4's validated
    #: fidelity 0.65 / 0.77 (lower lip -0.14 / 0.55, chin -0.19 / 0.14, brows 0.59 / 0.65,
    #: mouth corners 0.90 / 0.90); the known warps (head moving, plain) mouth corners' gain
    #: 0.79 / 0.85, brows 0.73 / 0.80, eyelids 0.77 / 0.86, leak 0.145 / 0.11; the degraded
    #: head-motion renders, head moving: worst RMSE 0.245 / 0.248, median 0.138 / 0.146, skin
    #: 0.98 / 0.96 mm, head 0.92 / 1.15 deg; the
    #: expression clip (apex / rest) 0.51 / 0.75 -> 0.70 / 0.76; gaze 6.07 -> 7.14 deg and
    #: frames/s 0.64 -> 0.39 of the default's (BENCHMARKS.md's full runs, 2026-12-04 01:37 and
    #: 03:50 UTC).
    photo_colour: bool = True
    photo_colour_sigma: float = 3.5
    #: with :attr:`photometric`: a frame's Gauss-Newton steps at most (in place of
    #: :attr:`iterations`; the coarse-to-fine levels take one each, the finest the rest).
    #: The frames rarely stop early (7.3 steps a frame of 8 on single_face.mp4): the later
    #: steps move the estimate by a little more than the solver's tolerances but change
    #: nothing measured. Measured 2026-12-04 (8 / 5): the known warps (all eight variants) the
    #: same gains, explained fractions and leaks to 0.0002; the degraded head-motion renders,
    #: head moving, worst RMSE 0.248 / 0.247, median 0.146 / 0.146, skin 0.96 / 0.95 mm, head
    #: 1.15 / 1.15 deg; single_face.mp4's fidelity by region (8 / 5 / 4 steps) the same to
    #: 0.02. The fit's CPU a frame 26.2 -> 21.0 ms (one pass of each on the sample,
    #: ``tools/photometric_profile.py``). (Without the 4 px level, 4: measured, not taken, at
    #: :data:`~myoface.analysis.photometric.BLUR_SCHEDULE_PX`.) A frame whose schedule skips
    #: the coarsest level (:data:`~myoface.analysis.photometric.COARSE_START_PX`) takes one
    #: step fewer: the same steps on the levels it is on.
    #: (2026-12-07, for ``analysis.fps``: the pass over single_face.mp4 against MediaPipe
    #: alone, five interleaved runs each, 5 / 3: 0.158x / 0.192x (medians 1.63 / 1.37 s); the
    #: degraded head-motion renders, head moving, camera seed 0, 5 / 4 / 3: worst RMSE 0.166 /
    #: 0.167 / 0.197, worst correlation 0.65 / 0.65 / 0.55, gain 0.65 / 0.63 / 0.60, skin
    #: 0.811 / 0.831 / 0.875 mm, head 0.72 / 0.75 / 0.76 deg; single_face.mp4's fidelity
    #: 0.778 / 0.780 / 0.783. Fewer steps leave the turning head's frames short: kept at 5.
    #: Nor did starting each frame from the head pose extrapolated from the last two
    #: frames' help (at 5 steps: skin 0.949 mm, head 0.99 deg).)
    photo_iterations: int = 5
    #: the lids read from the image as a term (:func:`myoface.analysis.lidtemplate.lid_term`:
    #: the closure of each eye's opening against the calibration frame, where it closes, in
    #: place of MediaPipe's upper lid points, which do not close in a blink; the lid margins'
    #: edges, :mod:`myoface.analysis.lidedges`, opt-in there). What was measured is in
    #: :mod:`myoface.analysis.lidtemplate` (gaze 5.05 -> 5.03 deg, fidelity 0.756 -> 0.763).
    #: None (the default): on without the photometric term, off with it (:attr:`reads_lids`),
    #: whose samples on the lids read their closure themselves. Measured 2026-12-04 with
    #: ``--photometric`` (on / off): single_face.mp4's validated fidelity 0.764 / 0.765 (its
    #: eyelids 0.811 / 0.812), the blink's frames said closed both ways and the gaze there
    #: held alike (SD 1.5 / 1.2 deg either way); gaze on the benchmark's clip and four more
    #: 3.31, 5.10, 4.58, 2.99, 5.16 / 3.33, 5.15, 4.53, 3.00, 4.66 deg; the known warps the
    #: same to 0.005; the expression clip 0.740 / 0.784 both; the pass over the sample 3-11 %
    #: faster (interleaved runs; the template's reading is 1.2-1.4 ms of a frame's fit).
    lid_edges: bool | None = None
    #: the AU-space prior (:mod:`myoface.analysis.au_prior`): contractions held near the AU
    #: table's span, sigma in contraction units (None: off; opt-in, see that module)
    au_prior_sigma: float | None = None
    #: the AU-space prior over the AUs that share a muscle (:func:`~myoface.analysis.au_prior.
    #: shared_aus`: AU1 and AU2, whose principal muscles are the frontalis' inner and outer
    #: parts and which share its middle part at 0.25 and 0.5), sigma in contraction units
    #: (None: off; the whole table's prior, :attr:`au_prior_sigma`, takes its place where
    #: that is on). The middle part belongs to neither AU, and where the frames blur the
    #: forehead's skin the fit gave a brow raise to it alone: on the degraded head-motion
    #: renders at surprise's apex the middle part at its bound, 1.0, where the truth has
    #: 0.47, the inner and outer parts 0.2 where it has 0.7 (the clean renders split it
    #: right; the L1 prior, :attr:`sparsity`, prices the middle part's larger reach lower).
    #: The paper's hierarchy resolves what the skin does not tell: the three parts are held
    #: near AU1 and AU2's span, at :data:`~myoface.analysis.au_prior.AU_PRIOR_SIGMA` (the
    #: whole table's prior's, chosen before any run). Measured 2026-12-06 (off / on): the
    #: degraded head-motion renders, camera seeds 0, 1, 2, head moving: worst RMSE 0.199,
    #: 0.204, 0.187 -> 0.166, 0.132, 0.149, median RMSE (median) 0.103 -> 0.101, worst
    #: correlation 0.49 -> 0.51, skin 0.894, 0.905, 0.835 -> 0.811, 0.826, 0.818 mm; head still
    #: worst 0.172, 0.166, 0.186 -> 0.114, 0.121, 0.136, median 0.077 -> 0.069, skin 0.587,
    #: 0.629, 0.714 -> 0.531, 0.589, 0.673 mm; the six expression clips pooled, apex / rest
    #: 0.668 / 0.819 -> 0.689 / 0.825; single_face.mp4's validated fidelity 0.778 either way
    #: (every region the same), the known warps the same to 0.01. Not taken wider: the AUs
    #: that share the orbital sphincter's upper part too (AU6 with AU7) read the moving head
    #: alike (skin 0.835 mm) but single_face.mp4's brows 0.70 -> 0.28 (fidelity 0.724), as
    #: the whole table's prior does.
    #: (Again 2026-12-06, night, on the degraded head-motion renders over camera seeds 0, 1,
    #: 2, the median; head moving: worst RMSE, median RMSE, worst correlation, skin mm,
    #: head deg; the default 0.149, 0.101, 0.51, 0.818, 0.72: None: 0.199, 0.103,
    #: 0.49, 0.894, 0.71. Kept.)
    shared_au_sigma: float | None = 0.1
    #: the photometric samples' weight for the model's own error, as :attr:`model_error` is
    #: the landmarks' (:func:`model_error_weights` at each sample: 1 where no muscle moves the
    #: skin, 0.5 where one moves it 2 mm at full contraction). The calibration frame's
    #: appearance does not change as the skin moves, a person's skin does (its folds, shading
    #: and stretch): weighed in full where the muscles move it, the pixels drove the muscles
    #: that explain a change of look best, not the motion. Measured 2026-12-02 (0 / 0.5 / 1):
    #: degraded head-motion renders, head moving, skin 1.64 / 1.03 / 1.18 mm, head 1.52 / 1.22 /
    #: 1.17 deg, worst RMSE 0.67 / 0.24 / 0.29; head still, skin 0.50 / 0.65 / 0.89 mm, worst
    #: correlation -0.08 / 0.94 / 0.89; single_face.mp4's analysis.fidelity 0.33 / 0.50 / 0.53
    #: (without the photometric term 0.58); the known warps (a real frame warped, its look
    #: otherwise unchanged: what favours reading the moving skin) lower, brows' gain 0.88 /
    #: 0.74, mouth corners' 0.79 / 0.72, leak 0.063 / 0.13. Fixing the pose from the rigid
    #: skin's pixels first and the muscles from all of them then (two stages) took the head to
    #: 1.22-1.30 deg but the skin to 1.80-2.05 mm: not done. Again with the redness
    #: (2026-12-04, 0 / 0.25 / 0.5): the known warps, head still, plain, mouth corners' gain
    #: 0.90 / - / 0.84, brows 0.92 / - / 0.81, eyelids 0.97 / - / 0.88, leak 0.047 / - / 0.107;
    #: but single_face.mp4's fidelity 0.705 / 0.768 / 0.771 and the degraded head-motion
    #: renders, head moving, skin 1.37 / 1.03 / 0.95 mm, median RMSE 0.187 / 0.150 / 0.146,
    #: head 1.23 / 1.20 / 1.14 deg: kept at 0.5.
    #: Tried since and not kept (2026-12-06; the expression benchmark's clips, apex / rest %
    #: read right; patches of the study, not in the code): the weight from the skin's
    #: displacement at the frame's start (the last frame's contractions) rather than from the
    #: largest any muscle could make, ``1 / (1 + (0.5 d / sigma)^2)``: the brows and the lips
    #: read more fully (AU1's gain 0.51 -> 0.83, AU25's 0.01 -> 0.43; ``bench`` 70.8 / 75.9 ->
    #: 82.3 / 50.0), but a face at rest then weighs its pixels in full and the turning head's
    #: look is read as expression. Eased in, the static weight at rest and the displacement's
    #: by ``min(1, d / E0)``: E0 4 mm, the benchmark's six clips pooled 65.1 / 81.8 -> 74.7 /
    #: 71.7, three held out 71.2 / 67.3 -> 77.8 / 46.5 (E0 2 and 8 mm on ``bench``: 81.2 /
    #: 62.1, 78.1 / 75.9); with ``d`` MediaPipe's points' displacement instead (no feedback
    #: from the fit's own reading; E0 3 mm) the same trade (``p2`` 87.5 / 89.7 -> 83.3 / 38.8).
    #: Again with the rest reference's |yaw| term (2026-12-07; E0 4 mm, the last frame's
    #: contractions): ``bench`` 0.698 / 0.914 -> 0.698 / 0.629, the corrugators read at a gain
    #: of 0.93 where the default reads 0.62, but the risorius at 1.29 and the orbital sphincter
    #: at 1.36, and the rest frames as disgust: the same trade, the rest reference no help.
    #: The apex gains are real; what they cost at rest is the appearance's view
    #: (:meth:`~myoface.analysis.modelfit.ModelFit.set_view_appearances`: with the views at
    #: rest given, ``bench`` 83.3 / 94.8, ``p2`` 78.1 / 89.7 with the MediaPipe-eased weight).
    #: (2026-12-07: what this weight does to the gain, :meth:`~myoface.bench.headmotion.
    #: HeadMotionResult.gain`, on the head-motion renders, head moving, camera seed 0; the
    #: paper's frontalis parts / the corrugators / the depressor anguli oris, the skin at rest
    #: and in expressions, mm; ``tools/photometric_ablation.py headmotion``. 0.5: degraded
    #: 0.58-0.68 / 0.46 / 0.36, rest 0.24, expressions 0.87; clean 0.77-0.87 / 0.55 / 0.72,
    #: 0.36 and 0.57. 0: degraded 1.02-1.48 / 1.03 / 1.10 but rest 1.08, expressions 1.27, the
    #: risorius read at 1.66; clean 1.00-1.11 / 0.97 / 1.56, rest 0.79: the weight is what
    #: holds the gain, and what it holds back is the turning head's look, read at rest
    #: even on the clean renders. Tried and not kept, over camera seeds 0, 1, 2 against the
    #: default's worst RMSE 0.166, 0.132, 0.149 and skin 0.81, 0.83, 0.82 mm: the weight from
    #: the strain the muscles make at the sample rather than its displacement (the
    #: appearance is carried exactly where the skin only moves; it cannot follow where the
    #: skin stretches or folds), ``1 / (1 + (s / s0)^2)`` with ``s`` the largest linearised
    #: strain of the sample's vertex's edges at any muscle's full contraction: s0 0.1 gave
    #: seed 0 0.165 and 0.75 mm (the gains 0.87-1.04 / 0.79 / 0.88) but seeds 1 and 2 0.235,
    #: 0.288 and 0.92, 0.99 mm, rest 0.41-0.70 mm; s0 0.05, 0.07, 0.14 the same trade; 0.25
    #: with :attr:`photo_sigma` 10 or 12 (the moving skin weighing more, the pixels as a whole
    #: less): worst 0.148, 0.204, 0.207 and 0.175, 0.199, 0.193, skin 0.86-0.97 mm, rest
    #: 0.49-0.67 mm. Nor with views of the face at rest (:meth:`~myoface.analysis.modelfit.
    #: ModelFit.set_view_appearances`, the clean renders' frames at rest 3, 6 and 87 at the
    #: fit's own poses): 0.5 / 0.25 / 0.1 worst 0.109 / 0.130 / 0.145, skin 0.51 / 0.62 /
    #: 0.78 mm (the frontalis' gains 0.71-0.89 / 0.87-1.03 / 0.92-1.06), and with the
    #: renderer's furrows off as well the same (0.51 / 0.61, and 0 0.85 mm): on renders whose
    #: texture and surface are the model's own, the moving skin's pixels weighed more read the
    #: expressions in full and the rest less well.)
    #: (2026-12-07, what that look is: on the clean renders at 0 the skin at rest 0.79 mm,
    #: 0.57 with the renders' specular highlight off (``tools/photometric_ablation.py
    #: headmotion --clean --specular 0``; the fit's light is Lambertian) and 0.43 with the
    #: person's neutral exact too (``--identity exact``). And the weight eased by the head's
    #: turn from the calibration's pose, ``0.5 turn^2 / (turn^2 + 10^2)`` (full weight near
    #: the calibration's view): degraded, seed 0, skin 0.811 -> 0.860 mm, at rest 0.236 ->
    #: 0.628: the frames near the calibration's view read the camera's degradation as
    #: expression as much as the far ones read the turn. docs/expressions.md, "Ten more
    #: stages asked".)
    #: (2026-12-08, on the degraded renders: the highlight is not what holds them. The
    #: head-motion renders drawn with a matte skin (``SkinMaterial.specular`` 0) and degraded
    #: as the benchmark's, head moving, seeds 0 / 1 / 2: worst RMSE 0.228 / 0.177 / 0.119,
    #: median 0.097 / 0.109 / 0.072, skin 0.85 / 0.69 / 0.69 mm, head 0.71 / 0.67 / 0.44 deg,
    #: against 0.143 / 0.153 / 0.138, 0.080 / 0.113 / 0.091, 0.80 / 0.92 / 0.73, 0.50 / 1.07 /
    #: 0.62 with the highlight (the same install): another draw, not a better one; and on the
    #: matte renders this weight at 0.15: worst 0.252 / 0.172 / 0.221, skin 0.99 / 0.70 / 0.85
    #: mm. The moving skin's pixels weighed more read worse with or without the highlight.)
    #: (2026-12-07, later: the damping undone after the fact, as a relaxed lasso does
    #: (Meinshausen 2007): each frame, once fitted, two more Gauss-Newton steps with only
    #: the muscles it read above 0.05 free, the moving skin's pixels weighed in full and no
    #: sparsity prior (a scratch patch of ``ModelFit._fit``). The degraded head-motion
    #: render, seed 0, head moving: the paper's muscles' median gain 0.65 -> 1.06, but worst
    #: RMSE 0.166 -> 0.219, median 0.100 -> 0.129, worst correlation 0.65 -> 0.34, skin
    #: 0.811 -> 1.049 mm (at rest 0.24 -> 0.55); single_face.mp4's validated fidelity 0.778
    #: -> 0.750. Half way (the weight's floor at 0.25, the sparsity prior kept): gain 0.75,
    #: worst RMSE 0.220, worst correlation 0.01, skin 0.899 mm; fidelity 0.768. What the
    #: weight damps is noise as much as gain: not taken.)
    #: 0.35 since 2026-12-07, night, with each sample weighed also by how little its
    #: foreshortening changed since calibration
    #: (:data:`~myoface.analysis.photometric.FORESHORTENING_POWER`, whose comment has the
    #: numbers): the turning head's look weighed down where it arises, this weight, which held
    #: it back over the moving skin everywhere, eased. The two together against 0.5 alone:
    #: the head-motion renders' skin 0.82 -> 0.74 mm and median RMSE 0.101 -> 0.089, the
    #: expression clips 0.696 / 0.885 -> 0.748 / 0.892 (held out 0.608 / 0.672 -> 0.632 /
    #: 0.770), the gaze's five clips 4.17 -> 4.36 deg on average (worse; the benchmark's
    #: median of three 4.24 -> 4.05), the codec's decoded fidelity 0.618 -> 0.547 (worse).
    photo_model_error: float = 0.35
    #: identity offset (calibration): the difference of neighbouring vertices' offsets (mm, 1
    #: sd) and the offset itself (mm, 1 sd)
    identity_edge_sigma_mm: float = 1.0
    identity_sigma_mm: float = 10.0
    #: take the detector's own offsets on this face off its points
    #: (:class:`~myoface.analysis.landmarks.TrackerOffsets`: the person's model, with its own
    #: texture, rendered neutral from each view direction it is seen from and read by
    #: MediaPipe; a model without a texture: not done). See that class for why and what was
    #: measured.
    tracker_offsets: bool = True
    #: for a model without a texture (the default face): the same table with the
    #: calibration frame as the texture (each vertex of the calibrated neutral where the
    #: calibration put it; :meth:`~myoface.analysis.synthesis.LandmarkSynthesis.from_frame`),
    #: then the calibration done again with the corrected points. Off: measured 2026-12-02
    #: it does not help on the real video (see the README's 3-D fit section).
    tracker_offsets_frame: bool = False
    #: with the detector's offsets of a textured face (:attr:`tracker_offsets`): at the
    #: calibration, MediaPipe's error also measured on the person's model laid over each
    #: calibration frame (the video's own room, hair and neck around it), and its excess over
    #: the table's (which renders the model on a plain background) added to the table at
    #: every view (:meth:`~myoface.analysis.modelfit.ModelFit.measure_detector_context`,
    #: where what was measured is).
    detector_context: bool = True
    #: with the detector's offsets taken off (:attr:`tracker_offsets`): a point's landmark
    #: variance grows by ``(offset_spread * spread)^2``, ``spread`` (mm) how far the detector's
    #: offset at that point, less the face's rigid part, moves across the views of a turning
    #: head (:meth:`~myoface.analysis.landmarks.TrackerOffsets.spread`;
    #: :func:`offset_spread_weights`): the correction at a frame's view is only as good as
    #: the table there (its grid, its interpolation, one read of MediaPipe a cell, and the
    #: camera it does not see), and where the offset moves far with the view (the jaw line,
    #: the chin, the forehead's top row) what it misses is large. 1: the spread counted one for
    #: one as the correction's own error (not tuned past it).
    #:
    #: At da930c9's muscles (the smile's field on the lower lip changed; both this and
    #: :data:`~myoface.analysis.modelfit.SCORE_CORRECTED` off / on, the full benchmarks):
    #: analysis.expression_accuracy's synthetic clip, apex 0.49 / 0.43, rest 0.78 / 0.86
    #: (the headline, the lower, 0.49 / 0.43), AUs at rest AU17 0.43 / 0.21, AU23 0.23 / 0.47
    #: (the lower face's false reading moves from the chin raiser to the lip tightener),
    #: AU12 0.13 / <0.05, AU20 0.16 / 0.10, contraction RMSE median 0.185 / 0.156 (this
    #: alone: apex 0.36, rest 0.93; the scoring alone: 0.43, 0.70); analysis.headmotion,
    #: moving, worst RMSE 0.316 / 0.295, median 0.166 / 0.149, skin 1.28 / 1.27 mm, head
    #: 1.79 / 1.89 deg; still, median 0.114 / 0.118, skin 1.00 / 1.03 mm. Set 0 to go back.
    #:
    #: Measured (issue 30, 2026-12-02, at e2115bd's muscles; degraded renders, MediaPipe).
    #: After the correction, the points' residual to the true vertices at rest scatters 1.2 mm
    #: (median over points) to 3.3 mm (the jaw line, the chin) and follows the pitch by up to
    #: 0.2 mm a degree; its spread correlates 0.53 with the table's. The expression
    #: benchmark's synthetic clip (356 frames, head moving), 0 / 1: AUs read at rest (means
    #: over the rest frames) AU17 0.17 / 0.085, AU23 0.25 / 0.17, AU4 0.13 / 0.12, AU10 0.08 /
    #: <0.05, AU12 0.10 / 0.06, AU5 0.17 / <0.05; contraction RMSE median 0.178 / 0.149, worst
    #: (12 muscles + jaw) 0.283 / 0.277; skin 1.30 / 1.20 mm. analysis.headmotion (90
    #: frames): head moving, worst RMSE 0.390 / 0.289, median 0.168 / 0.152, worst
    #: correlation -0.22 / -0.21, skin 1.34 / 1.32 mm, head 1.80 / 1.92 deg; head still,
    #: worst 0.212 / 0.226, median 0.105 / 0.107, worst correlation 0.73 / 0.57 (the inner
    #: brows': the forehead's top row weighs less), head 1.40 / 1.54 deg. The spread with the
    #: rigid part left in weighed the forehead less still (head still, worst correlation
    #: 0.41). Much of the gain is the landmarks weighing less as a whole (their residual after
    #: the correction is ~1.8 mm RMS, against landmark_sigma_mm's 1): every point weighed
    #: 0.26 (the spread weights' mean) gave on the clip AU17 0.11, AU23 0.16, median 0.148,
    #: skin 1.24 mm. The spread weighs only where the offsets are taken off (a textured
    #: model), so the default face on a real video is unchanged. Weighing each point by its
    #: visibility (its normal's cosine to the view, n.v) is not the lever: the residual after
    #: the correction is nearly flat in n.v (1.7 mm RMS at n.v > 0.9, 1.9 at 0.2-0.3, 2.2
    #: behind the outline), and giving the fit the true positions of every point with n.v <
    #: 0.3 left AU17 at 0.13 and AU23 at 0.23. A finer table (5 or 2.5 deg) did not help
    #: either (AU17 0.21, 0.30: more cells, each one read of MediaPipe, more of its scatter).
    #:
    #: **Off** (0) by default: at the released muscles (b5a2c3f), with
    #: :data:`~myoface.analysis.modelfit.SCORE_CORRECTED` on, ``myoface bench --only
    #: analysis.expression_accuracy`` gave apex 0.40 / 0.34 / 0.34 and rest 0.81 / 0.91 / 0.92
    #: at offset_spread 0 / 0.5 / 1 (both off: 0.56 / 0.79): what it takes off the rest frames
    #: it takes off the expressions too (the landmarks weigh less as a whole: the prior
    #: damps), and a damped fit is what the analysis must not be rewarded for. Opt in with
    #: ``FitSettings(offset_spread=1.0)``.
    offset_spread: float = 0.0
    #: fit the mandible's sideways turn (the lateral pterygoids, FACS AD30;
    #: :class:`~myoface.muscles.types.PterygoidMuscle`) as well; off, the fit holds them at
    #: rest. Off by default, measured 2026-12-05 (on / off): single_face.mp4's validated
    #: fidelity 0.767 / 0.767 (chin 0.023 / 0.014): the fit set them below 0.1 on every frame
    #: although the validated reader reads the chin 2 % of the inter-ocular distance
    #: sideways through the smile. On a degraded head-motion render (head moving) with a known
    #: sideways jaw (0.3 and 0.25 of the travel, 2.4 and 2.0 mm at the chin;
    #: ``tools/jaw_sideways_render.py [--on]``) the default fit read them at correlations
    #: 0.76 and 0.83, but at up to 0.68 where the truth was 0.24 and 0.5 where it was 0 (the
    #: skin 1.29 mm from the truth, 1.00 with them held); the points' fit alone at 0.72 and
    #: 0.65, up to 0.24 and 0.10.
    #: Free, they took up head turns: the appearance's parallax search (calibration) found 2.5
    #: degrees of turn where there was none, and a looped clip was not read alike loop after
    #: loop (0.06 apart; tests/analysis/test_photometric.py).
    jaw_sideways: bool = False
    #: the sparsity prior as the minimax concave penalty with this knee (a contraction; None:
    #: the L1 prior, :class:`~myoface.analysis.terms.SparsityPrior`): the L1 prior's pull
    #: fades to nothing at the knee, so that large contractions are not read short. Measured
    #: 2026-12-05 (the L1 prior / knee 0.1 / 0.2 / 0.35 / :attr:`sparsity` 8 with knee 0.2):
    #: the known warps' worst gain 0.897 / 0.906 / 0.900 / 0.899 / 0.925 (brows 0.90 ->
    #: 0.94-0.95, eyelids 0.90-0.92 -> 0.95-0.97; leak 0.060 -> 0.043-0.045);
    #: single_face.mp4's validated fidelity 0.767 / 0.774 / 0.767 / 0.768 / 0.767 (mouth
    #: corners' gain 0.87 -> 0.88-0.89); but the degraded head-motion renders, head moving,
    #: worst RMSE 0.22 / 0.30 / 0.29 / 0.26 / 0.28, median 0.12 / 0.18 / 0.18 / 0.17 / 0.15,
    #: skin 0.98 / 1.40 / 1.39 / 1.29 / 1.27 mm: there many muscles read high (with 8 and
    #: 0.2 the depressor anguli oris' mean error +0.08 -> +0.24), which the L1 prior's pull
    #: had held down. On the clean renders (no camera) the concave prior was as good or better
    #: (skin 0.84 -> 0.80 mm, head 0.84 -> 0.45 deg, median 0.10 -> 0.12), without the
    #: moving light still worse (skin 0.89 -> 1.07 mm): the camera's other degradations are
    #: read as muscle. Not taken.
    sparsity_knee: float | None = None
    #: the sparsity prior weighs each muscle by its reach (the skin's motion per unit of its
    #: contraction, over the fitted muscles' median) to this power: 0, every muscle alike
    #: (a unit of contraction costs the same whatever skin it moves); 1, a millimetre of the
    #: skin's motion costs the same whichever muscle makes it. The reach (the norm over the
    #: vertices of its response, mm per unit contraction) runs from 4 mm
    #: (depressor supercilii, mentalis) through 20 (the median) to 59 (zygomaticus major) and
    #: 210 (the jaw), so at 1 the zygomaticus pays three times the median muscle's prior and
    #: the mentalis a quarter. Measured 2026-12-05 (0 / 0.5 / 1; the degraded head-motion
    #: renders over the camera seeds 0, 1, 2): head moving, skin 0.98, 1.17, 0.99 / 0.93,
    #: 1.14, 0.97 / 0.90, 0.84, 0.98 mm; head still 0.66, 0.60, 0.76 / 0.63, 0.57, 0.69 /
    #: 0.62, 0.56, 0.63 mm; but the expression clip (apex / rest) 0.76 / 0.83 -> 0.56 / 0.58
    #: -> 0.42 / 0.62 (the lids' raiser, cheap, read at rest and in smiles: AU5 0.04 -> 0.14
    #: at rest), the known warps' worst gain 0.897 -> 0.878 -> 0.858 (the corners),
    #: single_face.mp4's validated fidelity 0.766 -> 0.774 -> 0.731 (the corners' gain 0.87
    #: -> 0.86 -> 0.69). Not taken. Nor (2026-12-06) each muscle weighed by its price in
    #: the AU table's units, one over the largest weight any AU gives it (the frontalis'
    #: middle part, 0.25 in AU1 and 0.5 in AU2, and the depressor supercilii and the
    #: orbital sphincter's upper part at 2, the rest 1-1.1): on the degraded head-motion
    #: renders the L1 prior gives a brow raise to the frontalis' middle part alone at its
    #: bound (surprise's apex: 1.0 where the truth has 0.47, the inner and outer parts 0.2
    #: for 0.7), which the clean renders split right. Priced so, head moving (camera seeds
    #: 0, 1, 2, median) worst RMSE 0.199 -> 0.181, median 0.103 -> 0.108, worst correlation
    #: 0.49 -> 0.47, skin 0.894 -> 0.867 mm; head still worst 0.172 -> 0.158, skin 0.629 ->
    #: 0.620 mm; the six expression clips pooled, apex / rest 0.668 / 0.819 -> 0.656 / 0.855
    #: (per clip -0.07 to +0.04 at the apex): within the clips' spread, not taken.
    sparsity_reach: float = 0.0
    #: the symmetry prior (:class:`~myoface.analysis.terms.SymmetryPrior`): each pair of
    #: muscles that mirror one another contract alike, within this sigma (a contraction; None:
    #: no prior), robustly: Cauchy's loss beyond :attr:`symmetry_scale` (None: quadratic), so
    #: that a difference of a few tenths, a one-sided action the frames show, is hardly pulled
    #: at all (at 0.6 a tenth of the quadratic prior's weight). Why: on the degraded
    #: head-motion renders the fit read a symmetric action on one side and gave the other's to
    #: a neighbouring muscle (frontalis inner 0.71 on both sides read 0.61 and 0.00, the left's
    #: motion given to the frontalis major, 0.67 against 0.47; the depressor anguli oris 0.63
    #: on both read 0.66 and 0.00), with the head turned and also nearly frontal.
    #: Measured 2026-12-05 (off / quadratic 0.3 / quadratic 0.1 / Cauchy 0.1 with scale 0.2,
    #: the default), the degraded head-motion renders over camera seeds 0, 1, 2: head moving,
    #: skin 0.97, 1.14, 0.97 / 0.85, 0.96, 0.90 / 0.84, 0.88, 0.83 / 0.84, 0.98, 0.84 mm,
    #: worst correlation 0.30, 0.21, 0.25 / 0.64, 0.24, 0.31 / 0.20, 0.46, 0.38 / 0.36, 0.42,
    #: 0.38, median RMSE 0.113, 0.144, 0.136 / 0.103, 0.131, 0.119 / 0.112, 0.133, 0.113 /
    #: 0.099, 0.142, 0.115; head still, skin 0.66, 0.59, 0.78 / 0.63, 0.59, 0.76 / 0.62,
    #: 0.58, 0.76 / 0.62, 0.58, 0.76 mm, median RMSE 0.099, 0.076, 0.077 / 0.086, 0.074,
    #: 0.067 / 0.083, 0.072, 0.064 / 0.082, 0.072, 0.064; the known warps' worst gain 0.905 /
    #: 0.899 / 0.901 / 0.900 (the mouth corners, head still); single_face.mp4's validated
    #: fidelity 0.771 / 0.777 / 0.778 / 0.778 (brows 0.66 -> 0.70). A smile of one zygomaticus
    #: major (0.7) on the turned, degraded render (tests/analysis/test_degraded.py), head
    #: turned 20 / 30 degrees: the person's left read 0.58 / 0.48 without the prior, 0.54 /
    #: 0.45 with quadratic 0.3, 0.38 / - with quadratic 0.1, 0.54 / 0.42 with the default;
    #: the right 0.65 / 0.64, 0.60 / 0.59, 0.47 / -, 0.63 / 0.60; the other side at most 0.13
    #: (quadratic 0.1), else 0.05. The quadratic prior strong enough to help as much damps a
    #: one-sided smile by a third; weak enough not to, it helps half as much (and the known
    #: warps' corners fall under 0.9). Expressions (off / the default, apex / rest %): the
    #: benchmark's clip 78 / 79 -> 71 / 76 (its sadness read as neutral: AU4 0.14 -> 0.09 of
    #: 0.45, the corrugators' one-sided readings go with it); the four clips
    #: ``tools/expression_runs.py`` holds out (heldp, p2, held, small) 71/64, 78/63, 62/66,
    #: 67/68 -> 68/88, 80/69, 71/93, 69/71 (mean 70 / 65 -> 72 / 80), their contractions'
    #: median RMSE 0.132, 0.126, 0.161, 0.110 -> 0.101, 0.093, 0.129, 0.095 and the worst
    #: muscle's 0.42, 0.40, 0.37, 0.34 -> 0.29, 0.36, 0.27, 0.18. BENCHMARKS.md's full runs
    #: (443f870 off, b9c1095 the default): the codec's bits a frame 27.9 -> 23.9 and its
    #: decoded fidelity 0.589 -> 0.633. **What it costs: gaze.** The five clips of
    #: ``tools/gaze_clips.py`` 4.48, 6.61, 5.15, 7.37, 3.73 -> 4.16, 6.56, 6.81, 7.55, 6.25
    #: deg (mean 5.47 -> 6.27; the benchmark's median of the first three 5.15 -> 6.56). On
    #: those clips the face is at rest, and what the fit reads there spuriously on one side it
    #: now reads on both (clip (31, 1): the mentalis 0.26 on the right -> 0.47 on both; clip
    #: (11, 5): the depressor anguli oris and the inner frontalis 0.13-0.15 on both), which
    #: moves the head frame the gaze is read in (clip (11, 5): both eyes' mean pitch error
    #: -4.5 -> -5.9 deg). Cauchy 0.2: gaze mean 5.67, the head-motion skin 0.85, 1.07, 0.94
    #: mm, the known warps 0.899. Leaving the lids' muscles or the mentalis out of the pairs
    #: did not change the gaze (the benchmark's three clips' median 6.55; the five clips'
    #: mean 6.35 deg), nor did leaving out every pair of the upper face (the brows', the
    #: eyes' and the lids': the five clips 4.48, 6.61, 6.43, 7.36, 6.55, mean 6.29), which
    #: also kept less of the head-motion gain (skin 0.85, 0.91, 0.90 mm): the lower face's
    #: symmetric spurious readings move the head frame as well.
    #: (Again 2026-12-06, night, on the degraded head-motion renders over camera seeds 0, 1,
    #: 2, the median; head moving: worst RMSE, median RMSE, worst correlation, skin mm,
    #: head deg; the default 0.149, 0.101, 0.51, 0.818, 0.72: None: 0.203, 0.128, 0.32,
    #: 0.972, 0.75. Kept.)
    symmetry_sigma: float | None = 0.1
    #: the symmetry prior's scale (a contraction): Cauchy's loss ``scale^2 log(1 + (d /
    #: scale)^2)`` of the two sides' difference ``d`` (over ``symmetry_sigma^2``); None: the
    #: quadratic ``d^2``
    symmetry_scale: float | None = 0.2

    def __post_init__(self) -> None:
        for name in ("symmetry_sigma", "symmetry_scale"):
            v = getattr(self, name)
            if v is not None and not (np.isfinite(v) and v > 0):
                raise MyofaceValueError(f"{name} must be None (none) or > 0; got {v}")
        for name in ("au_prior_sigma", "shared_au_sigma"):  # (None or 0: off, as before)
            v = getattr(self, name)
            if v is not None and not (np.isfinite(v) and v >= 0):
                raise MyofaceValueError(f"{name} must be None or 0 (off) or > 0; got {v}")
        g = self.photo_landmark_gain
        if g is not None and not 0 < g <= 1.5:
            raise MyofaceValueError(
                f"photo_landmark_gain must be None (estimated) or in (0, 1.5]; got {g}"
            )
        for name in ("rate_per_s", "photo_rate_per_s"):
            if not getattr(self, name) > 0:
                raise MyofaceValueError(f"{name} must be > 0; got {getattr(self, name)}")
        k = self.sparsity_knee
        if k is not None and not 0 < k <= 1:
            raise MyofaceValueError(f"sparsity_knee must be None (L1) or in (0, 1]; got {k}")

    @property
    def reads_lids(self) -> bool:
        """Whether the lids' term is read (:attr:`lid_edges`; None: without the photometric
        term only)."""
        return (not self.photometric) if self.lid_edges is None else bool(self.lid_edges)


# ------------------------------------------------------------------ the model's structure


def landmark_weights(face, oval_weight: float = FitSettings.oval_weight) -> np.ndarray:
    """Per-vertex base weights (V,): 1, ``oval_weight`` on the face oval (the mesh's outer
    boundary loop, which MediaPipe places on the silhouette)."""
    w = np.ones(face.n_vertices)
    loops = face.boundary_loops
    if loops:
        w[loops[0]] = oval_weight
    return w


def offset_spread_weights(spread_mm, scale: float = 1.0,
                          sigma_mm: float = FitSettings.landmark_sigma_mm) -> np.ndarray:  # fmt: skip
    """Per-vertex weights (V,) for the detector's offsets' own error
    (:attr:`FitSettings.offset_spread`): ``1 / (1 + (scale * spread_mm / sigma_mm)^2)``, the
    landmark's variance ``sigma_mm^2`` grown by ``(scale * spread_mm)^2`` (``spread_mm``
    (V,): :meth:`~myoface.analysis.landmarks.TrackerOffsets.spread`)."""
    if not scale >= 0:
        raise MyofaceValueError(f"offset_spread must be >= 0; got {scale}")
    return 1.0 / (1.0 + (scale * np.asarray(spread_mm, dtype=np.float64) / sigma_mm) ** 2)


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
    return np.asarray(rigid_vertices(model))


def laplacian(face) -> sparse.csr_matrix:
    """The mesh graph's Laplacian (V, V): sum over edges of (e_a - e_b)(e_a - e_b)^T."""
    e = face.edges
    n = face.n_vertices
    rows = np.concatenate([e[:, 0], e[:, 1], e[:, 0], e[:, 1]])
    cols = np.concatenate([e[:, 0], e[:, 1], e[:, 1], e[:, 0]])
    vals = np.concatenate([np.ones(2 * len(e)), -np.ones(2 * len(e))])
    return sparse.csr_matrix((vals, (rows, cols)), shape=(n, n))
