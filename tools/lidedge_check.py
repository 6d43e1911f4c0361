"""Where the 3-D fit puts the lid margins on the gaze benchmark's renders, against the truth,
with and without the lid margins' edge term (:mod:`myoface.analysis.lidedges`).

    python tools/lidedge_check.py finder [key=value ...]   # the edge finder alone
    python tools/lidedge_check.py fit off|on [key=value ...] [--clip2] [--photometric]

``finder``: on each frame whose lids rest in the truth, the finder started from the true
margins moved -1.5..1.5 px across them: where it puts the margin, px along the normal (+ into
the opening), per eye and lid. ``fit``: the analysis as ``myoface bench --only
analysis.gaze_error_deg`` runs it (``on``: FitSettings.lid_edges; ``key=value``: fields of
:class:`~myoface.analysis.lidedges.LidEdgeSettings`), and per eye and lid the fitted
margin's signed distance from the true margin (px, along the true margin's normal, + into the
opening) over the frames at rest, and over the frames of the blinks' edges (closure 0.05-0.5),
and the gaze's error. ``--clip2``: the benchmark's second clip (gaze seed 7, camera seed 3); ``--headmotion``
(``finder`` only): the head-motion benchmark's 90 degraded renders (expressions, head moving).
"""

from __future__ import annotations

import ast
import functools
import sys

import numpy as np


def _clip(second: bool):
    import myoface.bench.gaze as B
    from myoface.bench.headmotion import _model

    model = _model()
    n = 90
    poses, gaze, closure, skins = B.make_gaze_sequence(model, n)
    deg = None
    if second:
        from dataclasses import replace

        from myoface.render.degrade import CameraDegradation

        gaze = B.gaze_programme(n, seed=7)
        deg = replace(CameraDegradation(), seed=3)
    frames, _ = B.render_gaze_sequence(model.face, poses, gaze, skins, deg)
    return model, frames, poses, gaze, closure, skins


def _true(model, poses, skins, k, sm):
    from myoface.analysis.camera import PinholeCamera
    from myoface.bench.headmotion import FOV_DEG, SIZE

    cam = PinholeCamera.for_image(SIZE[0], SIZE[1], FOV_DEG)
    uv = cam.project(poses[k].apply(sm.points(skins[k])))
    return uv, sm.normals(uv)


def _table(rows, sm, label):
    for e in (0, 1):
        for li in (0, 1):
            sel = (sm.eye == e) & (sm.lid == li)
            v = np.concatenate([r[sel] for r in rows]) if rows else np.zeros(0)
            v = v[np.isfinite(v)]
            if not len(v):
                continue
            print(
                f"  {label:10s} eye {'lr'[e]} {'upper' if li == 0 else 'lower'}: "
                f"bias {v.mean():+.2f}  rms {np.sqrt((v**2).mean()):.2f}  n {len(v)}"
            )


def _headmotion():
    """The head-motion benchmark's degraded renders (90 frames, head moving) and their truth;
    the lids' closure from the truth's palpebral orbicularis."""
    import myoface.bench.headmotion as H

    fm, truth, poses, skins, _, _ = H._sequence(False, False, False, True)
    frames = H._frames(False, False, True)
    ids = list(fm.ids)
    cols = [ids.index(m) for m in ids if m.startswith("orbicularis_oculi_palpebralis")]
    return fm, frames, poses, None, np.asarray(truth)[:, cols].max(axis=1), skins


def finder(settings) -> None:
    from myoface.analysis.lidedges import MarginSamples, find_edges

    if "--headmotion" in sys.argv:
        model, frames, poses, _, closure, skins = _headmotion()
    else:
        model, frames, poses, _, closure, skins = _clip("--clip2" in sys.argv)
    sm = MarginSamples(model.face)
    rows = []
    for k in range(len(frames)):
        if closure[k] > 0.05:
            continue
        uv, nrm = _true(model, poses, skins, k, sm)
        for d in (-1.5, -0.75, 0.0, 0.75, 1.5):
            sign = np.where(sm.lid == 0, settings.upper_sign, 0)
            off, _, ok = find_edges(frames[k], uv + d * nrm, nrm, settings, sign)
            rows.append(np.where(ok, d + off, np.nan))
            rows[-1][~ok] = np.nan
    _table(rows, sm, "finder")
    clear = np.mean([np.isfinite(r).mean() for r in rows])
    print(f"  clear: {clear:.2f} of the samples")


def fit(on: bool, settings, photometric: bool) -> None:
    import myoface.analysis.lidedges as L
    import myoface.analysis.pipeline as P
    from myoface.analysis.weights import FitSettings
    from myoface.bench.gaze import run_gaze

    if on:
        P.FitSettings = functools.partial(FitSettings, lid_edges=True)
        L.LidEdgeSettings = functools.partial(L.LidEdgeSettings, **settings.__dict__)
    model, frames, poses, gaze, closure, skins = _clip("--clip2" in sys.argv)
    sm = L.MarginSamples(model.face)
    fitted = {}
    from myoface.analysis.trackers import landmark_fit as LF

    measure = LF.FitTracker.measure

    def spy(self, frame, index=0, *a, **kw):
        m = measure(self, frame, index, *a, **kw)
        if m.pose is not None and np.isfinite(m.contractions).all():
            shape = self.fit.shape(m.contractions)
            fitted[index] = self.fit.camera.project(m.pose.apply(sm.points(shape)))
        return m

    LF.FitTracker.measure = spy
    res = run_gaze(model, frames, poses, gaze, closure, skins, photometric=photometric)
    rest, edge = [], []
    for k, uv in fitted.items():
        tuv, nrm = _true(model, poses, skins, k, sm)
        d = ((uv - tuv) * nrm).sum(1)
        if closure[k] <= 0.05:
            rest.append(d)
        elif closure[k] < 0.5:
            edge.append(d)
    print(f"lid edges {'on' if on else 'off'}{' + photometric' if photometric else ''}")
    _table(rest, sm, "at rest")
    _table(edge, sm, "blink edge")
    for s in "lr":
        e = res["per_eye"][s]
        print(
            f"  gaze {s}: rms {e['rms_deg']} (yaw {e['yaw_rms_deg']}, pitch {e['pitch_rms_deg']},"
            f" mean {e['mean_deg']}), opening {e['eye_opening_px_mean']}, partly closed "
            f"{e['partly_closed_frames']['rms_deg']} ({e['partly_closed_frames']['frames']} frames;"
            f" {e['frames']} read, {e['open_frames_said_closed']} of the open said closed)"
        )
    print(f"  gaze_error_deg {res['value']}  ({res['analysis_seconds']} s)")


def main() -> None:
    from myoface.analysis.lidedges import LidEdgeSettings

    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    kw = {}
    for a in args:
        if "=" in a:
            k, v = a.split("=", 1)
            kw[k] = ast.literal_eval(v)
    s = LidEdgeSettings(**kw)
    if args[0] == "finder":
        finder(s)
    else:
        fit(args[1] == "on", s, "--photometric" in sys.argv)


if __name__ == "__main__":
    main()
