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
    m_in, m_out = _corner_motion(a), _corner_motion(b)
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

#: the strongest muscles of the model's best smile (:func:`smile_reach`) the detail lists
REACH_MUSCLES = 6


def smile_reach(model, d_in: np.ndarray, apex) -> dict:
    """What the person's face could do at best on the input's mouth corners ``d_in`` (T, 2, 2,
    as :func:`smile_gain` takes them): the contractions fitted frame by frame to the corners'
    displacements alone (:func:`myoface.analysis.fidelity.model_reach`, every muscle in [0, 1]),
    the same ratio and its parts (:func:`smile_gain`) over the same ``apex`` frames, and the
    strongest muscles there (their mean contraction). Where the best smile is short too, the
    analysis is not what holds the ratio; a muscle at 1 there is a muscle at its bound: the
    person's corners go farther than the model's muscles take them."""
    from myoface.analysis.fidelity import model_reach

    reach, table = model_reach(model, {"mouth_corners": d_in})
    d_out = reach.d_out["mouth_corners"]
    apex = list(apex)
    ratio = float(np.median(_corner_motion(d_out)[apex] / _corner_motion(d_in)[apex]))
    parts = _component_ratios(np.asarray(d_in)[apex], np.asarray(d_out)[apex])
    mean = np.nanmean(table[apex], axis=0)
    top = np.argsort(-mean)[:REACH_MUSCLES]
    return {
        "ratio": round(ratio, 3),
        **parts,
        "muscles_at_apex": {model.ids[j]: round(float(mean[j]), 3) for j in top},
    }


def _corner_motion(d: np.ndarray) -> np.ndarray:
    """(T,): the two corners' mean displacement (IOD) per frame."""
    return np.linalg.norm(np.asarray(d, dtype=np.float64), axis=2).mean(axis=1)


@benchmark("synth.smile_gain", "-", higher_is_better=True)
def bench_smile_gain(quick: bool) -> Measurement:
    """The person's own face (``face_from_photo`` on the calibration frame of
    ``single_face.mp4``) driven by the contractions the analysis measures on that video (the
    3-D fit, ``myoface analyze --tracker landmarks``), against the video, both sides read as
    ``analysis.fidelity`` reads them (:func:`myoface.analysis.fidelity.fidelity_of_analysis`):
    the video by the validated motion reader (optical flow from the calibration frame, the
    head's motion taken out), the model from its own skin vertices, the mouth corners'
    displacement over each side's inter-ocular distance. Value: the median over the smile's
    apex frames (the input's corners at 90 % or more of their largest displacement) of the
    resynthesis' displacement over the video's: 1 when the model smiles as widely as the
    person. Target within [0.85, 1.15]. The detail: the apex frames, both displacements, the
    cosine between their directions, the ratio across the face and up, and the model's reach
    (:func:`smile_reach`: the same ratio for the contractions fitted to the video's corners
    alone, and the muscles that make it), which says whether the analysis or the model's
    muscles hold the ratio. (Before 2026-12-05 the detail had MediaPipe's gain on renders of
    the same face, from when both sides were read by MediaPipe.)"""
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
        fid = write_fidelity_report(
            res.folder, path, model=person, calibration_frame=int(cal), mediapipe_on_both=False
        )
    d_in = fid.d_in["mouth_corners"]
    ratio, detail = smile_gain(d_in, fid.d_out["mouth_corners"])
    detail["target"] = list(SMILE_GAIN_TARGET)
    detail["input_reader"] = fid.reader or fid.method
    # which stage holds it: the best the person's face does on the video's corners alone
    detail["model_reach"] = smile_reach(person, d_in, detail["apex_frames"])
    return Measurement(ratio, len(detail["apex_frames"]), detail=detail)
