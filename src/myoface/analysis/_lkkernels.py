"""Compiled inner loops of the model-anchored point tracker (:mod:`myoface.analysis.modelflow`):
each point's template taken from the calibration frame through a 2x2 warp, then aligned to the
current frame by translation-only Lucas-Kanade (inverse compositional, the brightness'
gain and offset in the patch taken out, Huber-weighted), coarse to fine; and each vertex's
local affine map between two projections of the face's mesh.

Images are image pyramids packed into one flat float32 array (level ``l`` at ``offsets[l]``,
``shapes[l]`` rows and columns; level ``l`` is the image reduced ``2**l`` times by
``cv2.pyrDown``, so a point ``p`` of level 0 is at ``p / 2**l`` there). ``nogil``: MediaPipe
runs on another thread meanwhile.
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: a track's status (:func:`track_points`)
OK, OUTSIDE, FLAT, SKIPPED = 0, 1, 2, 3


@njit(cache=True, nogil=True)
def _sample(flat, off, rows, cols, x, y):
    """Bilinear sample of a packed level at (x, y) (column, row); NaN outside."""
    if not (x >= 0.0 and y >= 0.0 and x <= cols - 1.001 and y <= rows - 1.001):
        return np.nan
    ix = int(x)
    iy = int(y)
    fx = x - ix
    fy = y - iy
    i = off + iy * cols + ix
    a = flat[i] + fx * (flat[i + 1] - flat[i])
    b = flat[i + cols] + fx * (flat[i + cols + 1] - flat[i + cols])
    return a + fy * (b - a)


@njit(cache=True, nogil=True)
def _patch(flat, mask, off, rows, cols, x0, y0, w, masked, tw, patch, pw):
    """The w x w patch of a packed level whose first pixel is at (x0, y0) (a translation: one
    set of bilinear weights for every pixel) into ``patch``, and each pixel's weight into
    ``pw``: ``tw``'s, 0 where ``mask`` is above 0.5 (looked up only when ``masked``). False
    when the patch leaves the level."""
    if not (x0 >= 0.0 and y0 >= 0.0 and x0 + w - 1 <= cols - 1.001 and y0 + w - 1 <= rows - 1.001):
        return False
    ix = int(x0)
    iy = int(y0)
    fx = x0 - ix
    fy = y0 - iy
    w00 = (1 - fx) * (1 - fy)
    w01 = fx * (1 - fy)
    w10 = (1 - fx) * fy
    w11 = fx * fy
    for v in range(w):
        i = off + (iy + v) * cols + ix
        for u in range(w):
            j = i + u
            patch[v, u] = (
                w00 * flat[j] + w01 * flat[j + 1] + w10 * flat[j + cols] + w11 * flat[j + cols + 1]
            )
            pw[v, u] = tw[v, u]
            if masked:
                mk = (
                    w00 * mask[j]
                    + w01 * mask[j + 1]
                    + w10 * mask[j + cols]
                    + w11 * mask[j + cols + 1]
                )
                if mk > 0.5:
                    pw[v, u] = 0.0
    return True


@njit(cache=True, nogil=True)
def _correlate(cur, cur_mask, cur_off, cur_shape, qx, qy, half, w, masked, tw, tpl, patch, pw):
    """The patch of the finest level at (qx, qy) against the template ``tpl`` (its inner w x
    w): (status, normalised cross-correlation, the template's weighted variance); status
    OUTSIDE where the patch leaves the level, FLAT where under half its pixels carry weight."""
    pn, pm, tm = 0.0, 0.0, 0.0
    bad = not _patch(cur, cur_mask, cur_off[0], cur_shape[0, 0], cur_shape[0, 1],
                     qx - half, qy - half, w, masked, tw, patch, pw)  # fmt: skip
    if not bad:
        for v in range(w):
            for u in range(w):
                pn += pw[v, u]
                pm += pw[v, u] * patch[v, u]
                tm += pw[v, u] * tpl[v + 1, u + 1]
    if bad or pn < 0.5 * w * w:
        return (OUTSIDE if bad else FLAT), 0.0, 0.0
    pm /= pn
    tm /= pn
    spt, spp, stt = 0.0, 0.0, 0.0
    for v in range(w):
        for u in range(w):
            a = patch[v, u] - pm
            b = tpl[v + 1, u + 1] - tm
            spt += pw[v, u] * a * b
            spp += pw[v, u] * a * a
            stt += pw[v, u] * b * b
    return OK, spt / max(np.sqrt(spp * stt), 1e-12), stt / pn


@njit(cache=True, nogil=True)
def track_points_reference(ref, ref_mask, ref_off, ref_shape, cur, cur_mask, cur_off, cur_shape, ref_xy,
                 guess, ainv, active, masked, half, iterations, huber, eps):  # fmt: skip
    """Track points from a reference image's pyramid into the current image's.

    Point ``i`` (``active[i]``) is the reference image's patch around ``ref_xy[i]`` seen
    through the 2x2 map ``ainv[i]`` (a pixel offset ``x`` in the current image is
    ``ainv[i] @ x`` in the reference's), a square of ``2 half + 1`` pixels a side at every
    level; it is looked for in the current image from ``guess[i]``, coarse to fine, by
    translation-only Lucas-Kanade: the template's gradient fixed (inverse compositional), the
    current patch's mean and contrast matched to the template's at each iteration, Huber's
    weights beyond ``huber`` times the residuals' mean absolute value, at most ``iterations``
    steps a level, stopping when a step is under ``eps`` px (of that level). ``ref_mask`` and
    ``cur_mask`` (packed as the images): a pixel where either is above 0.5 (e.g. the mouth's
    gap) weighs nothing, for the points ``masked`` (N,) bool (the others' patches are not
    near the mask: not looked up).

    Returns ``xy`` (N, 2) where each point was found (the guess where it was not), ``ncc``
    (N,) the normalised cross-correlation of the template and the patch found (level 0, the
    unmasked pixels), ``contrast`` (N,) the template's variance over those pixels (grey
    levels squared, level 0),
    ``step`` (N,) the last step's length (px, level 0), and ``status`` (N,): :data:`OK`,
    :data:`OUTSIDE` (the patch left an image), :data:`FLAT` (no gradient to align, or too
    few pixels unmasked) or :data:`SKIPPED` (not active)."""
    n = ref_xy.shape[0]
    levels = ref_off.shape[0]
    w = 2 * half + 1
    xy = guess.copy()
    ncc = np.zeros(n)
    contrast = np.zeros(n)
    step = np.full(n, np.inf)
    status = np.full(n, SKIPPED, dtype=np.int64)
    tpl = np.empty((w + 2, w + 2))
    tw = np.empty((w, w))  # the template's pixels' weights (its mask)
    pw = np.empty((w, w))  # ... times the current patch's
    gx = np.empty((w, w))
    gy = np.empty((w, w))
    patch = np.empty((w, w))
    for i in range(n):
        if not active[i]:
            continue
        status[i] = OK
        qx = guess[i, 0]
        qy = guess[i, 1]
        a00, a01 = ainv[i, 0, 0], ainv[i, 0, 1]
        a10, a11 = ainv[i, 1, 0], ainv[i, 1, 1]
        for lev in range(levels - 1, -1, -1):
            s = 1.0 / (1 << lev)
            roff, rr, rc = ref_off[lev], ref_shape[lev, 0], ref_shape[lev, 1]
            coff, cr, cc = cur_off[lev], cur_shape[lev, 0], cur_shape[lev, 1]
            # the template, one pixel wider for its central differences
            cxr = ref_xy[i, 0] * s
            cyr = ref_xy[i, 1] * s
            bad = False
            for v in range(w + 2):
                dy = v - half - 1.0
                for u in range(w + 2):
                    dx = u - half - 1.0
                    x = cxr + a00 * dx + a01 * dy
                    y = cyr + a10 * dx + a11 * dy
                    val = _sample(ref, roff, rr, rc, x, y)
                    if np.isnan(val):
                        bad = True
                        break
                    tpl[v, u] = val
                    if 0 < v <= w and 0 < u <= w:
                        mk = _sample(ref_mask, roff, rr, rc, x, y) if masked[i] else 0.0
                        tw[v - 1, u - 1] = 1.0 if mk <= 0.5 else 0.0
                if bad:
                    break
            if bad:
                status[i] = OUTSIDE
                break
            tn, tmean = 0.0, 0.0
            for v in range(w):
                for u in range(w):
                    tn += tw[v, u]
                    tmean += tw[v, u] * tpl[v + 1, u + 1]
            if tn < 0.5 * w * w:
                status[i] = FLAT
                break
            tmean /= tn
            sxx, sxy, syy = 0.0, 0.0, 0.0
            for v in range(w):
                for u in range(w):
                    gx[v, u] = 0.5 * (tpl[v + 1, u + 2] - tpl[v + 1, u])
                    gy[v, u] = 0.5 * (tpl[v + 2, u + 1] - tpl[v, u + 1])
                    sxx += tw[v, u] * gx[v, u] * gx[v, u]
                    sxy += tw[v, u] * gx[v, u] * gy[v, u]
                    syy += tw[v, u] * gy[v, u] * gy[v, u]
            tr = 0.5 * (sxx + syy)
            mineig = tr - np.sqrt(max(tr * tr - (sxx * syy - sxy * sxy), 0.0))
            if mineig <= 1e-9:
                status[i] = FLAT
                break
            lx = qx * s
            ly = qy * s
            scale = -1.0  # the residuals' mean absolute value (Huber's scale)
            last = np.inf
            for _ in range(iterations):
                if not _patch(cur, cur_mask, coff, cr, cc, lx - half, ly - half, w,
                              masked[i], tw, patch, pw):  # fmt: skip
                    bad = True
                    break
                pn, pmean = 0.0, 0.0
                for v in range(w):
                    for u in range(w):
                        pn += pw[v, u]
                        pmean += pw[v, u] * patch[v, u]
                if pn < 0.5 * w * w:
                    bad = True
                    break
                pmean /= pn
                tm2 = 0.0
                for v in range(w):
                    for u in range(w):
                        tm2 += pw[v, u] * tpl[v + 1, u + 1]
                tm2 /= pn
                pvar, tvar = 0.0, 0.0
                for v in range(w):
                    for u in range(w):
                        d = patch[v, u] - pmean
                        pvar += pw[v, u] * d * d
                        d = tpl[v + 1, u + 1] - tm2
                        tvar += pw[v, u] * d * d
                gain = np.sqrt(tvar / max(pvar, 1e-9))
                h00, h01, h11, b0, b1, mabs = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
                for v in range(w):
                    for u in range(w):
                        if pw[v, u] == 0.0:
                            continue
                        e = (patch[v, u] - pmean) * gain - (tpl[v + 1, u + 1] - tm2)
                        ae = abs(e)
                        mabs += ae
                        wt = 1.0
                        if scale > 0.0 and ae > huber * scale:
                            wt = huber * scale / ae
                        h00 += wt * gx[v, u] * gx[v, u]
                        h01 += wt * gx[v, u] * gy[v, u]
                        h11 += wt * gy[v, u] * gy[v, u]
                        b0 += wt * gx[v, u] * e
                        b1 += wt * gy[v, u] * e
                scale = mabs / pn
                det = h00 * h11 - h01 * h01
                if det <= 1e-12:
                    bad = True
                    break
                ddx = (h11 * b0 - h01 * b1) / det
                ddy = (h00 * b1 - h01 * b0) / det
                lx -= ddx
                ly -= ddy
                last = np.sqrt(ddx * ddx + ddy * ddy)
                if last < eps:
                    break
            if bad:
                status[i] = OUTSIDE
                break
            qx = lx / s
            qy = ly / s
            if lev == 0:
                step[i] = last
        if status[i] != OK:
            continue
        # the normalised cross-correlation of the template and the patch found
        found = _correlate(cur, cur_mask, cur_off, cur_shape, qx, qy, half, w, masked[i], tw,
                           tpl, patch, pw)  # fmt: skip
        if found[0] != OK:
            status[i] = found[0]
            xy[i, 0] = guess[i, 0]
            xy[i, 1] = guess[i, 1]
            continue
        xy[i, 0] = qx
        xy[i, 1] = qy
        ncc[i] = found[1]
        contrast[i] = found[2]
    return xy, ncc, contrast, step, status


@njit(cache=True, nogil=True, fastmath=True)
def _template(ref, ref_mask, roff, rr, rc, cx, cy, a00, a01, a10, a11, half, masked, tpl, tw):
    """The template around (cx, cy) of a packed level seen through the 2x2 map ``a``: its
    ``(w + 2)**2`` pixels (one wider for the central differences) into ``tpl``, the inner
    ones' weights into ``tw`` (0 where ``ref_mask`` is above 0.5, looked up only when
    ``masked``). False when it leaves the level. The map is applied incrementally (one
    multiply-add a pixel)."""
    w = 2 * half + 1
    lo_x = -half - 1.0
    for v in range(w + 2):
        dy = v - half - 1.0
        x = cx + a00 * lo_x + a01 * dy
        y = cy + a10 * lo_x + a11 * dy
        for u in range(w + 2):
            if not (x >= 0.0 and y >= 0.0 and x <= rc - 1.001 and y <= rr - 1.001):
                return False
            ix = int(x)
            iy = int(y)
            fx = x - ix
            fy = y - iy
            i = roff + iy * rc + ix
            a = ref[i] + fx * (ref[i + 1] - ref[i])
            b = ref[i + rc] + fx * (ref[i + rc + 1] - ref[i + rc])
            tpl[v, u] = a + fy * (b - a)
            if 0 < v <= w and 0 < u <= w:
                mk = 0.0
                if masked:
                    a = ref_mask[i] + fx * (ref_mask[i + 1] - ref_mask[i])
                    b = ref_mask[i + rc] + fx * (ref_mask[i + rc + 1] - ref_mask[i + rc])
                    mk = a + fy * (b - a)
                tw[v - 1, u - 1] = 1.0 if mk <= 0.5 else 0.0
            x += a00
            y += a10
    return True


@njit(cache=True, nogil=True, fastmath=True)
def track_points(ref, ref_mask, ref_off, ref_shape, cur, cur_mask, cur_off, cur_shape, ref_xy,
                 guess, ainv, active, masked, half, iterations, huber, eps, coarse_eps):  # fmt: skip
    """:func:`track_points_reference`'s alignment (its arguments, then ``coarse_eps``: the
    step under which the levels above the image stop, px of that level, where the image's
    stops at ``eps``; its returns, then an ``(N,)`` count of the Lucas-Kanade steps taken
    over the levels), computed with fewer passes over each patch: a patch without masked
    pixels (the points not ``masked``: nearly all) has the template's weights, mean and
    contrast fixed at each level, so an iteration samples the current patch once (its sums
    and sums of squares on the way) and makes one pass for the residuals, Huber's weights
    and the normal equations, where the reference makes five; a masked patch gets its
    weights and both patches' sums in one pass, then the residuals. With ``coarse_eps`` =
    ``eps`` the reference's result to rounding (tests/analysis/test_modelflow.py; on the
    sample video's frames within 1e-10 px, 0.69x its CPU)."""
    n = ref_xy.shape[0]
    levels = ref_off.shape[0]
    w = 2 * half + 1
    ww = float(w * w)
    xy = guess.copy()
    ncc = np.zeros(n)
    contrast = np.zeros(n)
    step = np.full(n, np.inf)
    status = np.full(n, SKIPPED, dtype=np.int64)
    steps = np.zeros(n, dtype=np.int64)
    tpl = np.empty((w + 2, w + 2))
    tw = np.empty((w, w))
    pw = np.empty((w, w))
    gx = np.empty((w, w))
    gy = np.empty((w, w))
    td = np.empty((w, w))  # the template less its mean (unmasked patches)
    patch = np.empty((w, w))
    nw = w * w
    pf = np.empty(nw)  # the current patch, flat (unmasked patches)
    gxf = gx.reshape(nw)  # (views)
    gyf = gy.reshape(nw)
    tdf = td.reshape(nw)
    twf = tw.reshape(nw)
    pwf = np.empty(nw)
    tinf = np.empty(nw)  # the template's inner pixels, flat
    for i in range(n):
        if not active[i]:
            continue
        status[i] = OK
        mi = masked[i]
        qx = guess[i, 0]
        qy = guess[i, 1]
        a00, a01 = ainv[i, 0, 0], ainv[i, 0, 1]
        a10, a11 = ainv[i, 1, 0], ainv[i, 1, 1]
        for lev in range(levels - 1, -1, -1):
            s = 1.0 / (1 << lev)
            roff, rr, rc = ref_off[lev], ref_shape[lev, 0], ref_shape[lev, 1]
            coff, cr, cc = cur_off[lev], cur_shape[lev, 0], cur_shape[lev, 1]
            if not _template(ref, ref_mask, roff, rr, rc, ref_xy[i, 0] * s, ref_xy[i, 1] * s,
                             a00, a01, a10, a11, half, mi, tpl, tw):  # fmt: skip
                status[i] = OUTSIDE
                break
            tn, tmean = 0.0, 0.0
            for v in range(w):
                for u in range(w):
                    tn += tw[v, u]
                    tmean += tw[v, u] * tpl[v + 1, u + 1]
            if tn < 0.5 * w * w:
                status[i] = FLAT
                break
            tmean /= tn
            sxx, sxy, syy, tvar0 = 0.0, 0.0, 0.0, 0.0
            for v in range(w):
                for u in range(w):
                    gxv = 0.5 * (tpl[v + 1, u + 2] - tpl[v + 1, u])
                    gyv = 0.5 * (tpl[v + 2, u + 1] - tpl[v, u + 1])
                    gx[v, u] = gxv
                    gy[v, u] = gyv
                    twv = tw[v, u]
                    sxx += twv * gxv * gxv
                    sxy += twv * gxv * gyv
                    syy += twv * gyv * gyv
                    tinf[v * w + u] = tpl[v + 1, u + 1]
                    d = tpl[v + 1, u + 1] - tmean
                    td[v, u] = d
                    tvar0 += d * d
            tr = 0.5 * (sxx + syy)
            mineig = tr - np.sqrt(max(tr * tr - (sxx * syy - sxy * sxy), 0.0))
            if mineig <= 1e-9:
                status[i] = FLAT
                break
            lx = qx * s
            ly = qy * s
            scale = -1.0
            last = np.inf
            bad = False
            for _ in range(iterations):
                x0 = lx - half
                y0 = ly - half
                if not (x0 >= 0.0 and y0 >= 0.0 and x0 + w - 1 <= cc - 1.001
                        and y0 + w - 1 <= cr - 1.001):  # fmt: skip
                    bad = True
                    break
                steps[i] += 1
                ix = int(x0)
                iy = int(y0)
                fx = x0 - ix
                fy = y0 - iy
                w00 = (1 - fx) * (1 - fy)
                w01 = fx * (1 - fy)
                w10 = (1 - fx) * fy
                w11 = fx * fy
                if not mi:
                    # the template's weights are all 1: its mean and contrast are fixed;
                    # one pass samples the patch (its sum and sum of squares on the way),
                    # one takes the residuals, Huber's weights and the normal equations
                    p1, p2 = 0.0, 0.0
                    k = 0
                    for v in range(w):
                        j = coff + (iy + v) * cc + ix
                        for _u in range(w):
                            pv = (w00 * cur[j] + w01 * cur[j + 1] + w10 * cur[j + cc]
                                  + w11 * cur[j + cc + 1])  # fmt: skip
                            pf[k] = pv
                            p1 += pv
                            p2 += pv * pv
                            j += 1
                            k += 1
                    pmean = p1 / ww
                    gain = np.sqrt(tvar0 / max(p2 - p1 * pmean, 1e-9))
                    off = pmean * gain
                    h00, h01, h11, b0, b1, mabs = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
                    if scale > 0.0:
                        cut = huber * scale
                        for k in range(nw):
                            e = pf[k] * gain - off - tdf[k]
                            ae = abs(e)
                            mabs += ae
                            wt = cut / max(ae, cut)
                            gxv = gxf[k]
                            gyv = gyf[k]
                            h00 += wt * gxv * gxv
                            h01 += wt * gxv * gyv
                            h11 += wt * gyv * gyv
                            b0 += wt * gxv * e
                            b1 += wt * gyv * e
                    else:
                        h00, h01, h11 = sxx, sxy, syy
                        for k in range(nw):
                            e = pf[k] * gain - off - tdf[k]
                            mabs += abs(e)
                            b0 += gxf[k] * e
                            b1 += gyf[k] * e
                    scale = mabs / ww
                else:
                    # a patch near the mask: the weights where neither is masked, the
                    # template's mean and contrast over them (their sums on the same pass)
                    pn, p1, p2, t1, t2 = 0.0, 0.0, 0.0, 0.0, 0.0
                    k = 0
                    for v in range(w):
                        j = coff + (iy + v) * cc + ix
                        for _u in range(w):
                            pv = (w00 * cur[j] + w01 * cur[j + 1] + w10 * cur[j + cc]
                                  + w11 * cur[j + cc + 1])  # fmt: skip
                            mk = (w00 * cur_mask[j] + w01 * cur_mask[j + 1]
                                  + w10 * cur_mask[j + cc] + w11 * cur_mask[j + cc + 1])  # fmt: skip
                            wv = 0.0 if mk > 0.5 else twf[k]
                            pf[k] = pv
                            pwf[k] = wv
                            tv = tinf[k]
                            pn += wv
                            p1 += wv * pv
                            p2 += wv * pv * pv
                            t1 += wv * tv
                            t2 += wv * tv * tv
                            j += 1
                            k += 1
                    if pn < 0.5 * w * w:
                        bad = True
                        break
                    pmean = p1 / pn
                    tm2 = t1 / pn
                    gain = np.sqrt(max(t2 - t1 * tm2, 0.0) / max(p2 - p1 * pmean, 1e-9))
                    h00, h01, h11, b0, b1, mabs = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
                    for k in range(nw):
                        if pwf[k] == 0.0:
                            continue
                        e = (pf[k] - pmean) * gain - (tinf[k] - tm2)
                        ae = abs(e)
                        mabs += ae
                        wt = 1.0
                        if scale > 0.0 and ae > huber * scale:
                            wt = huber * scale / ae
                        gxv = gxf[k]
                        gyv = gyf[k]
                        h00 += wt * gxv * gxv
                        h01 += wt * gxv * gyv
                        h11 += wt * gyv * gyv
                        b0 += wt * gxv * e
                        b1 += wt * gyv * e
                    scale = mabs / pn
                det = h00 * h11 - h01 * h01
                if det <= 1e-12:
                    bad = True
                    break
                ddx = (h11 * b0 - h01 * b1) / det
                ddy = (h00 * b1 - h01 * b0) / det
                lx -= ddx
                ly -= ddy
                last = np.sqrt(ddx * ddx + ddy * ddy)
                if last < (eps if lev == 0 else coarse_eps):
                    break
            if bad:
                status[i] = OUTSIDE
                break
            qx = lx / s
            qy = ly / s
            if lev == 0:
                step[i] = last
        if status[i] != OK:
            continue
        # the normalised cross-correlation of the template and the patch found
        found = _correlate(cur, cur_mask, cur_off, cur_shape, qx, qy, half, w, mi, tw,
                           tpl, patch, pw)  # fmt: skip
        if found[0] != OK:
            status[i] = found[0]
            xy[i, 0] = guess[i, 0]
            xy[i, 1] = guess[i, 1]
            continue
        xy[i, 0] = qx
        xy[i, 1] = qy
        ncc[i] = found[1]
        contrast[i] = found[2]
    return xy, ncc, contrast, step, status, steps


@njit(cache=True, nogil=True)
def local_affines(src, dst, nbr_start, nbr):
    """Each vertex's 2x2 linear map (V, 2, 2) taking its neighbours' offsets in ``src`` (V, 2)
    to theirs in ``dst`` (V, 2), least squares (``nbr[nbr_start[v]:nbr_start[v + 1]]`` are
    vertex ``v``'s neighbours), and its condition (V,): the smaller singular value of the
    neighbours' offsets in ``src`` over the larger (0: degenerate, the map the identity)."""
    nv = src.shape[0]
    out = np.zeros((nv, 2, 2))
    cond = np.zeros(nv)
    for v in range(nv):
        cxx, cxy, cyy = 0.0, 0.0, 0.0
        pxx, pxy, pyx, pyy = 0.0, 0.0, 0.0, 0.0
        for k in range(nbr_start[v], nbr_start[v + 1]):
            j = nbr[k]
            ax = src[j, 0] - src[v, 0]
            ay = src[j, 1] - src[v, 1]
            bx = dst[j, 0] - dst[v, 0]
            by = dst[j, 1] - dst[v, 1]
            cxx += ax * ax
            cxy += ax * ay
            cyy += ay * ay
            pxx += bx * ax
            pxy += bx * ay
            pyx += by * ax
            pyy += by * ay
        tr = 0.5 * (cxx + cyy)
        disc = np.sqrt(max(tr * tr - (cxx * cyy - cxy * cxy), 0.0))
        lo, hi = tr - disc, tr + disc
        det = cxx * cyy - cxy * cxy
        if hi <= 1e-12 or det <= 1e-12 * hi * hi:
            out[v, 0, 0] = 1.0
            out[v, 1, 1] = 1.0
            continue
        cond[v] = np.sqrt(max(lo, 0.0) / hi)
        # A = P C^-1
        i00, i01, i11 = cyy / det, -cxy / det, cxx / det
        out[v, 0, 0] = pxx * i00 + pxy * i01
        out[v, 0, 1] = pxx * i01 + pxy * i11
        out[v, 1, 0] = pyx * i00 + pyy * i01
        out[v, 1, 1] = pyx * i01 + pyy * i11
    return out, cond
