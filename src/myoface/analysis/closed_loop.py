"""Closed-loop accuracy: the model performs known contractions, is rendered (with the make-up
the paper's subject wore), the frames are analysed, and the recovered contractions are compared
with the truth, per muscle (beyond the paper: it had no ground truth, Section VI)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from myoface.analysis.curvefit import CurveEstimator
from myoface.analysis.landmarks import similarity_affine
from myoface.analysis.sections import (
    CURVE_EXCLUDED,
    PAPER_MUSCLES,
    SECTIONS,
    project_sections,
    section_vertices,
)
from myoface.analysis.snakes import resample_polyline
from myoface.analysis.trackers.landmark_paper import PaperLandmarkTracker
from myoface.analysis.trackers.snakes import Analyzer
from myoface.errors import MyofaceValueError
from myoface.render import Camera, Renderer, to_srgb8
from myoface.render.dressing import default_skin_texture

#: what ``run_closed_loop`` analyses the frames with
TRACKERS = ("snakes", "landmarks", "oracle")


@dataclass
class ClosedLoopResult:
    ids: tuple
    truth: np.ndarray  # (T, M)
    estimate: np.ndarray  # (T, M)
    quality: list

    def rmse(self) -> np.ndarray:
        return np.sqrt(np.nanmean((self.estimate - self.truth) ** 2, axis=0))

    def corr(self) -> np.ndarray:
        out = np.full(len(self.ids), np.nan)
        for j in range(len(self.ids)):
            a, b = self.estimate[:, j], self.truth[:, j]
            ok = np.isfinite(a)
            if a[ok].std() > 1e-9 and b[ok].std() > 1e-9:
                out[j] = np.corrcoef(a[ok], b[ok])[0, 1]
        return out

    def table(self) -> str:
        lines = [f"{'muscle':42s} {'rmse':>6s} {'corr':>6s}"]
        for k, r, c in zip(self.ids, self.rmse(), self.corr(), strict=True):
            lines.append(f"{k:42s} {r:6.3f} {c:6.2f}")
        return "\n".join(lines)


def truth_sequence(n_frames: int, ids, seed: int = 0) -> np.ndarray:
    """Smooth random contraction curves (T, M) in [0, 0.8], neutral on frame 0."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, n_frames)
    out = np.zeros((n_frames, len(ids)))
    for j in range(len(ids)):
        amp = rng.uniform(0.3, 0.8)
        out[:, j] = amp * np.sin(np.pi * (t * rng.uniform(1, 2) + rng.uniform(0, 1))) ** 2
    out[0] = 0.0
    return out


def run_closed_loop(
    model,
    n_frames: int = 24,
    size: int = 256,
    ids=PAPER_MUSCLES,
    seed: int = 0,
    refine: int = 2,
    head_frame: str = "contours",
    tracker: str = "snakes",
    synthesis: bool = False,
    teeth: bool = False,
    **analyzer_options,
) -> ClosedLoopResult:
    """Render ``n_frames`` of known contractions (orthographic frontal camera framing the face
    over the whole sequence, make-up texture), analyse them with :class:`Analyzer` (contours initialised from the known camera; static
    head, so no head-frame correction), and return truth and estimates.

    ``tracker="landmarks"`` analyses the same frames with
    :class:`~myoface.analysis.trackers.landmark_paper.PaperLandmarkTracker` (MediaPipe's face mesh) instead.
    ``tracker="oracle"`` skips the images: the curve estimator is given the model's own
    section curves, projected by the camera, as if tracked perfectly; what error remains is
    the estimator's (its linearisation and the ``refine`` rounds through the tissue), so the
    difference from ``"snakes"`` is the tracking's share.
    ``synthesis=True`` (snakes only) gives the analyzer the camera, so that it removes the
    tracker's bias by analysis by synthesis (:mod:`myoface.analysis.synthesis`); its
    appearance model is made from the first (neutral) frame, not from the known texture.
    ``teeth``: render the teeth, the tongue and the shaded cavity in the mouth (as a video
    shows them; analysis by synthesis then renders them too); False (default): the mouth drawn
    shut by a fan of the lips' colour, as the paper's synthetic frames. With the mouth's dark
    inside the lips' snake needs the mouth layer (``mouth_sections=MOUTH_SECTIONS`` of
    :class:`Analyzer`: 0.024 worst with it, 0.147 without), which on the real sample video
    draws the right zygomatic major's estimate down; the default analysis leaves it off.
    ``analyzer_options`` go to :class:`Analyzer` (e.g. ``estimator="fiducials"``)."""
    if tracker not in TRACKERS:
        raise MyofaceValueError(f"tracker must be one of {TRACKERS}; got {tracker!r}")
    if synthesis and tracker != "snakes":
        raise MyofaceValueError("synthesis=True needs tracker='snakes'")
    ids = tuple(ids)
    truth = truth_sequence(n_frames, ids, seed)
    states = []
    state = model.rest_state()
    for c in truth:
        state = model.relax(dict(zip(ids, c, strict=True)), state).state
        states.append(state)
    # framed on the face's extent over the sequence, as a camera operator would: a chin that
    # the opened jaw took out of a frame framed at rest would leave its contour on the border
    extent = np.concatenate([model.face.vertices] + [model.skin_vertices(s) for s in states])
    cam = Camera.front(extent, width=size, height=size, fov_deg=None)
    if tracker != "oracle":  # the oracle reads the model's curves, not images
        tex = to_srgb8(default_skin_texture(model.face, 512, makeup=True))
        renderer = Renderer(model.face, cam, texture=tex, teeth=teeth)
    frames = []
    for state in states:
        if tracker == "oracle":
            frames.append(project_sections(model, cam, state))
        else:
            frames.append(renderer.render(model.skin_vertices(state), jaw=model.jaw_pose(state)))
    if tracker == "oracle":
        est = _estimate_from_true_curves(model, cam, frames, ids, refine)
        return ClosedLoopResult(ids, truth, est, ["ok"] * len(frames))
    if tracker == "landmarks":
        an = PaperLandmarkTracker(model, ids, refine=0)
    else:
        init = project_sections(model, cam)
        an = Analyzer(
            model,
            init,
            ids,
            refine=refine,
            head_frame=head_frame,
            head_reference=(),
            synthesis=cam if synthesis else None,
            **{"synthesis_teeth": teeth, **analyzer_options},
        )
    try:
        ms = [an.measure(f, k) for k, f in enumerate(frames)]
    finally:
        an.close()
    est, quality = [m.contractions for m in ms], [m.quality for m in ms]
    return ClosedLoopResult(ids, truth, np.array(est), quality)


def _estimate_from_true_curves(model, cam, curves: list[dict], ids, refine: int) -> np.ndarray:
    """The curve estimator on exact section curves (``tracker="oracle"``): calibrated on the
    first frame's curves, resampled at 1 px like the snakes' nodes, with the model-to-image
    map that the camera gives."""
    secs = {
        s: (section_vertices(model.face, s), SECTIONS[s][1])
        for s in SECTIONS
        if s not in CURVE_EXCLUDED
    }
    est = CurveEstimator(model, secs, ids)
    verts = np.concatenate([v for v, _ in secs.values()])
    mm = model.face.vertices[verts, :2] * np.array([1.0, -1.0])  # image-like: y down
    mat, off = similarity_affine(mm, cam.project(model.face.vertices)[verts, :2])
    first = {s: resample_polyline(curves[0][s], 1.0, closed=c) for s, (_, c) in secs.items()}
    est.calibrate(first, mat, off)
    return np.array([est.estimate({s: cur[s] for s in secs}, refine=refine) for cur in curves])
