"""How much of a video's expression motion the resynthesized model reproduces.

A measure with a detector that is not the fit: MediaPipe's face mesh is run on the input video
and on the model's resynthesis of it (the model driven by the analysis' contractions, rendered
front on), and the two are compared point by point:

1. each frame's points are aligned to the sequence's own reference frame (its first measured
   frame) by a 3-D similarity (scale, rotation, translation; Umeyama 1991) fitted to the
   *rigid* points, which no muscle moves: the eye corners and the nose bridge
   (:data:`RIGID_POINTS`). This takes out the head's motion and the two videos' different
   sizes and positions of the face;
2. the *expressive* points' displacements from the reference frame (:data:`REGIONS`: mouth
   corners, lip centres, brows, eyelids, chin) are divided by the reference frame's
   inter-ocular distance (outer eye corners), so that both are in the same unit, and
   expressed in the axes of a face front on (the reference frame's rigid points mapped onto
   the default face's), so that a reference frame with the head turned is compared in the
   same axes as one front on;
3. per region and overall (every expressive point), over the frames and points::

       explained = 1 - sum |d_in - d_out|^2 / sum |d_in|^2

   1 when the resynthesis moves as the input does, 0 when it is no better than a still face
   (negative when worse), with ``gain = sum d_in . d_out / sum |d_in|^2`` (the least-squares
   factor from the input's motion to the output's: < 1 when the model moves too little) and
   ``corr = sum d_in . d_out / sqrt(sum |d_in|^2 sum |d_out|^2)`` (the correlation about
   zero, the reference frame's position: 1 when the output moves in proportion to the input
   whatever the gain). ``explained = 2 gain - sum |d_out|^2 / sum |d_in|^2``.

The displacements are measured in the face's frontal plane (x across, y up; ``dims=2``):
MediaPipe's monocular depth scatters by more than an expression moves the skin towards the
camera (:class:`~myoface.analysis.weights.FitSettings` weighs it a tenth of
x and y), and it would count that noise as unexplained motion. ``dims=3`` keeps it.

Point indices are those of MediaPipe's 468-point face mesh, which is the default face's
topology (its named landmark groups in ``data/``: ``mouth_corner_l``, ``eye_l``, ...).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from myoface._io import atomic_output, read_text
from myoface.analysis.contractions_csv import read_contractions_csv
from myoface.analysis.resynthesis import resynthesis_frames
from myoface.analysis.video import open_video
from myoface.errors import MyofaceValueError
from myoface.face import load_default_face
from myoface.face.personal import face_from_photo, fit_similarity_3d
from myoface.facemesh import FaceMeshDetector
from myoface.model import build_face_model
from myoface.render import progress

#: points no muscle moves (MediaPipe face mesh indices): the eye corners (right eye outer and
#: inner, left eye inner and outer) and the nose bridge (from between the eyes down the ridge)
RIGID_POINTS = (33, 133, 362, 263, 168, 6, 197, 195)
#: the outer eye corners, whose distance in the reference frame is the unit of displacement
EYE_OUTER = (33, 263)
#: the expressive points, by region
REGIONS = {
    "mouth_corners": (61, 291),
    # upper and lower lip centres, outer and inner edge
    "lips": (0, 13, 14, 17),
    # the brows' upper edges, right and left (eyebrow_r, eyebrow_l)
    "brows": (107, 66, 105, 63, 70, 336, 296, 334, 293, 300),
    # the upper and lower lid centres, right and left
    "eyelids": (159, 145, 386, 374),
    # chin boss and menton
    "chin": (200, 199, 175, 152),
}
#: a region below this sum of squared input displacements (IOD^2, over frames and points)
#: did not move: its explained fraction is not defined (NaN). About 0.3 % of the IOD RMS over
#: 10 points and 100 frames, MediaPipe's own jitter on a still face.
MIN_MOTION = 1e-5


def _check_sequence(points, what: str) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 3 or p.shape[2] not in (2, 3) or p.shape[1] <= max(RIGID_POINTS):
        raise MyofaceValueError(
            f"{what} must be (T, 468, 3) face mesh points per frame; got shape {p.shape}"
        )
    return p


def align_sequence(points, reference: int = 0, rigid=RIGID_POINTS) -> np.ndarray:
    """Each frame of ``points`` (T, N, 3) mapped onto frame ``reference`` by the 3-D similarity
    (scale, rotation, translation) that best maps its ``rigid`` points onto the reference
    frame's (least squares, Umeyama 1991). Frames with NaN (no face) stay NaN.

    Units are those of ``points`` (MediaPipe's: pixels, depth in the same scale)."""
    p = _check_sequence(points, "points")
    if p.shape[2] != 3:
        raise MyofaceValueError("align_sequence needs 3-D points (T, N, 3)")
    ref = p[reference, list(rigid)]
    if not np.isfinite(ref).all():
        raise MyofaceValueError(f"the reference frame {reference} has no face")
    out = np.full_like(p, np.nan)
    for k, frame in enumerate(p):
        if not np.isfinite(frame).all():
            continue
        s, r, t = fit_similarity_3d(frame[list(rigid)], ref)
        out[k] = s * frame @ r.T + t
    return out


@lru_cache(maxsize=1)
def _canonical_rigid() -> np.ndarray:
    """The rigid points of the default face, front on (head frame, mm)."""
    return load_default_face().vertices[list(RIGID_POINTS)].astype(np.float64)


def displacements(points, reference: int = 0, dims: int = 2, regions=None) -> dict:
    """{region: (T, P, dims)} displacements of the expressive points from frame ``reference``,
    after :func:`align_sequence`, in units of the reference frame's inter-ocular distance
    (outer eye corners). NaN rows where a frame has no face.

    The displacements are expressed in the head frame of a face front on (x to the subject's
    left, y up, z towards the viewer): the reference frame's rigid points are mapped onto the
    default face's by one more similarity, so that two sequences whose reference frames show
    the head in different poses are compared in the same axes. ``points`` are MediaPipe's (x
    right, y down, z away from the viewer)."""
    if dims not in (2, 3):
        raise MyofaceValueError(f"dims must be 2 or 3; got {dims!r}")
    regions = REGIONS if regions is None else regions
    a = align_sequence(points, reference) * np.array([1.0, -1.0, -1.0])  # right-handed, y up
    s, r, t = fit_similarity_3d(a[reference, list(RIGID_POINTS)], _canonical_rigid())
    a = s * a @ r.T + t
    iod = float(np.linalg.norm(a[reference, EYE_OUTER[0]] - a[reference, EYE_OUTER[1]]))
    if not iod > 0:
        raise MyofaceValueError("the reference frame's eye corners coincide")
    return {
        name: (a[:, list(idx), :dims] - a[reference, list(idx), :dims]) / iod
        for name, idx in regions.items()
    }


@dataclass(frozen=True)
class Scores:
    """The agreement of an output's displacements with an input's (see the module)."""

    explained: float
    gain: float
    corr: float
    #: RMS of the input's and the output's displacements (units of the inter-ocular distance)
    rms_in: float
    rms_out: float

    def as_dict(self) -> dict:
        return {
            k: (None if not np.isfinite(v) else round(float(v), 4)) for k, v in vars(self).items()
        }


def scores(d_in, d_out, min_motion: float = MIN_MOTION) -> Scores:
    """:class:`Scores` of displacements ``d_out`` against ``d_in`` (the same shape; frames
    with NaN in either are left out). NaN when the input did not move (``sum |d_in|^2 <
    min_motion``)."""
    a = np.asarray(d_in, dtype=np.float64)
    b = np.asarray(d_out, dtype=np.float64)
    if a.shape != b.shape:
        raise MyofaceValueError(f"d_in and d_out differ in shape: {a.shape} and {b.shape}")
    ok = np.isfinite(a).reshape(len(a), -1).all(1) & np.isfinite(b).reshape(len(b), -1).all(1)
    a, b = a[ok], b[ok]
    ss_in, ss_out = float((a**2).sum()), float((b**2).sum())
    n = max(a.size // max(a.shape[-1], 1), 1)
    rms_in, rms_out = np.sqrt(ss_in / n), np.sqrt(ss_out / n)
    if ss_in < min_motion:
        return Scores(np.nan, np.nan, np.nan, rms_in, rms_out)
    dot = float((a * b).sum())
    explained = 1.0 - float(((a - b) ** 2).sum()) / ss_in
    corr = dot / np.sqrt(ss_in * ss_out) if ss_out > 0 else np.nan
    return Scores(explained, dot / ss_in, corr, rms_in, rms_out)


@dataclass
class FidelityResult:
    """The measure on two landmark sequences (:func:`measure_fidelity`).

    Attributes
    ----------
    overall : Scores over every expressive point.
    regions : {region: Scores}.
    reference : the reference frame's index (the first frame with a face in both).
    n_frames : frames compared (a face in both).
    d_in, d_out : {region: (T, P, dims)} displacements, for plots.
    """

    overall: Scores
    regions: dict
    reference: int
    n_frames: int
    dims: int
    d_in: dict = field(repr=False, default_factory=dict)
    d_out: dict = field(repr=False, default_factory=dict)

    def as_dict(self) -> dict:
        return {
            "overall": self.overall.as_dict(),
            "regions": {k: v.as_dict() for k, v in self.regions.items()},
            "reference_frame": self.reference,
            "frames_compared": self.n_frames,
            "dims": self.dims,
        }


def measure_fidelity(points_in, points_out, dims: int = 2, regions=None) -> FidelityResult:
    """The fidelity of ``points_out`` (T, 468, 3), e.g. MediaPipe on the resynthesis, to
    ``points_in`` (T, 468, 3), MediaPipe on the input (frame k of one is frame k of the other;
    NaN frames: no face). Both are aligned to their own reference frame, the first frame with a
    face in both (see the module)."""
    pin = _check_sequence(points_in, "points_in")
    pout = _check_sequence(points_out, "points_out")
    if len(pin) != len(pout):
        raise MyofaceValueError(
            f"the two sequences differ in length: {len(pin)} and {len(pout)} frames"
        )
    both = np.isfinite(pin).reshape(len(pin), -1).all(1) & np.isfinite(pout).reshape(
        len(pout), -1
    ).all(1)
    if both.sum() < 2:
        raise MyofaceValueError(
            f"fewer than 2 frames have a face in both sequences ({int(both.sum())})"
        )
    pin, pout = pin.copy(), pout.copy()
    pin[~both] = np.nan
    pout[~both] = np.nan
    ref = int(np.argmax(both))
    d_in = displacements(pin, ref, dims, regions)
    d_out = displacements(pout, ref, dims, regions)
    per = {k: scores(d_in[k], d_out[k]) for k in d_in}
    cat_in = np.concatenate(list(d_in.values()), axis=1)
    cat_out = np.concatenate(list(d_out.values()), axis=1)
    return FidelityResult(scores(cat_in, cat_out), per, ref, int(both.sum()), dims, d_in, d_out)


def plot_fidelity(result: FidelityResult, path, times=None, title: str = "") -> None:
    """One panel per region: the RMS displacement over the region's points, per frame, of the
    input, of the resynthesis and of their difference (units of the inter-ocular distance),
    with the region's scores in its title. Written to ``path`` (PNG) whole or not at all."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(result.d_in)
    n = len(next(iter(result.d_in.values())))
    t = np.arange(n) if times is None else np.asarray(times, dtype=np.float64)
    fig, axes = plt.subplots(len(names), 1, figsize=(8, 1.7 * len(names) + 0.8), sharex=True)
    axes = np.atleast_1d(axes)
    for ax, name in zip(axes, names, strict=True):
        a, b = result.d_in[name], result.d_out[name]

        def rms(x):
            return np.sqrt((x**2).sum(-1).mean(-1))

        ax.plot(t, rms(a), color="0.2", label="input")
        ax.plot(t, rms(b), color="tab:orange", label="resynthesis")
        ax.plot(t, rms(a - b), color="tab:red", lw=0.8, ls="--", label="difference")
        s = result.regions[name]
        ax.set_title(
            f"{name.replace('_', ' ')}: explained {s.explained:.2f}, gain {s.gain:.2f}, "
            f"corr {s.corr:.2f}",
            fontsize=8,
        )
        ax.set_ylabel("RMS / IOD", fontsize=7)
        ax.tick_params(labelsize=7)
    axes[0].legend(loc="upper right", fontsize=7, ncol=3)
    axes[-1].set_xlabel("time (s)" if times is not None else "frame")
    o = result.overall
    head = f"{title}: " if title else ""
    fig.suptitle(
        f"{head}explained {o.explained:.2f}, gain {o.gain:.2f}, corr {o.corr:.2f} (overall; "
        "MediaPipe face mesh on both, each aligned to its reference frame)",
        fontsize=8,
    )
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)


# ------------------------------------------------------------------ the driver on videos


def detect_landmarks(frames, n_points: int = 468) -> np.ndarray:
    """MediaPipe's face mesh on every frame of ``frames`` (an iterable of RGB images), each
    frame on its own (image mode): (T, 468, 3) points, pixels (x, y) and MediaPipe's relative
    depth; NaN where no face was found.

    Image mode, not MediaPipe's tracking (video) mode: in video mode the first frame's points
    come from the face detector's box and the later frames' from the previous frame's points,
    and the change of box moves the points by 0.3-1.3 % of the inter-ocular distance (RMS;
    the mouth corners most) between the reference frame and the rest of a held frame (the
    sample video's first), which the measure would take for expression motion; in image mode
    a held frame gives the same points."""
    out = []
    with FaceMeshDetector(video=False) as det:
        for f in frames:
            p = det.detect(f)
            out.append(np.full((n_points, 3), np.nan) if p is None else p[:n_points])
    return np.array(out).reshape(-1, n_points, 3)


def person_model(video_path, calibration_frame: int):
    """The face model of the person in ``video_path``: ``face_from_photo`` on the calibration
    frame (as ``myoface face from-photo --frame N`` and the demo make it), with the default
    muscles; and a text saying how it was made."""
    import itertools

    frame = next(itertools.islice(iter(open_video(video_path)), calibration_frame, None), None)
    if frame is None:
        raise MyofaceValueError(f"{video_path}: no frame {calibration_frame}")
    face, _ = face_from_photo(frame, name="person")
    how = f"face_from_photo on frame {calibration_frame} (the calibration frame)"
    return build_face_model(face), how


def fidelity_of_analysis(
    video_path,
    contractions_csv,
    *,
    model=None,
    fallback_model=None,
    calibration_frame: int = 0,
    size: int | None = None,
    dims: int = 2,
    show_progress: bool = False,
) -> tuple[FidelityResult, dict]:
    """The fidelity measure of an analysis: MediaPipe on the frames of ``video_path`` that
    ``contractions_csv`` measured (its ``frame`` column; "ok" rows) and on the resynthesis of
    those rows by ``model`` (default: the person's own face made from ``calibration_frame``,
    :func:`person_model`; if no face is found there, ``fallback_model``, e.g. the analysis'
    own, and the reason in the returned dict), rendered front on at ``size`` pixels
    (default: the video's height, at least 256). Returns the result and a dict of how it was
    measured (for fidelity.json)."""
    import csv
    import time

    t0 = time.perf_counter()
    how = {}
    if model is None:
        try:
            model, how["face"] = person_model(video_path, calibration_frame)
        except MyofaceValueError as exc:
            if fallback_model is None:
                raise
            model = fallback_model
            how["face"] = f"the analysis' face model ({model.face.name}): {exc}"
    else:
        how["face"] = f"the analysis' face model ({model.face.name})"
    times, table, quality = read_contractions_csv(contractions_csv, list(model.ids))
    rows = list(csv.DictReader(read_text(Path(contractions_csv), "contractions CSV").splitlines()))
    frames = [int(r["frame"]) for r in rows]
    ok = np.array([q == "ok" for q in quality])
    video = open_video(video_path)
    if size is None:
        size = max(256, int(video.size[1]))
    wanted = dict.fromkeys(frames)
    picked = {}
    for k, f in enumerate(video):
        if k in wanted:
            picked[k] = f
        if k >= max(frames):
            break
    missing = [f for f in frames if f not in picked]
    if missing:
        raise MyofaceValueError(
            f"{video_path} has no frame {missing[0]}, which {contractions_csv} measured"
        )
    lm_in = detect_landmarks(picked[f] for f in frames)
    rendered = progress(
        resynthesis_frames(model, table, size),
        total=len(table),
        desc="fidelity",
        enabled=show_progress,
    )
    lm_out = detect_landmarks(rendered)
    lm_in[~ok] = np.nan  # frames the analysis did not measure are not compared
    lm_out[~ok] = np.nan
    res = measure_fidelity(lm_in, lm_out, dims=dims)
    how.update(
        {
            "video": str(Path(video_path).resolve()),
            "contractions": str(Path(contractions_csv).resolve()),
            "frames": len(frames),
            "frames_without_face_in_input": int((~np.isfinite(lm_in).all((1, 2)) & ok).sum()),
            "frames_without_face_in_resynthesis": int(
                (~np.isfinite(lm_out).all((1, 2)) & ok).sum()
            ),
            "render": f"front view, {size}x{size}, perspective (myoface resynth's camera)",
            "seconds": round(time.perf_counter() - t0, 2),
        }
    )
    how["times_s"] = [float(x) for x in times]
    return res, how


def write_fidelity_report(
    folder: str | os.PathLike,
    video_path,
    *,
    model=None,
    fallback_model=None,
    calibration_frame: int | None = None,
    show_progress: bool = False,
) -> FidelityResult:
    """``fidelity.json`` and ``fidelity.png`` in an analysis' output ``folder`` (its
    ``contractions.csv``; the calibration frame from its ``analysis.json`` unless given):
    :func:`fidelity_of_analysis`, then :func:`plot_fidelity`."""
    import json

    folder = Path(folder)
    if calibration_frame is None:
        side = json.loads((folder / "analysis.json").read_text())
        calibration_frame = int(side.get("calibration_frame", 0))
    res, how = fidelity_of_analysis(
        video_path,
        folder / "contractions.csv",
        model=model,
        fallback_model=fallback_model,
        calibration_frame=calibration_frame,
        show_progress=show_progress,
    )
    times = how.pop("times_s")
    doc = {
        **res.as_dict(),
        "measure": (
            "explained = 1 - sum|d_in - d_out|^2 / sum|d_in|^2 over frames and points; "
            "gain = sum d_in.d_out / sum|d_in|^2; corr = sum d_in.d_out / "
            "sqrt(sum|d_in|^2 sum|d_out|^2); d = displacement from the reference frame after "
            "a 3-D similarity on the rigid points, over the inter-ocular distance"
        ),
        "rigid_points": list(RIGID_POINTS),
        "regions_points": {k: list(v) for k, v in REGIONS.items()},
        **how,
    }
    with atomic_output(folder / "fidelity.json") as tmp:
        tmp.write_text(json.dumps(doc, indent=1))
    plot_fidelity(res, folder / "fidelity.png", times=times)
    return res
