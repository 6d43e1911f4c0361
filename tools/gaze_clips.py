"""The gaze benchmark's clip and four more (other gaze programmes and camera noise), analysed end
to end (:func:`myoface.bench.gaze.run_gaze`): each clip's worse eye's RMS error (deg) and the
fitted head's rotation error (RMS pitch / yaw / roll, deg), then their mean and median.

    python tools/gaze_clips.py [--photometric] [--const '{"modelfit.PARALLAX_REFINE": false}']
                               [--wide-registration]

``--const``: module constants under ``myoface.analysis`` (JSON), as
``tools/photometric_ablation.py`` takes them. The clips are (gaze seed, camera seed) (0, 0)
(the benchmark's), (7, 3), (11, 5), (23, 9) and (31, 1); about 40 s a clip on two cores with
the photometric fit. The README's tables of the photometric fit's gaze were made this way.
``--wide-registration`` (with ``--photometric``, which it implies: the appearance is the
photometric fit's): the appearance registered on 12 frames spread evenly over the clip
(its blinks left out; MediaPipe's points on each frame alone) in place of the calibration
window's (:meth:`~myoface.analysis.modelfit.ModelFit.set_appearance`'s ``views``).
Measured 2026-12-06 (``--photometric`` without / with it): 4.16, 6.56, 6.81, 7.55, 6.25 ->
4.42, 5.62, 7.05, 8.11, 6.88 deg (mean 6.27 -> 6.42), the head's pitch RMS 0.86-1.60 ->
0.59-1.11 deg.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace

import numpy as np
from photometric_ablation import _constants  # (this folder's: the constants it sets)

#: (gaze programme seed, camera degradation seed) of each clip; the first is the benchmark's
CLIPS = ((0, 0), (7, 3), (11, 5), (23, 9), (31, 1))


def spread_views(frames, closure, n: int = 12) -> dict:
    """``{frame: (MediaPipe's points, image)}`` of ``n`` frames spread evenly over the clip,
    those whose lids close (``closure`` > 0 on either eye) left out."""
    from myoface.analysis.modelfit import spread_evenly
    from myoface.analysis.pipeline import detected_views

    shut = np.asarray(closure, dtype=np.float64).reshape(len(frames), -1).max(axis=1) > 0
    return detected_views({k: frames[k] for k in spread_evenly(np.flatnonzero(~shut), n)})


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--photometric", action="store_true", help="the fit with its pixels")
    ap.add_argument("--const", default="{}", help="module constants (JSON)")
    ap.add_argument("--wide-registration", action="store_true",
                    help="the appearance registered on frames spread over the clip")  # fmt: skip
    a = ap.parse_args(argv)
    a.photometric = a.photometric or a.wide_registration
    _constants(json.loads(a.const))
    import myoface.bench.gaze as bg
    from myoface.bench.headmotion import _model
    from myoface.render.degrade import CameraDegradation

    model = _model()
    values = []
    for gaze_seed, camera_seed in CLIPS:
        poses, gaze, closure, skins = bg.make_gaze_sequence(model, 90)
        if gaze_seed:
            gaze = bg.gaze_programme(90, seed=gaze_seed)
        frames, _ = bg.render_gaze_sequence(
            model.face, poses, gaze, skins, replace(CameraDegradation(), seed=camera_seed)
        )
        views = spread_views(frames, closure) if a.wide_registration else None
        r = bg.run_gaze(model, frames, poses, gaze, closure, skins, photometric=a.photometric,
                        registration=views)  # fmt: skip
        values.append(r["value"])
        print(f"clip {gaze_seed, camera_seed}: gaze {r['value']:.2f} deg, head rotation error "
              f"RMS {r['head_rotation_error_deg']['rms']} deg", flush=True)  # fmt: skip
    print(f"gaze: mean {np.mean(values):.2f}, median {np.median(values):.2f}, "
          f"worst {np.max(values):.2f} deg")  # fmt: skip


if __name__ == "__main__":
    main()
