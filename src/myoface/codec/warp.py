"""The piecewise-affine warp of a picture over a moving triangle mesh: a backward map for
:func:`cv2.remap` built by rasterising the mesh where it is now.

Each node of the mesh has a place in the destination image (where it is now) and one in the
source picture (where it was); every destination pixel inside a triangle reads the source at
the same barycentric coordinates inside that triangle's source (an affine map per triangle:
the warp is continuous across the triangles' shared edges). Triangles are drawn in layers:
a layer drawn later covers an earlier one, and within a layer drawn with the depth test the
nearest triangle wins (the skin's own occlusions, e.g. the nose over a cheek when the head
turns).

Image coordinates are (x, y) = (column, row) in pixels, pixel centres at half-integers (as the
cameras project: :class:`myoface.analysis.camera.PinholeCamera`); the map holds the source's
pixel indices (a pixel's centre at an integer), what :func:`cv2.remap` reads.

:func:`raster_warp` is the numba kernel; :func:`raster_warp_reference` the same in plain numpy
(the tests hold one against the other).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: a pixel centre within this (barycentric units) outside a triangle's edge still counts as
#: inside: the triangles that share an edge leave no crack between them
EDGE_EPS = 1e-6
#: triangles whose destination area is below this (pixels squared) cover no pixel centre
MIN_AREA_PX2 = 1e-9


@njit(cache=True)
def raster_warp(dst, src, depth, tris, map_x, map_y, label, lab, zbuf, ztest, src_dx, src_dy):
    """Draw the triangles ``tris`` (F, 3) int of nodes at ``dst`` (N, 2) px (now) into the
    backward map ``map_x``, ``map_y`` (H, W) float32: each covered pixel gets its source
    position, the same barycentric point of the nodes at ``src`` (N, 2) px, shifted by
    (``src_dx``, ``src_dy``) px, as a pixel index; ``label`` (H, W) uint8 gets ``lab``.
    With ``ztest``, a pixel is drawn only where its depth (``depth`` (N,), mm from the
    camera, interpolated) is below ``zbuf`` (H, W) float32, which is updated; else every
    covered pixel is drawn (over what an earlier layer drew). Returns the pixels drawn."""
    h, w = map_x.shape
    n_drawn = 0
    for t in range(tris.shape[0]):
        i0, i1, i2 = tris[t, 0], tris[t, 1], tris[t, 2]
        x0, y0 = dst[i0, 0], dst[i0, 1]
        x1, y1 = dst[i1, 0], dst[i1, 1]
        x2, y2 = dst[i2, 0], dst[i2, 1]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if abs(area) < MIN_AREA_PX2:
            continue
        lo_x = min(x0, min(x1, x2))
        hi_x = max(x0, max(x1, x2))
        lo_y = min(y0, min(y1, y2))
        hi_y = max(y0, max(y1, y2))
        if not (hi_x > -1.0 and hi_y > -1.0 and lo_x < w + 1.0 and lo_y < h + 1.0):
            continue
        xa = max(int(math.ceil(lo_x - 0.5)), 0)
        xb = min(int(math.floor(hi_x - 0.5)), w - 1)
        ya = max(int(math.ceil(lo_y - 0.5)), 0)
        yb = min(int(math.floor(hi_y - 0.5)), h - 1)
        if xa > xb or ya > yb:
            continue
        inv = 1.0 / area
        # barycentric planes: b1 = a1 x + c1 y + k1, b2 = a2 x + c2 y + k2, b0 = 1 - b1 - b2
        a1 = (y2 - y0) * inv
        c1 = -(x2 - x0) * inv
        k1 = -(a1 * x0 + c1 * y0)
        a2 = -(y1 - y0) * inv
        c2 = (x1 - x0) * inv
        k2 = -(a2 * x0 + c2 * y0)
        sx0, sy0 = src[i0, 0] - 0.5 + src_dx, src[i0, 1] - 0.5 + src_dy
        sx1, sy1 = src[i1, 0] - 0.5 + src_dx, src[i1, 1] - 0.5 + src_dy
        sx2, sy2 = src[i2, 0] - 0.5 + src_dx, src[i2, 1] - 0.5 + src_dy
        d0, d1, d2 = depth[i0], depth[i1], depth[i2]
        a0 = -(a1 + a2)
        for py in range(ya, yb + 1):
            yc = py + 0.5
            # the row's span: each barycentric b = a x + k(y) >= -EDGE_EPS bounds x on one side
            q1 = c1 * yc + k1
            q2 = c2 * yc + k2
            q0 = 1.0 - q1 - q2
            lo, hi = lo_x - 1.0, hi_x + 1.0
            empty = False
            for a, q in ((a0, q0), (a1, q1), (a2, q2)):
                if a > 0.0:
                    lo = max(lo, (-EDGE_EPS - q) / a)
                elif a < 0.0:
                    hi = min(hi, (-EDGE_EPS - q) / a)
                elif q < -EDGE_EPS:
                    empty = True
            if empty:
                continue
            pa = max(int(math.ceil(lo - 0.5)) - 1, xa)
            pb = min(int(math.floor(hi - 0.5)) + 1, xb)
            for px in range(pa, pb + 1):
                xc = px + 0.5
                b1 = a1 * xc + c1 * yc + k1
                b2 = a2 * xc + c2 * yc + k2
                b0 = 1.0 - b1 - b2
                if b0 < -EDGE_EPS or b1 < -EDGE_EPS or b2 < -EDGE_EPS:
                    continue
                if ztest:
                    z = b0 * d0 + b1 * d1 + b2 * d2
                    if z >= zbuf[py, px]:
                        continue
                    zbuf[py, px] = z
                map_x[py, px] = b0 * sx0 + b1 * sx1 + b2 * sx2
                map_y[py, px] = b0 * sy0 + b1 * sy1 + b2 * sy2
                label[py, px] = lab
                n_drawn += 1
    return n_drawn


def raster_warp_reference(dst, src, depth, tris, map_x, map_y, label, lab, zbuf, ztest,
                          src_dx=0.0, src_dy=0.0):  # fmt: skip
    """:func:`raster_warp` in plain numpy (slow; for the tests): the same arguments, the same
    result."""
    h, w = map_x.shape
    ys, xs = np.mgrid[0:h, 0:w]
    xc, yc = xs + 0.5, ys + 0.5
    n_drawn = 0
    for i0, i1, i2 in np.asarray(tris):
        (x0, y0), (x1, y1), (x2, y2) = dst[i0], dst[i1], dst[i2]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if abs(area) < MIN_AREA_PX2:
            continue
        b1 = ((xc - x0) * (y2 - y0) - (x2 - x0) * (yc - y0)) / area
        b2 = ((x1 - x0) * (yc - y0) - (xc - x0) * (y1 - y0)) / area
        b0 = 1.0 - b1 - b2
        inside = (b0 >= -EDGE_EPS) & (b1 >= -EDGE_EPS) & (b2 >= -EDGE_EPS)
        if ztest:
            z = b0 * depth[i0] + b1 * depth[i1] + b2 * depth[i2]
            inside &= z < zbuf
            zbuf[inside] = z[inside]
        sx = b0 * src[i0, 0] + b1 * src[i1, 0] + b2 * src[i2, 0] - 0.5 + src_dx
        sy = b0 * src[i0, 1] + b1 * src[i1, 1] + b2 * src[i2, 1] - 0.5 + src_dy
        map_x[inside] = sx[inside]
        map_y[inside] = sy[inside]
        label[inside] = lab
        n_drawn += int(inside.sum())
    return n_drawn
