"""docs/gaze_side_by_side.mp4 (`python tools/gaze_side_by_side.py docs/gaze_side_by_side.mp4`): the person's video (left) and the resynthesis (right), eyes turned
where the analysis read them: single_face.mp4, then the benchmark's render of the same person
looking around (degraded as a webcam)."""

import os
import sys
import tempfile
from pathlib import Path

import numpy as np

import myoface.bench.gaze as B
from myoface.analysis.contractions_csv import write_contractions_csv
from myoface.analysis.pipeline import Tracking, make_analyzer
from myoface.analysis.resynthesis import read_performance, resynthesize
from myoface.analysis.video import open_video
from myoface.render import VideoWriter

H = 240
tmp = Path(tempfile.mkdtemp())
model, frames, poses, gaze, closure, skins, report, kind = B._sequence(False)
render_mp4 = tmp / "render.mp4"
with VideoWriter(render_mp4, 30.0) as vw:
    for f in frames:
        vw.write(f)
parts = []
for name, src in (
    ("real", Path(os.path.expanduser("~/.cache/myoface/single_face.mp4"))),
    ("render", render_mp4),
):
    v = open_video(src)
    an, first = make_analyzer(model, v, "landmarks", calibration_frame=None)
    ms = [m for _, m in Tracking(v, an, first)]
    an.close()
    csvp = tmp / f"{name}.csv"
    write_contractions_csv(csvp, an.ids, ms, model.muscles.jaw)
    perf = read_performance(csvp, model, pose=True)
    out = tmp / f"{name}_sbs.mp4"
    resynthesize(
        model,
        perf.times,
        perf.contractions,
        out,
        perf.fps,
        size=H,
        side_by_side=src,
        show_progress=False,
        poses=perf.poses,
        gaze=perf.gaze,
    )
    parts.append(out)
    if name == "real":
        import csv

        rows = list(csv.DictReader(open(csvp)))
        for s in "lr":
            a = np.array(
                [
                    [float(r[f"gaze_{s}_yaw_deg"]), float(r[f"gaze_{s}_pitch_deg"])]
                    for r in rows
                    if r[f"gaze_{s}_state"] == "ok"
                ]
            )
            print(
                name,
                s,
                "n ok",
                len(a),
                "mean",
                a.mean(0).round(2),
                "SD",
                a.std(0).round(2),
                "closed",
                [r["frame"] for r in rows if r[f"gaze_{s}_state"] == "closed"],
            )
dst = Path(sys.argv[1])
clips = [list(open_video(p)) for p in parts]
W = max(c[0].shape[1] for c in clips)
W += W % 2
with VideoWriter(dst, 30.0, quality_crf=int(sys.argv[2]) if len(sys.argv) > 2 else 28) as vw:
    for c in clips:
        for f in c:
            out = np.zeros((f.shape[0], W, 3), np.uint8)
            x0 = (W - f.shape[1]) // 2
            out[:, x0 : x0 + f.shape[1]] = f
            vw.write(out)
print(dst, dst.stat().st_size // 1024, "KB")
