"""Compiled inner loop of the lids' template reader (:mod:`myoface.analysis.lidtemplate`): each
column's template slid along the column, the frame sampled where each of its samples lands for
each shift, the cost of each shift. ``nogil``: MediaPipe runs on another thread meanwhile."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _bilinear(img, x, y):
    """Bilinear sample of ``img`` (H, W) at (x, y) (column, row; pixel centres at integers),
    the coordinates clamped to the image (the border replicated, as OpenCV's
    ``BORDER_REPLICATE``)."""
    h, w = img.shape
    x = min(max(x, 0.0), w - 1.0)
    y = min(max(y, 0.0), h - 1.0)
    ix = min(int(x), w - 2) if w > 1 else 0
    iy = min(int(y), h - 2) if h > 1 else 0
    fx = x - ix
    fy = y - iy
    ix1 = min(ix + 1, w - 1)
    iy1 = min(iy + 1, h - 1)
    top = (1.0 - fx) * img[iy, ix] + fx * img[iy, ix1]
    bot = (1.0 - fx) * img[iy1, ix] + fx * img[iy1, ix1]
    return (1.0 - fy) * top + fy * bot


@njit(cache=True, nogil=True)
def slide_cost(x0, gap, shift, where, rot, trans, focal, cx, cy, ox, oy, imgs, tmpls):
    """(N, S) the cost of each column ``n`` at each shift ``s``: the mean squared difference
    between the template ``tmpls[c, n]`` (nb,) and the frame's channel ``imgs[c]`` (H, W)
    sampled at the column's points ``x0[n] + where[s, b] * gap[n] + shift[n]`` (head frame,
    mm) seen through the pose (``rot`` (3, 3), ``trans`` (3,)) and the pinhole camera
    (``focal``, ``cx``, ``cy`` px; the image's top left corner at (``ox``, ``oy``)), summed
    over the channels; channel 0 (the luma) with its mean over the samples taken out."""
    n_cols = x0.shape[0]
    n_shifts, nb = where.shape
    n_ch = imgs.shape[0]
    cost = np.zeros((n_cols, n_shifts))
    us = np.empty(nb)
    vs = np.empty(nb)
    vals = np.empty(nb)
    for n in range(n_cols):
        for s in range(n_shifts):
            for b in range(nb):
                w = where[s, b]
                p0 = x0[n, 0] + w * gap[n, 0] + shift[n, 0]
                p1 = x0[n, 1] + w * gap[n, 1] + shift[n, 1]
                p2 = x0[n, 2] + w * gap[n, 2] + shift[n, 2]
                q0 = rot[0, 0] * p0 + rot[0, 1] * p1 + rot[0, 2] * p2 + trans[0]
                q1 = rot[1, 0] * p0 + rot[1, 1] * p1 + rot[1, 2] * p2 + trans[1]
                q2 = rot[2, 0] * p0 + rot[2, 1] * p1 + rot[2, 2] * p2 + trans[2]
                d = max(-q2, 1e-6)
                us[b] = cx + focal * q0 / d - ox
                vs[b] = cy - focal * q1 / d - oy
            total = 0.0
            for c in range(n_ch):
                img = imgs[c]
                mean = 0.0
                for b in range(nb):
                    vals[b] = _bilinear(img, us[b], vs[b])
                    mean += vals[b]
                mean = mean / nb if c == 0 else 0.0
                acc = 0.0
                for b in range(nb):
                    r = vals[b] - mean - tmpls[c, n, b]
                    acc += r * r
                total += acc / nb
            cost[n, s] = total
    return cost
