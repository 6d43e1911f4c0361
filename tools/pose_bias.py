"""Where the fitted head frame sits against the true one: the head-motion benchmark's clip
analysed with and without MediaPipe's depth in the calibration (``modelfit.IDENTITY_DEPTH``).

    python tools/pose_bias.py [--clean] [--moving] [--photometric]

For each setting: the head angles' error (estimate - truth, degrees: yaw, pitch, roll), its
mean over the clip (a bias: the head frame turned) and its spread, the benchmark's numbers
(``analysis.headmotion``'s head RMS, skin mm, median RMSE), and the calibrated neutral's
linear part: the least-squares affine map of the model's neutral onto the identity offset
(mm per mm; ``d offset_y / d z`` and ``d offset_z / d y`` are the shear that a frontal view
cannot tell from a pitch of the head). ``--clean``: the clean renders (default: degraded by
the camera, as the benchmark); ``--moving``: the head turning (default: still);
``--photometric``: the fit with its photometric term (default: the landmarks alone).
"""

from __future__ import annotations

import argparse

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clean", action="store_true", help="the clean renders")
    ap.add_argument("--moving", action="store_true", help="the head turning")
    ap.add_argument("--photometric", action="store_true", help="with the photometric term")
    a = ap.parse_args(argv)

    import myoface.analysis.modelfit as MF
    from myoface.analysis.weights import FitSettings
    from myoface.bench import headmotion as H

    still, degraded = not a.moving, not a.clean
    fm, truth, poses, skins, points, _ = H._sequence(False, still, False, degraded)
    frames = H._frames(False, still, degraded)
    print(f"clip: head {'still' if still else 'moving'}, {'degraded' if degraded else 'clean'}"
          f" renders, {'photometric' if a.photometric else 'landmarks'} fit, {len(frames)} frames")  # fmt: skip
    saved = MF.IDENTITY_DEPTH
    try:
        for depth in (True, False):
            MF.IDENTITY_DEPTH = depth
            identity = []
            orig = MF.ModelFit.calibrate

            def calibrate(self, *args, _orig=orig, _out=identity, **kw):
                cal = _orig(self, *args, **kw)
                _out.append((self.neutral.copy(), self.identity_mm.copy()))
                return cal

            MF.ModelFit.calibrate = calibrate
            try:
                res = H.run_headmotion(fm, points, truth, poses, skins, frames=frames,
                                       settings=FitSettings(photometric=a.photometric))  # fmt: skip
            finally:
                MF.ModelFit.calibrate = orig
            err = res.angles_est - res.angles_true
            s = res.summary()
            neutral, ident = identity[-1]
            x = np.c_[neutral - neutral.mean(0), np.ones(len(neutral))]
            lin, *_ = np.linalg.lstsq(x, ident, rcond=None)
            print(f"MediaPipe's depth in the calibration {'on ' if depth else 'off'}: "
                  f"angle error mean {np.round(np.nanmean(err, 0), 2)} sd "
                  f"{np.round(np.nanstd(err, 0), 2)} deg; head {s['pose_deg']:.2f} deg, skin "
                  f"{s['skin_mm']:.2f} mm, median RMSE {s['rmse_median_all']:.3f}; the neutral's "
                  f"shear d(offset y)/dz {lin[2, 1]:+.4f}, d(offset z)/dy {lin[1, 2]:+.4f}")  # fmt: skip
    finally:
        MF.IDENTITY_DEPTH = saved
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
