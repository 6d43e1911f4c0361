"""Compiled inner loops of the 3-D fit (:mod:`myoface.analysis.modelfit`): the normal equations
of the weighted landmark residuals (:class:`~myoface.analysis.terms.LandmarkTerm`), their
cost, and the small box-constrained quadratic programme each Levenberg-Marquardt step solves
(:mod:`myoface.analysis.solver`).

The normal equations are formed without the (2-3 V) x (6 + K) Jacobian: each vertex's rows
are accumulated into the normal matrix as they are made (the tests hold them against central
differences of the term's cost, and the step against scipy's BVLS). ``nogil``: a frame can be
fitted while another thread runs the face detector on the next one.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def landmark_terms(rot, trans, shape, f, cx, cy, p, use_z, w0, kxy, inv_ds, k, huber):
    """Per vertex: the weighted residuals' pieces (V, 4): ru, rv (in sigmas), rz (in sigmas,
    its ``w0``-weighted mean removed), and the 2-D distance in sigmas."""
    nv = shape.shape[0]
    out = np.zeros((nv, 4))
    zsum, wsum = 0.0, 0.0
    for v in range(nv):
        # the camera point, its pixel and its depth in front of the camera (in scalars: a
        # small array a vertex cost more than the rest of the loop)
        x0, x1, x2 = shape[v, 0], shape[v, 1], shape[v, 2]
        pc0 = rot[0, 0] * x0 + rot[0, 1] * x1 + rot[0, 2] * x2 + trans[0]
        pc1 = rot[1, 0] * x0 + rot[1, 1] * x1 + rot[1, 2] * x2 + trans[1]
        pc2 = rot[2, 0] * x0 + rot[2, 1] * x1 + rot[2, 2] * x2 + trans[2]
        d = max(-pc2, 1e-6)
        ru = (cx + f * pc0 / d - p[v, 0]) * kxy
        rv = (cy - f * pc1 / d - p[v, 1]) * kxy
        out[v, 0], out[v, 1] = ru, rv
        out[v, 3] = np.sqrt(ru * ru + rv * rv)
        if use_z:
            dz = -pc2 - k * p[v, 2]
            out[v, 2] = dz
            zsum += w0[v] * dz
            wsum += w0[v]
    if use_z:
        m = zsum / wsum
        for v in range(nv):
            out[v, 2] = (out[v, 2] - m) * inv_ds
    return out


@njit(cache=True, nogil=True)
def landmark_cost(rot, trans, shape, f, cx, cy, p, use_z, w0, mxy, kxy, inv_ds, k, huber):
    """Huber loss of the weighted 2-D residuals (each vertex's weighed ``w0 mxy``) plus the
    depth residuals under the Huber weights (weighed ``w0``): the landmark term's cost."""
    t = landmark_terms(rot, trans, shape, f, cx, cy, p, use_z, w0, kxy, inv_ds, k, huber)
    cost = 0.0
    for v in range(shape.shape[0]):
        r = t[v, 3]
        if r <= huber:
            cost += w0[v] * mxy[v] * r * r
            hw = 1.0
        else:
            cost += w0[v] * mxy[v] * (2.0 * huber * r - huber * huber)
            hw = huber / max(r, 1e-12)
        cost += w0[v] * hw * t[v, 2] * t[v, 2]
    return cost


@njit(cache=True, nogil=True)
def normal_equations(
    rot, trans, shape, dsdc, free, f, cx, cy, p, use_z, w0, mxy, kxy, inv_ds, k, huber
):
    """(H, b): ``J^T J`` and ``-J^T r`` of the landmark rows (Huber-reweighted ``w0``; the 2-D
    rows also times ``mxy``) in the unknowns (omega (3), dt (3), dc[free]).

    The weighted rows are made vertex by vertex into ``J^T`` (unknowns x rows, so that each
    product of two unknowns' columns is one contiguous dot product, :func:`_gram`): the
    depth rows' weighted mean is removed from them first (``sum_v w_v (z_v - zbar)(z_v -
    zbar)^T`` is the Gram matrix of ``sqrt(w_v) (z_v - zbar)``). Rows that weigh nothing
    are left out of ``J^T`` (they add nothing to either sum): with the optical flow's term
    (:class:`~myoface.analysis.terms.OpticalFlowTerm`) the landmarks' x, y rows of the
    tracked vertices and the flow's of the others, a third of the rows the two terms make."""
    nv = shape.shape[0]
    nf = free.shape[0]
    n = 6 + nf
    t = landmark_terms(rot, trans, shape, f, cx, cy, p, use_z, w0, kxy, inv_ds, k, huber)
    w = np.empty(nv)
    wsum = 0.0
    nxy, nz = 0, 0
    for v in range(nv):
        r = t[v, 3]
        w[v] = w0[v] * (huber / max(r, 1e-12) if r > huber else 1.0)
        wsum += w[v]
        if w[v] * mxy[v] > 0.0:
            nxy += 1
        if use_z and w[v] > 0.0:
            nz += 1
    nrow = 2 * nxy + nz
    jt = np.zeros((n, nrow))  # the weighted rows, transposed: u (nxy), v (nxy), z (nz)
    rw = np.empty(nrow)  # ... and their weighted residuals
    zsw = np.empty(nz)  # the square root of each depth row's weight
    zmean = np.zeros(n)
    g = np.empty((3, 3))  # per vertex, d(u, v, z-row)/dP
    cols = np.empty(3, dtype=np.int64)
    ixy, iz = 0, 0
    for v in range(nv):
        use_xy = w[v] * mxy[v] > 0.0
        use_zv = use_z and w[v] > 0.0
        if not (use_xy or use_zv):
            continue
        y0 = rot[0, 0] * shape[v, 0] + rot[0, 1] * shape[v, 1] + rot[0, 2] * shape[v, 2]
        y1 = rot[1, 0] * shape[v, 0] + rot[1, 1] * shape[v, 1] + rot[1, 2] * shape[v, 2]
        y2 = rot[2, 0] * shape[v, 0] + rot[2, 1] * shape[v, 1] + rot[2, 2] * shape[v, 2]
        pc0, pc1, pc2 = y0 + trans[0], y1 + trans[1], y2 + trans[2]
        d = max(-pc2, 1e-6)
        sw = np.sqrt(w[v])
        sxy = sw * np.sqrt(mxy[v])  # (the 2-D rows' own weight: 0 where another term reads x, y)
        s = kxy * sxy
        # rows u, v: (a00, 0, a02) and (0, a11, a12) . dP; z: -dP_z / sd (unweighted: the
        # mean is removed below, then weighted)
        g[0, 0], g[0, 1], g[0, 2] = f / d * s, 0.0, f * pc0 / (d * d) * s
        g[1, 0], g[1, 1], g[1, 2] = 0.0, -f / d * s, -f * pc1 / (d * d) * s
        g[2, 0], g[2, 1], g[2, 2] = 0.0, 0.0, -inv_ds
        nq = 0
        q0 = 0 if use_xy else 2
        if use_xy:
            cols[0], cols[1] = ixy, nxy + ixy
            rw[ixy] = t[v, 0] * sxy
            rw[nxy + ixy] = t[v, 1] * sxy
            ixy += 1
            nq = 2
        if use_zv:
            cols[nq] = 2 * nxy + iz
            zsw[iz] = sw
            rw[2 * nxy + iz] = t[v, 2] * sw
            iz += 1
            nq += 1
        for qi in range(nq):
            q = q0 + qi
            col = cols[qi]
            # dP/d(omega) = -[y]x, dP/d(dt) = I, dP/d(dc) = R dshape/dc
            jt[0, col] = -g[q, 1] * y2 + g[q, 2] * y1
            jt[1, col] = g[q, 0] * y2 - g[q, 2] * y0
            jt[2, col] = -g[q, 0] * y1 + g[q, 1] * y0
            jt[3, col] = g[q, 0]
            jt[4, col] = g[q, 1]
            jt[5, col] = g[q, 2]
            # (g R) . dshape/dc
            e0 = g[q, 0] * rot[0, 0] + g[q, 1] * rot[1, 0] + g[q, 2] * rot[2, 0]
            e1 = g[q, 0] * rot[0, 1] + g[q, 1] * rot[1, 1] + g[q, 2] * rot[2, 1]
            e2 = g[q, 0] * rot[0, 2] + g[q, 1] * rot[1, 2] + g[q, 2] * rot[2, 2]
            for j in range(nf):
                m = free[j]
                jt[6 + j, col] = e0 * dsdc[v, 0, m] + e1 * dsdc[v, 1, m] + e2 * dsdc[v, 2, m]
            if q == 2:
                for j in range(n):
                    zmean[j] += w[v] * jt[j, col]
    if nz > 0:
        for j in range(n):
            zm = zmean[j] / wsum
            for i in range(nz):
                col = 2 * nxy + i
                jt[j, col] = (jt[j, col] - zm) * zsw[i]
    return _gram(jt, rw)


@njit(cache=True, nogil=True, fastmath=True)
def _gram(jt, r):
    """``(jt jt^T, -jt r)`` for ``jt`` (n, R): dot products of contiguous rows (vectorised:
    the order of the sums is the compiler's; :func:`cross_gram`)."""
    n, nr = jt.shape
    b = np.empty(n)
    for i in range(n):
        acc = 0.0
        for q in range(nr):
            acc += jt[i, q] * r[q]
        b[i] = -acc
    return cross_gram(jt, jt), b


@njit(cache=True, nogil=True, fastmath=True)
def cross_gram(at, bt):
    """The symmetric ``at bt^T`` (n, n) of ``at``, ``bt`` (n, R) whose product is symmetric
    (``jt jt^T``; the photometric term's ``D^T (K D)``): its upper triangle, four rows by four
    (each pair of loads feeds 16 products, where a dot product at a time loads two numbers
    for each: 3-4x faster on 45 x 1404), mirrored."""
    n, nr = at.shape
    h = np.empty((n, n))
    for i in range(0, n, 4):
        for j in range(i, n, 4):
            i1, j1 = min(i + 4, n), min(j + 4, n)
            if i1 - i == 4 and j1 - j == 4:
                a00, a01, a02, a03 = 0.0, 0.0, 0.0, 0.0
                a10, a11, a12, a13 = 0.0, 0.0, 0.0, 0.0
                a20, a21, a22, a23 = 0.0, 0.0, 0.0, 0.0
                a30, a31, a32, a33 = 0.0, 0.0, 0.0, 0.0
                for q in range(nr):
                    x0, x1, x2, x3 = at[i, q], at[i + 1, q], at[i + 2, q], at[i + 3, q]
                    y0, y1, y2, y3 = bt[j, q], bt[j + 1, q], bt[j + 2, q], bt[j + 3, q]
                    a00 += x0 * y0
                    a01 += x0 * y1
                    a02 += x0 * y2
                    a03 += x0 * y3
                    a10 += x1 * y0
                    a11 += x1 * y1
                    a12 += x1 * y2
                    a13 += x1 * y3
                    a20 += x2 * y0
                    a21 += x2 * y1
                    a22 += x2 * y2
                    a23 += x2 * y3
                    a30 += x3 * y0
                    a31 += x3 * y1
                    a32 += x3 * y2
                    a33 += x3 * y3
                h[i, j], h[i, j + 1], h[i, j + 2], h[i, j + 3] = a00, a01, a02, a03
                h[i + 1, j], h[i + 1, j + 1], h[i + 1, j + 2], h[i + 1, j + 3] = a10, a11, a12, a13
                h[i + 2, j], h[i + 2, j + 1], h[i + 2, j + 2], h[i + 2, j + 3] = a20, a21, a22, a23
                h[i + 3, j], h[i + 3, j + 1], h[i + 3, j + 2], h[i + 3, j + 3] = a30, a31, a32, a33
            else:  # (the last rows, fewer than four)
                for ii in range(i, i1):
                    for jj in range(j, j1):
                        acc = 0.0
                        for q in range(nr):
                            acc += at[ii, q] * bt[jj, q]
                        h[ii, jj] = acc
    for i in range(n):  # (the upper triangle, mirrored)
        for j in range(i + 1, n):
            h[j, i] = h[i, j]
    return h


@njit(cache=True, nogil=True)
def _solve_free(h, g, free_mask):
    """``-h[F, F]^-1 g[F]`` on the free set F (zeros elsewhere), by Cholesky."""
    n = h.shape[0]
    idx = np.empty(n, dtype=np.int64)
    m = 0
    for i in range(n):
        if free_mask[i]:
            idx[m] = i
            m += 1
    a = np.empty((m, m))
    r = np.empty(m)
    for i in range(m):
        r[i] = -g[idx[i]]
        for j in range(m):
            a[i, j] = h[idx[i], idx[j]]
    step = np.zeros(n)
    if m == 0:
        return step
    x = np.linalg.solve(a, r)
    for i in range(m):
        step[idx[i]] = x[i]
    return step


@njit(cache=True, nogil=True)
def box_qp(h, rhs, lo, hi):
    """``argmin x^T h x / 2 - rhs . x`` subject to ``lo <= x <= hi`` (``h`` symmetric
    positive definite, ``lo <= 0 <= hi``): the primal active-set method (Nocedal & Wright 2006,
    Algorithm 16.3) from ``x = 0``, exact in finitely many steps."""
    n = h.shape[0]
    x = np.zeros(n)
    at_lo = np.zeros(n, dtype=np.bool_)
    at_hi = np.zeros(n, dtype=np.bool_)
    free_mask = np.ones(n, dtype=np.bool_)
    for i in range(n):  # bounds that are zero are active from the start if they bind
        if lo[i] == 0.0 or hi[i] == 0.0:
            g0 = -rhs[i]
            if lo[i] == 0.0 and g0 > 0.0:
                at_lo[i], free_mask[i] = True, False
            elif hi[i] == 0.0 and g0 < 0.0:
                at_hi[i], free_mask[i] = True, False
    tol = 1e-12 * (1.0 + np.abs(rhs).max())  # a multiplier within rounding of 0 is 0
    for _ in range(10 * n + 20):
        g = h @ x - rhs
        step = _solve_free(h, g, free_mask)
        alpha, block, to_hi = 1.0, -1, False
        for i in range(n):
            if not free_mask[i]:
                continue
            if step[i] < 0.0 and x[i] + step[i] < lo[i]:
                a = (lo[i] - x[i]) / step[i]
                if a < alpha:
                    alpha, block, to_hi = a, i, False
            elif step[i] > 0.0 and x[i] + step[i] > hi[i]:
                a = (hi[i] - x[i]) / step[i]
                if a < alpha:
                    alpha, block, to_hi = a, i, True
        for i in range(n):
            x[i] += alpha * step[i]
        if block >= 0:  # a bound blocks the step: it joins the active set
            free_mask[block] = False
            if to_hi:
                at_hi[block], x[block] = True, hi[block]
            else:
                at_lo[block], x[block] = True, lo[block]
            continue
        # the minimum on this face: release the bound whose multiplier has the wrong sign
        g = h @ x - rhs
        worst, which = -tol, -1
        for i in range(n):
            if at_lo[i] and g[i] < worst:
                worst, which = g[i], i
            elif at_hi[i] and -g[i] < worst:
                worst, which = -g[i], i
        if which < 0:
            return x
        at_lo[which] = at_hi[which] = False
        free_mask[which] = True
    return x


@njit(cache=True, nogil=True)
def vertex_normals(vertices, triangles):
    """:func:`myoface.face.mesh.vertex_normals` compiled (its ``np.add.at`` costs more than a
    Gauss-Newton step): area-weighted unit vertex normals (V, 3); (0, 0, 1) for a vertex in no
    triangle."""
    nv = vertices.shape[0]
    vn = np.zeros((nv, 3))
    for t in range(triangles.shape[0]):
        a, b, c = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        e1x = vertices[b, 0] - vertices[a, 0]
        e1y = vertices[b, 1] - vertices[a, 1]
        e1z = vertices[b, 2] - vertices[a, 2]
        e2x = vertices[c, 0] - vertices[a, 0]
        e2y = vertices[c, 1] - vertices[a, 1]
        e2z = vertices[c, 2] - vertices[a, 2]
        nx = e1y * e2z - e1z * e2y
        ny = e1z * e2x - e1x * e2z
        nz = e1x * e2y - e1y * e2x
        for v in (a, b, c):
            vn[v, 0] += nx
            vn[v, 1] += ny
            vn[v, 2] += nz
    for v in range(nv):
        norm = np.sqrt(vn[v, 0] ** 2 + vn[v, 1] ** 2 + vn[v, 2] ** 2)
        if norm > 0:
            for i in range(3):
                vn[v, i] /= max(norm, 1e-300)
        else:
            vn[v, 0], vn[v, 1], vn[v, 2] = 0.0, 0.0, 1.0
    return vn


@njit(cache=True, nogil=True)
def nearest_triangles(pix, order, i0, i1, a, b, c, lo, hi, tri_depth):
    """For each pixel of ``pix`` (N, 2) the nearest triangle over it (:func:`~myoface.analysis.
    terms.patch_footprint`'s rasterisation): ``(owner (N,), bary (N, 3))``, owner -1 where no
    triangle covers the pixel. The triangles' corners ``a``, ``b``, ``c`` (T, 2) px, their
    boxes ``lo``, ``hi`` (T, 2), the depths of their corners ``tri_depth`` (T, 3); ``order``
    sorts the pixels by x, and ``order[i0[t]:i1[t]]`` are those within triangle ``t``'s x range.
    Ties in depth keep the earlier triangle (as a ``<`` test in triangle order does)."""
    n = pix.shape[0]
    owner = np.full(n, -1, dtype=np.int64)
    best = np.full(n, np.inf)
    bary = np.zeros((n, 3))
    for t in range(a.shape[0]):
        if i1[t] <= i0[t]:
            continue
        e1x, e1y = b[t, 0] - a[t, 0], b[t, 1] - a[t, 1]
        e2x, e2y = c[t, 0] - a[t, 0], c[t, 1] - a[t, 1]
        den = e1x * e2y - e1y * e2x
        if abs(den) < 1e-9:
            continue
        for j in range(i0[t], i1[t]):
            i = order[j]
            y = pix[i, 1]
            if y < lo[t, 1] or y > hi[t, 1]:
                continue
            qx, qy = pix[i, 0] - a[t, 0], y - a[t, 1]
            l1 = (qx * e2y - qy * e2x) / den
            l2 = (e1x * qy - e1y * qx) / den
            l0 = 1.0 - l1 - l2
            if l0 < -1e-9 or l1 < -1e-9 or l2 < -1e-9:
                continue
            z = l0 * tri_depth[t, 0] + l1 * tri_depth[t, 1] + l2 * tri_depth[t, 2]
            if z < best[i]:
                owner[i] = t
                best[i] = z
                bary[i, 0] = l0
                bary[i, 1] = l1
                bary[i, 2] = l2
    return owner, bary
