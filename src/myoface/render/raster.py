"""The z-buffer rasterizer: numba kernel with per-pixel (Phong-interpolated) Blinn-Phong shading,
perspective-correct attributes and bilinear texture lookup; a plain numpy reference beside it.

Shading model, per pixel, in linear RGB::

    colour = albedo * (ambient + sum_l max(n.L_l, 0) c_l) + ks * sum_l (n.h_l)^shininess c_l

(the power by Schlick's rational approximation x / (s - s x + x), Schlick 1994)

with the normal n interpolated from the vertices and flipped towards the viewer (both sides of
an open surface are lit), albedo = vertex colour x texture (bilinear, wrap-free clamp).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

#: pixels whose depth is below this (mm) are behind the camera's near plane
NEAR_MM = 1.0


@njit(cache=True, fastmath=True)
def _tex_bilinear(tex, u, v, out):
    h, w = tex.shape[0], tex.shape[1]
    x = u * w - 0.5
    y = (1.0 - v) * h - 0.5
    if x < 0.0:
        x = 0.0
    if y < 0.0:
        y = 0.0
    if x > w - 1.0:
        x = w - 1.0
    if y > h - 1.0:
        y = h - 1.0
    x0 = int(x)
    y0 = int(y)
    x1 = min(x0 + 1, w - 1)
    y1 = min(y0 + 1, h - 1)
    fx = x - x0
    fy = y - y0
    for c in range(3):
        a = tex[y0, x0, c] * (1 - fx) + tex[y0, x1, c] * fx
        b = tex[y1, x0, c] * (1 - fx) + tex[y1, x1, c] * fx
        out[c] = a * (1 - fy) + b * fy


@njit(cache=True, fastmath=True)
def _raster_band(
    band_lo,  # first image row of this band
    band_hi,  # one past its last row
    scr,  # (N, 3) pixel x, pixel y, depth
    winv,  # (N,) 1/w (1/depth for perspective, 1 for orthographic)
    tris,  # (F, 3) int
    normals,  # (N, 3) world unit normals
    world,  # (N, 3) world positions
    uv,  # (N, 2)
    vcol,  # (N, 3) linear albedo per vertex
    tex,  # (H, W, 3) float32 linear texture (1x1 white when unused)
    tri_tex,  # (F,) bool: triangle uses the texture
    eye,  # (3,) camera position (perspective) — for view vectors
    view_dir,  # (3,) camera forward (orthographic)
    ortho,  # bool
    light_dir,  # (L, 3) unit, towards the light
    light_col,  # (L, 3)
    ambient,  # (3,)
    ks,
    shininess,
    img,  # (H, W, 3) float32 out (holds the background)
    zbuf,  # (H, W) float64 out
    tri_id,  # (H, W) int32 out
):
    w = img.shape[1]
    nl = light_dir.shape[0]
    texel = np.empty(3)
    for f in range(tris.shape[0]):
        i0, i1, i2 = tris[f, 0], tris[f, 1], tris[f, 2]
        if scr[i0, 2] < NEAR_MM or scr[i1, 2] < NEAR_MM or scr[i2, 2] < NEAR_MM:
            continue
        x0, y0 = scr[i0, 0], scr[i0, 1]
        x1, y1 = scr[i1, 0], scr[i1, 1]
        x2, y2 = scr[i2, 0], scr[i2, 1]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if abs(area) < 1e-12:
            continue
        inv_area = 1.0 / area
        xmin = max(int(np.floor(min(x0, x1, x2))), 0)
        xmax = min(int(np.ceil(max(x0, x1, x2))), w - 1)
        ymin = max(int(np.floor(min(y0, y1, y2))), band_lo)
        ymax = min(int(np.ceil(max(y0, y1, y2))), band_hi - 1)
        if xmin > xmax or ymin > ymax:
            continue
        q0, q1, q2 = winv[i0], winv[i1], winv[i2]
        use_tex = tri_tex[f]
        for py in range(ymin, ymax + 1):
            cy = py + 0.5
            for px in range(xmin, xmax + 1):
                cx = px + 0.5
                l0 = ((x1 - cx) * (y2 - cy) - (x2 - cx) * (y1 - cy)) * inv_area
                l1 = ((x2 - cx) * (y0 - cy) - (x0 - cx) * (y2 - cy)) * inv_area
                l2 = 1.0 - l0 - l1
                if l0 < 0.0 or l1 < 0.0 or l2 < 0.0:
                    continue
                # perspective-correct weights
                p0, p1, p2 = l0 * q0, l1 * q1, l2 * q2
                s = p0 + p1 + p2
                p0 /= s
                p1 /= s
                p2 /= s
                z = p0 * scr[i0, 2] + p1 * scr[i1, 2] + p2 * scr[i2, 2]
                if z >= zbuf[py, px]:
                    continue
                zbuf[py, px] = z
                tri_id[py, px] = f
                nx = p0 * normals[i0, 0] + p1 * normals[i1, 0] + p2 * normals[i2, 0]
                ny = p0 * normals[i0, 1] + p1 * normals[i1, 1] + p2 * normals[i2, 1]
                nz = p0 * normals[i0, 2] + p1 * normals[i1, 2] + p2 * normals[i2, 2]
                nn = np.sqrt(nx * nx + ny * ny + nz * nz) + 1e-12
                nx /= nn
                ny /= nn
                nz /= nn
                if ortho:
                    vx, vy, vz = -view_dir[0], -view_dir[1], -view_dir[2]
                else:
                    wx = p0 * world[i0, 0] + p1 * world[i1, 0] + p2 * world[i2, 0]
                    wy = p0 * world[i0, 1] + p1 * world[i1, 1] + p2 * world[i2, 1]
                    wz = p0 * world[i0, 2] + p1 * world[i1, 2] + p2 * world[i2, 2]
                    vx, vy, vz = eye[0] - wx, eye[1] - wy, eye[2] - wz
                    vn = np.sqrt(vx * vx + vy * vy + vz * vz) + 1e-12
                    vx /= vn
                    vy /= vn
                    vz /= vn
                if nx * vx + ny * vy + nz * vz < 0.0:  # the back of an open surface
                    nx, ny, nz = -nx, -ny, -nz
                ar = p0 * vcol[i0, 0] + p1 * vcol[i1, 0] + p2 * vcol[i2, 0]
                ag = p0 * vcol[i0, 1] + p1 * vcol[i1, 1] + p2 * vcol[i2, 1]
                ab = p0 * vcol[i0, 2] + p1 * vcol[i1, 2] + p2 * vcol[i2, 2]
                if use_tex:
                    tu = p0 * uv[i0, 0] + p1 * uv[i1, 0] + p2 * uv[i2, 0]
                    tv = p0 * uv[i0, 1] + p1 * uv[i1, 1] + p2 * uv[i2, 1]
                    _tex_bilinear(tex, tu, tv, texel)
                    ar *= texel[0]
                    ag *= texel[1]
                    ab *= texel[2]
                dr, dg, db = ambient[0], ambient[1], ambient[2]
                sr = 0.0
                sg = 0.0
                sb = 0.0
                for k in range(nl):
                    lx, ly, lz = light_dir[k, 0], light_dir[k, 1], light_dir[k, 2]
                    ndl = nx * lx + ny * ly + nz * lz
                    if ndl <= 0.0:
                        continue
                    dr += ndl * light_col[k, 0]
                    dg += ndl * light_col[k, 1]
                    db += ndl * light_col[k, 2]
                    hx, hy, hz = lx + vx, ly + vy, lz + vz
                    hn = np.sqrt(hx * hx + hy * hy + hz * hz) + 1e-12
                    ndh = (nx * hx + ny * hy + nz * hz) / hn
                    if ndh > 0.5 and ks > 0.0:
                        # Schlick's rational approximation of ndh^shininess (Schlick 1994)
                        sp = ks * ndh / (shininess - shininess * ndh + ndh)
                        sr += sp * light_col[k, 0]
                        sg += sp * light_col[k, 1]
                        sb += sp * light_col[k, 2]
                img[py, px, 0] = ar * dr + sr
                img[py, px, 1] = ag * dg + sg
                img[py, px, 2] = ab * db + sb


@njit(cache=True, parallel=True)
def rasterize(
    scr,
    winv,
    tris,
    normals,
    world,
    uv,
    vcol,
    tex,
    tri_tex,
    eye,
    view_dir,
    ortho,
    light_dir,
    light_col,
    ambient,
    ks,
    shininess,
    background,
    img,
    zbuf,
    tri_id,
):
    """Clear the buffers (image <- ``background`` (H, 1, 3) rows) and draw every triangle with
    z-buffering and per-pixel shading; the image is split into horizontal bands drawn in
    parallel (each band owns its rows, so no two threads write the same pixel)."""
    h = img.shape[0]
    n_bands = min(h, 8)
    for b in prange(n_bands):
        lo = b * h // n_bands
        hi = (b + 1) * h // n_bands
        for y in range(lo, hi):
            for x in range(img.shape[1]):
                zbuf[y, x] = np.inf
                tri_id[y, x] = -1
                for c in range(3):
                    img[y, x, c] = background[y, 0, c]
        _raster_band(
            lo,
            hi,
            scr,
            winv,
            tris,
            normals,
            world,
            uv,
            vcol,
            tex,
            tri_tex,
            eye,
            view_dir,
            ortho,
            light_dir,
            light_col,
            ambient,
            ks,
            shininess,
            img,
            zbuf,
            tri_id,
        )


def rasterize_coverage_numpy(scr: np.ndarray, tris: np.ndarray, h: int, w: int):
    """Reference: nearest-triangle id (H, W) and depth (H, W) by brute force over pixel centres
    (affine depth; for tests on small images)."""
    ys, xs = np.mgrid[0:h, 0:w]
    cx, cy = xs + 0.5, ys + 0.5
    zbuf = np.full((h, w), np.inf)
    tid = np.full((h, w), -1, np.int32)
    for f, (a, b, c) in enumerate(tris):
        x0, y0, z0 = scr[a]
        x1, y1, z1 = scr[b]
        x2, y2, z2 = scr[c]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if abs(area) < 1e-12:
            continue
        l0 = ((x1 - cx) * (y2 - cy) - (x2 - cx) * (y1 - cy)) / area
        l1 = ((x2 - cx) * (y0 - cy) - (x0 - cx) * (y2 - cy)) / area
        l2 = 1 - l0 - l1
        inside = (l0 >= 0) & (l1 >= 0) & (l2 >= 0)
        z = l0 * z0 + l1 * z1 + l2 * z2
        better = inside & (z < zbuf)
        zbuf[better] = z[better]
        tid[better] = f
    return tid, zbuf


@njit(cache=True, inline="always")
def _box(img, f, y, x, c):
    """Mean of the f x f block of channel c whose corner is (y f, x f)."""
    s = 0.0
    for dy in range(f):
        for dx in range(f):
            s += img[y * f + dy, x * f + dx, c]
    return s / (f * f)


def srgb_lut(n: int = 4096) -> np.ndarray:
    """uint8 sRGB codes of linear values (i + 0.5) / n, i = 0..n-1 (IEC 61966-2-1)."""
    c = (np.arange(n) + 0.5) / n
    s = np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)
    return (s * 255.0 + 0.5).astype(np.uint8)


@njit(cache=True, parallel=True)
def resolve_srgb(img, f, lut, out):
    """Box-filter (H*f, W*f, 3) linear RGB down by ``f`` and encode to sRGB uint8 via ``lut``."""
    h, w = out.shape[0], out.shape[1]
    n = lut.shape[0]
    for y in prange(h):
        for x in range(w):
            for c in range(3):
                v = _box(img, f, y, x, c)
                k = int(v * n)
                if k < 0:
                    k = 0
                elif k >= n:
                    k = n - 1
                out[y, x, c] = lut[k]


@njit(cache=True)
def downsample(img, f, out):
    """Box-filter an (H*f, W*f, 3) image down to (H, W, 3)."""
    h, w = out.shape[0], out.shape[1]
    for y in range(h):
        for x in range(w):
            for c in range(3):
                out[y, x, c] = _box(img, f, y, x, c)


@njit(cache=True)
def vertex_normals_numba(v, tris, out):
    """Area-weighted vertex normals (unit) of mesh (v, tris) into out (V, 3)."""
    out[:] = 0.0
    for f in range(tris.shape[0]):
        a, b, c = tris[f, 0], tris[f, 1], tris[f, 2]
        e1x, e1y, e1z = v[b, 0] - v[a, 0], v[b, 1] - v[a, 1], v[b, 2] - v[a, 2]
        e2x, e2y, e2z = v[c, 0] - v[a, 0], v[c, 1] - v[a, 1], v[c, 2] - v[a, 2]
        nx = e1y * e2z - e1z * e2y
        ny = e1z * e2x - e1x * e2z
        nz = e1x * e2y - e1y * e2x
        for i in (a, b, c):
            out[i, 0] += nx
            out[i, 1] += ny
            out[i, 2] += nz
    for i in range(out.shape[0]):
        n = np.sqrt(out[i, 0] ** 2 + out[i, 1] ** 2 + out[i, 2] ** 2)
        if n > 0:
            out[i, 0] /= n
            out[i, 1] /= n
            out[i, 2] /= n
