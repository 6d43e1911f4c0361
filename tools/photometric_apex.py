"""Where the photometric fit's energy holds a frame's expression back (issue 30's diagnosis).

Runs the 3-D fit with its photometric term (``myoface analyze --photometric``'s) on a video up
to ``--frame``, then at that frame, with the term's weights and light fixed where the fit
landed (the finest level):

- the photometric cost along the straight line from the fit's contractions to those of a
  contractions CSV's row for the same frame (``--toward``, e.g. the default analysis'), the
  head's pose held: if the cost rises, the energy prefers the fit's reading (a question of
  the energy's terms or the model, not of the solver);
- which samples resist (their cost rises toward the other reading) by the height of the face
  they lie at (head frame);
- a picture (``--out``): left, each weighing sample's residual at the fit (red: the frame
  brighter than the appearance under its light, blue: darker; 30 grey levels full), right,
  each sample's cost change toward the other reading (red: resists it, green: favours it).

    python tools/photometric_apex.py VIDEO --frame 45 --toward out/contractions.csv \\
        --landmark-weight 0.01 --out /tmp/apex.png

Measured on the sample video's smile (frame 45, 2026-12-02) with the default analysis' row:
the cost rises from 683 to 800 (the mouth's samples, head-frame y < -30 mm, +90 of the +117;
the lips' inner edges where the teeth show, the nostrils' edge and the chin's lower edge
resist; the cheeks favour the fuller smile).
"""

from __future__ import annotations

import argparse
import csv
from dataclasses import replace

import numpy as np

BANDS = (
    ("mouth and chin (y < -30 mm)", -np.inf, -30.0),
    ("cheeks and nose (-30..0)", -30.0, 0.0),
    ("eyes (0..40)", 0.0, 40.0),
    ("brows and forehead (> 40)", 40.0, np.inf),
)


class _Clip:
    def __init__(self, frames, fps):
        self.frames, self.fps, self.n_frames = frames, float(fps), len(frames)
        self.size = (frames[0].shape[1], frames[0].shape[0])
        self.path = "clip"

    def __iter__(self):
        return iter(self.frames)


def main(argv=None) -> None:
    import cv2

    import myoface.analysis.photometric as photometric
    from myoface.analysis.pipeline import Tracking
    from myoface.analysis.terms import Estimate
    from myoface.analysis.trackers.landmark_fit import FitTracker
    from myoface.analysis.video import open_video
    from myoface.analysis.weights import FitSettings
    from myoface.model import build_face_model

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("video")
    ap.add_argument("--frame", type=int, required=True)
    ap.add_argument("--toward", required=True, help="a contractions CSV (its row --frame)")
    ap.add_argument("--calibration-frame", type=int, default=0)
    ap.add_argument("--landmark-weight", type=float, default=FitSettings.photo_landmark_weight)
    ap.add_argument("--out", default="photometric_apex.png")
    a = ap.parse_args(argv)

    # the fit's last photometric term of the brightness (the frame's), kept as the fit makes
    # it (the redness's, FitSettings.photo_colour, is not drawn)
    made = {}
    init = photometric.PhotometricTerm.__init__

    def keep(self, *args, **kw):
        init(self, *args, **kw)
        if self.channel == "grey":
            made["term"] = self

    photometric.PhotometricTerm.__init__ = keep
    frames = []
    for k, f in enumerate(open_video(a.video)):
        if k > a.frame:
            break
        frames.append(f)
    clip = _Clip(frames, 30.0)
    model = build_face_model()
    settings = replace(FitSettings(), photometric=True, photo_landmark_weight=a.landmark_weight)
    tracker = FitTracker(model, fps=30.0, settings=settings)
    try:
        first = tracker.calibrate(iter(clip), a.calibration_frame)
        for _ in Tracking(clip, tracker, first):
            pass
        fit, term = tracker.fit, made["term"]
        pose, c_fit = fit._prev.pose, fit._prev.contractions.copy()
        ids = list(model.ids)
        rows = {int(r["frame"]): r for r in csv.DictReader(open(a.toward))}
        c_other = np.array([float(rows[a.frame][k]) for k in ids])

        def est(c):
            return Estimate(pose, c, fit.shape(c), fit.response, np.arange(len(c)))

        term.restart()
        e0 = est(c_fit)
        term.prepare(e0)
        while term.settling:
            term.advance()
            term.prepare(e0)

        def per_sample(c):
            _, uv = term._uv(est(c))
            r = np.nan_to_num(term._residual(uv)) / term.sigma
            return term._w * r * r, uv, r

        print(f"frame {a.frame}: the photometric cost, weights and light fixed at the fit")
        for t in (0.0, 0.25, 0.5, 0.75, 1.0):
            c = np.clip(c_fit + t * (c_other - c_fit), 0.0, 1.0)
            print(f"  {t:.2f} of the way to {a.toward}'s contractions: {term.cost(est(c)):.1f}")
        cost0, uv0, r0 = per_sample(c_fit)
        cost1, _, _ = per_sample(c_other)
        delta = cost1 - cost0
        y = term.app.samples.points(fit.shape(np.zeros(len(ids))))[:, 1]
        print(f"  the change {delta.sum():+.1f}, by the face's height:")
        for name, lo, hi in BANDS:
            sel = (y >= lo) & (y < hi)
            print(f"    {name:32s} {delta[sel].sum():+8.1f} ({int(sel.sum())} samples)")
        top = np.argsort(c_fit)[::-1][:6]
        print(
            "  the fit's largest contractions:", ", ".join(f"{ids[i]} {c_fit[i]:.2f}" for i in top)
        )
        top = np.argsort(c_other)[::-1][:6]
        print("  the other's:", ", ".join(f"{ids[i]} {c_other[i]:.2f}" for i in top))

        w = term._w
        s = 3
        base = cv2.resize(frames[a.frame], None, fx=s, fy=s, interpolation=cv2.INTER_CUBIC)
        left, right = base.copy(), base.copy()
        for (x, yy), rr, dd, ww in zip(uv0, r0 * term.sigma, delta, w, strict=True):
            if ww <= 0:
                continue
            p = (int(x * s), int(yy * s))
            v = float(np.clip(rr / 30.0, -1, 1))
            cv2.circle(left, p, 2, (int(255 * v), 0, 0) if v > 0 else (0, 0, int(-255 * v)), -1)
            v = float(np.clip(dd, -1, 1))
            cv2.circle(right, p, 3, (int(255 * v), 0, 0) if v > 0 else (0, int(-255 * v), 0), -1)
        lo = np.maximum((uv0[w > 0].min(0) * s - 20).astype(int), 0)
        hi = (uv0[w > 0].max(0) * s + 20).astype(int)
        crop = [im[lo[1] : hi[1], lo[0] : hi[0]] for im in (left, right)]
        cv2.imwrite(a.out, cv2.cvtColor(np.concatenate(crop, axis=1), cv2.COLOR_RGB2BGR))
        print(f"wrote {a.out}")
    finally:
        tracker.close()


if __name__ == "__main__":
    main()
