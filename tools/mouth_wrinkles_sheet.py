"""Before/after contact sheet of the mouth (teeth, cavity, lip contact) and the wrinkle shading.

Top row: the renderer without them (a dark fan in the mouth, smooth skin); bottom row: with
them (both rows show the model's skin, with the lip contact). Columns: neutral, AU26 (jaw open), a broad smile (AU6+12+25),
viseme A, brow raise (AU1+2), frown (AU4).

    python tools/mouth_wrinkles_sheet.py docs/mouth_wrinkles.png
"""

from __future__ import annotations

import sys

import numpy as np

import myoface as mf
from myoface.render import Renderer, write_image
from myoface.synth import make_camera

CASES = (
    ("neutral", {}),
    ("AU26", {26: 1.0}),
    ("AU6+12+25", {6: 0.6, 12: 1.0, 25: 0.6}),
    ("viseme A", "A"),
    ("AU1+2", {1: 1.0, 2: 1.0}),
    ("AU4", {4: 1.0}),
)


def main(out: str, size: int = 200) -> None:
    fm = mf.build_face_model()
    cam = make_camera(fm.face.vertices, "front", size, size)
    before = Renderer(fm.face, cam, teeth=False, wrinkles=False)
    after = Renderer(fm.face, cam)
    rows = [[], []]
    for _name, ctl in CASES:
        if isinstance(ctl, str):
            c = mf.viseme_contractions(ctl, 1.0, fm.ids)
        else:
            c = mf.au_contractions(ctl, fm.ids)
        st = fm.relax(c).state
        skin = fm.skin_vertices(st)
        rows[0].append(before.render(skin))
        rows[1].append(after.render(skin, jaw=fm.jaw_pose(st)))
    write_image(out, np.concatenate([np.concatenate(r, axis=1) for r in rows], axis=0))


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "mouth_wrinkles.png")
