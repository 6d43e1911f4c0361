"""Record what the 3-D fit hands the gaze reader on each frame, once, then replay the reader
alone on it with other settings: the reader's variants compared in seconds on the same fit
(the fit takes minutes; the reader a few ms a frame).

    python tools/gaze_replay.py record bench  /tmp/bench.pkl     # the benchmark's clip
    python tools/gaze_replay.py record bench2 /tmp/bench2.pkl    # gaze seed 7, camera seed 3
    python tools/gaze_replay.py record bench-clean /tmp/clean.pkl # the clip undegraded
    python tools/gaze_replay.py record ~/.cache/myoface/single_face.mp4 /tmp/sample.pkl
    python tools/gaze_replay.py record ~/.cache/myoface/single_face.mp4 /tmp/s_cli.pkl default
    python tools/gaze_replay.py record bench /tmp/bench_flow.pkl tracker=flow  # or photometric
    python tools/gaze_replay.py replay /tmp/bench.pkl /tmp/sample.pkl socket_prior_mm=1.0
    python tools/gaze_replay.py replay /tmp/bench.pkl oracle=skin     # the socket's ceiling

``record`` runs the analysis as ``myoface bench --only analysis.gaze_error_deg`` does (on a
video: with the benchmark's face model, the sample person's from the photo; with ``default``
after the output path, the bundled default face, as ``myoface analyze --tracker landmarks``
without ``--face`` does) and keeps, per measured frame, the
frame, the fit's camera, head pose, fitted skin and MediaPipe's points, the neutral the reader
was calibrated on, and the reading; on the benchmark's clips also the truth (gaze, closure,
head poses, skin). ``replay`` runs a
fresh :class:`~myoface.analysis.gaze.GazeEstimator` (``key=value``: fields of
:class:`~myoface.analysis.gaze.GazeSettings`, as Python literals) over each recording and
prints, with the truth, each eye's RMS error over the frames open in the truth (the
benchmark's ``per_eye``; its headline is the worse eye) and the same for the reader on the
true geometry (the true pose, skin and camera: ``true_geometry``), else each eye's mean and SD,
the median of its change from one frame to the next (``step_median_deg``: the reading's
jitter) and the frames said closed; and whether the readings are those recorded (the same settings and code
give the same readings, bit for bit). With the truth, also where the reader put each eye
(``placed``: over the frames whose lids rest in the truth, the eyeball's centre and the eye's
skin ring, the neutral's vertices within 15 x 10 mm of the eyeball's centre and 5 mm or more
in front of it, moved by the socket's offset, against the truth's in the image, px: mean and
RMS; ``centre_minus_skin`` is what no 2-D move of the skin can take off, the head's rotation
error times the eyeball's depth behind the skin). ``oracle=skin`` replaces each socket offset by
the move that puts the skin ring where the truth's is (a perfect registration of the eye's
surroundings: the ceiling of a socket), ``oracle=centre`` by the one that puts the eyeball's
centre where the truth's is; ``oracle=anchor`` moves each eye by one constant for the whole
clip, the mean of the moves that put its centre where the truth's is (the best a per-video
anchor of the eye could do, the socket left to take the rest); ``oracle=lids`` gives the
reader the truth's lid margins relative to the eyeball's centre (the lids' shape; the eye's
place stays the fit's). ``record ... calibration=N`` runs the same analysis with its
calibration frame (the most neutral of the first 2 s) replaced by the frame ``N`` of that
window, every frame still measured from the first (``myoface analyze --calibration-frame N``
calibrates on ``N`` alone, without the window's scores): how much the calibration's draw moves the reading,
:mod:`myoface.analysis.gaze`'s docstring. ``record clip:G,C PATH`` records the benchmark's
head and blinks with gaze programme seed G and camera seed C (the benchmark's clips are 0,0,
7,3 and 11,5; ``upper_margin``'s docstring in :mod:`myoface.analysis.gaze` used 3,1 and 5,2
held out)."""

from __future__ import annotations

import ast
import os
import pickle
import sys
import time
from functools import lru_cache

import numpy as np

#: the 3-D fit's variants ``record`` can run (``tracker=NAME``): make_analyzer's arguments
TRACKERS = {
    "fit": {},
    "photometric": {"photometric": True},
    "flow": {"flow": True},
    "synthesis": {"estimator": "fit-synthesis"},
}


def _synthetic_source(source: str):
    """``record``'s rendered sources as (gaze programme seed, camera degradation): ``bench``
    (0, the camera's default draw), ``bench2`` (7, camera seed 3), ``bench-clean`` (0, no
    degradation but the texture's resolution), ``clip:G,C`` (G, camera seed C); None for a
    video's path."""
    from dataclasses import replace

    from myoface.render.degrade import CameraDegradation

    if source == "bench":
        return 0, CameraDegradation()
    if source == "bench2":
        return 7, CameraDegradation(seed=3)
    if source == "bench-clean":
        return 0, replace(CameraDegradation(), light_amplitude=0.0, exposure_drift=0.0,
                          background=False, blur_sigma_px=0.0, full_scale_electrons=1e9,
                          read_noise_electrons=0.0, crf=None)  # fmt: skip
    if source.startswith("clip:"):
        gaze_seed, camera_seed = (int(v) for v in source[5:].split(","))
        return gaze_seed, CameraDegradation(seed=camera_seed)
    return None


def record(source: str, out: str, face: str = "bench", tracker: str = "fit",
           calibration: str | None = None) -> None:  # fmt: skip
    if calibration is not None:
        # the default analysis (every frame from the first, the calibration scored as it
        # goes) with its choice of the calibration frame replaced: the same analysis on
        # another draw (``--calibration-frame`` calibrates on that frame without the scores)
        import myoface.analysis.modelfit as mf
        import myoface.analysis.trackers.landmark_fit as lf

        choose = mf.choose_calibration_frame
        mf.choose_calibration_frame = lf.choose_calibration_frame = lambda scores: int(calibration)
        try:
            return record(source, out, face, tracker)
        finally:
            mf.choose_calibration_frame = lf.choose_calibration_frame = choose
    import myoface.bench.gaze as B
    from myoface.analysis.pipeline import Tracking, make_analyzer
    from myoface.bench.headmotion import _Clip, _model
    from myoface.model import load_face_model

    model = _model() if face == "bench" else load_face_model(None)
    truth = None
    sequence = _synthetic_source(source)
    if sequence is not None:  # (a render of the benchmark's head, gaze and blinks)
        gaze_seed, deg = sequence
        poses, gaze, closure, skins = B.make_gaze_sequence(model, 90, gaze_seed)
        frames, _ = B.render_gaze_sequence(model.face, poses, gaze, skins, deg)
        video = _Clip(frames)
        truth = {"gaze": gaze, "closure": closure, "poses": poses, "skins": skins}
    else:
        from myoface.analysis.video import open_video

        video = open_video(os.path.expanduser(source))
    an, first = make_analyzer(model, video, "landmarks", calibration_frame=None,
                              **TRACKERS[tracker])  # fmt: skip
    by_reader, neutrals = {}, {}  # (per reader: a speculative calibration makes a new one)
    from myoface.analysis.gaze import GazeEstimator

    measure, calibrate = GazeEstimator.measure, GazeEstimator.calibrate

    def recorded(self, frame, camera, pose, shape, points=None):
        g = measure(self, frame, camera, pose, shape, points)
        kept_frame = (np.array(frame), camera, pose, np.array(shape),
                      None if points is None else np.array(points), g)  # fmt: skip
        by_reader.setdefault(id(self), []).append(kept_frame)
        return g

    def kept(self, v):
        neutrals[id(self)] = np.array(v)
        return calibrate(self, v)

    GazeEstimator.measure, GazeEstimator.calibrate = recorded, kept
    try:
        index = [m.index for _, m in Tracking(video, an, first) if m.gaze is not None]
    finally:
        an.close()
        GazeEstimator.measure, GazeEstimator.calibrate = measure, calibrate
    frames, neutral = by_reader.get(id(an.gaze), []), neutrals[id(an.gaze)]  # (the one kept)
    with open(out, "wb") as f:
        pickle.dump({"frames": frames, "index": index, "neutral": neutral,
                     "truth": truth, "face": face}, f)  # fmt: skip
    print(f"recorded {len(frames)} frames of {source} into {out}")


def _skin_ring(neutral, centre) -> np.ndarray:
    """The eye's skin ring about the eyeball's ``centre`` (3,) mm: the vertices of ``neutral``
    within 15 x 10 mm of it in (x, y) and 5 mm or more in front of it (the canthi, the lids'
    outer skin, the brow's lower edge and the cheek's upper; the opening's margins are
    nearer the eyeball), as a bool mask."""
    v = np.asarray(neutral)
    return (
        (np.abs(v[:, 0] - centre[0]) < 15)
        & (np.abs(v[:, 1] - centre[1]) < 10)
        & (v[:, 2] > centre[2] + 5)
    )


@lru_cache(maxsize=1)
def _true_centres() -> dict:
    """The benchmark's face's eyeball centres (mm, head frame), ``{"l": (3,), "r": (3,)}``:
    the truth's."""
    from myoface.bench.headmotion import _model
    from myoface.face.eyes import eye_loop, eyeball_center

    face = _model().face
    return {s: eyeball_center(face.vertices, eye_loop(face, g))
            for s, g in (("l", "eye_l"), ("r", "eye_r"))}  # fmt: skip


class _Oracle:
    """Each frame's socket offsets replaced by the truth's answer (``kind``: ``"skin"``, the
    move that puts the eye's skin ring where the truth's is in the image; ``"centre"``, the
    one that puts the eyeball's centre there): least squares on the move's Jacobian."""

    def __init__(self, kind, rec, reader):
        from myoface.analysis.camera import PinholeCamera
        from myoface.bench.headmotion import FOV_DEG, SIZE

        self.kind, self.rec, self.reader = kind, rec, reader
        self.cam = PinholeCamera.for_image(SIZE[0], SIZE[1], FOV_DEG)
        self.true_c = _true_centres()
        self.k = 0
        for side, sock in reader.sockets.items():
            sock.offset = self._offset(side)

    def _offset(self, side):
        def offset(frame, camera, pose, iris_centre, iris_radius_px):
            truth, k = self.rec["truth"], self.k
            c = self.reader.centres_mm[side]
            if self.kind == "centre":
                pts = c[None]
                want = self.cam.project(truth["poses"][k].apply(self.true_c[side][None]))[0]
            else:
                ring = _skin_ring(self.rec["neutral"], c)
                pts = self.rec["neutral"][ring]
                want = self.cam.project(truth["poses"][k].apply(truth["skins"][k][ring])).mean(0)

            def at(d):
                return camera.project(pose.apply(pts + np.array([d[0], d[1], 0.0]))).mean(0)

            h = 1e-3
            jac = np.column_stack([(at((h, 0)) - at((0, 0))) / h, (at((0, h)) - at((0, 0))) / h])
            return np.linalg.solve(jac, want - at((0, 0)))

        return offset


def _anchor(rec, reader) -> dict:
    """``oracle=anchor``: each eye moved, in the head frame, by one constant for the whole
    recording, the mean over the frames whose lids rest of the move that puts the eyeball's
    centre, as the fit's pose places it, where the truth's is in the image: its centre, its
    lids' margins and its socket's grid (a perfect per-video anchor, the frame-to-frame
    misplacement left to the socket). Returns the moves (mm, head frame x and y)."""
    from myoface.analysis.camera import PinholeCamera
    from myoface.bench.headmotion import FOV_DEG, SIZE

    truth = rec["truth"]
    cam = PinholeCamera.for_image(SIZE[0], SIZE[1], FOV_DEG)
    moves = {}
    for side in ("l", "r"):
        true_c = _true_centres()[side]
        c = reader.centres_mm[side]
        ds = []
        for (_, camera, pose, *_), k in zip(rec["frames"], rec["index"], strict=True):
            if truth["closure"][k] > 0.05:
                continue
            want = cam.project(truth["poses"][k].apply(true_c[None]))[0]

            def at(d, camera=camera, pose=pose, c=c):
                return camera.project(pose.apply((c + np.array([d[0], d[1], 0.0]))[None]))[0]

            h = 1e-3
            jac = np.column_stack([(at((h, 0)) - at((0, 0))) / h, (at((0, h)) - at((0, 0))) / h])
            ds.append(np.linalg.solve(jac, want - at((0, 0))))
        moves[side] = np.array([*np.mean(ds, axis=0), 0.0])
        reader.centres_mm[side] = c + moves[side]
        if side in reader.sockets:
            reader.sockets[side].points = reader.sockets[side].points + moves[side]

    def placement(side, camera, pose, shape, points):
        _, upper, lower = reader._eyes[side]
        centre = pose.apply(reader.centres_mm[side][None])[0]
        up2, lo2 = (camera.project(pose.apply(shape[c] + moves[side])) for c in (upper, lower))
        return centre, up2, lo2

    reader._placement = placement
    print("anchor moves (mm, head frame):", {s: m[:2].round(2).tolist() for s, m in moves.items()})
    return moves


def _placed(rec, reader, frame_pose, k, acc) -> None:
    """Add frame ``k``'s misplacements (px) of each eye (its centre and its skin ring, moved by
    the socket's offset) against the truth's to ``acc``."""
    from myoface.analysis.camera import PinholeCamera
    from myoface.bench.headmotion import FOV_DEG, SIZE

    truth = rec["truth"]
    if truth["closure"][k] > 0.05:
        return
    if "true_c" not in acc:
        acc["cam"] = PinholeCamera.for_image(SIZE[0], SIZE[1], FOV_DEG)
        acc["true_c"] = _true_centres()
    camera, pose = frame_pose
    cam, tp = acc["cam"], truth["poses"][k]
    for s in "lr":
        d = reader.offsets[s]
        move = np.zeros(3) if d is None else np.array([d[0], d[1], 0.0])
        c = reader.centres_mm[s]
        ring = _skin_ring(rec["neutral"], c)
        centre = camera.project(pose.apply((c + move)[None]))[0]
        centre = centre - cam.project(tp.apply(acc["true_c"][s][None]))[0]
        skin = camera.project(pose.apply(rec["neutral"][ring] + move)).mean(0)
        skin = skin - cam.project(tp.apply(truth["skins"][k][ring])).mean(0)
        acc.setdefault(s, []).append(np.concatenate([centre, skin]))


def _placed_summary(rows) -> dict:
    a = np.asarray(rows)

    def part(x):
        return {"mean": x.mean(0).round(2).tolist(),
                "rms": round(float(np.sqrt((x**2).sum(1).mean())), 2)}  # fmt: skip

    return {"centre_px": part(a[:, :2]), "skin_px": part(a[:, 2:]),
            "centre_minus_skin_px": part(a[:, :2] - a[:, 2:])}  # fmt: skip


def _true_lids(rec, reader, shape, k) -> np.ndarray:
    """``oracle=lids``: the fitted skin ``shape`` with each eye's lid margins the truth's at
    frame ``k``, relative to the eyeball's centre (the truth's margins moved by the calibrated
    neutral's centre less the truth's): the lids' shape the truth's, the eye's place the
    fit's."""
    shape = np.array(shape)
    for side, true_c in _true_centres().items():
        _, upper, lower = reader._eyes[side]
        idx = np.concatenate([upper, lower])
        shape[idx] = rec["truth"]["skins"][k][idx] - true_c + reader.centres_mm[side]
    return shape


def replay(path: str, settings, oracle: str | None = None) -> dict:
    """The reader with ``settings`` over the recording at ``path``: its readings, their errors
    (with the truth) or spread, where it placed the eyes (with the truth), and the CPU time a
    frame; ``oracle`` (``"skin"``, ``"centre"``): the sockets' offsets the truth's (see the
    module)."""
    from myoface.analysis.gaze import GazeEstimator
    from myoface.bench.headmotion import _model
    from myoface.model import load_face_model

    with open(path, "rb") as f:
        rec = pickle.load(f)
    bench = rec.get("face", "bench") == "bench"
    reader = GazeEstimator((_model() if bench else load_face_model(None)).face, settings)
    reader.calibrate(rec["neutral"])
    if oracle is not None and rec["truth"] is None:
        sys.exit("an oracle needs a recording with the truth")
    if oracle == "anchor":
        _anchor(rec, reader)
    orc = None if oracle in (None, "anchor", "lids") else _Oracle(oracle, rec, reader)
    out, prev, placed = [], None, {}
    t0 = time.process_time()
    for (frame, camera, pose, shape, points, _), k in zip(rec["frames"], rec["index"],
                                                          strict=True):  # fmt: skip
        if prev is not None and k != prev + 1:
            reader.reset()  # (as the tracker after a frame it did not measure)
        prev = k
        if orc is not None:
            orc.k = k
        if oracle == "lids":
            shape = _true_lids(rec, reader, shape, k)
        out.append(reader.measure(frame, camera, pose, shape, points))
        if rec["truth"] is not None and "poses" in rec["truth"]:
            _placed(rec, reader, (camera, pose), k, placed)
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
            step = np.diff(got, axis=0)  # (frame to frame: the reading's jitter, and saccades)
            step = step[np.isfinite(step).all(axis=1)]
            res[s] = {"read": int(ok.sum()), "mean_deg": got[ok].mean(0).round(2).tolist(),
                      "sd_deg": got[ok].std(0).round(2).tolist(),
                      "step_median_deg": np.median(np.abs(step), axis=0).round(2).tolist(),
                      "closed": closed}  # fmt: skip
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
        if placed:
            res["placed"] = {s: _placed_summary(placed[s]) for s in "lr" if s in placed}
        if "poses" in truth:
            res["true_geometry"] = _on_true_geometry(reader.__class__, rec, settings)
    return res


def _on_true_geometry(cls, rec, settings) -> dict:
    """The reader with ``settings`` on the recording's frames given the true head pose, skin
    and camera (the benchmark's ``reader_on_true_geometry``): each eye's RMS error (deg)."""
    from myoface.analysis.camera import PinholeCamera
    from myoface.bench.headmotion import FOV_DEG, SIZE, _model

    truth = rec["truth"]
    cam = PinholeCamera.for_image(SIZE[0], SIZE[1], FOV_DEG)
    reader = cls(_model().face, settings)
    got = {s: np.full((len(truth["gaze"]), 2), np.nan) for s in "lr"}
    for k, (frame, *_) in zip(rec["index"], rec["frames"], strict=True):
        g = reader.measure(frame, cam, truth["poses"][k], truth["skins"][k])
        for s in "lr":
            if g.eye(s).ok:
                got[s][k] = (g.eye(s).yaw_deg, g.eye(s).pitch_deg)
    out = {}
    open_ = np.asarray(truth["closure"]) < 0.5
    for s in "lr":
        ok = open_ & np.isfinite(got[s]).all(axis=1)
        e = got[s][ok] - np.asarray(truth["gaze"])[ok]
        out[s] = {"rms_deg": round(float(np.sqrt(np.mean(e**2))), 3),
                  "yaw_rms_deg": round(float(np.sqrt(np.mean(e[:, 0] ** 2))), 3),
                  "pitch_rms_deg": round(float(np.sqrt(np.mean(e[:, 1] ** 2))), 3),
                  "frames": int(ok.sum())}  # fmt: skip
    return out


def _same(a, b) -> bool:
    """Two readings alike to the bit (NaN as NaN)."""
    return a.state == b.state and all(
        x == y or (np.isnan(x) and np.isnan(y))
        for x, y in ((a.yaw_deg, b.yaw_deg), (a.pitch_deg, b.pitch_deg),
                     (a.explained, b.explained), (a.contrast, b.contrast))
    )  # fmt: skip


def main(argv) -> None:
    from myoface.analysis.gaze import GazeSettings

    if len(argv) >= 3 and argv[0] == "record":
        kw = dict(a.split("=", 1) for a in argv[3:] if "=" in a)
        record(*[a for a in argv[1:] if "=" not in a], **kw)
        return
    if len(argv) < 2 or argv[0] != "replay":
        sys.exit(__doc__)
    paths = [a for a in argv[1:] if "=" not in a]
    kw = {k: ast.literal_eval(v) for k, v in (a.split("=", 1) for a in argv[1:] if "=" in a)
          if k != "oracle"}  # fmt: skip
    oracle = next((a.split("=", 1)[1] for a in argv[1:] if a.startswith("oracle=")), None)
    if oracle not in (None, "skin", "centre", "anchor", "lids"):
        sys.exit(f"oracle must be skin, centre, anchor or lids; got {oracle!r}")
    settings = GazeSettings(**kw)
    for p in paths:
        print(p, replay(p, settings, oracle))


if __name__ == "__main__":
    main(sys.argv[1:])
