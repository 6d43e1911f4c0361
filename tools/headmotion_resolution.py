"""The head-motion benchmark's renders at another resolution: how much the frame's pixels hold
the default analysis' numbers (issue 30).

    python tools/headmotion_resolution.py 1280 960 [--seed N] [--still]

Renders the benchmark's clip (``myoface.bench.headmotion``: the person's face, the head
turning, the six expressions, degraded as a webcam's by ``CameraDegradation`` with the
camera seed ``N``) at ``W x H`` pixels with the same camera's field of view, runs the default
analysis on it as the benchmark does and prints its headline numbers (worst and median RMSE,
worst correlation, skin mm, head deg). The degradations are in pixels, so at twice the
resolution they are half as strong on the face; the face's texture is the benchmark's. About
two minutes at 1280 x 960 on two cores. Measured 2026-12-06: README, "At twice the webcam's
resolution".
"""

from __future__ import annotations

import argparse


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("width", type=int)
    ap.add_argument("height", type=int)
    ap.add_argument("--seed", type=int, default=0, help="the camera's seed (default 0)")
    ap.add_argument("--still", action="store_true", help="the head still (default: moving)")
    a = ap.parse_args(argv)

    import myoface.bench.headmotion as H
    from myoface.analysis.weights import FitSettings

    size = (a.width, a.height)
    H.SIZE = size  # (read by run_headmotion's camera and the offsets table)
    defaults = list(H.camera_renderer.__defaults__)
    defaults[0] = size  # (camera_renderer's size, bound when it was defined)
    H.camera_renderer.__defaults__ = tuple(defaults)
    fm, truth, poses, skins, points, _ = H._sequence(False, a.still, False, True, a.seed)
    frames = H._frames(False, a.still, True, a.seed)
    res = H.run_headmotion(fm, points, truth, poses, skins, settings=FitSettings(), frames=frames)
    s = res.summary()
    head = "still" if a.still else "moving"
    keys = ("rmse_worst", "corr_worst", "rmse_median_all", "skin_mm", "pose_deg")
    print(f"{size[0]}x{size[1]}, camera seed {a.seed}, head {head}:")
    for k in keys:
        print(f"  {k:16s} {float(s[k]):.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
