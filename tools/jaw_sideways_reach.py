"""Which stage holds the fidelity measure's chin: the model's reach with and without a sideways
jaw (FACS AD30), on a video's motion as the validated reader reads it.

The fidelity report's ``model_reach`` (:func:`myoface.analysis.fidelity.model_reach`) is the
best any contractions of the person's face reach against the reader's displacements; on
single_face.mp4 its chin is far below the other regions. This tool reads the video's judged
points as the report does (DIS flow from the calibration frame, the head's motion taken out in
3-D), prints the chin's mean displacement over the frames after ``--from`` (x across the face,
y up, per cent of the inter-ocular distance), and then the model's reach per region fitted
linearly through the skin's response at rest (each frame's contractions in [0, 1], least
squares with a small ridge, as ``model_reach`` does without its relaxation rounds) twice: with
the model's muscles and jaw as they are, and with two more columns, the skin that follows the
mandible (the jaw's weights) moved sideways by up to ``--lateral-mm`` either way. A diagnostic,
fitted to the judge's own reading: it says whether a motion is one the model cannot make.

Usage::

    PYTHONPATH=src python tools/jaw_sideways_reach.py [VIDEO] [--calibration-frame 0]
        [--lateral-mm 5] [--from 30]
"""

from __future__ import annotations

import argparse

import av
import numpy as np
from scipy.optimize import lsq_linear

from myoface.analysis import fidelity as F
from myoface.analysis.sample import fetch_sample_video

RIDGE = 0.02


def reach(jac, target, ridge=RIDGE):
    """Per frame the bounded least-squares fit of ``jac`` (P*2, n) to ``target`` (T, P, 2):
    the reached displacements (T, P, 2)."""
    out = np.full_like(target, np.nan)
    n = jac.shape[1]
    for t in range(len(target)):
        want = target[t].reshape(-1)
        seen = np.isfinite(want)
        if not seen.any():
            continue
        a = np.vstack([jac[seen], ridge * np.eye(n)])
        c = lsq_linear(a, np.concatenate([want[seen], np.zeros(n)]), bounds=(0, 1)).x
        out[t] = (jac @ c).reshape(-1, 2)
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("video", nargs="?", default=None)
    ap.add_argument("--calibration-frame", type=int, default=0)
    ap.add_argument("--lateral-mm", type=float, default=5.0)
    ap.add_argument("--from", dest="start", type=int, default=30)
    args = ap.parse_args(argv)
    video = args.video or str(fetch_sample_video(quiet=True))
    model, _ = F.person_model(video, args.calibration_frame)
    names = list(F.JUDGED_REGIONS)
    with av.open(video) as c:
        frames = list(range(sum(1 for _ in c.decode(video=0))))
    ref, pts, unsure, _ = F.read_video_points(
        video, frames, args.calibration_frame, "dis", detect_landmarks_too=False
    )
    lids_out = F.lids_unread(unsure)
    table = np.zeros((len(frames), len(model.ids)))
    _, side = F.model_displacements(model, table, np.ones(len(frames), bool), F.JUDGED_REGIONS,
                                    "3d", lids_out)  # fmt: skip
    d_in = F.input_displacements(ref, pts, side, F.JUDGED_REGIONS, "3d", unsure, lids_out)
    chin = np.nanmean(d_in["chin"][args.start :], axis=(0, 1)) * 100
    print(f"chin's mean displacement from frame {args.start}: x {chin[0]:+.2f}, y {chin[1]:+.2f}"
          " % of the inter-ocular distance")  # fmt: skip

    jac, iod = F.region_response(model, names)  # (P, 2, M) mm
    verts = [i for k in names for i in F.JUDGED_REGIONS[k]]
    w = np.asarray(model.muscles.jaw.weights)[verts]
    side_cols = np.zeros((len(verts), 2, 2))
    side_cols[:, 0, 0] = w * args.lateral_mm
    side_cols[:, 0, 1] = -w * args.lateral_mm
    target = np.concatenate([d_in[k] for k in names], axis=1)
    for label, cols in (("muscles and jaw", jac), ("and a sideways jaw",
                                                   np.concatenate([jac, side_cols], axis=2))):  # fmt: skip
        out = reach(cols.reshape(-1, cols.shape[2]) / iod, target)
        k0, parts = 0, []
        for k in names:
            n = len(F.JUDGED_REGIONS[k])
            s = F.scores(d_in[k], out[:, k0 : k0 + n])
            parts.append(f"{k} {s.explained:.2f}/{s.gain:.2f}")
            k0 += n
        print(f"reach (explained/gain), {label}: " + ", ".join(parts))


if __name__ == "__main__":
    main()
