"""The whole analysis on known answers made from real frames (names stable across releases):
the sample video's first frame warped by the motion the face model makes for an expression
(:func:`~myoface.analysis.knownwarp.expression_warp`: the model's skin displacement at the
expression's contractions, mapped onto the frame's landmarks and interpolated linearly between
them), rising, held and falling, with and without fake head motion, analysed by the 3-D fit
(:class:`~myoface.analysis.trackers.landmark_fit.FitTracker`, as ``myoface analyze`` runs
it); the model's motion read exactly from its own vertices (the fit's skin relaxed at each
frame's contractions, head frame) and compared, region by region, with the warp's.

The field is one a face makes: a sum of bumps at the regions' points (the reader's own
validation, ``tests/analysis/test_motionreader.py``) is not, and given the warped points
exactly the fit reproduced only 0.34-0.4 of the lips' and chin's bumps (2026-12-01); given the
expression warp's points exactly it reproduces 0.86-1.07 of every region.

``analysis.known_warp_gain``: the region whose gain is farthest from 1 (the model's motion
over the warp's, least squares), ``analysis.known_warp_explained``: the lowest ``1 - sum
|d_model - d_true|^2 / sum |d_true|^2``, over both clips of the default analysis. The
targets: gain in [0.9, 1.1] and explained >= 0.9 in every region. The detail gives every
region, head still and moving, the leak (the model's motion error at the rigid points), the
contractions' RMSE against the truth, and the same for the photometric fit
(:mod:`myoface.analysis.photometric`).

A full run also analyses the clips **with the look** the expressions add
(:data:`LOOK_KEYS`; :func:`~myoface.analysis.knownwarp.expression_look`): a warp moves a
real frame's pixels but a real expression also changes what they show. The smile's lips part
(:data:`LOOK_EXTRA`: the jaw at 0.2, as in the sample video's smile) and the teeth and the
dark of the mouth show between them, and its nasolabial folds deepen; surprise's mouth shows
its inside and the forehead folds. The motion is the known answer as before; the look is what
a reader of pixels that assumes the calibration frame's appearance must not read as motion.
These are in the detail only; the headline numbers stay the plain clips'. Measured
2026-12-02 at e2e7a8f (``myoface bench --only analysis.known_warp``; head still / moving),
gain per region with the look (without it): the default analysis' mouth corners 0.72 / 0.75
(0.57 / 0.56), lips 0.90 / 0.87 (0.51 / 0.52), brows 0.50 / 0.45 (0.57 / 0.56), eyelids
0.58 / 0.58 (0.52 / 0.57), chin 0.89 / 0.81 (0.53 / 0.48); the photometric fit's mouth
corners 0.86 / 0.89 (0.72 / 0.73), lips 1.18 / 1.21 (0.95 / 0.98), brows 0.70 / 0.69 (0.75 /
0.73), eyelids 0.68 / 0.67 (0.80 / 0.77), chin 1.15 / 1.18 (0.96 / 0.99); explained >= 0.85
in every region with the look (the default's lowest 0.57). The look does not damp the
photometric fit as the sample video's real smile does (its mouth corners' gain there 0.54,
the default's 0.65): the mouth's dark and teeth open its lips and jaw by a fifth more than
the warp, and its corners move more with them.

The fit with optical flow (``myoface analyze --flow``) by each point tracker
(``flow, anchored``: :mod:`myoface.analysis.modelflow`, every point against the calibration
frame through the model; ``flow, chained``: :class:`~myoface.analysis.flow.FlowRefiner`).
Measured 2026-12-02 at 4c5dcdb (``myoface bench --only analysis.known_warp_gain``; head
still / moving, gain and explained): anchored mouth corners 0.81 / 0.80 (explained 0.95),
lips 0.97 / 0.98, brows 0.87, eyelids 0.91, chin 0.95 / 0.96 (explained >= 0.95 in every
region), leak 0.060 / 0.058; chained 0.80, 0.90 / 0.89, 0.83 / 0.84, 0.86 / 0.87, 0.88 /
0.87, leak 0.073 / 0.069; the default's 0.48-0.57 and leak 0.22 in the same run. With the
look, anchored corners 0.75 / 0.79 (chained 0.90 / 0.89: the corners' patches stop matching
the calibration frame as the look changes them, and MediaPipe's points stand there), lips
1.06 / 1.08, brows 0.81, eyelids 0.86, chin 1.04 / 1.06.

With the flow's term reading each point against the model's motion averaged over the
tracker's patch (:attr:`~myoface.analysis.weights.FitSettings.flow_footprint`, since
2026-12-02: a patch reads its window's mean motion, short of a peak's; at the points the
anchored tracker read 0.90 of the corners' and 0.97 of the brows' motion, of their patches'
mean 0.98 and 1.00), measured 2026-12-02 (``myoface bench --only analysis.known_warp_gain``;
head still / moving, gain): anchored mouth corners 0.88 / 0.87, lips 0.99 / 0.99, brows
0.93, eyelids 0.97 / 0.96, chin 0.96, explained >= 0.93 in every region, leak 0.040; with
the look corners 0.81 / 0.83, lips 1.10, brows 0.86 / 0.87, eyelids 0.91 / 0.93, chin 1.06.
The corners' gain with a perfect patch reader (``tools/flow_known_warp_stages.py
exact_patch``) is 0.91, with every point given exactly 0.92: what is left is mostly the
clips' own. The warp moves the frame by the model's x, y displacement (mapped by the nose's
similarity), while the fit sees the model through a camera at the person's pose (2-3
degrees off frontal, the face off the image's centre), where the smile's corners, which
move back 3.7 mm as they rise 4.9 mm, show 7 % more motion with their depth than without
it (0.97 against 0.91 of the warp's; the rest a scale the inter-ocular distance takes out):
the smile that reproduces the warp there is that much short in the head frame.

Since 2026-12-03 the clips' field is **projected** (:data:`FIELD`; ``field="flat"`` keeps the
construction above): the person's skin as the default fit calibrates it on the clip's first
frame, moved by the model at the expression's contractions, seen through the fit's camera at
the calibration's pose (:func:`~myoface.analysis.knownwarp.projected_warp`), and the truth
judged against is that skin's motion in the head frame (x, y, in its own inter-ocular
distance), where the model's motion is read. The flat field was not the image of any motion
of a face seen at that pose: at the calibration pose the smile's 3-D motion projects to 1.08
times its x, y motion at the mouth's corners, 1.13 at the lips, and surprise's chin, which
moves back 5-6 mm as the jaw opens below the camera's axis, to 0.71 (``1 / 1.08 = 0.92``:
the corners' gain with every point given exactly on the flat field). The geometry is the
default fit's for every variant, so that every analysis is judged on the same clips; the
calibration's pose is a fitted one, so the clips hold no error of the pose the fit starts
from. Measured 2026-12-03 (:func:`run_known_warp`, head still / moving, gain):
anchored flow mouth corners 0.93 / 0.91, lips 0.96 / 0.94, brows 0.92 / 0.93, eyelids 0.94
/ 0.95, chin 0.94 / 0.91, explained >= 0.97 in every region, leak 0.046 / 0.040: every region
in [0.9, 1.1]; the default's 0.46-0.62 (explained >= 0.51), leak 0.20 / 0.21. The corners
gain what the flat field withheld; the lips, lids and chin lose 0.02-0.05 (surprise's chin
and lips, which the flat field overstated, now ask for what the camera sees).

The default analysis (the photometric fit since 2026-12-05) with MediaPipe's points read at
the detector's own gain and a looser temporal prior
(:attr:`~myoface.analysis.weights.FitSettings.photo_landmark_gain`,
:attr:`~myoface.analysis.weights.FitSettings.photo_rate_per_s`), full runs of 10:45 and
13:37 UTC (head still / moving, gain): mouth corners 0.83 / 0.85 -> 0.90 / 0.92, lips 0.97 /
1.00 -> 1.01 / 1.02, brows 0.81 / 0.80 -> 0.90 / 0.90, eyelids 0.88 / 0.86 -> 0.92 / 0.90,
chin 0.99 / 1.01 -> 1.01 / 1.02, explained >= 0.971, leak 0.106 / 0.110 -> 0.058 / 0.060;
the worst, the smile's corners with the head still, 0.897. Given every point exactly the fit
reaches 1.015 there (``tools/flow_known_warp_stages.py exact_all``); from the pixels alone
(the points weighing 0.01) 0.87 on the smile, whatever the priors: the textured skin beside
the corner moves less than the corner, and does not pin it.
"""

from __future__ import annotations

import numpy as np

from myoface.bench import Measurement, benchmark

#: the clip: neutral frames (the calibration finds the person's neutral there), then the
#: expression rising, held, and falling
NEUTRAL_FRAMES = 6
RISE, HOLD, FALL = 6, 6, 6
#: the expressions the clips make (each at this intensity): together they move every region
#: (the smile the mouth corners, cheeks and lower lids; surprise the brows, upper lids, and
#: the jaw: lips and chin)
EXPRESSIONS = ("happiness", "surprise")
INTENSITY = 0.8
#: the bump programme the reader of motion is validated on (tests/analysis/test_motionreader.py,
#: :func:`~myoface.analysis.knownwarp.region_warp`): the amounts at the apex, inter-ocular
#: distances, image axes (x right, y down), one row per region point or one for all, and the
#: bumps' radius
APEX_IOD = {
    "mouth_corners": [[-0.05, -0.04], [0.05, -0.04]],  # out and up: a smile's corners
    "lips": [[0, -0.02], [0, -0.01], [0, 0.02], [0, 0.03]],  # the lips part a little
    "brows": [[0, -0.03]],  # raised
    "eyelids": [[0, 0.01], [0, 0.0], [0, 0.01], [0, 0.0]],  # the upper lids lowered
    "chin": [[0, 0.03]],  # down
}
RADIUS_IOD = 0.25
#: the clips with an expression's look (:func:`make_clip`'s ``look``): the contractions added
#: at the apex, as the sample video's smile does: its lips part (the lower lip drops ~4 mm
#: while the chin stays); the jaw at 0.2 parts the model's smile by 0.064 inter-ocular
#: distances at the lips' centre (0.021 without), where the look shows the teeth and the dark
#: of the mouth
LOOK_EXTRA = {"happiness": {"jaw": 0.2}}
#: the detail's keys of the clips with the look (a full run; every variant). The headline
#: numbers (``known_warp_gain``, ``known_warp_explained``) stay the clips' without it, as
#: before, so that they compare with earlier runs
LOOK_KEYS = ("head still, with the look", "head moving, with the look")
#: the clips the headline numbers are taken over
PLAIN_KEYS = ("head still", "head moving")
GAIN_TARGET = (0.9, 1.1)
EXPLAINED_TARGET = 0.9
#: the analyses compared: the default (the 3-D fit with its photometric term, since
#: 2026-12-05) alone and with the model-anchored flow (``--flow``), the fit on MediaPipe's
#: points alone (``--no-photometric``, the default before), and that fit with optical flow
#: (``--no-photometric --flow``) by each of its point trackers
#: (:data:`~myoface.analysis.modelflow.FLOW_METHODS`): FitSettings' changes, and the flow's
#: tracker (key ``"flow_method"``)
VARIANTS = {
    "default": {},
    # the default with the model-anchored flow's points (myoface analyze --flow)
    "default with flow, anchored": {"flow": True, "flow_method": "anchored"},
    "points": {"photometric": False},
    "flow, anchored": {"photometric": False, "flow": True, "flow_method": "anchored"},
    "flow, chained": {"photometric": False, "flow": True, "flow_method": "chained"},
}


#: how the clips' field is made (:func:`make_clip`'s ``field``): ``"projected"``, the face's
#: 3-D motion seen through the camera at the calibration's pose
#: (:func:`~myoface.analysis.knownwarp.projected_warp`), judged in the head frame; ``"flat"``,
#: the model's x, y motion mapped by the nose's similarity
#: (:func:`~myoface.analysis.knownwarp.expression_warp`), judged in the image (the construction
#: before 2026-12-03)
FIELDS = ("projected", "flat")
FIELD = "projected"


def calibrated_geometry(frame, model):
    """What a projected clip is made with (:func:`make_clip`): the default fit calibrated on
    ``frame`` held still for :data:`NEUTRAL_FRAMES` frames (its person's skin, its camera and
    the head's pose). The same for every analysis compared (whatever the variant's settings):
    the clips are the same, only their analysis differs."""
    from myoface.analysis.trackers.landmark_fit import FitTracker
    from myoface.analysis.weights import FitSettings

    # (MediaPipe's points alone: the clips as they were made before the photometric term
    # became the default; the pose and the skin are the points' either way)
    tracker = FitTracker(model, fps=30.0, settings=FitSettings(photometric=False))
    try:
        tracker.calibrate(iter(_Clip([frame] * NEUTRAL_FRAMES, 30.0)), 0)
        return tracker.fit, tracker.calibration.pose
    finally:
        tracker.close()


def _envelope(n_neutral, rise, hold, fall) -> np.ndarray:
    ramp = 0.5 - 0.5 * np.cos(np.linspace(0, np.pi, rise + 1)[1:])
    return np.concatenate([np.zeros(n_neutral), ramp, np.ones(hold), ramp[::-1]])


class _Clip:
    """Frames in memory with what the analysis' driver reads of a video."""

    def __init__(self, frames, fps: float):
        self.frames = frames
        self.fps = float(fps)
        self.n_frames = len(frames)
        self.size = (frames[0].shape[1], frames[0].shape[0])
        self.path = "known-warp clip"

    def __iter__(self):
        return iter(self.frames)


def make_clip(frame, points, model, expression: str, head_moves: bool, quick: bool = False,
              look: bool = False, field: str = FIELD, geometry=None):  # fmt: skip
    """The known-warp clip of ``frame`` (its landmarks ``points``): the face model's
    ``expression`` rising, held and falling, with fake head motion if ``head_moves``, and
    with ``look`` the look the expression adds painted on each frame as strong as the
    expression is then (:func:`~myoface.analysis.knownwarp.expression_look`: the lips' gap,
    teeth and the dark of the mouth, folds; the motion unchanged).

    ``field`` (:data:`FIELDS`): ``"projected"``, the person's skin (``geometry``: (fit,
    pose), default :func:`calibrated_geometry`) moved by the model at the expression's
    contractions and seen through the fit's camera at the calibration's pose
    (:func:`~myoface.analysis.knownwarp.projected_warp`); ``"flat"``, the model's x, y
    motion (:func:`~myoface.analysis.knownwarp.expression_warp`). Returns (frames, the true
    displacements (T, 468, 2) of the expression alone: ``"projected"``, the skin's x, y in
    the head frame, mm, y down; ``"flat"``, the image's, pixels; the true contractions (T,
    M))."""
    from myoface.analysis.knownwarp import expression_look, expression_warp, projected_warp
    from myoface.control import expression_contractions

    if field not in FIELDS:
        raise ValueError(f"field must be one of {FIELDS}; got {field!r}")
    if field == "projected":
        fit, pose = geometry or calibrated_geometry(frame, model)
        fit.state = model.rest_state()
        s0 = fit.skin()

    scale = 0.5 if quick else 1.0
    env = _envelope(NEUTRAL_FRAMES, int(RISE * scale) or 1, HOLD, int(FALL * scale) or 1)
    apex = expression_contractions(expression, INTENSITY, model.ids).copy()
    if look:
        for mid, c in LOOK_EXTRA.get(expression, {}).items():
            i = list(model.ids).index(mid)
            apex[i] = max(apex[i], c)
    frames, truth, state = [], [], None
    for k, a in enumerate(env):
        head = {}
        if head_moves:
            head = {
                "rotation_deg": 3.0 * np.sin(k / 3),
                "scale": 1 + 0.02 * np.sin(k / 4),
                "translation_px": (4 * np.sin(k / 2), 3 * np.cos(k / 2) - 3),
            }
        if field == "projected":
            s1 = fit.skin(a * apex)
            warp = projected_warp(points, s0, s1, fit.camera, pose, **head)
            truth.append((s1 - s0)[:, :2] * np.array([1.0, -1.0]))
        else:
            warp, state = expression_warp(points, model, a * apex, state, **head)
            truth.append(warp.displacement(points[:, :2]))
        img = warp.apply(frame)
        if look:
            img = expression_look(img, warp.moved(points[:, :2]), expression, a)
        frames.append(img)
    return frames, np.array(truth), env[:, None] * apex[None, :]


def run_known_warp(head_moves: bool, quick: bool = False, settings=None, look: bool = False,
                   expressions=EXPRESSIONS, flow_method: str | None = None,
                   field: str = FIELD) -> dict:  # fmt: skip
    """The known-warp clips of ``expressions`` (``look``: with the look each adds,
    :func:`make_clip`) analysed (see the module's docstring) with the fit's
    ``settings`` (default: the default analysis'; ``flow_method``: the point tracker of
    ``settings.flow``, :class:`~myoface.analysis.trackers.landmark_fit.FitTracker`'s): per region the gain and explained
    fraction of the model's motion against the warp's, over every clip's frames; the leak
    (the model's motion error at the points no muscle moves, over the moving regions' true
    motion, RMS); and the contractions' RMSE against the truth."""
    from myoface.analysis.fidelity import EYE_OUTER, REGIONS, RIGID_POINTS
    from myoface.analysis.motionreader import explained, gain
    from myoface.analysis.pipeline import Tracking
    from myoface.analysis.sample import fetch_sample_video
    from myoface.analysis.trackers.landmark_fit import FitTracker
    from myoface.analysis.video import open_video
    from myoface.facemesh import FaceMeshDetector
    from myoface.model import build_face_model

    frame = next(iter(open_video(fetch_sample_video(quiet=True))))
    with FaceMeshDetector(video=False) as det:
        pts = det.detect(frame)
    iod = float(np.linalg.norm(pts[EYE_OUTER[0], :2] - pts[EYE_OUTER[1], :2]))
    model = build_face_model()
    geometry = None
    if field == "projected":
        # the truth is the skin's motion in the head frame, in the unit of its own IOD
        geometry = calibrated_geometry(frame, model)
        t0 = geometry[0].skin()
        iod = float(np.linalg.norm(t0[EYE_OUTER[0], :2] - t0[EYE_OUTER[1], :2]))
    d_model, d_true, c_err = [], [], []
    for expression in expressions:
        frames, truth, true_c = make_clip(
            frame, pts, model, expression, head_moves, quick, look=look, field=field,
            geometry=geometry,
        )  # fmt: skip
        video = _Clip(frames, 30.0)
        tracker = FitTracker(model, fps=video.fps, settings=settings, flow_method=flow_method)
        try:
            first = tracker.calibrate(iter(video), 0)
            measured = [m for _, m in Tracking(video, tracker, first)]
            fit = tracker.fit
            shapes = [fit.skin(m.contractions) if m.quality == "ok" else None for m in measured]
        finally:
            tracker.close()
        if shapes[0] is None:
            raise RuntimeError("the known-warp clip's first frame was not measured")
        s0 = shapes[0]
        iod_model = float(np.linalg.norm(s0[EYE_OUTER[0], :2] - s0[EYE_OUTER[1], :2]))
        for k, s in enumerate(shapes):
            if s is None:
                continue
            # (head frame: y up; the image's y runs down)
            d_model.append((s[:, :2] - s0[:, :2]) * np.array([1.0, -1.0]) / iod_model)
            d_true.append(truth[k] / iod)
            c_err.append(measured[k].contractions - true_c[k])
    d_model, d_true = np.array(d_model), np.array(d_true)
    out: dict = {"frames": len(d_model), "expressions": list(expressions), "field": field,
                 "regions": {}}  # fmt: skip
    stats = tracker.describe().get("optical_flow_points")
    if stats is not None:  # (the last clip's)
        out["optical_flow_points"] = stats
    for r, ii in REGIONS.items():
        j = list(ii)
        out["regions"][r] = {
            "gain": round(gain(d_model[:, j], d_true[:, j]), 4),
            "explained": round(explained(d_model[:, j], d_true[:, j]), 4),
            "true_rms_iod": round(float(np.sqrt((d_true[:, j] ** 2).mean())), 4),
        }
    rigid = list(RIGID_POINTS)
    moving = sorted({i for v in REGIONS.values() for i in v})
    err = d_model[:, rigid] - d_true[:, rigid]
    out["leak"] = round(
        float(np.sqrt((err**2).mean() / max((d_true[:, moving] ** 2).mean(), 1e-12))), 4
    )
    c_err = np.array(c_err)
    out["contraction_rmse"] = {
        i: round(float(v), 4) for i, v in zip(model.ids, np.sqrt((c_err**2).mean(0)), strict=True)
    }
    return out


def _both(quick: bool) -> dict:
    """Every variant (:data:`VARIANTS`; a quick run: the default only), head still and moving;
    the default's first."""
    from dataclasses import replace

    from myoface.analysis.weights import FitSettings
    from myoface.facemesh import mediapipe_available

    if not mediapipe_available():
        return {}
    out = {}
    for name, kw in VARIANTS.items():
        if quick and name != "default":
            break  # (a quick run shows the benchmark runs: the default's clips, ~20 s less)
        kw = dict(kw)
        method = kw.pop("flow_method", None)
        settings = replace(FitSettings(), **kw)
        out[name] = {
            "head still": run_known_warp(False, quick, settings, flow_method=method),
            "head moving": run_known_warp(True, quick, settings, flow_method=method),
        }
        if not quick:
            # the same expressions with the look they add (LOOKS; not in the headline)
            for key, moves in ((LOOK_KEYS[0], False), (LOOK_KEYS[1], True)):
                out[name][key] = run_known_warp(
                    moves, quick, settings, look=True, flow_method=method
                )
    return out


_CACHE: dict = {}


def _results(quick: bool) -> dict:
    if quick not in _CACHE:
        _CACHE[quick] = _both(quick)
    return _CACHE[quick]


def _worst(key: str, quick: bool, lowest: bool) -> Measurement:
    every = _results(quick)
    if not every:
        return Measurement(float("nan"), 0, detail={"skipped": "MediaPipe is not installed"})
    res = every["default"]
    plain = [res[k] for k in PLAIN_KEYS]
    vals = []
    for r in plain:
        for v in r["regions"].values():
            vals.append(v[key] if lowest else abs(v[key] - 1.0))
    detail = {
        **res,
        "variants": {k: v for k, v in every.items() if k != "default"},
        "targets": {"gain": list(GAIN_TARGET), "explained": EXPLAINED_TARGET},
        "expressions": list(EXPRESSIONS),
        "intensity": INTENSITY,
    }
    if lowest:
        return Measurement(float(min(vals)), len(vals), detail=detail)
    # the gain farthest from 1 (signed), over both clips and every region
    worst = max(
        (v["gain"] for r in plain for v in r["regions"].values()),
        key=lambda g: abs(g - 1.0),
    )
    return Measurement(float(worst), len(vals), detail=detail)


@benchmark("analysis.known_warp_gain", "-", higher_is_better=True)
def bench_known_warp_gain(quick: bool) -> Measurement:
    """The region whose gain is farthest from 1 (the model's motion over the warp's) on the
    known-warp clips, head still and moving (see the module's docstring)."""
    return _worst("gain", quick, lowest=False)


@benchmark("analysis.known_warp_explained", "-", higher_is_better=True)
def bench_known_warp_explained(quick: bool) -> Measurement:
    """The lowest explained fraction of a region on the known-warp clips, head still and
    moving (see the module's docstring)."""
    return _worst("explained", quick, lowest=True)
