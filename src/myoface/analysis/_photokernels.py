"""Compiled inner loops of the photometric term (:class:`~myoface.analysis.photometric.
PhotometricTerm`): per Gauss-Newton step, the samples' camera points and pixels, their
triangles' facing, their distance to the face's outline, the frame's light (its normal
equations over the samples), the samples' weights, the term's normal equations (summed over
the mesh's vertex pairs, :func:`pair_normal_equations`), the weighted rows of its Jacobian
(the rows themselves, :func:`weighted_rows`: the tests' and the tools') and its cost.

They compute what the numpy code they replace computed (the same formulas, the same order of
the operations on each sample; sums over the samples in another order, so the normal
equations agree to rounding, ~1e-14 relative: ``tests/analysis/test_photometric.py`` holds
them against the numpy formulas). A sample is read from its triangle's three vertices by its
barycentric coordinates directly (no sparse matrix, no row slice of one). ``nogil`` as in
:mod:`myoface.analysis._fitkernels`: a frame can be fitted while another thread runs the face
detector on the next one.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from myoface.analysis._fitkernels import cross_gram, vertex_normals


@njit(cache=True, nogil=True)
def camera_points(rot, trans, shape):
    """``shape`` (V, 3) head frame -> camera frame (V, 3): ``R X + t``."""
    nv = shape.shape[0]
    out = np.empty((nv, 3))
    for v in range(nv):
        x0, x1, x2 = shape[v, 0], shape[v, 1], shape[v, 2]
        for i in range(3):
            out[v, i] = rot[i, 0] * x0 + rot[i, 1] * x1 + rot[i, 2] * x2 + trans[i]
    return out


@njit(cache=True, nogil=True)
def sample_pixels(pc, tri, bary, idx, f, cx, cy):
    """The pixels (N, 2) of the samples ``idx`` (N,): each its triangle's vertices ``pc``
    (V, 3, camera frame) by its barycentric coordinates, projected as
    :meth:`~myoface.analysis.camera.PinholeCamera.project` does."""
    n = idx.shape[0]
    out = np.empty((n, 2))
    for i in range(n):
        s = idx[i]
        a, b, c = tri[s, 0], tri[s, 1], tri[s, 2]
        w0, w1, w2 = bary[s, 0], bary[s, 1], bary[s, 2]
        p0 = w0 * pc[a, 0] + w1 * pc[b, 0] + w2 * pc[c, 0]
        p1 = w0 * pc[a, 1] + w1 * pc[b, 1] + w2 * pc[c, 1]
        p2 = w0 * pc[a, 2] + w1 * pc[b, 2] + w2 * pc[c, 2]
        d = max(-p2, 1e-6)
        out[i, 0] = cx + f * p0 / d
        out[i, 1] = cy - f * p1 / d
    return out


@njit(cache=True, nogil=True)
def zbuffer_window(uv, depth, tris, xa, ya, xb, yb):
    """The nearest depth of the triangles ``tris`` (vertices at ``uv`` (V, 2) pixels,
    ``depth`` (V,) mm) on the pixels ``xa..xb`` x ``ya..yb`` (inclusive; inf where no
    triangle covers a pixel's centre), shape (yb - ya + 1, xb - xa + 1):
    :func:`~myoface.analysis.photometric._zbuffer` on the window that holds the mesh (the
    same pixels, the same depths), not the whole frame."""
    z = np.full((yb - ya + 1, xb - xa + 1), np.inf)
    for f in range(tris.shape[0]):
        i0, i1, i2 = tris[f, 0], tris[f, 1], tris[f, 2]
        x0, y0, x1, y1, x2, y2 = uv[i0, 0], uv[i0, 1], uv[i1, 0], uv[i1, 1], uv[i2, 0], uv[i2, 1]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if abs(area) < 1e-9:
            continue
        fxa = max(int(np.floor(min(x0, x1, x2))), xa)
        fxb = min(int(np.ceil(max(x0, x1, x2))), xb)
        fya = max(int(np.floor(min(y0, y1, y2))), ya)
        fyb = min(int(np.ceil(max(y0, y1, y2))), yb)
        for y in range(fya, fyb + 1):
            for x in range(fxa, fxb + 1):
                l1 = ((x - x0) * (y2 - y0) - (x2 - x0) * (y - y0)) / area
                l2 = ((x1 - x0) * (y - y0) - (x - x0) * (y1 - y0)) / area
                l0 = 1.0 - l1 - l2
                if l0 < -1e-6 or l1 < -1e-6 or l2 < -1e-6:
                    continue
                d = l0 * depth[i0] + l1 * depth[i1] + l2 * depth[i2]
                if d < z[y - ya, x - xa]:
                    z[y - ya, x - xa] = d
    return z


@njit(cache=True, nogil=True)
def facing(pc, triangles, tri_index):
    """Each sample's facing (S,): the cosine between its triangle's normal and the direction
    to the camera (:func:`~myoface.analysis.photometric.facing`)."""
    nt = triangles.shape[0]
    cos = np.empty(nt)
    for t in range(nt):
        a, b, c = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        e1x, e1y, e1z = pc[b, 0] - pc[a, 0], pc[b, 1] - pc[a, 1], pc[b, 2] - pc[a, 2]
        e2x, e2y, e2z = pc[c, 0] - pc[a, 0], pc[c, 1] - pc[a, 1], pc[c, 2] - pc[a, 2]
        nx = e1y * e2z - e1z * e2y
        ny = e1z * e2x - e1x * e2z
        nz = e1x * e2y - e1y * e2x
        nn = max(np.sqrt(nx * nx + ny * ny + nz * nz), 1e-12)
        mx = (pc[a, 0] + pc[b, 0] + pc[c, 0]) / 3
        my = (pc[a, 1] + pc[b, 1] + pc[c, 1]) / 3
        mz = (pc[a, 2] + pc[b, 2] + pc[c, 2]) / 3
        mm = max(np.sqrt(mx * mx + my * my + mz * mz), 1e-12)
        cos[t] = (nx / nn) * (-mx / mm) + (ny / nn) * (-my / mm) + (nz / nn) * (-mz / mm)
    ns = tri_index.shape[0]
    out = np.empty(ns)
    for s in range(ns):
        out[s] = cos[tri_index[s]]
    return out


@njit(cache=True, nogil=True)
def clear_of_polyline(points, line, dist, ok):
    """Whether each point (N, 2) with ``ok`` is at least ``dist`` from the closed polyline
    ``line`` (K, 2) (False where not ``ok``): ``distance_to_polyline(points, line) >= dist``
    of :mod:`myoface.analysis.photometric`, each segment's distance computed as there. A
    point outside a segment's box widened by ``dist`` (and a margin for rounding) is not
    nearer to it than ``dist`` (the segments are boxed in runs of :data:`_RUN` too, and each
    run's box first); a point stops at the first segment nearer than ``dist``."""
    n, k = points.shape[0], line.shape[0]
    out = np.zeros(n, dtype=np.bool_)
    pad = dist * (1.0 + 1e-9) + 1e-9
    box = np.empty((k, 4))  # per segment: x lo, x hi, y lo, y hi
    nrun = (k + _RUN - 1) // _RUN
    runbox = np.empty((nrun, 4))
    for j in range(k):
        ax, ay = line[j, 0], line[j, 1]
        bx, by = line[(j + 1) % k, 0], line[(j + 1) % k, 1]
        box[j, 0], box[j, 1] = min(ax, bx) - pad, max(ax, bx) + pad
        box[j, 2], box[j, 3] = min(ay, by) - pad, max(ay, by) + pad
    for g in range(nrun):
        runbox[g, 0], runbox[g, 1] = np.inf, -np.inf
        runbox[g, 2], runbox[g, 3] = np.inf, -np.inf
        for j in range(g * _RUN, min((g + 1) * _RUN, k)):
            runbox[g, 0] = min(runbox[g, 0], box[j, 0])
            runbox[g, 1] = max(runbox[g, 1], box[j, 1])
            runbox[g, 2] = min(runbox[g, 2], box[j, 2])
            runbox[g, 3] = max(runbox[g, 3], box[j, 3])
    for i in range(n):
        if not ok[i]:
            continue
        px, py = points[i, 0], points[i, 1]
        clear = True
        for g in range(nrun):
            if px < runbox[g, 0] or px > runbox[g, 1] or py < runbox[g, 2] or py > runbox[g, 3]:
                continue
            for j in range(g * _RUN, min((g + 1) * _RUN, k)):
                if px < box[j, 0] or px > box[j, 1] or py < box[j, 2] or py > box[j, 3]:
                    continue
                ax, ay = line[j, 0], line[j, 1]
                bx, by = line[(j + 1) % k, 0], line[(j + 1) % k, 1]
                dx, dy = bx - ax, by - ay
                den = dx * dx + dy * dy
                t = ((px - ax) * dx + (py - ay) * dy) / den if den > 1e-12 else 0.0
                t = min(max(t, 0.0), 1.0)
                ex, ey = px - (ax + t * dx), py - (ay + t * dy)
                if np.sqrt(ex * ex + ey * ey) < dist:
                    clear = False
                    break
            if not clear:
                break
        out[i] = clear
    return out


#: :func:`clear_of_polyline`'s runs of segments
_RUN = 6


@njit(cache=True, nogil=True)
def shading_basis(pc, triangles, tri, bary, order):
    """The first-order spherical harmonics (S, 4) (``order`` 1; (S, 1) for 0) of the unit
    normals at the samples: the mesh's vertex normals at ``pc`` interpolated by the samples'
    barycentric coordinates (:func:`~myoface.analysis.photometric.sample_normals`,
    :func:`~myoface.analysis.photometric.shading_basis`)."""
    vn = vertex_normals(pc, triangles)
    ns = tri.shape[0]
    nb = 9 if order >= 2 else (4 if order >= 1 else 1)
    out = np.empty((ns, nb))
    for s in range(ns):
        out[s, 0] = 1.0
        if nb == 1:
            continue
        a, b, c = tri[s, 0], tri[s, 1], tri[s, 2]
        w0, w1, w2 = bary[s, 0], bary[s, 1], bary[s, 2]
        n0 = w0 * vn[a, 0] + w1 * vn[b, 0] + w2 * vn[c, 0]
        n1 = w0 * vn[a, 1] + w1 * vn[b, 1] + w2 * vn[c, 1]
        n2 = w0 * vn[a, 2] + w1 * vn[b, 2] + w2 * vn[c, 2]
        nn = max(np.sqrt(n0 * n0 + n1 * n1 + n2 * n2), 1e-12)
        x, y, z = n0 / nn, n1 / nn, n2 / nn
        out[s, 1], out[s, 2], out[s, 3] = x, y, z
        if nb == 9:
            out[s, 4], out[s, 5], out[s, 6] = x * y, x * z, y * z
            out[s, 7], out[s, 8] = x * x - y * y, 3.0 * z * z - 1.0
    return out


@njit(cache=True, nogil=True)
def light_system(basis, alb, region, n_regions, val, use, field):
    """The normal equations (gram (k, k), rhs (k,)) of the frame's light over the samples
    ``use`` (bool, S): the columns ``alb * basis``, with ``field`` the basis' normal columns
    ``basis[:, 1:]`` too (a field linear in the normals, added:
    :meth:`~myoface.analysis.photometric.PhotometricTerm._light_basis`), and one per
    region (:meth:`~myoface.analysis.photometric.PhotometricTerm._light_basis`); ``k = nb (+
    nb - 1) + n_regions``, the gram plus 1e-9 on its diagonal."""
    ns, nb = basis.shape
    nf = nb + nb - 1 if field else nb
    k = nf + n_regions
    gram = np.zeros((k, k))
    rhs = np.zeros(k)
    x = np.empty(nf)
    for s in range(ns):
        if not use[s]:
            continue
        a = alb[s]
        for i in range(nb):
            x[i] = a * basis[s, i]
        for i in range(nb, nf):
            x[i] = basis[s, i - nb + 1]
        r = nf + region[s]
        v = val[s]
        for i in range(nf):
            xi = x[i]
            for j in range(i, nf):
                gram[i, j] += xi * x[j]
            gram[i, r] += xi  # (the region's column is 1 for this sample)
            rhs[i] += xi * v
        gram[r, r] += 1.0
        rhs[r] += v
    for i in range(k):
        gram[i, i] += 1e-9
        for j in range(i + 1, k):
            gram[j, i] = gram[i, j]
    return gram, rhs


@njit(cache=True, nogil=True)
def light_apply(basis, sol, region, alb0, field):
    """Each sample's scale (S,) (``basis @ sol[:nb]``), offset (S,) (its region's, and with
    ``field`` the field's, :func:`light_system`) and its appearance under that light (S,):
    ``alb0 * scale + offset`` (``alb0``: the albedo, 0 where unknown)."""
    ns, nb = basis.shape
    nf = nb + nb - 1 if field else nb
    scale = np.empty(ns)
    off = np.empty(ns)
    lit = np.empty(ns)
    for s in range(ns):
        acc = 0.0
        for i in range(nb):
            acc += basis[s, i] * sol[i]
        o = sol[nf + region[s]]
        for i in range(nb, nf):
            o += basis[s, i - nb + 1] * sol[i]
        scale[s] = acc
        off[s] = o
        lit[s] = alb0[s] * acc + o
    return scale, off, lit


@njit(cache=True, nogil=True)
def step_weights(val, lit, ok, sigma, huber, indep, weight, own, outliers, outlier_sigmas):
    """Each sample's weight (S,) over a step: ``indep * hub * weight * own`` where ``ok``, 0
    elsewhere; ``hub`` Huber's weight of its residual ``(val - lit) / sigma`` beyond
    ``huber``, 0 beyond ``outlier_sigmas`` when ``outliers``."""
    ns = val.shape[0]
    w = np.zeros(ns)
    for s in range(ns):
        if not ok[s]:
            continue
        r = (val[s] - lit[s]) / sigma
        ar = abs(r)
        hub = huber / max(ar, 1e-12) if ar > huber else 1.0
        if outliers and ar > outlier_sigmas:
            hub = 0.0
        w[s] = indep * hub * weight * own[s]
    return w


@njit(cache=True, nogil=True)
def step_light(read, a, seen, prev_w, basis, alb_ok, alb0, region, n_regions, field, sigma,
               huber, indep, weight, own, outliers, outlier_sigmas):  # fmt: skip
    """A step's light and weights from what it read (:meth:`~myoface.analysis.photometric.
    PhotometricTerm.prepare`): ``read`` (S, 3) the image and its gradient at the samples;
    a sample is usable where it is ``seen``, its appearance ``a`` (S,) known and its pixel
    read; the light (:func:`light_system`, :func:`light_apply`, ``basis`` and ``field`` as
    there) fitted over the usable samples whose albedo is known (``alb_ok``) and, after the
    first step (``prev_w`` not empty), that weighed at the last (at least 40 of them, else
    no light: scale 1, offset 0); then their weights (:func:`step_weights`). Returns the
    samples' scale, offset, appearance under the light and weight (S,), the samples that
    weigh (N,), and what was read there (N, 3) and its image (N,)."""
    ns = read.shape[0]
    val = np.empty(ns)
    ok = np.zeros(ns, dtype=np.bool_)
    m = np.zeros(ns, dtype=np.bool_)
    after = prev_w.shape[0] > 0
    count = 0
    for s in range(ns):
        v = read[s, 0]
        val[s] = v
        usable = seen[s] and np.isfinite(a[s]) and np.isfinite(v)
        ok[s] = usable
        if usable and alb_ok[s] and (not after or prev_w[s] > 0):
            m[s] = True
            count += 1
    if count < 40:
        scale = np.ones(ns)
        off = np.zeros(ns)
        lit = alb0.copy()
    else:
        gram, rhs = light_system(basis, alb0, region, n_regions, val, m, field)
        sol = np.linalg.solve(gram, rhs)
        scale, off, lit = light_apply(basis, sol, region, alb0, field)
    w = step_weights(val, lit, ok, sigma, huber, indep, weight, own, outliers, outlier_sigmas)
    n = 0
    for s in range(ns):
        if w[s] > 0:
            n += 1
    use = np.empty(n, dtype=np.int64)
    at = np.empty((n, 3))
    at0 = np.empty(n)
    i = 0
    for s in range(ns):
        if w[s] > 0:
            use[i] = s
            at[i, 0], at[i, 1], at[i, 2] = read[s, 0], read[s, 1], read[s, 2]
            at0[i] = read[s, 0]
            i += 1
    return scale, off, lit, w, use, at, at0


@njit(cache=True, nogil=True)
def weighted_rows(rot, trans, shape, jac, free, f, cx, cy, tri, bary, use, samp, lit, w, sigma):
    """The term's rows in the unknowns (omega (3), dt (3), dc[free]) at the samples ``use``
    (N,), transposed (n, N), and their residuals (N,), each times the square root of the
    sample's weight ``w`` (unweighted where ``w`` is empty): ``samp`` (N, 3) the image, its
    x and its y gradient at the samples' pixels (NaN off the image: 0, as ``nan_to_num``),
    ``lit`` (S,) the appearance under the frame's light, in sigmas.

    A sample's row is the image's gradient times the derivative of its pixel, its
    triangle's vertices' derivatives (``d(u, v)/dP dP/d(unknowns)``, made once per vertex)
    by its barycentric coordinates."""
    # per vertex, d(u, v)/d(unknowns) (V, 2, n): a sample's row is then its three vertices'
    # contiguous rows combined
    duv = vertex_duv(rot, trans, shape, jac, free, f, cx, cy)
    n = duv.shape[2]
    nu = use.shape[0]
    rw = np.empty(nu)
    jt = np.empty((n, nu))
    row = np.empty(n)
    weighted = w.shape[0] > 0
    for i in range(nu):
        s = use[i]
        gx, gy, val = samp[i, 1], samp[i, 2], samp[i, 0]
        gx = 0.0 if np.isnan(gx) else gx  # (as nan_to_num)
        gy = 0.0 if np.isnan(gy) else gy
        sw = np.sqrt(w[s]) if weighted else 1.0
        r = val - lit[s]
        r = 0.0 if np.isnan(r) else r
        rw[i] = r / sigma * sw
        # the image's gradient times the barycentric coordinates, times sqrt(w) / sigma
        q = sw / sigma
        a, b, c = tri[s, 0], tri[s, 1], tri[s, 2]
        u0, u1, u2 = gx * bary[s, 0] * q, gx * bary[s, 1] * q, gx * bary[s, 2] * q
        v0, v1, v2 = gy * bary[s, 0] * q, gy * bary[s, 1] * q, gy * bary[s, 2] * q
        for k in range(n):
            row[k] = (u0 * duv[a, 0, k] + u1 * duv[b, 0, k] + u2 * duv[c, 0, k]) + (
                v0 * duv[a, 1, k] + v1 * duv[b, 1, k] + v2 * duv[c, 1, k]
            )
        for k in range(n):
            jt[k, i] = row[k]
    return jt, rw


@njit(cache=True, nogil=True)
def weighted_cost(val, lit, w, use, sigma):
    """``sum w r^2`` over the samples ``use`` (N,), ``r = (val - lit) / sigma`` (``val``
    (N,) at those samples; 0 where NaN, as ``nan_to_num``)."""
    acc = 0.0
    for i in range(use.shape[0]):
        s = use[i]
        r = val[i] - lit[s]
        r = 0.0 if np.isnan(r) else r / sigma
        acc += w[s] * r * r
    return acc


@njit(cache=True, nogil=True)
def patch_sums(a, b, ok, tri, nv):
    """Per vertex (V, 6), over the samples ``ok`` on its triangles: their count and the sums
    of ``a``, ``b``, ``a^2``, ``b^2``, ``a b`` (:meth:`~myoface.analysis.photometric.
    PhotometricTerm.occlusion`'s patches)."""
    out = np.zeros((nv, 6))
    for s in range(tri.shape[0]):
        if not ok[s]:
            continue
        x, y = a[s], b[s]
        for q in range(3):
            v = tri[s, q]
            out[v, 0] += 1.0
            out[v, 1] += x
            out[v, 2] += y
            out[v, 3] += x * x
            out[v, 4] += y * y
            out[v, 5] += x * y
    return out


def vertex_pairs(triangles: np.ndarray, n_vertices: int):
    """The mesh's vertex pairs that share a triangle (each vertex with itself too), as
    compressed rows: ``ptr`` (V + 1,), ``nbr`` (P,) the pairs' second vertex, row by row, and
    ``slot`` (T, 3, 3): the pair of each triangle's corners ``p``, ``q`` (its index in ``nbr``).
    (:func:`pair_normal_equations`' sparse sum over the samples.)"""
    tris = np.asarray(triangles, dtype=np.int64)
    a = np.repeat(tris, 3, axis=1).ravel()  # corner p of each (p, q), row-major
    b = np.tile(tris, (1, 3)).ravel()
    key = a * int(n_vertices) + b
    uniq = np.unique(key)
    ptr = np.zeros(int(n_vertices) + 1, dtype=np.int64)
    np.add.at(ptr, uniq // int(n_vertices) + 1, 1)
    ptr = np.cumsum(ptr)
    nbr = (uniq % int(n_vertices)).astype(np.int64)
    slot = np.searchsorted(uniq, key).reshape(len(tris), 3, 3).astype(np.int64)
    return ptr, nbr, np.ascontiguousarray(slot)


@njit(cache=True, nogil=True)
def vertex_duv(rot, trans, shape, jac, free, f, cx, cy):
    """Per vertex, the derivative of its pixel (V, 2, n) in the unknowns (omega (3), dt (3),
    dc[free]) at the pose ``rot``, ``trans`` and the skin ``shape`` with its response
    ``jac``."""
    nv = shape.shape[0]
    nf = free.shape[0]
    n = 6 + nf
    duv = np.empty((nv, 2, n))
    for v in range(nv):
        x0, x1, x2 = shape[v, 0], shape[v, 1], shape[v, 2]
        y0 = rot[0, 0] * x0 + rot[0, 1] * x1 + rot[0, 2] * x2
        y1 = rot[1, 0] * x0 + rot[1, 1] * x1 + rot[1, 2] * x2
        y2 = rot[2, 0] * x0 + rot[2, 1] * x1 + rot[2, 2] * x2
        pc0, pc1, pc2 = y0 + trans[0], y1 + trans[1], y2 + trans[2]
        d = max(-pc2, 1e-6)
        # d(u, v)/dP: (a00, 0, a02), (0, a11, a12)
        a00, a02 = f / d, f * pc0 / d**2
        a11, a12 = -f / d, -f * pc1 / d**2
        # omega x (R X) = -[RX]x omega; dt: I; dc: R dX/dc
        duv[v, 0, 0] = a02 * y1
        duv[v, 0, 1] = a00 * y2 - a02 * y0
        duv[v, 0, 2] = -a00 * y1
        duv[v, 1, 0] = -a11 * y2 + a12 * y1
        duv[v, 1, 1] = -a12 * y0
        duv[v, 1, 2] = a11 * y0
        duv[v, 0, 3], duv[v, 0, 4], duv[v, 0, 5] = a00, 0.0, a02
        duv[v, 1, 3], duv[v, 1, 4], duv[v, 1, 5] = 0.0, a11, a12
        # (a R) . dX/dc
        e00 = a00 * rot[0, 0] + a02 * rot[2, 0]
        e01 = a00 * rot[0, 1] + a02 * rot[2, 1]
        e02 = a00 * rot[0, 2] + a02 * rot[2, 2]
        e10 = a11 * rot[1, 0] + a12 * rot[2, 0]
        e11 = a11 * rot[1, 1] + a12 * rot[2, 1]
        e12 = a11 * rot[1, 2] + a12 * rot[2, 2]
        for j in range(nf):
            m = free[j]
            j0, j1, j2 = jac[v, 0, m], jac[v, 1, m], jac[v, 2, m]
            duv[v, 0, 6 + j] = e00 * j0 + e01 * j1 + e02 * j2
            duv[v, 1, 6 + j] = e10 * j0 + e11 * j1 + e12 * j2
    return duv


@njit(cache=True, nogil=True)
def pair_sums(kb, e, tri, bary, tri_index, use, samp, lit, w, sigma, slot):
    """Add the samples ``use`` (N,) of one channel to the sparse sums of
    :func:`pair_normal_equations`: ``kb`` (P, 4), per vertex pair, ``sum c_p c_q^T`` (2 x 2,
    row-major) of the samples' weights ``c`` on their corners' pixel motions (the image's
    gradient times the barycentric coordinate, times ``sqrt(w) / sigma``), and ``e`` (V, 2),
    per vertex, ``sum c_p r`` (``r`` the weighted residual in sigmas). Arguments as
    :func:`weighted_rows`' (``w`` never empty here)."""
    cu = np.empty(3)
    cv = np.empty(3)
    for i in range(use.shape[0]):
        s = use[i]
        gx, gy, val = samp[i, 1], samp[i, 2], samp[i, 0]
        gx = 0.0 if np.isnan(gx) else gx  # (as nan_to_num)
        gy = 0.0 if np.isnan(gy) else gy
        sw = np.sqrt(w[s])
        r = val - lit[s]
        r = 0.0 if np.isnan(r) else r
        rr = r / sigma * sw
        q = sw / sigma
        for p in range(3):
            cu[p] = gx * bary[s, p] * q
            cv[p] = gy * bary[s, p] * q
        t = tri_index[s]
        for p in range(3):
            vert = tri[s, p]
            up, vp = cu[p], cv[p]
            e[vert, 0] += up * rr
            e[vert, 1] += vp * rr
            for qq in range(3):
                sl = slot[t, p, qq]
                kb[sl, 0] += up * cu[qq]
                kb[sl, 1] += up * cv[qq]
                kb[sl, 2] += vp * cu[qq]
                kb[sl, 3] += vp * cv[qq]


@njit(cache=True, nogil=True, fastmath=True)
def pair_normal_equations(duv, kb, e, ptr, nbr):
    """``(H, b)`` of the rows summed into ``kb``, ``e`` (:func:`pair_sums`), with the vertices'
    pixel derivatives ``duv`` (V, 2, n) (:func:`vertex_duv`).

    A sample's row is ``c^T D``: its six weights ``c`` on the pixel motions of its triangle's
    corners, ``D`` the vertices' ``duv`` (2 V x n). So ``H = sum_s D^T c_s c_s^T D = D^T K D``
    with ``K = sum_s c_s c_s^T``, which is sparse (a block per pair of vertices that share a
    triangle) and cheap to sum (36 products a sample), and ``b = -D^T sum_s c_s r_s``: the
    product with the ``n`` unknowns is then made once per vertex, not once per sample (a
    vertex carries ~16 samples of two channels), and any number of channels summed into
    ``kb`` costs one product."""
    nv = duv.shape[0]
    n = duv.shape[2]
    # the vertices that carry a sample, as columns: D^T (n, 2 m) and (K D)^T (n, 2 m)
    col = np.full(nv, -1, dtype=np.int64)
    m = 0
    for v in range(nv):
        for sl in range(ptr[v], ptr[v + 1]):
            if kb[sl, 0] != 0.0 or kb[sl, 3] != 0.0 or e[v, 0] != 0.0 or e[v, 1] != 0.0:
                col[v] = m
                m += 1
                break
    dt = np.empty((n, 2 * m))
    gt = np.zeros((n, 2 * m))
    b = np.zeros(n)
    g0 = np.empty(n)
    g1 = np.empty(n)
    for v in range(nv):
        c = col[v]
        if c < 0:
            continue
        for j in range(n):
            g0[j] = 0.0
            g1[j] = 0.0
        for sl in range(ptr[v], ptr[v + 1]):
            k0, k1, k2, k3 = kb[sl, 0], kb[sl, 1], kb[sl, 2], kb[sl, 3]
            if k0 == 0.0 and k1 == 0.0 and k2 == 0.0 and k3 == 0.0:
                continue
            v2 = nbr[sl]
            for j in range(n):
                d0, d1 = duv[v2, 0, j], duv[v2, 1, j]
                g0[j] += k0 * d0 + k1 * d1
                g1[j] += k2 * d0 + k3 * d1
        e0, e1 = e[v, 0], e[v, 1]
        for j in range(n):
            dt[j, 2 * c] = duv[v, 0, j]
            dt[j, 2 * c + 1] = duv[v, 1, j]
            gt[j, 2 * c] = g0[j]
            gt[j, 2 * c + 1] = g1[j]
            b[j] -= duv[v, 0, j] * e0 + duv[v, 1, j] * e1
    return cross_gram(dt, gt), b
