"""What part of the camera costs the anchored flow the expressions (docs/expression_trackers.md):
the benchmark's clip (head moving) degraded with parts of the camera off, read by MediaPipe,
fitted with the flow without and with the AU-space prior, labelled as contractions.csv is.

    python tools/expression_camera_parts.py [no_light] [light_only] [no_room]

``no_light``: no moving light and no exposure drift (blur, sensor noise, H.264 kept);
``light_only``: the moving light and the drift, without blur, sensor noise and H.264. Both
keep the half-resolution texture and the room behind the head. ``no_room``: every part but the
room behind the head (which pitches the calibration: ``tools/headmotion_background.py``).
About 3 minutes a part on a loaded 2-core machine.
"""

from __future__ import annotations

import json
import sys
from dataclasses import replace


def main() -> None:
    from myoface.analysis.expressions import expression_sequence
    from myoface.analysis.weights import FitSettings
    from myoface.bench import expression as ex
    from myoface.bench import headmotion as hm
    from myoface.render.degrade import CameraDegradation

    fm = hm._model()
    truth, played, phase = ex.episode_programme(fm.ids, ex.EPISODES, ex.PHASES)
    poses = hm.head_trajectory(len(truth), False)
    skins = hm.relaxed_skins(fm, truth)
    base = CameraDegradation()
    parts = {
        "no_light": replace(base, light_amplitude=0.0, exposure_drift=0.0),
        "light_only": replace(
            base, blur_sigma_px=0.0, full_scale_electrons=None, read_noise_electrons=0.0,
            crf=None,
        ),
        "no_room": replace(base, background=False),
    }  # fmt: skip
    for name in sys.argv[1:] or list(parts):
        frames, _ = hm.degraded_sequence(fm.face, poses, skins, parts[name])
        points, _ = hm.detect_sequence(frames)
        for prior in (None, 0.1):
            res = hm.run_headmotion(
                fm, points, truth, poses, skins, settings=FitSettings(au_prior_sigma=prior),
                frames=frames, anchored_flow=True,
            )  # fmt: skip
            _, labels = expression_sequence(res.estimate, fm.ids, res.angles_est)
            s = ex.score_labels(labels, played, phase)
            print(name, "AU prior", prior, f"apex {s['apex_accuracy']:.3f}",
                  f"rest {s['rest_accuracy']:.3f}", json.dumps(s["confusion"]), flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
