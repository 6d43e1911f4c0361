"""What of the gaze benchmark's error the camera's room, the key light and the face's texture
hold (issue 35): ``analysis.gaze_error_deg``'s clip (:mod:`myoface.bench.gaze`, 90 frames)
rendered again with one part changed, analysed end to end as the benchmark does, and each
eye's yaw bias (the mean error) with the reader alone on the true geometry beside it.

Usage: ``python tools/gaze_parts.py [PART ...]`` with parts ``default`` (the benchmark's
camera), ``no_room`` (the studio background in place of the room behind the head),
``front_light`` (no room; one frontal light of the default lights' total intensity in place
of the key, fill and rim) and ``no_texture`` (no room; the face without its texture); about 30
s a part on two cores.

Measured 2026-12-03 at 3ad5490 (the worse eye's RMS; yaw mean left / right; the reader's own
yaw mean on the true geometry left / right): default 4.49 deg, -2.84 / -4.49, -0.04 / -1.28;
no_room 3.70, -1.63 / -3.79, -0.17 / -1.22; front_light 5.46, -2.14 / -4.90, -0.47 / -1.11
(the fit's poses worse under a flat light); no_texture 8.69 (MediaPipe reads the untextured
face badly), the reader -0.39 / -0.82. The room costs about 0.8 deg of the 4.5; the right
eye's own reader bias stays with one frontal light, so it is not the key light's shading, and
it shrinks without the texture: part is how the person's texture around that eye looks to the
reader's eyeball model, part the eye's own shape. The most of the yaw bias is where the fit's
poses put the eyeballs' centres (0.7 px to the image's right of the truth for the right eye
without the room): with the room gone and that taken off, both eyes would be near 2.6-2.9.
"""

from __future__ import annotations

import sys
from dataclasses import replace

import numpy as np

PARTS = ("default", "no_room", "front_light", "no_texture")


def run(part: str) -> dict:
    import myoface.render.renderer as rr
    from myoface.bench import gaze as g
    from myoface.bench.headmotion import _model
    from myoface.face import FaceMesh
    from myoface.render.degrade import CameraDegradation

    model = _model()
    poses, gaze, closure, skins = g.make_gaze_sequence(model, 90)
    deg = CameraDegradation()
    face = model.face
    if part != "default":
        deg = replace(deg, background=False)
    if part == "no_texture":
        face = FaceMesh(
            face.vertices, face.triangles, face.uv, None, face.landmarks, name=face.name
        )
    saved = rr.default_lights
    if part == "front_light":
        total = sum(li.intensity for li in saved())
        rr.default_lights = lambda: [rr.Light((0.0, 0.0, 1.0), (1.0, 1.0, 1.0), total)]
    try:
        frames, _ = g.render_gaze_sequence(face, poses, gaze, skins, degradation=deg)
    finally:
        rr.default_lights = saved
    return g.run_gaze(model, frames, poses, gaze, closure, skins)


def main(parts) -> None:
    print(f"{'part':12s} worse eye  yaw mean l / r   reader's own yaw mean l / r (deg)")
    for part in parts:
        if part not in PARTS:
            raise SystemExit(f"unknown part {part!r}; the parts: {', '.join(PARTS)}")
        r = run(part)
        yaw = [r["per_eye"][e]["mean_deg"][0] for e in "lr"]
        own = [r["reader_on_true_geometry"][e]["mean_deg"][0] for e in "lr"]
        print(f"{part:12s} {r['value']:9.2f}  {np.round(yaw, 2)}   {np.round(own, 2)}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:] or PARTS)
