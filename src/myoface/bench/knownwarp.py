"""The whole analysis on known answers made from real frames (names stable across releases):
the sample video's first frame warped by a known smooth field that moves the mouth corners,
lips, brows, lids and chin as an expression would (:mod:`myoface.analysis.knownwarp`), with
and without fake head motion, analysed as ``myoface analyze --tracker landmarks`` does; the
model's motion read exactly from its own vertices (the fit's skin at each frame's
contractions, head frame) and compared, region by region, with the warp's.

``analysis.known_warp_gain``: the worst moving region's gain (the model's motion over the
warp's, least squares; 1 the motion in full), ``analysis.known_warp_explained``: the worst
moving region's ``1 - sum |d_model - d_true|^2 / sum |d_true|^2``. The targets: gain in [0.9,
1.1] and explained >= 0.9 in every region. The detail gives every region, head still and
moving, and the motion that leaked into the regions the warp left still.
"""

from __future__ import annotations

import numpy as np

from myoface.bench import Measurement, benchmark

#: the clip: neutral frames (the calibration finds the person's neutral there), then the
#: expression rising, held, and falling; the amounts at the apex, inter-ocular distances,
#: image axes (x right, y down), one row per region point or one for all
NEUTRAL_FRAMES = 6
RISE, HOLD, FALL = 6, 6, 6
APEX_IOD = {
    "mouth_corners": [[-0.05, -0.04], [0.05, -0.04]],  # out and up: a smile's corners
    "lips": [[0, -0.02], [0, -0.01], [0, 0.02], [0, 0.03]],  # the lips part a little
    "brows": [[0, -0.03]],  # raised
    "eyelids": [[0, 0.01], [0, 0.0], [0, 0.01], [0, 0.0]],  # the upper lids lowered
    "chin": [[0, 0.03]],  # down
}
#: the bumps' radius, inter-ocular distances (the motion's scale on a face)
RADIUS_IOD = 0.25
GAIN_TARGET = (0.9, 1.1)
EXPLAINED_TARGET = 0.9


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


def run_known_warp(head_moves: bool, quick: bool = False) -> dict:
    """The known-warp clip analysed (see the module's docstring): per region the gain and
    explained fraction of the model's motion against the warp's, and the leak (the model's
    motion RMS at the points no bump moves, over the moving regions')."""
    from myoface.analysis.fidelity import EYE_OUTER, REGIONS, RIGID_POINTS
    from myoface.analysis.knownwarp import region_warp
    from myoface.analysis.motionreader import aligned_displacements, explained, gain
    from myoface.analysis.pipeline import Tracking, make_analyzer
    from myoface.analysis.sample import fetch_sample_video
    from myoface.analysis.video import open_video
    from myoface.facemesh import FaceMeshDetector
    from myoface.model import build_face_model

    frame = next(iter(open_video(fetch_sample_video(quiet=True))))
    with FaceMeshDetector(video=False) as det:
        pts = det.detect(frame)
    iod = float(np.linalg.norm(pts[EYE_OUTER[0], :2] - pts[EYE_OUTER[1], :2]))
    scale = 0.5 if quick else 1.0
    env = _envelope(NEUTRAL_FRAMES, int(RISE * scale) or 1, HOLD, int(FALL * scale) or 1)
    idx = sorted({i for v in REGIONS.values() for i in v} | set(RIGID_POINTS))
    pos = {i: k for k, i in enumerate(idx)}
    rigid = [pos[i] for i in RIGID_POINTS]
    eyes = (pos[EYE_OUTER[0]], pos[EYE_OUTER[1]])
    ref = pts[idx, :2]
    frames, truth = [], []
    for k, a in enumerate(env):
        head = {}
        if head_moves:
            head = {
                "rotation_deg": 3.0 * np.sin(k / 3),
                "scale": 1 + 0.02 * np.sin(k / 4),
                "translation_px": (4 * np.sin(k / 2), 3 * np.cos(k / 2) - 3),
            }
        amounts = {r: np.asarray(v) * a * iod for r, v in APEX_IOD.items()}
        warp = region_warp(pts, REGIONS, amounts, radius_px=RADIUS_IOD * iod, **head)
        frames.append(warp.apply(frame))
        truth.append(aligned_displacements(ref, warp.moved(ref), rigid, eyes))
    video = _Clip(frames, 30.0)
    tracker, first = make_analyzer(build_face_model(), video, "landmarks", calibration_frame=None)
    try:
        measured = [m for _, m in Tracking(video, tracker, first)]
        fit = tracker.fit
        shapes = [fit.shape(m.contractions) if m.quality == "ok" else None for m in measured]
    finally:
        tracker.close()
    ok = [k for k, s in enumerate(shapes) if s is not None]
    if 0 not in ok:
        raise RuntimeError("the known-warp clip's first frame was not measured")
    s0 = shapes[0]
    iod_model = float(np.linalg.norm(s0[EYE_OUTER[0], :2] - s0[EYE_OUTER[1], :2]))
    model = {
        k: (shapes[k][idx, :2] - s0[idx, :2]) * np.array([1.0, -1.0]) / iod_model for k in ok
    }  # (head frame: y up; the image's y runs down)
    out: dict = {"frames": len(env), "measured": len(ok), "regions": {}}
    for r, ii in REGIONS.items():
        j = [pos[i] for i in ii]
        d_model = np.array([model[k][j] for k in ok])
        d_true = np.array([truth[k][j] for k in ok])
        out["regions"][r] = {
            "gain": round(gain(d_model, d_true), 4),
            "explained": round(explained(d_model, d_true), 4),
            "true_rms_iod": round(float(np.sqrt((d_true**2).mean())), 4),
        }
    # the motion the model shows where the warp moved nothing: the rigid points, relative to
    # the moving regions' true motion
    still = np.array([model[k][rigid] for k in ok])
    moving = np.array([truth[k][[pos[i] for v in REGIONS.values() for i in v]] for k in ok])
    out["leak"] = round(float(np.sqrt((still**2).mean() / max((moving**2).mean(), 1e-12))), 4)
    return out


def _both(quick: bool) -> dict:
    from myoface.facemesh import mediapipe_available

    if not mediapipe_available():
        return {}
    return {
        "head still": run_known_warp(False, quick),
        "head moving": run_known_warp(True, quick),
    }


_CACHE: dict = {}


def _results(quick: bool) -> dict:
    if quick not in _CACHE:
        _CACHE[quick] = _both(quick)
    return _CACHE[quick]


def _worst(key: str, quick: bool, lowest: bool) -> Measurement:
    res = _results(quick)
    if not res:
        return Measurement(float("nan"), 0, detail={"skipped": "MediaPipe is not installed"})
    vals = []
    for r in res.values():
        for v in r["regions"].values():
            vals.append(v[key] if lowest else abs(v[key] - 1.0))
    detail = {
        **res,
        "targets": {"gain": list(GAIN_TARGET), "explained": EXPLAINED_TARGET},
        "bump_radius_iod": RADIUS_IOD,
    }
    if lowest:
        return Measurement(float(min(vals)), len(vals), detail=detail)
    # the gain farthest from 1 (signed), over both clips and every region
    worst = max(
        (v["gain"] for r in res.values() for v in r["regions"].values()),
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
