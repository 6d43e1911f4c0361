"""Skin that folds: wrinkle shading driven by the compression of the skin (epidermal) triangles.

Where the skin shortens along a direction, it buckles into furrows across it. Per frame, the
skin's deformation gradient F at each vertex (fitted by least squares to the displacements of
the vertices within ``PATCH_RADIUS_MM`` at rest: a furrow needs a compressed patch, not one
small triangle) gives its stretch along two fixed rest directions of the head frame, up (y) and
lateral (x), and across the nasolabial fold (the landmark groups' polylines, when the face has
them). The compression beyond a dead zone,

    c = max(0, 1 - |F t| - COMPRESSION_DEAD_ZONE),

scales a height field of the skin in its rest coordinates X:

    h = A_y sin(k X_y) + A_x sin(k X_x) - A_n exp(-(s / w)^2),    A = gain * c,

horizontal furrows where the skin is squeezed vertically (the forehead in a brow raise, crow's
feet), vertical ones where it is squeezed sideways (the glabella in a frown), and one groove
along the nasolabial line (s: the rest distance to it) where the cheek pushes against it. The
furrows A_x, A_y are weighted by where skin folds into lines (:func:`furrow_regions`: forehead,
glabella, crow's feet, the nose's bridge); the squeezed cheek shows the groove only. The
renderer tilts each pixel's normal by the height field's gradient on the deformed surface
(n' = normalize(n - grad h)): a normal map whose strength is the skin's own compression, zero
wherever the skin is not compressed. Millimetres; head frame x lateral, y up, z forward.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit

from myoface.face import vertex_normals

#: compressions (1 - stretch) below this leave the skin smooth: 0.05 mm of noise on the default
#: face's vertices reads as up to 0.024 (10 draws); the AUs' compressions reach 0.04 (the
#: forehead in AU1+2) to 0.1-0.4 (glabella in AU4, cheeks in AU6+12)
COMPRESSION_DEAD_ZONE = 0.03
#: furrow spacing (mm): forehead lines and crow's feet lie some 5-10 mm apart
WAVELENGTH_MM = 6.0
#: furrow height (mm) per unit compression (a 10 % compression: 0.4 mm, slopes ~0.4)
FURROW_GAIN_MM = 4.0
#: the nasolabial groove: half-width (mm) and depth (mm) per unit compression (set by eye: the
#: smile's fold is a broad crease that reads from nose to mouth corner; at 2.5 mm and 6 mm it
#: hardly showed in AU6+12, where the cheek is compressed 0.1-0.25 across it)
FOLD_WIDTH_MM = 4.0
FOLD_GAIN_MM = 12.0
#: a rest direction whose part in a vertex's tangent plane is shorter than this has no
#: meaningful stretch there (the sides of the face for x, the underside of the nose for y)
MIN_IN_PLANE = 0.3
#: the strain is fitted over the vertices within this rest distance (mm): a furrow needs a
#: compressed patch some half a wavelength across, not one small triangle
PATCH_RADIUS_MM = 8.0
PATCH_MIN_VERTICES = 16
#: ... with the directions whose spread is below this fraction of the largest left out
PATCH_RCOND = 0.1
#: the nasolabial groove is evaluated this near its line (mm)
FOLD_REACH_MM = 15.0
#: per-vertex columns of :meth:`WrinkleField.vertex_fields`: rest x, rest y, nasolabial
#: distance s, amplitudes A_x, A_y, A_n
N_VERTEX = 6


#: a face without eye landmarks folds into lines on the top part of its height only (the
#: forehead: above the brows, about the top third on the default face and Waters' face)
FOREHEAD_FRACTION = 0.35


def _smoothstep(x, lo, hi):
    t = np.clip((np.asarray(x, dtype=np.float64) - lo) / (hi - lo), 0.0, 1.0)
    return t * t * (3 - 2 * t)


def furrow_regions(face) -> np.ndarray:
    """Per vertex (V,), in [0, 1]: where the skin folds into fine furrows when it is squeezed.

    Expression lines form where the skin is thin and tied to the muscle beneath: the forehead
    and the glabella (above the eyes' upper edge), the crow's feet (beside the eyes' outer
    corners) and the nose's bridge and sides (AU9's lines). Elsewhere (the cheeks, around the mouth,
    the chin) compressed skin bulges rather than folding into parallel lines; the cheek's
    compression shows as the nasolabial groove instead. From the face's landmark groups
    (``eye_l``, ``eye_r``, ``nose_tip``), with margins in units of the inter-ocular distance
    so they scale with the face. Without those groups (e.g. Waters' face), the forehead only:
    the top :data:`FOREHEAD_FRACTION` of the face's height."""
    lm = face.landmarks
    v = np.asarray(face.vertices, dtype=np.float64)
    if not all(k in lm and len(lm[k]) for k in ("eye_l", "eye_r", "nose_tip")):
        lo, hi = float(v[:, 1].min()), float(v[:, 1].max())
        start = hi - FOREHEAD_FRACTION * (hi - lo)
        return _smoothstep(v[:, 1], start, start + 0.08 * (hi - lo))
    eyes = [v[np.asarray(lm[k])] for k in ("eye_l", "eye_r")]
    centre = [e.mean(axis=0) for e in eyes]
    iod = float(np.linalg.norm(centre[0][:2] - centre[1][:2]))
    top = max(float(e[:, 1].max()) for e in eyes)
    mid_y = 0.5 * (centre[0][1] + centre[1][1])
    outer = 0.5 * (float(np.abs(eyes[0][:, 0]).max()) + float(np.abs(eyes[1][:, 0]).max()))
    inner = 0.5 * (float(np.abs(eyes[0][:, 0]).min()) + float(np.abs(eyes[1][:, 0]).min()))
    nose_y = float(v[np.asarray(lm["nose_tip"]), 1].mean())
    y, ax = v[:, 1], np.abs(v[:, 0])
    forehead = _smoothstep(y, top - 0.03 * iod, top + 0.1 * iod)
    crows = _smoothstep(ax, outer - 0.06 * iod, outer + 0.03 * iod) * (
        1.0 - _smoothstep(np.abs(y - mid_y), 0.2 * iod, 0.3 * iod)
    )
    bridge = (1.0 - _smoothstep(ax, 0.8 * inner, 1.1 * inner)) * _smoothstep(
        y, nose_y - 0.05 * iod, nose_y + 0.1 * iod
    )
    return np.maximum.reduce([forehead, crows, bridge])


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
    """The wrinkle height field of a face (rest: ``face`` a FaceMesh); :meth:`vertex_fields`
    (:meth:`fields_fast`) and :meth:`gradients` give its per-frame amplitudes and gradients
    for deformed skin vertices.

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
        nv = len(v)
        self.fold_s = np.full(nv, np.inf)
        fold_dir = np.zeros((nv, 3))
        lm = face.landmarks
        lines = [lm[g] for g in ("nasolabial_l", "nasolabial_r") if g in lm and len(lm[g]) >= 2]
        for line in lines:
            d, across = _polyline_distance(v[:, :2], v[np.asarray(line)][:, :2])
            better = d < self.fold_s
            self.fold_s[better] = d[better]
            fold_dir[better, :2] = across[better]
        near_fold = self.fold_s < FOLD_REACH_MM
        self.has_fold = bool(lines)
        # per vertex and direction: the rest direction t in the tangent plane (unit) and the
        # least-squares weights c_ij over the patch (neighbours within PATCH_RADIUS_MM) with
        # F t = t + sum_j c_ij (u_j - u_i), u the displacement from rest
        from scipy.spatial import cKDTree

        normals = vertex_normals(v, t)
        tree = cKDTree(v)
        # the radius grows where the mesh is coarse, to hold PATCH_MIN_VERTICES neighbours
        knn, _ = tree.query(v, PATCH_MIN_VERTICES + 1)
        patches = tree.query_ball_point(v, np.maximum(PATCH_RADIUS_MM, 1.01 * knn[:, -1]))
        self._dirs = np.zeros((3, nv, 3))
        self._patches = []
        self._coef = [[], [], []]
        mats = []
        for i in range(nv):
            nb = np.array([j for j in patches[i] if j != i], dtype=np.int64)
            dx = v[nb] - v[i] if len(nb) else np.zeros((0, 3))
            m = dx.T @ dx
            ok_i = len(nb) >= 3
            # the patch's spread across the surface only: its thickness direction (and a
            # direction the neighbours hardly span) is left out
            pinv = np.linalg.pinv(m, rcond=PATCH_RCOND) if ok_i else np.zeros((3, 3))
            self._patches.append(nb)
            for k, dvec in enumerate((np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), fold_dir[i])):
                tv = dvec - (dvec @ normals[i]) * normals[i]
                tn = np.linalg.norm(tv)
                use = ok_i and tn > MIN_IN_PLANE and (k < 2 or near_fold[i])
                tv = tv / tn if use else np.zeros(3)
                self._dirs[k, i] = tv
                self._coef[k].append(dx @ (pinv @ tv) if use else np.zeros(len(nb)))
            mats.append(len(nb))
        self._ops = []
        for k in range(3):
            rows = np.repeat(np.arange(nv), mats)
            cols = np.concatenate(self._patches) if nv else np.zeros(0, np.int64)
            vals = np.concatenate(self._coef[k]) if nv else np.zeros(0)
            op = sp.csr_matrix((vals, (rows, cols)), shape=(nv, nv))
            op = op - sp.diags(np.asarray(op.sum(axis=1)).ravel())
            self._ops.append(op.tocsr())
        self._used = np.abs(self._dirs).sum(axis=2).T > 0  # (V, 3)
        s_fold = np.where(np.isfinite(self.fold_s), self.fold_s, 1e3)
        self._static = np.column_stack([v[:, 0], v[:, 1], s_fold])
        self._gains = np.array([FURROW_GAIN_MM, FURROW_GAIN_MM, FOLD_GAIN_MM])
        #: (V, 3) per-vertex gains: the furrows only where the skin folds into lines
        #: (:func:`furrow_regions`), the nasolabial groove wherever it applies
        regions = furrow_regions(face)
        self._vertex_gains = self._gains * np.column_stack([regions, regions, np.ones(nv)])
        self._fields = np.zeros((nv, N_VERTEX))
        self._fields[:, :3] = self._static

    def compressions(self, skin: np.ndarray) -> np.ndarray:
        """Per-vertex compression (V, 3), 1 - stretch where positive (0 where a direction does
        not apply), along rest x, rest y and across the nasolabial line, for deformed skin
        vertices (V, 3) mm: the stretch |F t| of the deformation gradient F fitted by least
        squares to the displacements over the patch around each vertex (plain loop: the
        reference of :meth:`fields_fast`)."""
        u = np.asarray(skin, dtype=np.float64) - self.rest
        out = np.zeros((len(u), 3))
        for i, nb in enumerate(self._patches):
            for k in range(3):
                if not self._used[i, k]:
                    continue
                ft = self._dirs[k, i] + self._coef[k][i] @ (u[nb] - u[i])
                out[i, k] = max(0.0, 1.0 - float(np.linalg.norm(ft)))
        return out

    def vertex_fields(self, skin: np.ndarray) -> np.ndarray:
        """Per-vertex (V, N_VERTEX): rest x, rest y, nasolabial distance, and the amplitudes
        A_x, A_y (furrow heights, mm) and A_n (groove depth, mm) for skin (V, 3) mm."""
        c = np.clip(self.compressions(skin) - COMPRESSION_DEAD_ZONE, 0.0, None)
        return np.column_stack([self._static, c * self._vertex_gains])

    def fields_fast(self, skin: np.ndarray) -> tuple[np.ndarray, bool]:
        """:meth:`vertex_fields` by sparse products, into a buffer reused between calls
        (valid until the next call), and whether any amplitude is non-zero."""
        u = np.asarray(skin, dtype=np.float64) - self.rest
        amp = self._fields[:, 3:]
        for k in range(3):
            ft = self._dirs[k] + self._ops[k] @ u
            c = 1.0 - np.sqrt((ft * ft).sum(axis=1)) - COMPRESSION_DEAD_ZONE
            amp[:, k] = np.where(self._used[:, k] & (c > 0.0), c * self._vertex_gains[:, k], 0.0)
        return self._fields, bool(amp.any())

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


@njit(cache=True, error_model="numpy")
def wrinkle_planes(fields, world, tris, setup, winv, wplanes, wflag):
    """Per skin triangle with a non-zero amplitude at a vertex (``wflag``), the planes of the
    perspective-correct numerators of the 6 vertex ``fields`` (from the triangle set-up's
    barycentric planes, columns 0..5, and the vertices' 1 / w), then the world gradients on the
    surface ``world`` (V, 3) of the fields rest x, rest y and fold distance (see
    :func:`myoface.render.raster._shade`)."""
    for f in range(tris.shape[0]):
        i0, i1, i2 = tris[f, 0], tris[f, 1], tris[f, 2]
        amp = 0.0
        for j in range(3, 6):
            amp = max(amp, fields[i0, j], fields[i1, j], fields[i2, j])
        wflag[f] = amp > 0.0
        if not wflag[f]:
            continue
        a0, b0, c0 = setup[f, 0], setup[f, 1], setup[f, 2]
        a1, b1, c1 = setup[f, 3], setup[f, 4], setup[f, 5]
        a2, b2, c2 = -a0 - a1, -b0 - b1, 1.0 - c0 - c1
        q0, q1, q2 = winv[i0], winv[i1], winv[i2]
        for j in range(6):
            v0, v1, v2 = fields[i0, j] * q0, fields[i1, j] * q1, fields[i2, j] * q2
            wplanes[f, 3 * j] = a0 * v0 + a1 * v1 + a2 * v2
            wplanes[f, 3 * j + 1] = b0 * v0 + b1 * v1 + b2 * v2
            wplanes[f, 3 * j + 2] = c0 * v0 + c1 * v1 + c2 * v2
        e1x = world[i1, 0] - world[i0, 0]
        e1y = world[i1, 1] - world[i0, 1]
        e1z = world[i1, 2] - world[i0, 2]
        e2x = world[i2, 0] - world[i0, 0]
        e2y = world[i2, 1] - world[i0, 1]
        e2z = world[i2, 2] - world[i0, 2]
        nx = e1y * e2z - e1z * e2y
        ny = e1z * e2x - e1x * e2z
        nz = e1x * e2y - e1y * e2x
        a2n = max(nx * nx + ny * ny + nz * nz, 1e-18)
        # grad l_k = (n x e_k) / |n|^2, e_k the edge opposite vertex k
        for k in range(3):
            if k == 0:
                ex, ey, ez = (
                    world[i2, 0] - world[i1, 0],
                    world[i2, 1] - world[i1, 1],
                    world[i2, 2] - world[i1, 2],
                )
                vi = i0
            elif k == 1:
                ex, ey, ez = (
                    world[i0, 0] - world[i2, 0],
                    world[i0, 1] - world[i2, 1],
                    world[i0, 2] - world[i2, 2],
                )
                vi = i1
            else:
                ex, ey, ez = e1x, e1y, e1z
                vi = i2
            gx = (ny * ez - nz * ey) / a2n
            gy = (nz * ex - nx * ez) / a2n
            gz = (nx * ey - ny * ex) / a2n
            for j in range(3):
                val = fields[vi, j]
                if k == 0:
                    wplanes[f, 18 + 3 * j] = val * gx
                    wplanes[f, 19 + 3 * j] = val * gy
                    wplanes[f, 20 + 3 * j] = val * gz
                else:
                    wplanes[f, 18 + 3 * j] += val * gx
                    wplanes[f, 19 + 3 * j] += val * gy
                    wplanes[f, 20 + 3 * j] += val * gz


#: the size (texels) of :class:`WrinkleNormalMap`'s square normal map: on the default face a
#: texel is about 0.3 mm of skin, some 20 texels a furrow
NORMAL_MAP_SIZE = 512
#: triangles cover the texels within this many texels outside their edges (so that bilinear
#: filtering at a UV seam does not blend in the flat normal of an uncovered texel)
NORMAL_MAP_BLEED_TEXELS = 1.5


class WrinkleNormalMap:
    """The wrinkle height field of a :class:`WrinkleField` baked into a tangent-space normal
    map over the face's UV layout, for renderers that take a normal texture (the web viewer's
    glTF skin) rather than shading each pixel as :mod:`myoface.render.raster` does.

    Each texel is a point of a skin triangle at rest (found once, with its barycentric
    weights); per frame the vertices' amplitudes (:meth:`WrinkleField.fields_fast`) are
    interpolated to the texels and the height field's surface gradient grad h (rest
    geometry) tilts the normal, n' = normalize(n - grad h), written in the glTF convention:
    tangent +X along increasing u, +Y along increasing v (up in the image), RGB = (n' + 1) / 2.

    Parameters
    ----------
    field : the face's :class:`WrinkleField`.
    uv : (V, 2) the face's texture coordinates (OBJ convention: v up, image row 0 at v = 1).
    size : texels per side.
    """

    def __init__(self, field: WrinkleField, uv, size: int = NORMAL_MAP_SIZE):
        uv = np.asarray(uv, dtype=np.float64)
        self.field = field
        self.size = int(size)
        s = self.size
        rest, tris = field.rest, field.triangles
        # texel centres in uv: column j -> u = (j + 0.5) / s, row i -> v = 1 - (i + 0.5) / s
        owner = np.full(s * s, -1, np.int64)
        bary = np.zeros((s * s, 3))
        for f, (a, b, c) in enumerate(tris):
            t = uv[[a, b, c]] * s
            t[:, 1] = s - t[:, 1]  # (column, row) coordinates
            m = np.array([t[1] - t[0], t[2] - t[0]]).T
            det = np.linalg.det(m)
            if abs(det) < 1e-12:
                continue
            eps = NORMAL_MAP_BLEED_TEXELS / np.sqrt(abs(det))
            lo = np.maximum(np.floor(t.min(0) - 2).astype(int), 0)
            hi = np.minimum(np.ceil(t.max(0) + 2).astype(int), s - 1)
            jj, ii = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1))
            p = np.column_stack([jj.ravel() + 0.5, ii.ravel() + 0.5]) - t[0]
            l12 = np.linalg.solve(m, p.T).T
            w = np.column_stack([1 - l12.sum(1), l12])
            idx = ii.ravel() * s + jj.ravel()
            inside = w.min(1) >= 0
            near = ~inside & (w.min(1) >= -eps) & (owner[idx] < 0)
            for sel in (inside, near):  # inside wins over another triangle's bleed
                owner[idx[sel]] = f
                bary[idx[sel]] = np.clip(w[sel], 0, None) / np.clip(w[sel], 0, None).sum(1)[:, None]
        self.texels = np.flatnonzero(owner >= 0)
        f = owner[self.texels]
        b = bary[self.texels]
        n_t, n_v = len(self.texels), len(rest)
        corners = tris[f]  # (N, 3)
        self._interp = sp.csr_matrix(
            (b.ravel(), (np.repeat(np.arange(n_t), 3), corners.ravel())), shape=(n_t, n_v)
        )
        # per triangle: J = dp/d(u, v) (rest geometry) and the uv gradient of the fold distance
        p0, p1, p2 = rest[tris[:, 0]], rest[tris[:, 1]], rest[tris[:, 2]]
        d1, d2 = uv[tris[:, 1]] - uv[tris[:, 0]], uv[tris[:, 2]] - uv[tris[:, 0]]
        muv = np.stack([d1, d2], axis=2)  # (T, 2, 2): columns the uv edges
        det = muv[:, 0, 0] * muv[:, 1, 1] - muv[:, 0, 1] * muv[:, 1, 0]
        ok = np.abs(det) > 1e-15
        inv = np.zeros_like(muv)
        inv[ok] = np.linalg.inv(muv[ok])
        jac = np.stack([p1 - p0, p2 - p0], axis=2) @ inv  # (T, 3, 2)
        sv = field._static[:, 2]
        ds = np.stack([sv[tris[:, 1]] - sv[tris[:, 0]], sv[tris[:, 2]] - sv[tris[:, 0]]], 1)
        grad_s = np.einsum("ti,tij->tj", ds, inv)  # (T, 2)
        # the tangent frame: T along +u, B along +v (Gram-Schmidt), both unit
        tu = jac[:, :, 0] / np.maximum(np.linalg.norm(jac[:, :, 0], axis=1), 1e-12)[:, None]
        bv = jac[:, :, 1] - (jac[:, :, 1] * tu).sum(1)[:, None] * tu
        bv /= np.maximum(np.linalg.norm(bv, axis=1), 1e-12)[:, None]
        # grad h = J (J^T J)^-1 g_uv: its (T, B) components are G^T g_uv, G = J (J^T J)^-1
        jtj = np.einsum("tki,tkj->tij", jac, jac)
        jtj_inv = np.zeros_like(jtj)
        good = ok & (np.abs(np.linalg.det(jtj)) > 1e-18)
        jtj_inv[good] = np.linalg.inv(jtj[good])
        g = jac @ jtj_inv  # (T, 3, 2)
        frame = np.stack([np.einsum("tk,tki->ti", tu, g), np.einsum("tk,tki->ti", bv, g)], 1)
        # d(x, y, s)/d(u, v) per texel's triangle, premultiplied into the frame: (N, 3 fields, 2)
        duv = np.stack([jac[:, 0, :], jac[:, 1, :], grad_s], axis=1)  # (T, 3, 2)
        dfield = np.einsum("tfj,tcj->tfc", duv, frame)[f]  # (N, 3, 2): (T, B) components
        # dh/d(x, y, s) per unit amplitude is static (the rest coordinates do not move):
        # k cos(k x), k cos(k y), 2 s / w^2 exp(-(s / w)^2)
        x, y, sf = (self._interp @ field._static).T
        k = field.k
        per_amp = np.column_stack(
            [k * np.cos(k * x), k * np.cos(k * y),
             2 * sf / FOLD_WIDTH_MM**2 * np.exp(-((sf / FOLD_WIDTH_MM) ** 2))]
        )  # fmt: skip
        #: (N, 3, 2) the (T, B) components of grad h per unit amplitude A_x, A_y, A_n
        self._slope = np.ascontiguousarray(per_amp[:, :, None] * dfield, dtype=np.float32)

    def image(self, skin: np.ndarray) -> np.ndarray | None:
        """The normal map (size, size, 3) uint8 for skin vertices (V, 3) mm, or None when no
        skin is compressed (the map would be flat)."""
        fields, any_ = self.field.fields_fast(skin)
        if not any_:
            return None
        amp = (self._interp @ fields[:, 3:]).astype(np.float32)  # (N, 3): A_x, A_y, A_n
        on = np.flatnonzero(amp.any(axis=1))
        grad_tb = np.einsum("nf,nfc->nc", amp[on], self._slope[on])  # grad h along T, B
        n = np.empty((len(on), 3), np.float32)
        n[:, :2] = -grad_tb
        n[:, 2] = 1.0
        n /= np.sqrt((n * n).sum(axis=1))[:, None]
        out = np.empty((self.size * self.size, 3), np.uint8)
        out[:] = (128, 128, 255)
        out[self.texels[on]] = np.clip(np.rint((n + 1.0) * 127.5), 0, 255).astype(np.uint8)
        return out.reshape(self.size, self.size, 3)
