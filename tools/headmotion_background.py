"""Which of the camera's degradations pitches the head-motion loop's calibration (issue 30).

Renders the still head's first second with each degradation of
:class:`~myoface.render.degrade.CameraDegradation` alone (and all, and none), detects
MediaPipe's points, calibrates the 3-D fit on them (the person's own offsets table, as the
benchmark does) and prints the calibration pose's error (yaw, pitch, roll, degrees) against the
truth. Usage: ``python tools/headmotion_background.py`` (about a minute on two cores).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np


def main() -> None:
    from myoface.analysis.camera import PinholeCamera
    from myoface.analysis.landmarks import TrackerOffsets
    from myoface.analysis.modelfit import ModelFit
    from myoface.analysis.weights import FitSettings
    from myoface.bench import headmotion as hm
    from myoface.render.degrade import CameraDegradation

    cam = PinholeCamera.for_image(hm.SIZE[0], hm.SIZE[1], hm.FOV_DEG)
    fm = hm._model()
    _, poses, skins = hm._truth(False, True)
    poses, skins = poses[:30], skins[:30]
    base = CameraDegradation()
    none = CameraDegradation(
        light_amplitude=0.0, exposure_drift=0.0, background=False, blur_sigma_px=0.0,
        full_scale_electrons=None, read_noise_electrons=0.0, crf=None,
    )  # fmt: skip
    variants = {
        "every degradation (the benchmark's)": base,
        "none (the texture resampled only)": none,
        "moving light and exposure only": replace(
            none, light_amplitude=base.light_amplitude, exposure_drift=base.exposure_drift
        ),
        "the room behind the head only": replace(none, background=True),
        "blur only": replace(none, blur_sigma_px=base.blur_sigma_px),
        "sensor noise only": replace(
            none,
            full_scale_electrons=base.full_scale_electrons,
            read_noise_electrons=base.read_noise_electrons,
        ),
        "H.264 only": replace(none, crf=base.crf),
    }

    def calibration_error(frames) -> np.ndarray:
        pts, _ = hm.detect_sequence(frames)
        s = FitSettings()
        fit = ModelFit(fm, cam, s, fps=30)
        fit.set_offsets(
            TrackerOffsets.of_textured_face(fm.face, fit.neutral, cam, hm.SIZE, s.tracking)
        )
        cal = fit.calibrate(pts)
        return cal.pose.angles_deg - poses[cal.index].angles_deg

    print(f"{'renders':40s} calibration pose error (yaw, pitch, roll) deg")
    print(f"{'the renderer own (full texture)':40s}", np.round(
        calibration_error(hm.render_sequence(fm.face, poses, skins)), 2))  # fmt: skip
    for name, deg in variants.items():
        frames, _ = hm.degraded_sequence(fm.face, poses, skins, deg)
        print(f"{name:40s}", np.round(calibration_error(frames), 2), flush=True)


if __name__ == "__main__":
    main()
