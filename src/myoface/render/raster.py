"""The z-buffer rasterizer: numba kernels with per-pixel (Phong-interpolated) Blinn-Phong shading,
perspective-correct attributes and bilinear texture lookup; a plain numpy reference beside it.

A frame is drawn in passes, like a GPU with multisample anti-aliasing:

1. :func:`setup_triangles` — per triangle, its barycentric and depth planes in screen space and
   its pixel box (back-facing triangles of closed surfaces are dropped);
2. :func:`visibility` — the z-buffer at ``fct`` x ``fct`` samples per output pixel, storing only
   the nearest triangle per sample (each triangle row is a solved span);
3. :func:`attribute_planes` — per triangle, the planes of its perspective-correct attributes;
4. :func:`shade_resolve` — per output pixel, each distinct triangle among its samples is shaded
   once (at the centroid of its samples) and weighted by its coverage, then encoded to sRGB.

Shading model, per pixel, in linear RGB::

    colour = albedo * (ambient + sum_l max(n.L_l, 0) c_l) + ks * sum_l (n.h_l)^shininess c_l

(the power by Schlick's rational approximation x / (s - s x + x), Schlick 1994)

with the normal n interpolated from the vertices and flipped towards the viewer (both sides of
an open surface are lit), albedo = vertex colour x texture (bilinear, wrap-free clamp), and the
view and half vectors h_l taken at each triangle's centroid.

The hot kernels use ``error_model="numpy"``: a float division by zero gives inf (every divisor
here is guarded or nonzero) instead of a Python exception, so numba need not test each one.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from myoface.render.wrinkles import FOLD_WIDTH_MM

#: pixels whose depth is below this (mm) are behind the camera's near plane
NEAR_MM = 1.0


@njit(cache=True, fastmath=True, inline="always", error_model="numpy")
def _tex_bilinear(tex, u, v):
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
    w00 = (1.0 - fx) * (1.0 - fy)
    w01 = fx * (1.0 - fy)
    w10 = (1.0 - fx) * fy
    w11 = fx * fy
    r = w00 * tex[y0, x0, 0] + w01 * tex[y0, x1, 0] + w10 * tex[y1, x0, 0] + w11 * tex[y1, x1, 0]
    g = w00 * tex[y0, x0, 1] + w01 * tex[y0, x1, 1] + w10 * tex[y1, x0, 1] + w11 * tex[y1, x1, 1]
    b = w00 * tex[y0, x0, 2] + w01 * tex[y0, x1, 2] + w10 * tex[y1, x0, 2] + w11 * tex[y1, x1, 2]
    return r, g, b


#: columns of the per-triangle set-up table built by :func:`setup_triangles`
_A0, _B0, _C0, _A1, _B1, _C1, _KA, _KB, _KC, _R0, _R1, _R2 = range(12)
SETUP_COLS = 12
#: samples within this many pixels outside an edge still count as inside (no cracks between
#: triangles that share an edge; the z-buffer resolves the overlap)
_EDGE_EPS = 1e-5


@njit(cache=True)
def setup_triangles(scr, winv, tris, cull, ortho, width, height, fct, setup, tbox, bbox):
    """Per-triangle screen-space set-up for one frame.

    ``setup[f]`` holds the barycentric planes l0 = a0 x + b0 y + c0, l1 = a1 x + b1 y + c1
    (l2 = 1 - l0 - l1), the plane of the depth key (-1/depth for perspective, which is affine
    in screen space; depth for orthographic) and 1/a0, 1/a1, 1/a2 (0 where a = 0).
    Triangles with ``cull[f]`` (parts of closed, outward-wound surfaces) are dropped when they
    face away from the camera (positive screen area, y pointing down). ``tbox[f]`` = pixel (x0, x1, y0, y1), inclusive,
    clipped to the image, or x0 > x1 for a triangle that is not drawn (degenerate, off-screen or
    crossing the near plane). ``bbox`` = the union of the drawn boxes (x0, x1, y0, y1), grown
    to whole blocks of ``fct`` x ``fct`` samples (output pixels)."""
    bbox[0] = width
    bbox[1] = -1
    bbox[2] = height
    bbox[3] = -1
    for f in range(tris.shape[0]):
        i0, i1, i2 = tris[f, 0], tris[f, 1], tris[f, 2]
        tbox[f, 0] = 1
        tbox[f, 1] = 0
        if scr[i0, 2] < NEAR_MM or scr[i1, 2] < NEAR_MM or scr[i2, 2] < NEAR_MM:
            continue
        x0, y0 = scr[i0, 0], scr[i0, 1]
        x1, y1 = scr[i1, 0], scr[i1, 1]
        x2, y2 = scr[i2, 0], scr[i2, 1]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if abs(area) < 1e-12 or (cull[f] and area > 0.0):
            continue
        xmin = max(int(np.floor(min(x0, x1, x2))), 0)
        xmax = min(int(np.ceil(max(x0, x1, x2))), width - 1)
        ymin = max(int(np.floor(min(y0, y1, y2))), 0)
        ymax = min(int(np.ceil(max(y0, y1, y2))), height - 1)
        if xmin > xmax or ymin > ymax:
            continue
        ia = 1.0 / area
        # l0 = ((x1 - x)(y2 - y) - (x2 - x)(y1 - y)) / area, l1 likewise with (2, 0)
        a0 = (y1 - y2) * ia
        b0 = (x2 - x1) * ia
        c0 = (x1 * y2 - x2 * y1) * ia
        a1 = (y2 - y0) * ia
        b1 = (x0 - x2) * ia
        c1 = (x2 * y0 - x0 * y2) * ia
        if ortho:
            k0, k1, k2 = scr[i0, 2], scr[i1, 2], scr[i2, 2]
        else:
            k0, k1, k2 = -winv[i0], -winv[i1], -winv[i2]
        setup[f, _A0] = a0
        setup[f, _B0] = b0
        setup[f, _C0] = c0
        setup[f, _A1] = a1
        setup[f, _B1] = b1
        setup[f, _C1] = c1
        # key = l0 k0 + l1 k1 + (1 - l0 - l1) k2
        setup[f, _KA] = a0 * (k0 - k2) + a1 * (k1 - k2)
        setup[f, _KB] = b0 * (k0 - k2) + b1 * (k1 - k2)
        setup[f, _KC] = c0 * (k0 - k2) + c1 * (k1 - k2) + k2
        a2 = -a0 - a1
        setup[f, _R0] = 1.0 / a0 if a0 != 0.0 else 0.0
        setup[f, _R1] = 1.0 / a1 if a1 != 0.0 else 0.0
        setup[f, _R2] = 1.0 / a2 if a2 != 0.0 else 0.0
        tbox[f, 0] = xmin
        tbox[f, 1] = xmax
        tbox[f, 2] = ymin
        tbox[f, 3] = ymax
        bbox[0] = min(bbox[0], xmin)
        bbox[1] = max(bbox[1], xmax)
        bbox[2] = min(bbox[2], ymin)
        bbox[3] = max(bbox[3], ymax)
    if bbox[0] <= bbox[1]:
        bbox[0] -= bbox[0] % fct
        bbox[2] -= bbox[2] % fct
        bbox[1] = min(bbox[1] - bbox[1] % fct + fct - 1, width - 1)
        bbox[3] = min(bbox[3] - bbox[3] % fct + fct - 1, height - 1)


@njit(cache=True, inline="always")
def _span(a, ra, b, c, cy, lo, hi):
    """Narrow the x interval [lo, hi] to where a x + b cy + c >= 0 (ra = 1 / a)."""
    v = b * cy + c
    if a > 0.0:
        lo = max(lo, -v * ra)
    elif a < 0.0:
        hi = min(hi, -v * ra)
    elif v < 0.0:
        hi = lo - 1.0
    return lo, hi


@njit(cache=True, parallel=True, error_model="numpy")
def visibility(setup, tbox, bbox, zbuf, tri_id, nt):
    """The z-buffer pass: for every sample (pixel centre) inside ``bbox``, the nearest
    triangle's index into ``tri_id`` (-1: none) and its depth key into ``zbuf``. Rows are split
    into bands drawn by ``nt`` threads, interleaved so that the dense eye rows are shared (a band
    owns its rows); each triangle row is a solved span, so the inner loop is a depth test only."""
    bx0, bx1, by0, by1 = bbox[0], bbox[1], bbox[2], bbox[3]
    if bx0 > bx1 or by0 > by1:
        return
    n_rows = by1 - by0 + 1
    n_bands = min(n_rows, 32)
    for th in prange(nt):
        for b in range(th, n_bands, nt):
            lo = by0 + b * n_rows // n_bands
            hi = by0 + (b + 1) * n_rows // n_bands  # one past
            for y in range(lo, hi):
                for x in range(bx0, bx1 + 1):
                    zbuf[y, x] = np.inf
                    tri_id[y, x] = -1
            for f in range(setup.shape[0]):
                tx0, tx1 = tbox[f, 0], tbox[f, 1]
                if tx0 > tx1:
                    continue
                ty0 = max(tbox[f, 2], lo)
                ty1 = min(tbox[f, 3], hi - 1)
                if ty0 > ty1:
                    continue
                a0, b0, c0 = setup[f, _A0], setup[f, _B0], setup[f, _C0]
                a1, b1, c1 = setup[f, _A1], setup[f, _B1], setup[f, _C1]
                a2, b2, c2 = -a0 - a1, -b0 - b1, 1.0 - c0 - c1
                ka, kb, kc = setup[f, _KA], setup[f, _KB], setup[f, _KC]
                r0, r1, r2 = setup[f, _R0], setup[f, _R1], setup[f, _R2]
                for py in range(ty0, ty1 + 1):
                    cy = py + 0.5
                    xl = tx0 - 1.0
                    xh = tx1 + 2.0
                    xl, xh = _span(a0, r0, b0, c0, cy, xl, xh)
                    xl, xh = _span(a1, r1, b1, c1, cy, xl, xh)
                    xl, xh = _span(a2, r2, b2, c2, cy, xl, xh)
                    if xl > xh:
                        continue
                    px0 = max(int(np.ceil(xl - 0.5 - _EDGE_EPS)), tx0)
                    px1 = min(int(np.floor(xh - 0.5 + _EDGE_EPS)), tx1)
                    key = ka * (px0 + 0.5) + kb * cy + kc
                    for px in range(px0, px1 + 1):
                        if key < zbuf[py, px]:
                            zbuf[py, px] = key
                            tri_id[py, px] = f
                        key += ka


#: attributes interpolated across a triangle, in the order of :func:`attribute_planes`:
#: the perspective denominator, normal xyz, albedo rgb, texture uv
N_PLANES = 9


def planes_columns(n_lights: int) -> int:
    """Columns of the per-triangle table of :func:`attribute_planes`."""
    return 3 * N_PLANES + 3 + 3 * n_lights


@njit(cache=True, parallel=True, error_model="numpy")
def attribute_planes(
    setup, tbox, tris, winv, normals, world, vcol, uv, eye, view_dir, ortho, light_dir, planes
):
    """Per drawn triangle, the screen-space planes of every perspective-correct attribute, and
    its view and half vectors.

    With barycentrics l_k affine in (x, y) and q_k = 1/w_k, the numerator sum_k l_k q_k a_k of
    each attribute a and the denominator D = sum_k l_k q_k are affine in (x, y); so attribute
    a at a pixel is (A x + B y + C) / D, one plane each (``planes[f, 3 j : 3 j + 3]``).
    The unit vector to the eye is taken at the triangle's centroid (a triangle spans about a
    degree of view), and with it the Blinn-Phong half vector of each light
    (``planes[f, 3 N_PLANES :]``: view xyz, then half xyz per light)."""
    nl = light_dir.shape[0]
    o = 3 * N_PLANES
    for f in prange(tris.shape[0]):
        if tbox[f, 0] > tbox[f, 1]:
            continue
        i0, i1, i2 = tris[f, 0], tris[f, 1], tris[f, 2]
        a0, b0, c0 = setup[f, _A0], setup[f, _B0], setup[f, _C0]
        a1, b1, c1 = setup[f, _A1], setup[f, _B1], setup[f, _C1]
        a2, b2, c2 = -a0 - a1, -b0 - b1, 1.0 - c0 - c1
        q0, q1, q2 = winv[i0], winv[i1], winv[i2]
        for j in range(N_PLANES):
            if j == 0:
                v0, v1, v2 = 1.0, 1.0, 1.0
            elif j < 4:
                v0, v1, v2 = normals[i0, j - 1], normals[i1, j - 1], normals[i2, j - 1]
            elif j < 7:
                v0, v1, v2 = vcol[i0, j - 4], vcol[i1, j - 4], vcol[i2, j - 4]
            else:
                v0, v1, v2 = uv[i0, j - 7], uv[i1, j - 7], uv[i2, j - 7]
            v0 *= q0
            v1 *= q1
            v2 *= q2
            planes[f, 3 * j] = a0 * v0 + a1 * v1 + a2 * v2
            planes[f, 3 * j + 1] = b0 * v0 + b1 * v1 + b2 * v2
            planes[f, 3 * j + 2] = c0 * v0 + c1 * v1 + c2 * v2
        if ortho:
            vx, vy, vz = -view_dir[0], -view_dir[1], -view_dir[2]
        else:
            vx = eye[0] - (world[i0, 0] + world[i1, 0] + world[i2, 0]) / 3.0
            vy = eye[1] - (world[i0, 1] + world[i1, 1] + world[i2, 1]) / 3.0
            vz = eye[2] - (world[i0, 2] + world[i1, 2] + world[i2, 2]) / 3.0
            vn = np.sqrt(vx * vx + vy * vy + vz * vz) + 1e-12
            vx /= vn
            vy /= vn
            vz /= vn
        planes[f, o] = vx
        planes[f, o + 1] = vy
        planes[f, o + 2] = vz
        for k in range(nl):
            hx, hy, hz = light_dir[k, 0] + vx, light_dir[k, 1] + vy, light_dir[k, 2] + vz
            hn = np.sqrt(hx * hx + hy * hy + hz * hz) + 1e-12
            planes[f, o + 3 + 3 * k] = hx / hn
            planes[f, o + 4 + 3 * k] = hy / hn
            planes[f, o + 5 + 3 * k] = hz / hn


@njit(cache=True, fastmath=True, inline="always", error_model="numpy")
def _plane(planes, f, j, cx, cy):
    return planes[f, 3 * j] * cx + planes[f, 3 * j + 1] * cy + planes[f, 3 * j + 2]


#: columns of a wrinkled triangle's row in ``wplanes`` (see :func:`_shade`): the planes of the
#: perspective-correct numerators of the 6 vertex fields of :mod:`myoface.render.wrinkles`
#: (rest x, rest y, fold distance, A_x, A_y, A_n), then the world gradients (3 x 3) of the first 3
W_COLS = 6 * 3 + 9
#: the nasolabial groove's half-width (mm)
_FOLD_W = FOLD_WIDTH_MM


@njit(cache=True, fastmath=True, inline="never", error_model="numpy")
def _wrinkle_normal(f, cx, cy, inv, nx, ny, nz, wplanes, wk):
    """The unit normal (nx, ny, nz) tilted by the wrinkle height field's gradient at screen
    point (cx, cy) of triangle ``f`` (kept out of line: most pixels have no wrinkles)."""
    wx = _plane(wplanes, f, 0, cx, cy) * inv
    wy = _plane(wplanes, f, 1, cx, cy) * inv
    ws = _plane(wplanes, f, 2, cx, cy) * inv
    amx = _plane(wplanes, f, 3, cx, cy) * inv
    amy = _plane(wplanes, f, 4, cx, cy) * inv
    amn = _plane(wplanes, f, 5, cx, cy) * inv
    # dh/dX, dh/dY, dh/ds of h = A_y sin(k Y) + A_x sin(k X) - A_n exp(-(s / w)^2)
    hx = amx * wk * np.cos(wk * wx)
    hy = amy * wk * np.cos(wk * wy)
    q = ws / _FOLD_W
    hs = amn * 2.0 * q / _FOLD_W * np.exp(-q * q)
    g = 18
    gx = hx * wplanes[f, g] + hy * wplanes[f, g + 3] + hs * wplanes[f, g + 6]
    gy = hx * wplanes[f, g + 1] + hy * wplanes[f, g + 4] + hs * wplanes[f, g + 7]
    gz = hx * wplanes[f, g + 2] + hy * wplanes[f, g + 5] + hs * wplanes[f, g + 8]
    nx -= gx
    ny -= gy
    nz -= gz
    nn = 1.0 / (np.sqrt(nx * nx + ny * ny + nz * nz) + 1e-30)
    nx *= nn
    ny *= nn
    nz *= nn
    return nx, ny, nz


@njit(cache=True, fastmath=True, inline="always", error_model="numpy")
def _shade(
    f, cx, cy, planes, tex, tri_tex, light_dir, light_col, ambient, ks, shininess,
    wplanes, wflag, wk, spec,
):  # fmt: skip
    """Linear RGB of triangle ``f`` at screen point (cx, cy): perspective-correct attributes,
    normal flipped towards the viewer and tilted by the wrinkle height field where
    ``wflag[f]`` (n' = n - grad h), Blinn-Phong with every light (specular x ``spec[f]``)."""
    inv = 1.0 / _plane(planes, f, 0, cx, cy)
    nx = _plane(planes, f, 1, cx, cy)  # (scaled by D > 0; normalized below)
    ny = _plane(planes, f, 2, cx, cy)
    nz = _plane(planes, f, 3, cx, cy)
    nn = 1.0 / (np.sqrt(nx * nx + ny * ny + nz * nz) + 1e-30)
    nx *= nn
    ny *= nn
    nz *= nn
    if f < wflag.shape[0] and wflag[f]:
        nx, ny, nz = _wrinkle_normal(f, cx, cy, inv, nx, ny, nz, wplanes, wk)
    ks = ks * spec[f]
    o = 3 * N_PLANES
    vx, vy, vz = planes[f, o], planes[f, o + 1], planes[f, o + 2]
    if nx * vx + ny * vy + nz * vz < 0.0:  # the back of an open surface
        nx, ny, nz = -nx, -ny, -nz
    ar = _plane(planes, f, 4, cx, cy) * inv
    ag = _plane(planes, f, 5, cx, cy) * inv
    ab = _plane(planes, f, 6, cx, cy) * inv
    if tri_tex[f]:
        tu = _plane(planes, f, 7, cx, cy) * inv
        tv = _plane(planes, f, 8, cx, cy) * inv
        tr, tg, tb = _tex_bilinear(tex, tu, tv)
        ar *= tr
        ag *= tg
        ab *= tb
    dr, dg, db = ambient[0], ambient[1], ambient[2]
    sr = 0.0
    sg = 0.0
    sb = 0.0
    for k in range(light_dir.shape[0]):
        lx, ly, lz = light_dir[k, 0], light_dir[k, 1], light_dir[k, 2]
        ndl = nx * lx + ny * ly + nz * lz
        if ndl <= 0.0:
            continue
        dr += ndl * light_col[k, 0]
        dg += ndl * light_col[k, 1]
        db += ndl * light_col[k, 2]
        hx, hy, hz = planes[f, o + 3 + 3 * k], planes[f, o + 4 + 3 * k], planes[f, o + 5 + 3 * k]
        ndh = nx * hx + ny * hy + nz * hz
        if ndh > 0.5 and ks > 0.0:
            # Schlick's rational approximation of ndh^shininess (Schlick 1994)
            sp = ks * ndh / (shininess - shininess * ndh + ndh)
            sr += sp * light_col[k, 0]
            sg += sp * light_col[k, 1]
            sb += sp * light_col[k, 2]
    return ar * dr + sr, ag * dg + sg, ab * db + sb


@njit(cache=True, parallel=True, fastmath=True, error_model="numpy")
def shade_resolve(
    fct,  # supersampling factor per axis
    bbox,
    tri_id,
    planes,  # from attribute_planes
    tex,
    tri_tex,
    light_dir,
    light_col,
    ambient,
    ks,
    shininess,
    background,  # (H * fct, 3) linear background per supersampled row
    lut,  # sRGB codes (used when srgb)
    srgb,  # bool: write ``out8`` (uint8 sRGB) instead of ``outf`` (float32 linear)
    out8,
    outf,
    nt,  # threads (rows are interleaved between them)
    wplanes,  # (F_w, W_COLS) wrinkle planes of the first F_w triangles (see _shade)
    wflag,  # (F_w,) bool: triangle is wrinkled
    wk,  # furrow wave number (rad / mm)
    spec,  # (F,) specular scale per triangle
):
    """Shade and resolve to the output size, like multisample anti-aliasing: each output pixel
    looks at its fct x fct samples and shades every distinct triangle among them once, at the
    centroid of the samples it covers, weighted by their number (background samples get the
    background). Interior pixels (one triangle) are shaded once instead of fct^2 times."""
    h = out8.shape[0] if srgb else outf.shape[0]
    w = out8.shape[1] if srgb else outf.shape[1]
    n_lut = lut.shape[0]
    nss = fct * fct
    inv = 1.0 / nss
    offy = np.empty(nss, np.int64)  # sample s of a pixel is at (y fct + offy[s], x fct + offx[s])
    offx = np.empty(nss, np.int64)
    for s in range(nss):
        offy[s] = s // fct
        offx[s] = s % fct
    for th in prange(nt):
        ids = np.empty(nss, np.int64)
        for y in range(th, h, nt):  # interleaved rows balance the threads
            bgr = 0.0
            bgg = 0.0
            bgb = 0.0
            for j in range(fct):
                bgr += background[y * fct + j, 0]
                bgg += background[y * fct + j, 1]
                bgb += background[y * fct + j, 2]
            bgr /= fct
            bgg /= fct
            bgb /= fct
            k = int(bgr * n_lut)
            bg8r = lut[min(max(k, 0), n_lut - 1)]
            k = int(bgg * n_lut)
            bg8g = lut[min(max(k, 0), n_lut - 1)]
            k = int(bgb * n_lut)
            bg8b = lut[min(max(k, 0), n_lut - 1)]
            # the box is whole pixels, so every sample of a pixel inside it was drawn
            if bbox[2] <= y * fct and y * fct <= bbox[3]:
                xin0 = bbox[0] // fct
                xin1 = bbox[1] // fct
            else:
                xin0 = w
                xin1 = -1
            for x in range(w):
                if x < xin0 or x > xin1:
                    if srgb:
                        out8[y, x, 0] = bg8r
                        out8[y, x, 1] = bg8g
                        out8[y, x, 2] = bg8b
                    else:
                        outf[y, x, 0] = bgr
                        outf[y, x, 1] = bgg
                        outf[y, x, 2] = bgb
                    continue
                r, g, b = bgr, bgg, bgb
                t0 = tri_id[y * fct, x * fct]
                same = True
                for s in range(1, nss):
                    if tri_id[y * fct + offy[s], x * fct + offx[s]] != t0:
                        same = False
                        break
                if same:  # the common case: one triangle (or none) covers the pixel
                    if t0 >= 0:
                        r, g, b = _shade(
                            t0, (x + 0.5) * fct, (y + 0.5) * fct, planes, tex, tri_tex,
                            light_dir, light_col, ambient, ks, shininess,
                            wplanes, wflag, wk, spec,
                        )  # fmt: skip
                else:
                    for s in range(nss):
                        ids[s] = tri_id[y * fct + offy[s], x * fct + offx[s]]
                    r = 0.0
                    g = 0.0
                    b = 0.0
                    for s in range(nss):
                        t = ids[s]
                        seen = False  # this triangle was handled at an earlier sample
                        for s2 in range(s):
                            if ids[s2] == t:
                                seen = True
                                break
                        if seen:
                            continue
                        # this triangle's samples in the pixel: count, centroid, background
                        cnt = 0
                        mx = 0.0
                        my = 0.0
                        br = 0.0
                        bg = 0.0
                        bb = 0.0
                        for s2 in range(s, nss):
                            if ids[s2] == t:
                                sy2 = y * fct + offy[s2]
                                cnt += 1
                                mx += x * fct + offx[s2] + 0.5
                                my += sy2 + 0.5
                                br += background[sy2, 0]
                                bg += background[sy2, 1]
                                bb += background[sy2, 2]
                        if t < 0:
                            r += br
                            g += bg
                            b += bb
                            continue
                        cr, cg, cb = _shade(
                            t, mx / cnt, my / cnt, planes, tex, tri_tex,
                            light_dir, light_col, ambient, ks, shininess,
                            wplanes, wflag, wk, spec,
                        )  # fmt: skip
                        r += cr * cnt
                        g += cg * cnt
                        b += cb * cnt
                    r *= inv
                    g *= inv
                    b *= inv
                if srgb:
                    k = int(r * n_lut)
                    out8[y, x, 0] = lut[min(max(k, 0), n_lut - 1)]
                    k = int(g * n_lut)
                    out8[y, x, 1] = lut[min(max(k, 0), n_lut - 1)]
                    k = int(b * n_lut)
                    out8[y, x, 2] = lut[min(max(k, 0), n_lut - 1)]
                else:
                    outf[y, x, 0] = r
                    outf[y, x, 1] = g
                    outf[y, x, 2] = b


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


def srgb_lut(n: int = 4096) -> np.ndarray:
    """uint8 sRGB codes of linear values (i + 0.5) / n, i = 0..n-1 (IEC 61966-2-1)."""
    c = (np.arange(n) + 0.5) / n
    s = np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)
    return (s * 255.0 + 0.5).astype(np.uint8)


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
