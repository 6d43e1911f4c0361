"""Render neutral + the six EMFACS expressions at apex on the default face, side by side.

Usage: ``python tools/expression_contact_sheet.py [OUT.png] [--size PX]`` (default
``docs/expressions.png``, 224 px per face). Each expression is relaxed at intensity 1
(``expression_contractions(name, 1.0)``) and rendered from the front, labelled below.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from _sheet import labelled

import myoface as mf

REPO = Path(__file__).resolve().parents[1]
NAMES = ("neutral", "happiness", "sadness", "surprise", "fear", "anger", "disgust")


def contact_sheet(size: int = 224) -> np.ndarray:
    """(H, W, 3) uint8: one row of the seven faces, each ``size`` px square, labelled."""
    fm = mf.build_face_model()
    tiles = []
    for name in NAMES:
        state = None
        if name != "neutral":
            state = mf.relax(fm, mf.expression_contractions(name, 1.0, fm.ids)).state
        tiles.append(labelled(mf.render_face(fm, state, width=size, height=size), name))
    return np.concatenate(tiles, axis=1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=str(REPO / "docs" / "expressions.png"))
    ap.add_argument("--size", type=int, default=224)
    a = ap.parse_args()
    mf.write_image(a.out, contact_sheet(a.size))
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
