"""``synth.smile_gain``: does the person's own face, driven by what the analysis measured, smile
as widely as the person did?"""

from __future__ import annotations

import numpy as np

from myoface.bench import Measurement, benchmark

#: frames whose input mouth-corner displacement is at least this fraction of its largest are
#: the smile's apex (the plateau of a held smile, not one frame's jitter)
APEX_FRACTION = 0.9


def smile_gain(d_in: np.ndarray, d_out: np.ndarray, apex_fraction: float = APEX_FRACTION):
    """The mouth corners' displacement ratio at the smile's apex, from the displacements of the
    two corners (T, 2, dims) in the input and in the resynthesis (units of the inter-ocular
    distance, as :func:`myoface.analysis.fidelity.displacements` gives them; NaN frames are
    left out).

    The apex: the frames where the input's corners (mean displacement of the two) move at
    least ``apex_fraction`` of their largest. Returns (ratio, detail): the median over the
    apex frames of |d_out| / |d_in| (mean over the corners), 1 when the model's corners
    travel as far as the person's; the detail gives the apex frames, both displacements, the
    cosine between their directions and the ratio's parts across the face and up
    (``lateral_ratio``, ``vertical_ratio``: a model that widens the mouth as the person does
    but raises its corners less has the second below the first)."""
    a = np.asarray(d_in, dtype=np.float64)
    b = np.asarray(d_out, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 3:
        raise ValueError(f"d_in and d_out must be (T, P, dims) alike; got {a.shape}, {b.shape}")
    ok = np.isfinite(a).all(axis=(1, 2)) & np.isfinite(b).all(axis=(1, 2))
    if not ok.any():
        raise ValueError("no frame has the mouth corners in both sequences")
    m_in = np.linalg.norm(a, axis=2).mean(axis=1)
    m_out = np.linalg.norm(b, axis=2).mean(axis=1)
    m_in[~ok] = np.nan
    peak = float(np.nanmax(m_in))
    if not peak > 0:
        raise ValueError("the input's mouth corners do not move")
    apex = np.flatnonzero(ok & (m_in >= apex_fraction * peak))
    ratio = float(np.median(m_out[apex] / m_in[apex]))
    va, vb = a[apex].reshape(-1), b[apex].reshape(-1)
    cos = float(va @ vb / max(np.linalg.norm(va) * np.linalg.norm(vb), 1e-300))
    detail = {
        "apex_frames": [int(k) for k in apex],
        "input_iod": round(float(np.median(m_in[apex])), 4),
        "resynthesis_iod": round(float(np.median(m_out[apex])), 4),
        "direction_cosine": round(cos, 3),
    }
    if a.shape[2] >= 2:
        detail.update(_component_ratios(a[apex], b[apex]))
    return ratio, detail


def _component_ratios(a: np.ndarray, b: np.ndarray) -> dict:
    """Where a smile's gain is lost: the resynthesis' corners over the input's across the face
    (``x``, each corner's along the side the input's corner moves to) and up (``y``), each
    the median over the apex frames ``a``, ``b`` (F, 2, dims) of the ratio of the two
    corners' means; None where the input does not move that way (below 1 % of the IOD)."""
    side = np.sign(a[..., 0].mean(axis=0))  # (2,): each corner's way out, as the input goes
    out = {}
    for name, x_in, x_out in (
        ("lateral_ratio", (a[..., 0] * side).mean(axis=1), (b[..., 0] * side).mean(axis=1)),
        ("vertical_ratio", a[..., 1].mean(axis=1), b[..., 1].mean(axis=1)),
    ):
        ok = np.abs(x_in) >= 0.01
        out[name] = round(float(np.median(x_out[ok] / x_in[ok])), 3) if ok.any() else None
    return out


#: the target range for the ratio: the person's smile within 15 %
SMILE_GAIN_TARGET = (0.85, 1.15)

#: the expressions rendered to measure how much of a render's motion MediaPipe reads
#: (:func:`tracker_gain`): the six EMFACS prototypes, at full intensity
PROBE_EXPRESSIONS = ("happiness", "sadness", "surprise", "fear", "anger", "disgust")


def region_gains(true_px: np.ndarray, read_px: np.ndarray, regions: dict) -> dict:
    """How much of the points' true motion a tracker reads, per region: ``true_px`` and
    ``read_px`` (T, V, 2) image positions (the model's own vertices projected, and what the
    tracker found) of a neutral frame (row 0) and probes; each region's gain is the
    least-squares factor from the true displacements from row 0 to the read ones,
    ``sum d_read . d_true / sum |d_true|^2`` over the probes and the region's points (1: the
    tracker follows the skin; below 1 it reads less motion than there is). None for a region
    that does not move."""
    t = np.asarray(true_px, dtype=np.float64)[..., :2]
    r = np.asarray(read_px, dtype=np.float64)[..., :2]
    if t.shape != r.shape or t.ndim != 3 or len(t) < 2:
        raise ValueError(
            f"true_px and read_px must be (T >= 2, V, 2) alike; got {t.shape}, {r.shape}"
        )
    dt, dr = t[1:] - t[0], r[1:] - r[0]
    ok = np.isfinite(dr).all(axis=(1, 2))
    out = {}
    for name, idx in regions.items():
        a, b = dt[ok][:, list(idx)], dr[ok][:, list(idx)]
        den = float((a * a).sum())
        out[name] = round(float((a * b).sum()) / den, 3) if den > 1e-12 else None
    return out


def tracker_gain(model, size: int = 360, expressions=PROBE_EXPRESSIONS) -> dict:
    """MediaPipe's gain on renders of ``model``: the face rendered front on as the fidelity's
    resynthesis is (:func:`myoface.analysis.fidelity.resynthesis_frames`), neutral and each of
    ``expressions`` at intensity 1, MediaPipe's face mesh on each render, and per region of
    :data:`myoface.analysis.fidelity.REGIONS` the share of the rendered skin's motion it reads
    (:func:`region_gains`). Where it reads less than there is, the resynthesis' motion as
    MediaPipe measures it is short of the model's by that factor."""
    from myoface.analysis.fidelity import REGIONS, detect_landmarks, resynthesis_frames
    from myoface.control import expression_contractions
    from myoface.synth import make_camera

    table = np.array(
        [np.zeros(len(model.ids))]
        + [expression_contractions(e, 1.0, model.ids) for e in expressions]
    )
    read = detect_landmarks(resynthesis_frames(model, table, size))
    cam = make_camera(model.face.vertices, "front", size, size)
    true = np.array([cam.project(model.skin_vertices(model.relax(c).state))[:, :2] for c in table])
    return region_gains(true, read, REGIONS)


@benchmark("synth.smile_gain", "-", higher_is_better=True)
def bench_smile_gain(quick: bool) -> Measurement:
    """The person's own face (``face_from_photo`` on the calibration frame of
    ``single_face.mp4``) driven by the contractions the analysis measures on that video (the
    3-D fit, ``myoface analyze --tracker landmarks``), rendered front on, and MediaPipe's face
    mesh on the render and on the video: each frame aligned to the first by a 3-D similarity
    on rigid points, the mouth corners' displacement over the inter-ocular distance
    (:mod:`myoface.analysis.fidelity`). Value: the median over the smile's apex frames (the
    input's corners at 90 % or more of their largest displacement) of the resynthesis'
    displacement over the video's: 1 when the model smiles as widely as the person. Target
    within [0.85, 1.15]. The detail: the apex frames, both displacements, the
    cosine between their directions, the ratio across the face and up, and MediaPipe's gain on
    renders of the same face (:func:`tracker_gain`): the resynthesis is measured through
    MediaPipe, so where it reads a render's motion short, the ratio is short by as much."""
    import json
    import tempfile
    from pathlib import Path

    from myoface.analysis.fidelity import person_model, write_fidelity_report
    from myoface.analysis.outputs import analyze_to_folder
    from myoface.analysis.sample import fetch_sample_video
    from myoface.model import build_face_model

    path = fetch_sample_video(quiet=True)
    with tempfile.TemporaryDirectory() as tmp:
        res = analyze_to_folder(
            path, Path(tmp) / "analysis", model=build_face_model(), tracker="landmarks",
            max_frames=48 if quick else None,
        )  # fmt: skip
        # the person's own face, from the analysis' calibration frame (as the report would
        # make it), built once for the report and for MediaPipe's gain below
        cal = json.loads((Path(res.folder) / "analysis.json").read_text())["calibration_frame"]
        person = person_model(path, int(cal))[0]
        fid = write_fidelity_report(res.folder, path, model=person, calibration_frame=int(cal))
    ratio, detail = smile_gain(fid.d_in["mouth_corners"], fid.d_out["mouth_corners"])
    detail["target"] = list(SMILE_GAIN_TARGET)
    # what MediaPipe reads of the same face's rendered motion (the resynthesis is measured
    # through it): the ratio cannot pass this gain unless the analysis moves the model more
    # than MediaPipe saw the person move
    detail["mediapipe_gain_on_renders"] = tracker_gain(person)
    return Measurement(ratio, len(detail["apex_frames"]), detail=detail)
