"""The inside of the mouth, drawn: teeth (upper fixed to the skull, lower and the tongue carried by
the jaw) as procedural meshes along a :class:`~myoface.face.teeth.Dentition`'s arches, gums, and a
cavity behind them whose walls darken with depth.

Every mesh is built once at rest (head frame, mm); the renderer moves the lower part by the jaw's
rigid motion each frame and re-attaches the cavity to the lips' current inner margin
(:func:`cavity_positions`). Colours are linear RGB with the mouth's shadow baked in (the
renderer's lights cast no shadows): the farther back inside the mouth, the darker.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from myoface.render.raster import vertex_normals_numba

#: linear RGB
ENAMEL = (0.74, 0.70, 0.60)
GUM = (0.42, 0.13, 0.12)
TONGUE = (0.36, 0.10, 0.09)
CAVITY_RIM = (0.06, 0.012, 0.011)
CAVITY_DEEP = (0.006, 0.0015, 0.0015)
#: teeth on one side, from the midline back: (name, mesiodistal width, crown height) mm of an
#: average adult's permanent teeth (dental anatomy textbooks' mean crown dimensions, rounded)
UPPER_TEETH = (
    ("central_incisor", 8.5, 10.5),
    ("lateral_incisor", 6.5, 9.0),
    ("canine", 7.5, 10.0),
    ("first_premolar", 7.0, 8.5),
    ("second_premolar", 6.5, 7.5),
    ("first_molar", 10.0, 7.0),
)
LOWER_TEETH = (
    ("central_incisor", 5.0, 9.0),
    ("lateral_incisor", 5.5, 9.5),
    ("canine", 7.0, 10.5),
    ("first_premolar", 7.0, 8.0),
    ("second_premolar", 7.0, 7.5),
    ("first_molar", 11.0, 7.5),
)
#: the cavity's first ring lies this far behind the lips' inner margin (mm), spread away from
#: the mouth's centre by CAVITY_SPREAD (x, y) so its walls pass outside the teeth, behind the lips
CAVITY_RING_DEPTH_MM = 24.0
CAVITY_SPREAD = (1.3, 2.2)
#: its back (the throat) this far behind the margin's centre (mm)
CAVITY_BACK_MM = 40.0
#: shadow inside the mouth: albedo x exp(-depth / this), depth behind the incisors (mm)
SHADOW_DEPTH_MM = 14.0


@dataclass
class MouthMeshes:
    """Rest meshes (head frame, mm): ``upper`` fixed, ``lower`` moved by the jaw; each a
    tuple (vertices (N, 3), triangles (F, 3), normals (N, 3), linear colours (N, 3))."""

    upper: tuple
    lower: tuple


def _superellipsoid(n_u: int = 8, n_v: int = 6, power: float = 4.0):
    """Unit rounded box: vertices (N, 3) in [-1, 1]^3 and triangles, closed, outward wound
    (a latitude-longitude sphere whose coordinates are raised to 2 / power)."""
    th = np.linspace(0.0, np.pi, n_v + 1)[1:-1]
    ph = np.linspace(0.0, 2 * np.pi, n_u, endpoint=False)
    e = 2.0 / power

    def f(c):
        return np.sign(c) * np.abs(c) ** e

    pts = [[0.0, 1.0, 0.0]]
    for t in th:
        for p in ph:
            pts.append([f(np.sin(t)) * f(np.cos(p)), f(np.cos(t)), f(np.sin(t)) * f(np.sin(p))])
    pts.append([0.0, -1.0, 0.0])
    v = np.array(pts)
    tris = []
    ring = lambda r, k: 1 + r * n_u + (k % n_u)  # noqa: E731
    for k in range(n_u):
        tris.append([0, ring(0, k + 1), ring(0, k)])
    for r in range(len(th) - 1):
        for k in range(n_u):
            a0, a1, b0, b1 = ring(r, k), ring(r, k + 1), ring(r + 1, k), ring(r + 1, k + 1)
            tris += [[a0, a1, b1], [a0, b1, b0]]
    last = len(v) - 1
    for k in range(n_u):
        tris.append([last, ring(len(th) - 1, k), ring(len(th) - 1, k + 1)])
    return v, np.array(tris, np.int64)


def _arch_point(arch, s: np.ndarray):
    """Points on the arch's front curve (in the y = 0 plane) at arc lengths ``s`` (signed,
    from the midline; mm), with unit tangents and outward normals (horizontal)."""
    xs = np.linspace(-arch.half_width * 1.3, arch.half_width * 1.3, 801)
    zs = arch.front_z(xs + arch.xc)
    seg = np.hypot(np.diff(xs), np.diff(zs))
    arc = np.r_[0.0, np.cumsum(seg)]
    arc -= np.interp(0.0, xs, arc)
    x = np.interp(s, arc, xs) + arch.xc
    z = arch.front_z(x)
    tan = np.column_stack([np.ones_like(x), np.zeros_like(x), -2 * arch.b * (x - arch.xc)])
    tan /= np.linalg.norm(tan, axis=1, keepdims=True)
    nrm = np.column_stack([-tan[:, 2], np.zeros_like(x), tan[:, 0]])
    return np.column_stack([x, np.zeros_like(x), z]), tan, nrm


def _mesh_normals(v, t):
    out = np.zeros_like(v)
    vertex_normals_numba(np.ascontiguousarray(v), np.ascontiguousarray(t, dtype=np.int64), out)
    return out


def _teeth_row(arch, table, scale, rng):
    """A row of rounded-box crowns along ``arch`` (both sides of the midline) and a gum band
    behind their roots: (vertices, triangles, normals, colours)."""
    unit_v, unit_t = _superellipsoid()
    verts, tris, cols = [], [], []
    n = 0
    up = arch.direction  # +1: crowns hang down from the upper gum; -1: stand up from the lower
    for side in (-1.0, 1.0):
        s0 = 0.0
        for k, (_name, width, height) in enumerate(table):
            w, h = width * scale, height * scale
            sc = side * (s0 + 0.5 * w)
            s0 += w
            p, tan, nrm = _arch_point(arch, np.array([sc]))
            p, tan, nrm = p[0], tan[0], nrm[0]
            depth = min(arch.thickness_mm, (5.5 + 0.6 * k) * scale)
            # local coordinates: a along the arch, b vertical (from the edge into the gum),
            # c across (into the mouth); the crown narrows towards its edge
            a = unit_v[:, 0] * 0.47 * w
            b = (unit_v[:, 1] + 1.0) * 0.5 * (h + 3.0 * scale)  # root part hidden in the gum
            taper = 0.55 + 0.45 * np.clip(b / max(h, 1e-9), 0, 1)
            c = (unit_v[:, 2] + 1.0) * 0.5 * depth * taper
            ax = sc + a
            base, tangent, normal = _arch_point(arch, ax)
            y = arch.edge(base[:, 0]) + up * b
            pos = base - normal * c[:, None]
            pos[:, 1] = y
            verts.append(pos)
            t = unit_t + n
            tris.append(t if up > 0 else t[:, ::-1])
            # per-tooth shade: a small random tint; darker towards the gaps and the gum,
            # greyer and more translucent at the edge
            tint = 1.0 + rng.uniform(-0.05, 0.05)
            gap = 1.0 - 0.35 * np.abs(unit_v[:, 0]) ** 6
            neck = 1.0 - 0.25 * np.clip(b / max(h, 1e-9), 0, 1) ** 3
            edge = np.clip(1.0 - b / (0.18 * h), 0, 1)[:, None]
            col = np.asarray(ENAMEL) * (tint * gap * neck)[:, None]
            col = col * (1 - 0.3 * edge) + 0.3 * edge * np.array([0.45, 0.48, 0.52])
            cols.append(col)
            n += len(pos)
            del p, tan, nrm, tangent
    v = np.concatenate(verts)
    t = np.concatenate(tris)
    # the gum: a band along the arch's front, from the crowns' necks into the lips' shadow
    s_max = sum(w for _n, w, _h in table) * scale
    s = np.linspace(-s_max, s_max, 25)
    base, _tan, normal = _arch_point(arch, s)
    rows = []
    neck_h = np.interp(np.abs(s), np.cumsum([0] + [w * scale for _n, w, _h in table]),
                       [h * scale for _n, _w, h in table] + [table[-1][2] * scale])  # fmt: skip
    # (its front at most 0.45 mm proud of the crowns' labial face: a thin attached gingiva,
    # which the skin below the lower lip covers, face.teeth.CHIN_CLEARANCE_MM; 0.9 showed
    # through the chin's coarse triangles in a glTF client by up to 0.26 mm)
    for frac, out_mm in ((0.8, 0.3), (1.05, 0.45), (1.5, 0.2), (2.0, -1.5)):
        r = base + normal * out_mm
        r[:, 1] = arch.edge(base[:, 0]) + up * frac * neck_h
        rows.append(r)
    g = np.concatenate(rows)
    m = len(s)
    gt = []
    for r in range(len(rows) - 1):
        for k in range(m - 1):
            a0, a1, b0, b1 = r * m + k, r * m + k + 1, (r + 1) * m + k, (r + 1) * m + k + 1
            gt += [[a0, a1, b1], [a0, b1, b0]]
    gt = np.array(gt, np.int64) + len(v)
    v = np.concatenate([v, g])
    t = np.concatenate([t, gt])
    cols.append(np.tile(GUM, (len(g), 1)))
    col = np.concatenate(cols)
    nrm = _mesh_normals(v, t)
    return v, t, nrm, col


def _tongue(dentition, scale, n_u: int = 16, n_v: int = 6):
    """A flattened half-ellipsoid resting inside the lower arch (rest pose)."""
    lo = dentition.lower
    rad = np.array([17.0, 6.5, 22.0]) * scale
    # its top just below the lower incisal edge, its tip behind the incisors
    c = np.array([lo.xc, lo.edge_y - 1.0 * scale - rad[1], lo.z0 - lo.thickness_mm - rad[2]])
    th = np.linspace(0.0, 0.5 * np.pi, n_v + 1)  # from the top down to the equator
    ph = np.linspace(0.0, 2 * np.pi, n_u, endpoint=False)
    pts = [c + rad * np.array([0.0, 1.0, 0.0])]
    for t in th[1:]:
        for p in ph:
            pts.append(
                c + rad * np.array([np.sin(t) * np.cos(p), np.cos(t), np.sin(t) * np.sin(p)])
            )
    v = np.array(pts)
    tris = []
    ring = lambda r, k: 1 + r * n_u + (k % n_u)  # noqa: E731
    for k in range(n_u):
        tris.append([0, ring(0, k + 1), ring(0, k)])
    for r in range(n_v - 1):
        for k in range(n_u):
            a0, a1, b0, b1 = ring(r, k), ring(r, k + 1), ring(r + 1, k), ring(r + 1, k + 1)
            tris += [[a0, a1, b1], [a0, b1, b0]]
    t = np.array(tris, np.int64)
    nrm = _mesh_normals(v, t)
    col = np.tile(TONGUE, (len(v), 1))
    return v, t, nrm, col


def _shadow(v, col, front_z):
    """Darken colours with depth behind the incisors' front (the mouth's shadow)."""
    depth = np.clip(front_z - v[:, 2], 0.0, None)
    return col * np.exp(-depth / SHADOW_DEPTH_MM)[:, None]


def mouth_meshes(dentition, seed: int = 0) -> MouthMeshes:
    """Teeth, gums and tongue for ``dentition`` (:func:`myoface.face.teeth.fit_dentition`)."""
    rng = np.random.default_rng(seed)
    sc = dentition.scale
    uv, ut, un, ucol = _teeth_row(dentition.upper, UPPER_TEETH, sc, rng)
    lv, lt, ln, lcol = _teeth_row(dentition.lower, LOWER_TEETH, sc, rng)
    tv, tt, tn, tcol = _tongue(dentition, sc)
    front = dentition.upper.z0
    upper = (uv, ut, un, _shadow(uv, ucol, front))
    lower = (
        np.concatenate([lv, tv]),
        np.concatenate([lt, tt + len(lv)]),
        np.concatenate([ln, tn]),
        np.concatenate([_shadow(lv, lcol, front), _shadow(tv, tcol, front)]),
    )
    return MouthMeshes(upper, lower)


def cavity_triangles(k: int, first: int) -> np.ndarray:
    """Triangles of the cavity for a margin loop of ``k`` vertices whose copies start at
    vertex ``first``: loop -> ring (k) -> back point, outward winding not guaranteed (the
    renderer lights both sides of open surfaces)."""
    i = np.arange(k)
    j = (i + 1) % k
    loop, ring, back = first + i, first + k + i, first + 2 * k
    wall = np.concatenate(
        [np.column_stack([loop, loop[j], ring[j]]), np.column_stack([loop, ring[j], ring])]
    )
    cap = np.column_stack([ring, ring[j], np.full(k, back)])
    return np.concatenate([wall, cap]).astype(np.int64)


def cavity_colors(k: int) -> np.ndarray:
    """Linear colours (2 k + 1, 3) of the cavity's vertices: the rim, the ring, the back."""
    return np.concatenate(
        [
            np.tile(CAVITY_RIM, (k, 1)),
            np.tile(np.sqrt(np.multiply(CAVITY_RIM, CAVITY_DEEP)), (k, 1)),
            np.asarray(CAVITY_DEEP)[None],
        ]
    )


def cavity_positions(loop_pts: np.ndarray, out: np.ndarray) -> None:
    """Write the cavity's 2 k + 1 vertices into ``out`` for the lips' inner margin
    ``loop_pts`` (k, 3) mm now: the rim on the margin, a ring behind it spread away from the
    mouth's centre (its walls pass outside the teeth, hidden behind the lips), the back."""
    k = len(loop_pts)
    c = loop_pts.mean(axis=0)
    out[:k] = loop_pts
    ring = c + (loop_pts - c) * np.array([CAVITY_SPREAD[0], CAVITY_SPREAD[1], 1.0])
    ring[:, 2] = loop_pts[:, 2] - CAVITY_RING_DEPTH_MM
    out[k : 2 * k] = ring
    out[2 * k] = c - np.array([0.0, 0.0, CAVITY_BACK_MM])
