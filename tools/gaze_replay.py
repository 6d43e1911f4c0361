"""Record what the 3-D fit hands the gaze reader on each frame, once, then replay the reader
alone on it with other settings: the reader's variants compared in seconds on the same fit
(the fit takes minutes; the reader a few ms a frame).

    python tools/gaze_replay.py record bench  /tmp/bench.pkl     # the benchmark's clip
    python tools/gaze_replay.py record bench2 /tmp/bench2.pkl    # gaze seed 7, camera seed 3
    python tools/gaze_replay.py record ~/.cache/myoface/single_face.mp4 /tmp/sample.pkl
    python tools/gaze_replay.py replay /tmp/bench.pkl /tmp/sample.pkl socket_prior_mm=1.0

``record`` runs the analysis as ``myoface bench --only analysis.gaze_error_deg`` (or
``myoface analyze --tracker landmarks`` on a video) does and keeps, per measured frame, the
frame, the fit's camera, head pose, fitted skin and MediaPipe's points, the neutral the reader
was calibrated on, and the reading; on the benchmark's clips also the truth. ``replay`` runs a
fresh :class:`~myoface.analysis.gaze.GazeEstimator` (``key=value``: fields of
:class:`~myoface.analysis.gaze.GazeSettings`, as Python literals) over each recording and
prints, with the truth, each eye's RMS error over the frames open in the truth (the
benchmark's ``per_eye``; its headline is the worse eye), else each eye's mean and SD and the
frames said closed; and whether the readings are those recorded (the same settings and code
give the same readings, bit for bit)."""

from __future__ import annotations

import ast
import os
import pickle
import sys
import time

import numpy as np


def record(source: str, out: str) -> None:
    import myoface.bench.gaze as B
    from myoface.analysis.pipeline import Tracking, make_analyzer
    from myoface.bench.headmotion import _Clip, _model

    model = _model()
    truth = None
    if source in ("bench", "bench2"):
        n = 90
        poses, gaze, closure, skins = B.make_gaze_sequence(model, n)
        deg = None
        if source == "bench2":
            from dataclasses import replace

            from myoface.render.degrade import CameraDegradation

            gaze = B.gaze_programme(n, seed=7)
            deg = replace(CameraDegradation(), seed=3)
        frames, _ = B.render_gaze_sequence(model.face, poses, gaze, skins, deg)
        video = _Clip(frames)
        truth = {"gaze": gaze, "closure": closure}
    else:
        from myoface.analysis.video import open_video

        video = open_video(os.path.expanduser(source))
    an, first = make_analyzer(model, video, "landmarks", calibration_frame=None)
    frames, neutral = [], []
    reader = an.gaze
    measure, calibrate = reader.measure, reader.calibrate

    def recorded(frame, camera, pose, shape, points=None):
        g = measure(frame, camera, pose, shape, points)
        frames.append((np.array(frame), camera, pose, np.array(shape),
                       None if points is None else np.array(points), g))  # fmt: skip
        return g

    def kept(v):
        neutral.append(np.array(v))
        return calibrate(v)

    reader.measure, reader.calibrate = recorded, kept
    try:
        index = [m.index for _, m in Tracking(video, an, first) if m.gaze is not None]
    finally:
        an.close()
    with open(out, "wb") as f:
        pickle.dump({"frames": frames, "index": index, "neutral": neutral[-1],
                     "truth": truth}, f)  # fmt: skip
    print(f"recorded {len(frames)} frames of {source} into {out}")


def replay(path: str, settings) -> dict:
    """The reader with ``settings`` over the recording at ``path``: its readings, their errors
    (with the truth) or spread, and the CPU time a frame."""
    from myoface.analysis.gaze import GazeEstimator
    from myoface.bench.headmotion import _model

    with open(path, "rb") as f:
        rec = pickle.load(f)
    reader = GazeEstimator(_model().face, settings)
    reader.calibrate(rec["neutral"])
    out, prev = [], None
    t0 = time.process_time()
    for (frame, camera, pose, shape, points, _), k in zip(rec["frames"], rec["index"],
                                                          strict=True):  # fmt: skip
        if prev is not None and k != prev + 1:
            reader.reset()  # (as the tracker after a frame it did not measure)
        prev = k
        out.append(reader.measure(frame, camera, pose, shape, points))
    ms = 1e3 * (time.process_time() - t0) / max(len(out), 1)
    same = all(a.eye(s) == b[-1].eye(s) or _same(a.eye(s), b[-1].eye(s))
               for a, b in zip(out, rec["frames"], strict=True) for s in "lr")  # fmt: skip
    res = {"ms_per_frame": round(ms, 2), "as_recorded": same}
    truth = rec["truth"]
    for s in "lr":
        got = np.full((max(rec["index"]) + 1, 2), np.nan)
        for g, k in zip(out, rec["index"], strict=True):
            if g.eye(s).ok:
                got[k] = (g.eye(s).yaw_deg, g.eye(s).pitch_deg)
        if truth is None:
            ok = np.isfinite(got).all(axis=1)
            closed = [k for g, k in zip(out, rec["index"], strict=True)
                      if g.eye(s).state == "closed"]  # fmt: skip
            res[s] = {"read": int(ok.sum()), "mean_deg": got[ok].mean(0).round(2).tolist(),
                      "sd_deg": got[ok].std(0).round(2).tolist(), "closed": closed}  # fmt: skip
            continue
        open_ = np.asarray(truth["closure"]) < 0.5
        ok = open_[: len(got)] & np.isfinite(got).all(axis=1)
        e = got[ok] - np.asarray(truth["gaze"])[: len(got)][ok]
        res[s] = {
            "rms_deg": round(float(np.sqrt(np.mean(e**2))), 3),
            "yaw_rms_deg": round(float(np.sqrt(np.mean(e[:, 0] ** 2))), 3),
            "pitch_rms_deg": round(float(np.sqrt(np.mean(e[:, 1] ** 2))), 3),
            "mean_deg": e.mean(0).round(2).tolist(),
            "frames": int(ok.sum()),
        }
    if truth is not None:
        res["worse_eye_rms_deg"] = max(res["l"]["rms_deg"], res["r"]["rms_deg"])
    return res


def _same(a, b) -> bool:
    """Two readings alike to the bit (NaN as NaN)."""
    return a.state == b.state and all(
        x == y or (np.isnan(x) and np.isnan(y))
        for x, y in ((a.yaw_deg, b.yaw_deg), (a.pitch_deg, b.pitch_deg),
                     (a.explained, b.explained), (a.contrast, b.contrast))
    )  # fmt: skip


def main(argv) -> None:
    from myoface.analysis.gaze import GazeSettings

    if len(argv) == 3 and argv[0] == "record":
        record(argv[1], argv[2])
        return
    if len(argv) < 2 or argv[0] != "replay":
        sys.exit(__doc__)
    paths = [a for a in argv[1:] if "=" not in a]
    kw = {k: ast.literal_eval(v) for k, v in (a.split("=", 1) for a in argv[1:] if "=" in a)}
    settings = GazeSettings(**kw)
    for p in paths:
        print(p, replay(p, settings))


if __name__ == "__main__":
    main(sys.argv[1:])
