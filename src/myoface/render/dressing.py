"""What the skin mesh lacks to read as a face: eyeballs behind the eye openings, dark sockets and
a mouth cavity closing the holes, and a neutral skin texture (lips, brows) for the default face.

The dressing follows the animated skin: sockets and the mouth cavity are fans attached to the
current boundary loops of the openings, so they keep filling the mouth when the jaw opens;
eyeballs stay fixed in the head.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from myoface.face.eyes import EYE_RADIUS_MM as _EYE_RADIUS_MM

#: colours (linear RGB)
SCLERA = (0.78, 0.74, 0.70)
IRIS = (0.10, 0.055, 0.030)
PUPIL = (0.005, 0.005, 0.005)
#: what shows of an eye's socket between the lids' margins and the eyeball (the fan that
#: closes the opening, where the sphere does not fill it: the corners and along the upper
#: lid): at the corners and the lower lid the conjunctiva and the caruncle, a pink dimmer
#: than the sclera; under the upper lid its shadow and the lashes' (graded between the two by
#: height above the corners: :meth:`Opening.vertex_colors`). It was a near-black (0.05,
#: 0.025, 0.022) throughout until 2026-12-04: the renders' eyes had black wedges at their
#: corners, which no eye has, and the gaze reader on the true geometry read an eye turned
#: towards a corner by up to 5 deg too far, the wedge taken for iris (the gaze benchmark's
#: clip and four more, the worse eye 2.54, 3.65, 2.93, 3.21, 3.42 -> 2.16, 3.74, 2.43, 3.13,
#: 2.86 deg RMS, the mean 3.15 -> 2.87; all pink, 2.72, but the upper lid's shadow is real).
#: Reverted the same day because the analysis' benchmarks read worse on these eyes (the gaze
#: 4.28 -> 4.43 deg, the expressions 0.646 -> 0.573) and put back the day after that was
#: understood: the renders are the known answers the analysis is judged on, and the black
#: wedges were marks MediaPipe and the photometric fit placed the eyes by that no real eye
#: shows (the real eyes of single_face.mp4 have pink corners and a dark lash line): a
#: benchmark that flatters the detector is not kept for its numbers.
SOCKET = (0.55, 0.36, 0.33)
SOCKET_UPPER = (0.16, 0.09, 0.08)
MOUTH = (0.09, 0.015, 0.015)
#: eye geometry (mm, degrees): eyeball radius (see myoface.face.eyes); angular radii of iris
#: and pupil. The visible iris is 11.7 mm across (horizontal "white-to-white" diameter
#: 11.71 +- 0.42 mm, 100 adults: F. Rüfer, A. Schröder, C. Erb, "White-to-white corneal
#: diameter", Cornea 24(3):259-261, 2005): asin(5.85 / 12) = 29 degrees on the 12 mm eyeball
#: (24 degrees, a 9.8 mm iris, left white above and below it: a stare); the pupil 4.2 mm
EYE_RADIUS_MM = _EYE_RADIUS_MM
IRIS_DEG = 29.0
PUPIL_DEG = 10.0


def _srgb_to_linear(c):
    c = np.asarray(c, dtype=np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def eyeball(center: np.ndarray, forward: np.ndarray, radius: float, n_lon: int = 40):
    """An eyeball sphere: vertices (N,3), triangles, unit normals, linear colours (N,3).

    Rings of latitude are doubled at the pupil and iris edges so the colour changes sharply.
    """
    f = forward / np.linalg.norm(forward)
    a = np.array([0.0, 1.0, 0.0]) if abs(f[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(a, f)
    u /= np.linalg.norm(u)
    w = np.cross(f, u)
    eps = 0.05
    thetas = [0.0, 4.0, PUPIL_DEG - eps, PUPIL_DEG + eps, 15.0, 20.0, IRIS_DEG - eps]
    thetas += [IRIS_DEG + eps, 32.0, 45.0, 60.0, 75.0, 90.0, 110.0, 135.0, 160.0, 180.0]
    th = np.deg2rad(np.array(thetas))
    ph = np.linspace(0, 2 * np.pi, n_lon, endpoint=False)
    verts, cols = [], []
    for t, tdeg in zip(th, thetas, strict=True):
        col = PUPIL if tdeg < PUPIL_DEG else IRIS if tdeg < IRIS_DEG else SCLERA
        if 0 < tdeg < 180:
            for p in ph:
                d = np.cos(t) * f + np.sin(t) * (np.cos(p) * u + np.sin(p) * w)
                verts.append(d)
                cols.append(col)
        else:
            verts.append(np.cos(t) * f)
            cols.append(col)
    verts = np.array(verts)
    tris = []
    # cap at the front pole (index 0), rings 1..R, back pole last
    n_rings = len(thetas) - 2
    ring = lambda r, k: 1 + r * n_lon + (k % n_lon)  # noqa: E731
    for k in range(n_lon):
        tris.append([0, ring(0, k), ring(0, k + 1)])
    for r in range(n_rings - 1):
        for k in range(n_lon):
            a0, a1 = ring(r, k), ring(r, k + 1)
            b0, b1 = ring(r + 1, k), ring(r + 1, k + 1)
            tris += [[a0, b0, b1], [a0, b1, a1]]
    last = len(verts) - 1
    for k in range(n_lon):
        tris.append([last, ring(n_rings - 1, k + 1), ring(n_rings - 1, k)])
    normals = verts.copy()
    return center + radius * verts, np.array(tris, np.int64), normals, np.array(cols)


def _loop_containing(loops, vertices_of_feature) -> np.ndarray | None:
    feat = set(int(v) for v in vertices_of_feature)
    best, score = None, 0
    for lp in loops:
        s = len(feat & set(lp.tolist()))
        if s > score:
            best, score = lp, s
    return best


@dataclass
class Opening:
    """A hole of the skin mesh closed by a fan to a point ``depth_mm`` behind it."""

    name: str
    loop: np.ndarray  # vertex indices, in order
    depth_mm: float
    color: tuple

    def vertex_colors(self, vertices: np.ndarray) -> np.ndarray:
        """The fan's colours (len(loop) + 1, 3): its loop's vertices then its centre. An eye's
        grade from :attr:`color` at the corners and along the lower lid to
        :data:`SOCKET_UPPER` along the middle of the upper lid (by each margin vertex's height
        above the line through the corners, the loop's ends in x, over the highest; the
        centre their mean); any other opening's, :attr:`color` throughout."""
        k = len(self.loop)
        col = np.tile(np.asarray(self.color, dtype=np.float64), (k + 1, 1))
        if not self.name.startswith("eye"):
            return col
        pts = np.asarray(vertices, dtype=np.float64)[self.loop]
        a, b = pts[np.argmin(pts[:, 0])], pts[np.argmax(pts[:, 0])]
        t = np.clip((pts[:, 0] - a[0]) / max(b[0] - a[0], 1e-9), 0.0, 1.0)
        height = pts[:, 1] - (a[1] + t * (b[1] - a[1]))
        w = np.clip(height / max(height.max(), 1e-9), 0.0, 1.0)[:, None]
        col[:k] = (1.0 - w) * col[:k] + w * np.asarray(SOCKET_UPPER, dtype=np.float64)
        col[k] = col[:k].mean(axis=0)
        return col


#: a hole with fewer boundary vertices than this is a crack in the mesh, not an opening
MIN_OPENING_LOOP = 6


def _openings_by_shape(face, inner) -> dict:
    """{name: loop} for a face without eye/mouth landmarks (e.g. Waters' face): the eyes are
    the pair of holes mirrored across the midline (x = 0, the face's axes: x lateral, y up, z
    forward) that lies highest, the mouth the hole on the midline below them. Empty when no
    such pair is found."""
    v = face.vertices
    holes = [lp for lp in inner if len(lp) >= MIN_OPENING_LOOP]
    if len(holes) < 2:
        return {}
    width = float(np.ptp(v[:, 0]))
    cen = np.array([v[lp].mean(axis=0) for lp in holes])
    size = np.array([np.ptp(v[lp][:, 0]) for lp in holes])
    best, found = None, {}
    for i in range(len(holes)):
        for j in range(len(holes)):
            a, b = cen[i], cen[j]
            # a mirrored pair: opposite sides, at mirrored x, the same height, similar size
            if not (a[0] > 0.05 * width and b[0] < -0.05 * width):
                continue
            tol = 0.25 * max(size[i], size[j])
            if abs(a[0] + b[0]) > tol or abs(a[1] - b[1]) > tol or abs(a[2] - b[2]) > tol:
                continue
            if best is None or a[1] + b[1] > best[0]:
                best = (a[1] + b[1], i, j)
    if best is None:
        return {}
    _, i, j = best
    # the subject's left eye is on +x (the face looks down +z)
    found["eye_l"], found["eye_r"] = holes[i], holes[j]
    eye_y = min(cen[i][1], cen[j][1])
    mouth = [
        k
        for k in range(len(holes))
        if k not in (i, j) and abs(cen[k][0]) < 0.1 * width and cen[k][1] < eye_y
    ]
    if mouth:
        found["mouth"] = holes[max(mouth, key=lambda k: len(holes[k]))]
    return found


def find_openings(face) -> list[Opening]:
    """The eye and mouth openings of a face: from the default landmark groups, or for a face
    without them, from the shape of its holes (:func:`_openings_by_shape`); else none."""
    out = []
    loops = face.boundary_loops
    if not loops:
        return out
    rim = max(loops, key=len)
    inner = [lp for lp in loops if lp is not rim]
    lm = face.landmarks
    if not any(k in lm for k in ("eye_l", "eye_r", "lip_upper_inner")):
        by_shape = _openings_by_shape(face, inner)
        for name, depth, col in (
            ("eye_l", EYE_RADIUS_MM, SOCKET),
            ("eye_r", EYE_RADIUS_MM, SOCKET),
            ("mouth", 16.0, MOUTH),
        ):
            if name in by_shape:
                out.append(Opening(name, by_shape[name], depth, col))
        return out
    for name, key, depth, col in (
        ("eye_l", "eye_l", EYE_RADIUS_MM, SOCKET),
        ("eye_r", "eye_r", EYE_RADIUS_MM, SOCKET),
        ("mouth", "lip_upper_inner", 16.0, MOUTH),
    ):
        if key not in lm:
            continue
        lp = _loop_containing(inner, lm[key])
        if lp is not None:
            out.append(Opening(name, lp, depth, col))
    return out


def orient_fan(loop_pts: np.ndarray, center: np.ndarray) -> bool:
    """True if the fan (loop_i, loop_i+1, center) faces +z as given (else reverse it)."""
    a = loop_pts
    b = np.roll(loop_pts, -1, axis=0)
    n = np.cross(b - a, center - a).sum(axis=0)
    return n[2] > 0


def _polyline_mask(pts_uv: np.ndarray, px: np.ndarray, size: int, width_uv: float):
    """Soft stroke along a polyline in UV space: 1 on the line, falling off over width_uv."""
    d = np.full(len(px), np.inf)
    for a, b in zip(pts_uv[:-1], pts_uv[1:], strict=True):
        ab = b - a
        t = np.clip(((px - a) @ ab) / max(ab @ ab, 1e-12), 0, 1)
        d = np.minimum(d, np.linalg.norm(px - (a + t[:, None] * ab), axis=1))
    return np.exp(-0.5 * (d / width_uv) ** 2).reshape(size, size)


def default_skin_texture(face, size: int = 512, makeup: bool = False) -> np.ndarray:
    """A neutral skin texture (size, size, 3) float32 linear RGB in the face's UV space:
    even skin tone, tinted lips, soft brows and a faint blush, from the landmark groups.

    ``makeup=True`` darkens the features the snakes track, as the paper's subject wore make-up
    (T&W 1993, Section V-E): dark brows, darker lips, and dark lines along the hairline, the
    nasolabial furrows, the nose base and the chin boss."""
    from matplotlib.path import Path as MplPath
    from scipy.ndimage import gaussian_filter

    skin = _srgb_to_linear([222, 176, 152])
    lips = _srgb_to_linear([178, 96, 96])
    brow = _srgb_to_linear([92, 66, 52])
    blush = _srgb_to_linear([214, 146, 132])
    uv = face.uv
    ys, xs = np.mgrid[0:size, 0:size]
    pts = np.column_stack([(xs.ravel() + 0.5) / size, 1.0 - (ys.ravel() + 0.5) / size])

    def mask(poly_uv, blur_px):
        m = MplPath(poly_uv).contains_points(pts).reshape(size, size).astype(np.float64)
        return gaussian_filter(m, blur_px) if blur_px > 0 else m

    rng = np.random.default_rng(0)
    tex = np.empty((size, size, 3))
    tex[:] = skin
    # a faint mottling so the skin is not plastic
    noise = gaussian_filter(rng.normal(0, 1, (size, size)), 2.0)
    tex *= (1.0 + 0.025 * noise / noise.std())[:, :, None]
    lm = face.landmarks
    s = size / 512.0
    for side in ("l", "r"):
        if f"cheek_{side}" in lm:
            c = uv[lm[f"cheek_{side}"]].mean(axis=0)
            d2 = ((pts - c) ** 2).sum(axis=1).reshape(size, size)
            wgt = 0.35 * np.exp(-d2 / (2 * 0.045**2))
            tex = tex * (1 - wgt[:, :, None]) + blush * wgt[:, :, None]
    if "lip_upper_outer" in lm and "lip_lower_outer" in lm:
        poly = np.vstack([uv[lm["lip_upper_outer"]], uv[lm["lip_lower_outer"]][::-1]])
        wgt = 0.9 * mask(poly, 2.5 * s)
        tex = tex * (1 - wgt[:, :, None]) + lips * wgt[:, :, None]
    for side in ("l", "r"):
        up, lo = f"eyebrow_{side}", f"eyebrow_{side}_lower"
        if up in lm and lo in lm:
            poly = np.vstack([uv[lm[up]], uv[lm[lo]][::-1]])
            wgt = 0.85 * mask(poly, 3.0 * s)
            tex = tex * (1 - wgt[:, :, None]) + brow * wgt[:, :, None]
    if makeup:
        dark = _srgb_to_linear([40, 26, 22])
        for side in ("l", "r"):  # fill the brows dark
            up, lo = f"eyebrow_{side}", f"eyebrow_{side}_lower"
            if up in lm and lo in lm:
                poly = np.vstack([uv[lm[up]], uv[lm[lo]][::-1]])
                wgt = mask(poly, 1.0 * s)
                tex = tex * (1 - wgt[:, :, None]) + dark * wgt[:, :, None]
        if "lip_upper_outer" in lm and "lip_lower_outer" in lm:  # and the lips darker red
            poly = np.vstack([uv[lm["lip_upper_outer"]], uv[lm["lip_lower_outer"]][::-1]])
            wgt = mask(poly, 1.0 * s)
            tex = tex * (1 - wgt[:, :, None]) + 0.45 * lips * wgt[:, :, None]
        for g in ("forehead_top", "nasolabial_l", "nasolabial_r", "nose_base", "chin_boss"):
            if g in lm:
                wgt = 0.9 * _polyline_mask(uv[lm[g]], pts, size, 0.006)
                tex = tex * (1 - wgt[:, :, None]) + dark * wgt[:, :, None]
    return np.clip(tex, 0, 1).astype(np.float32)
