"""Close-ups of the eyes in the lid action units, side by side.

Usage: ``python tools/eyelid_sheet.py [OUT.png] [--size PX]`` (default ``docs/eyelids.png``,
tiles ``PX`` wide and ``PX / 2`` high, 384 by default, in rows of four). Each tile is the default face relaxed for
its action units and rendered from the front, framed on both eyes and brows, labelled below:
neutral, AU5, AU7, AU43 at 0.5, AU45 at 1, AU6, AU1+2+5.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from _sheet import grid, labelled

import myoface as mf
from myoface.render import Camera, Renderer

REPO = Path(__file__).resolve().parents[1]
TILES = (
    ("neutral", {}),
    ("AU5", {5: 1.0}),
    ("AU7", {7: 1.0}),
    ("AU43 0.5", {43: 0.5}),
    ("AU45", {45: 1.0}),
    ("AU6", {6: 1.0}),
    ("AU1+2+5", {1: 1.0, 2: 1.0, 5: 1.0}),
)


def eyelid_sheet(size: int = 384) -> np.ndarray:
    """(H, W, 3) uint8: close-ups in rows of four, each ``size`` x ``size // 2`` px, labelled."""
    fm = mf.build_face_model()
    f = fm.face
    keys = ("eye_l", "eye_r", "eyebrow_l_lower", "eyebrow_r_lower")
    frame = f.vertices[np.concatenate([f.landmarks[k] for k in keys])]
    cam = Camera.front(frame, width=size, height=size // 2, margin=1.05)
    r = Renderer(f, cam)
    tiles = []
    for label, aus in TILES:
        state = mf.relax(fm, mf.au_contractions(aus, fm.ids)).state if aus else None
        tiles.append(labelled(r.render(fm.skin_vertices(state)), label))
    return grid(tiles, 4)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=str(REPO / "docs" / "eyelids.png"))
    ap.add_argument("--size", type=int, default=384)
    a = ap.parse_args()
    mf.write_image(a.out, eyelid_sheet(a.size))
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
