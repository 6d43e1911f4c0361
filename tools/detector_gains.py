"""How much of each muscle's motion MediaPipe's face mesh reads on a person's face: the
detector's gain per muscle, measured by analysis by synthesis at the calibration pose.

    python tools/detector_gains.py [VIDEO]    # default: the sample video, single_face.mp4

The video's first 2 s are calibrated as ``myoface analyze`` does (the most neutral frame, the
person's neutral); the model, textured with the calibration frame where the calibration put
each vertex (:meth:`~myoface.analysis.synthesis.LandmarkSynthesis.from_frame`: the person's
own skin, as the frame shows it), is rendered at the calibration pose at rest and with one
muscle at a time contracted to 0.5 and to 1.0, and MediaPipe reads each render. A muscle's
gain is how far MediaPipe's points moved along the model's own motion, over how far the
model moved (least squares over the vertices the muscle moves by more than a fifth of its
largest motion, in the image, x and y), and ``agree`` the cosine between the two motions
there (1: MediaPipe moves its points the way the skin moved). What the 3-D fit on
MediaPipe's points inherits (its readings short of the motion: README, "Known answers for
the whole analysis"); :class:`~myoface.analysis.landmarks.TrackerOffsets` has what a linear
correction with these gains did.
"""

from __future__ import annotations

import sys

import numpy as np


def main(argv=None) -> int:
    from myoface.analysis.sample import fetch_sample_video
    from myoface.analysis.synthesis import LandmarkSynthesis
    from myoface.analysis.trackers.landmark_fit import FitTracker
    from myoface.analysis.video import open_video
    from myoface.model import build_face_model

    args = sys.argv[1:] if argv is None else argv
    path = args[0] if args else fetch_sample_video()
    fm = build_face_model()
    video = open_video(path)
    frames = [f for _, f in zip(range(int(round(2 * video.fps)) + 1), video, strict=False)]
    tracker = FitTracker(fm, fps=video.fps, gaze=False)
    try:
        tracker.calibrate(iter(frames))
        fit, cal = tracker.fit, tracker.calibration
        shape = fit.neutral + fit.identity_mm
        syn = LandmarkSynthesis.from_frame(fm.face, fit.camera, frames[cal.index], shape, cal.pose)
        try:
            rest = syn.tracker_error(shape, cal.pose)
            uv0 = fit.camera.project(cal.pose.apply(shape))
            print(f"{path}: calibrated on frame {cal.index}\n")
            print("| muscle | gain at 0.5 | gain at 1.0 | agree at 1.0 | largest motion (px) |")
            print("|---|---:|---:|---:|---:|")
            gains = []
            for j, name in enumerate(fm.ids):
                row = [name]
                for amp in (0.5, 1.0):
                    moved = shape + amp * fit.response[:, :, j]
                    d_model = fit.camera.project(cal.pose.apply(moved)) - uv0
                    size = np.linalg.norm(d_model, axis=1)
                    err = syn.tracker_error(moved, cal.pose)
                    if err is None or rest is None or size.max() < 0.3:
                        row.append("-")
                        continue
                    # MediaPipe's points moved by the model's motion plus its error's change
                    d_read = d_model + err[:, :2] - rest[:, :2]
                    use = size > 0.2 * size.max()
                    m, r = d_model[use].ravel(), d_read[use].ravel()
                    g = float(m @ r / (m @ m))
                    row.append(f"{g:.2f}")
                    if amp == 1.0:
                        gains.append(g)
                        row.append(f"{m @ r / np.sqrt((m @ m) * (r @ r)):.2f}")
                        row.append(f"{size.max():.1f}")
                print("| " + " | ".join(row) + " |", flush=True)
            if gains:
                q = np.percentile(gains, [25, 50, 75])
                print(f"\ngain at 1.0 over {len(gains)} muscles: quartiles "
                      f"{q[0]:.2f} / {q[1]:.2f} / {q[2]:.2f}")  # fmt: skip
        finally:
            syn.close()
    finally:
        tracker.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
