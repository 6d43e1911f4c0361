"""Compiled inner loops of the 3-D fit (:mod:`myoface.analysis.fit`): the normal equations of
the weighted landmark residuals, the landmark cost, and the small box-constrained quadratic
programme each Levenberg-Marquardt step solves.

They compute what :meth:`ModelFit._residuals`, :meth:`ModelFit._jacobians` and
:func:`myoface.analysis.fit._bounded_normal` define (those stay as the readable reference the
tests compare against), without forming the (2-3 V) x (6 + K) Jacobian: each vertex's rows
are accumulated into the normal matrix as they are made. ``nogil``: a frame can be fitted
while another thread runs the face detector on the next one.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _point(rot, trans, x, f, cx, cy):
    """Camera point (3,), its pixel (2,) and the depth in front of the camera."""
    pc = np.empty(3)
    for i in range(3):
        pc[i] = rot[i, 0] * x[0] + rot[i, 1] * x[1] + rot[i, 2] * x[2] + trans[i]
    d = max(-pc[2], 1e-6)
    return pc, cx + f * pc[0] / d, cy - f * pc[1] / d, d


@njit(cache=True, nogil=True)
def landmark_terms(rot, trans, shape, f, cx, cy, p, use_z, w0, kxy, inv_ds, k, huber):
    """Per vertex: the weighted residuals' pieces (V, 4): ru, rv (in sigmas), rz (in sigmas,
    its ``w0``-weighted mean removed), and the 2-D distance in sigmas."""
    nv = shape.shape[0]
    out = np.zeros((nv, 4))
    zsum, wsum = 0.0, 0.0
    for v in range(nv):
        pc, u, vv, _ = _point(rot, trans, shape[v], f, cx, cy)
        ru = (u - p[v, 0]) * kxy
        rv = (vv - p[v, 1]) * kxy
        out[v, 0], out[v, 1] = ru, rv
        out[v, 3] = np.sqrt(ru * ru + rv * rv)
        if use_z:
            dz = -pc[2] - k * p[v, 2]
            out[v, 2] = dz
            zsum += w0[v] * dz
            wsum += w0[v]
    if use_z:
        m = zsum / wsum
        for v in range(nv):
            out[v, 2] = (out[v, 2] - m) * inv_ds
    return out


@njit(cache=True, nogil=True)
def landmark_cost(rot, trans, shape, f, cx, cy, p, use_z, w0, kxy, inv_ds, k, huber):
    """Huber loss of the weighted 2-D residuals plus the depth residuals under the Huber
    weights (the landmark part of :meth:`ModelFit._cost`)."""
    t = landmark_terms(rot, trans, shape, f, cx, cy, p, use_z, w0, kxy, inv_ds, k, huber)
    cost = 0.0
    for v in range(shape.shape[0]):
        r = t[v, 3]
        if r <= huber:
            cost += w0[v] * r * r
            hw = 1.0
        else:
            cost += w0[v] * (2.0 * huber * r - huber * huber)
            hw = huber / max(r, 1e-12)
        cost += w0[v] * hw * t[v, 2] * t[v, 2]
    return cost


@njit(cache=True, nogil=True)
def normal_equations(rot, trans, shape, dsdc, free, f, cx, cy, p, use_z, w0, kxy, inv_ds, k, huber):
    """(H, b): ``J^T J`` and ``-J^T r`` of the landmark rows (Huber-reweighted ``w0``) in the
    unknowns (omega (3), dt (3), dc[free]) — the products :meth:`ModelFit._jacobians` and the
    residuals of :meth:`ModelFit._residuals` make."""
    nv = shape.shape[0]
    nf = free.shape[0]
    n = 6 + nf
    t = landmark_terms(rot, trans, shape, f, cx, cy, p, use_z, w0, kxy, inv_ds, k, huber)
    w = np.empty(nv)
    for v in range(nv):
        r = t[v, 3]
        w[v] = w0[v] * (huber / max(r, 1e-12) if r > huber else 1.0)
    h = np.zeros((n, n))
    b = np.zeros(n)
    dp = np.zeros((3, n))
    ju = np.zeros(n)
    jv = np.zeros(n)
    zmean = np.zeros(n)
    wsum = 0.0
    zrow = np.zeros((nv, n)) if use_z else np.zeros((0, n))
    for v in range(nv):
        y = np.empty(3)
        for i in range(3):
            y[i] = rot[i, 0] * shape[v, 0] + rot[i, 1] * shape[v, 1] + rot[i, 2] * shape[v, 2]
        pc0, pc1, pc2 = y[0] + trans[0], y[1] + trans[1], y[2] + trans[2]
        d = max(-pc2, 1e-6)
        # dP/dx: omega -> -[y]x, dt -> I, dc -> R dshape/dc
        dp[:, :] = 0.0
        dp[0, 1], dp[0, 2] = y[2], -y[1]
        dp[1, 0], dp[1, 2] = -y[2], y[0]
        dp[2, 0], dp[2, 1] = y[1], -y[0]
        dp[0, 3] = dp[1, 4] = dp[2, 5] = 1.0
        for j in range(nf):
            m = free[j]
            for i in range(3):
                dp[i, 6 + j] = (
                    rot[i, 0] * dsdc[v, 0, m]
                    + rot[i, 1] * dsdc[v, 1, m]
                    + rot[i, 2] * dsdc[v, 2, m]
                )
        sw = np.sqrt(w[v])
        a00, a02 = f / d, f * pc0 / (d * d)
        a11, a12 = -f / d, -f * pc1 / (d * d)
        s = kxy * sw
        for j in range(n):
            ju[j] = (a00 * dp[0, j] + a02 * dp[2, j]) * s
            jv[j] = (a11 * dp[1, j] + a12 * dp[2, j]) * s
        bu, bv = -t[v, 0] * sw, -t[v, 1] * sw
        for i in range(n):
            b[i] += ju[i] * bu + jv[i] * bv
            for j in range(i, n):
                h[i, j] += ju[i] * ju[j] + jv[i] * jv[j]
        if use_z:
            for j in range(n):
                zrow[v, j] = -dp[2, j] * inv_ds
                zmean[j] += w[v] * zrow[v, j]
            wsum += w[v]
    if use_z:
        for j in range(n):
            zmean[j] /= wsum
        for v in range(nv):
            rz = t[v, 2]
            for i in range(n):
                zi = zrow[v, i] - zmean[i]
                b[i] -= w[v] * zi * rz
                for j in range(i, n):
                    h[i, j] += w[v] * zi * (zrow[v, j] - zmean[j])
    for i in range(n):
        for j in range(i):
            h[i, j] = h[j, i]
    return h, b


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
