"""Skin that folds: wrinkle shading driven by the compression of the skin (epidermal) triangles.

Where the skin shortens along a direction, it buckles into furrows across it. Per frame, each
skin triangle's deformation gradient F (deformed edges over rest edges, in the triangle's plane)
gives its stretch along two fixed rest directions of the head frame, up (y) and lateral (x), and
across the nasolabial fold (the landmark group's polyline, when the face has it). The
compression beyond a dead zone,

    c = max(0, 1 - |F t| - COMPRESSION_DEAD_ZONE),

averaged onto the vertices (area-weighted), scales a height field of the skin in its rest
coordinates X:

    h = A_y sin(k X_y) + A_x sin(k X_x) - A_n exp(-(s / w)^2),    A = gain * c,

horizontal furrows where the skin is squeezed vertically (the forehead in a brow raise, crow's
feet), vertical ones where it is squeezed sideways (the glabella in a frown), and one groove
along the nasolabial line (s: the rest distance to it) where the cheek pushes against it. The
renderer tilts each pixel's normal by the height field's gradient on the deformed surface
(n' = normalize(n - grad h)): a normal map whose strength is the skin's own compression, zero
wherever the skin is not compressed. Millimetres; head frame x lateral, y up, z forward.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

#: compressions below this (1 - stretch) leave the skin smooth: the relaxed tissue's rounding
#: and the small strains of a face at rest make no furrows
COMPRESSION_DEAD_ZONE = 0.02
#: furrow spacing (mm): forehead lines and crow's feet lie some 5-10 mm apart
WAVELENGTH_MM = 6.0
#: furrow height (mm) per unit compression (a 10 % compression: 0.4 mm, slopes ~0.4)
FURROW_GAIN_MM = 4.0
#: the nasolabial groove: half-width (mm) and depth (mm) per unit compression
FOLD_WIDTH_MM = 2.5
FOLD_GAIN_MM = 6.0
#: a rest direction that lies this close to a triangle's normal (cosine of the angle to the
#: plane below it) has no meaningful stretch in that triangle
MIN_IN_PLANE = 0.3
#: per-vertex columns of :meth:`WrinkleField.vertex_fields`: rest x, rest y, nasolabial
#: distance s, amplitudes A_x, A_y, A_n
N_VERTEX = 6


def _polyline_distance(p: np.ndarray, line: np.ndarray):
    """Distance (N,) in the (x, y) plane from points (N, 2) to a polyline (K, 2), and the unit
    direction (N, 2) across the polyline at the nearest point."""
    best = np.full(len(p), np.inf)
    across = np.zeros((len(p), 2))
    for a, b in zip(line[:-1], line[1:], strict=True):
        ab = b - a
        t = np.clip(((p - a) @ ab) / max(ab @ ab, 1e-12), 0.0, 1.0)
        d = np.linalg.norm(p - (a + t[:, None] * ab), axis=1)
        better = d < best
        best[better] = d[better]
        nrm = np.array([-ab[1], ab[0]]) / max(np.linalg.norm(ab), 1e-12)
        across[better] = nrm
    return best, across


class WrinkleField:
    """The wrinkle height field of a face (rest: ``face`` a FaceMesh); :meth:`compute` gives
    its per-frame amplitudes and gradients for deformed skin vertices.

    Attributes
    ----------
    rest : (V, 3) rest vertices (mm).
    fold_s : (V,) rest distance (mm) of each vertex to the nearest nasolabial line (inf
        without the landmark groups).
    """

    def __init__(self, face):
        v = np.asarray(face.vertices, dtype=np.float64)
        t = np.asarray(face.triangles, dtype=np.int64)
        self.rest = v
        self.triangles = t
        self.k = 2 * np.pi / WAVELENGTH_MM
        nv, nt = len(v), len(t)
        # rest-plane basis of each triangle, and the inverse of its rest edge matrix
        e1 = v[t[:, 1]] - v[t[:, 0]]
        e2 = v[t[:, 2]] - v[t[:, 0]]
        n = np.cross(e1, e2)
        area2 = np.linalg.norm(n, axis=1)
        ok = area2 > 1e-12
        n = n / np.where(ok, area2, 1.0)[:, None]
        b1 = e1 / np.maximum(np.linalg.norm(e1, axis=1), 1e-12)[:, None]
        b2 = np.cross(n, b1)
        dm = np.stack(
            [
                np.stack([(e1 * b1).sum(1), (e2 * b1).sum(1)], 1),
                np.stack([(e1 * b2).sum(1), (e2 * b2).sum(1)], 1),
            ],
            1,
        )  # fmt: skip  (T, 2, 2): rows = basis, cols = edges
        det = dm[:, 0, 0] * dm[:, 1, 1] - dm[:, 0, 1] * dm[:, 1, 0]
        ok &= np.abs(det) > 1e-12
        dm_inv = np.zeros_like(dm)
        dm_inv[ok] = np.linalg.inv(dm[ok])
        self._dm_inv = dm_inv
        self._ok = ok
        # the rest directions in each triangle's plane (2-D, unit), and whether they are usable
        dirs = [np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])]
        self.fold_s = np.full(nv, np.inf)
        fold_dir = np.zeros((nv, 3))
        lm = face.landmarks
        lines = [lm[g] for g in ("nasolabial_l", "nasolabial_r") if g in lm and len(lm[g]) >= 2]
        for line in lines:
            d, across = _polyline_distance(v[:, :2], v[np.asarray(line)][:, :2])
            better = d < self.fold_s
            self.fold_s[better] = d[better]
            fold_dir[better, :2] = across[better]
        self.has_fold = bool(lines)
        tri_fold = fold_dir[t].mean(axis=1)
        self._t2d = []
        self._use = []
        for dvec in [*dirs, tri_fold]:
            dv = np.broadcast_to(dvec, (nt, 3))
            p1 = (dv * b1).sum(1)
            p2 = (dv * b2).sum(1)
            m = np.hypot(p1, p2)
            self._use.append(
                ok & (m > MIN_IN_PLANE * np.maximum(np.linalg.norm(dv, axis=1), 1e-12))
            )
            m = np.maximum(m, 1e-12)
            self._t2d.append(np.column_stack([p1 / m, p2 / m]))
        # the fold only near the fold line (3 groove widths)
        near = self.fold_s[t].min(axis=1) < 3 * FOLD_WIDTH_MM * 2
        self._use[2] &= near
        # triangle -> vertex area-weighted averaging
        w = 0.5 * area2
        rows = t.ravel()
        cols = np.repeat(np.arange(nt), 3)
        a = sp.csr_matrix((np.repeat(w, 3), (rows, cols)), shape=(nv, nt))
        tot = np.asarray(a.sum(axis=1)).ravel()
        self._avg = sp.diags(1.0 / np.maximum(tot, 1e-12)) @ a
        s_fold = np.where(np.isfinite(self.fold_s), self.fold_s, 1e3)
        self._static = np.column_stack([v[:, 0], v[:, 1], s_fold])

    def compressions(self, skin: np.ndarray) -> np.ndarray:
        """Per-triangle compression (T, 3) beyond the dead zone along rest x, rest y and
        across the nasolabial line, for deformed skin vertices (V, 3) mm."""
        t = self.triangles
        d1 = skin[t[:, 1]] - skin[t[:, 0]]
        d2 = skin[t[:, 2]] - skin[t[:, 0]]
        out = np.zeros((len(t), 3))
        for j in range(3):
            a = self._dm_inv @ self._t2d[j][:, :, None]  # (T, 2, 1): edge weights
            ft = d1 * a[:, 0] + d2 * a[:, 1]
            stretch = np.linalg.norm(ft, axis=1)
            c = np.clip(1.0 - stretch - COMPRESSION_DEAD_ZONE, 0.0, None)
            out[:, j] = np.where(self._use[j], c, 0.0)
        return out

    def vertex_fields(self, skin: np.ndarray) -> np.ndarray:
        """Per-vertex (V, N_VERTEX): rest x, rest y, nasolabial distance, and the amplitudes
        A_x, A_y (furrow heights, mm) and A_n (groove depth, mm) for skin (V, 3) mm."""
        c = self._avg @ self.compressions(skin)
        amp = np.column_stack([FURROW_GAIN_MM * c[:, 0], FURROW_GAIN_MM * c[:, 1],
                               FOLD_GAIN_MM * c[:, 2]])  # fmt: skip
        return np.column_stack([self._static, amp])

    def gradients(self, skin: np.ndarray) -> np.ndarray:
        """Per-triangle world gradients (T, 3, 3) on the deformed surface of the three
        per-vertex scalar fields rest x, rest y and nasolabial distance (rows)."""
        t = self.triangles
        p0, p1, p2 = skin[t[:, 0]], skin[t[:, 1]], skin[t[:, 2]]
        n = np.cross(p1 - p0, p2 - p0)
        a2 = np.maximum((n * n).sum(1), 1e-18)
        # grad of barycentric l_i = (n x e_i) / |n|^2, e_i the edge opposite vertex i
        g0 = np.cross(n, p2 - p1) / a2[:, None]
        g1 = np.cross(n, p0 - p2) / a2[:, None]
        g2 = np.cross(n, p1 - p0) / a2[:, None]
        f = self._static[t]  # (T, 3 vertices, 3 fields)
        return (
            f[:, 0, :, None] * g0[:, None]
            + f[:, 1, :, None] * g1[:, None]
            + (f[:, 2, :, None] * g2[:, None])
        )


def wrinkle_height(fields: np.ndarray, k: float) -> np.ndarray:
    """The height field (N,) mm at points whose interpolated vertex fields are ``fields``
    (N, N_VERTEX) (reference for the renderer's per-pixel evaluation)."""
    x, y, s, ax, ay, an = fields.T
    return ay * np.sin(k * y) + ax * np.sin(k * x) - an * np.exp(-((s / FOLD_WIDTH_MM) ** 2))
