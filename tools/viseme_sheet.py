"""Close-ups of the mouth in the 14 MPEG-4 visemes and rest, on the default face.

Usage: ``python tools/viseme_sheet.py [OUT.png] [--size PX]`` (default ``docs/visemes.png``,
tiles ``PX`` wide and ``0.8 PX`` high, 200 by default, in rows of five). Each tile is the
default face relaxed for a viseme at intensity 1 (``viseme_contractions``), rendered from the
front (teeth, the mouth's cavity, the lips' contact) and framed on the mouth and chin,
labelled below with the viseme and its phonemes.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from _sheet import grid, labelled

import myoface as mf
from myoface.render import Camera, Renderer

REPO = Path(__file__).resolve().parents[1]


def viseme_sheet(size: int = 200) -> np.ndarray:
    """(H, W, 3) uint8: the visemes in rows of five, each ``size`` x ``0.8 size`` px."""
    from myoface.control.facs import _visemes

    doc = _visemes()
    fm = mf.build_face_model()
    f = fm.face
    keys = ("lip_upper_outer", "lip_lower_outer", "nose_base", "chin_boss")
    frame = f.vertices[np.concatenate([f.landmarks[k] for k in keys])]
    r = Renderer(f, Camera.front(frame, width=size, height=int(0.8 * size), margin=1.1))
    tiles = []
    for name, entry in doc.items():
        st = mf.relax(fm, mf.viseme_contractions(name, 1.0, fm.ids)).state
        img = r.render(fm.skin_vertices(st), jaw=fm.jaw_pose(st))
        phon = entry.get("phonemes", "")
        tiles.append(labelled(img, f"{name} ({phon})" if phon else name))
    return grid(tiles, 5)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=str(REPO / "docs" / "visemes.png"))
    ap.add_argument("--size", type=int, default=200)
    a = ap.parse_args()
    mf.write_image(a.out, viseme_sheet(a.size))
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
