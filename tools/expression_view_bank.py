"""The face at rest from its views: a clip of :mod:`myoface.bench.expression` analysed twice,
the second time with the photometric term reading each frame against the appearance of the
face at rest seen from the nearest of several views
(:meth:`~myoface.analysis.modelfit.ModelFit.set_view_appearances`), not only the calibration
frame's.

    PYTHONPATH=src python tools/expression_view_bank.py --clip h4 [--views oracle|first-pass]
                                                         [--list]

The first pass is the benchmark's analysis (the default fit on the camera's degraded frames);
its photometric fit's head pose at each frame is kept. The views are frames of the clip at rest,
at most :data:`MAX_VIEWS`, each :data:`MIN_SEPARATION_DEG` or more from the calibration frame's
view and from each other, the least expressive first:

- ``oracle``: the truth's rest frames (with the two before them): what the bank can do when
  the frames at rest are known;
- ``first-pass``: chosen from the first pass's own readings, as an analysis would have to:
  frames inside runs of at least :data:`RUN` frames that the expression reader labels
  neutral (a frame in from either end), whose contractions changed by at most
  :data:`STILL_CHANGE` (summed over the muscles) from frame to frame within two frames
  either side (an onset or an offset is not at rest), the least expressive
  (``1 - expr_neutral``) first.

The second pass is the benchmark's analysis again with each view's appearance taken at its
first-pass pose. Prints both passes' apex and rest accuracies (the benchmark's
``score_labels``) and the truth's phase at each view (``--list``: the views only, no second
pass). About two minutes a clip.

Measured 2026-12-06 (docs/expressions.md, "The face at rest from its views"). ``--still-points
1.5`` (the candidates also those whose MediaPipe points lie within 1.5 mm of the neutral at
the fitted pose, 90th percentile: at rest 0.4-3.0 mm, median 1.3-1.4, at the apex frames the
first pass missed 1.5-4.5) left 0-5 views a clip and no gain: the turned views' points sit
further from the neutral than that, and on ``p2`` a single view beside the calibration's took
its rest frames from 89.7 to 66.4 %: a view's appearance is only as good as the pose it is
taken at.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

#: at most this many views besides the calibration frame's
MAX_VIEWS = 12
#: the views are at least this far apart in head rotation (deg)
MIN_SEPARATION_DEG = 8.0
#: ``first-pass``: a view lies inside a run of at least this many frames labelled neutral
RUN = 6
#: ``first-pass``: the contractions' largest change from a frame to the next within two frames
#: of a view (summed over the muscles)
STILL_CHANGE = 0.45
#: ``--still-points``: the percentile over the points of their distance (mm, image plane) from
#: the person's neutral at the frame's fitted pose (the detector's offsets taken off)
POINTS_PCT = 90


def first_pass_candidates(labels, estimate) -> list[int]:
    """The frames a first pass's readings put at rest (see the module's docstring)."""
    out, k, n = [], 0, len(labels)
    while k < n:
        if labels[k] != "neutral":
            k += 1
            continue
        j = k
        while j < n and labels[j] == "neutral":
            j += 1
        if j - k >= RUN:
            out += list(range(k + 1, j - 1))
        k = j
    est = np.nan_to_num(np.asarray(estimate, dtype=np.float64))
    change = np.r_[0.0, np.abs(np.diff(est, axis=0)).sum(1)]
    near = np.array([change[max(0, k - 2) : k + 3].max() for k in range(n)])
    return [k for k in out if near[k] <= STILL_CHANGE]


def choose_views(candidates, strength, poses, calibration: int) -> list[int]:
    """At most :data:`MAX_VIEWS` of ``candidates``, the least ``strength`` first, each
    :data:`MIN_SEPARATION_DEG` from the calibration frame's view and the others chosen."""
    from myoface.analysis.camera import rotation_angle_deg

    chosen = [calibration]
    for k in sorted(candidates, key=lambda k: strength[k]):
        if len(chosen) > MAX_VIEWS:
            break
        if k in poses and all(
            rotation_angle_deg(poses[k].rotation, poses[j].rotation) >= MIN_SEPARATION_DEG
            for j in chosen
            if j in poses
        ):
            chosen.append(k)
    return chosen[1:]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clip", default="bench")
    ap.add_argument("--views", choices=("oracle", "first-pass"), default="first-pass")
    ap.add_argument("--list", action="store_true", help="the views only, no second pass")
    ap.add_argument(
        "--still-points",
        type=float,
        default=None,
        metavar="MM",
        help="first-pass: also MediaPipe's points within MM of the posed neutral (POINTS_PCT)",
    )
    a = ap.parse_args(argv)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from expression_calibration import register_held_out

    from myoface.analysis import modelfit
    from myoface.analysis.expressions import expression_sequence
    from myoface.bench import expression as ex

    register_held_out()
    clip = ex._clip(False, False, False, a.clip)
    phase, frames, points = clip[2], clip[6], clip[8]
    index = {id(p): k for k, p in enumerate(points) if p is not None}
    poses: dict = {}
    moved: dict = {}  # (MediaPipe's points' distance from the posed neutral, mm: POINTS_PCT)
    fit = modelfit.ModelFit.fit

    def recording(self, p, *args, **kw):  # (each frame's photometric fit's pose, pass 1)
        r = fit(self, p, *args, **kw)
        if id(p) in index:
            poses[index[id(p)]] = r.pose
            q = self._corrected(np.asarray(p, dtype=np.float64), r.pose)
            uv0 = self.camera.project(r.pose.apply(self.neutral + self.identity_mm))
            d = np.linalg.norm(q[:, :2] - uv0, axis=1) * self._pixel_mm(r.pose)
            moved[index[id(p)]] = float(np.nanpercentile(d, POINTS_PCT))
        return r

    modelfit.ModelFit.fit = recording
    try:
        first = ex._synthetic(False, clip=a.clip)
    finally:
        modelfit.ModelFit.fit = fit
    arr = next(v for k, v in reversed(ex._cache.items()) if k[0] == "arrays")
    scores, labels = expression_sequence(arr["estimate"], list(arr["ids"]), arr["angles_est"])
    strength = 1.0 - np.asarray(scores, dtype=np.float64)[:, -1]
    if a.views == "oracle":
        rest = [str(p) in ("rest", "first rest") for p in phase]
        cand = [k for k in range(2, len(rest)) if rest[k] and rest[k - 1] and rest[k - 2]]
    else:
        found = first_pass_candidates(labels, arr["estimate"])
        cand = found
        if a.still_points is not None:
            cand = [k for k in found if moved.get(k, np.inf) <= a.still_points]
    views = choose_views(cand, strength, poses, first["calibration_frame"])
    print(f"{a.clip}: pass 1 apex {first['apex_accuracy']:.3f} rest {first['rest_accuracy']:.3f}")
    print(f"  views ({a.views}): {views}")
    print(f"  the truth's phase there: {[str(phase[k]) for k in views]}")
    if a.list:
        if a.views == "first-pass":  # (each candidate's points' distance, by the truth's phase)
            for ph in ("first rest", "rest", "onset", "apex", "offset"):
                ds = [moved[k] for k in found if str(phase[k]) == ph and k in moved]
                if ds:
                    print(f"  {ph}: {len(ds)} candidates, points' distance (mm) "
                          f"{np.round(np.percentile(ds, [0, 50, 100]), 2)}")  # fmt: skip
        return
    bank = [(frames[k], poses[k]) for k in views]
    take = modelfit.ModelFit.set_appearance

    def with_views(self, frame, window=None, views=None):
        take(self, frame, window, views)
        self.set_view_appearances(bank)

    modelfit.ModelFit.set_appearance = with_views
    try:
        for k in [k for k in ex._cache if k[0] in ("synthetic", "arrays")]:
            del ex._cache[k]  # (the first pass's; the clip's frames stay)
        second = ex._synthetic(False, clip=a.clip)
    finally:
        modelfit.ModelFit.set_appearance = take
    print(f"  pass 2 apex {second['apex_accuracy']:.3f} rest {second['rest_accuracy']:.3f}")
    print(f"  confusion: {second['confusion']}")


if __name__ == "__main__":
    main()
