"""The fit's compiled normal equations against an independent reference: the Jacobian of the
weighted residual rows taken by central differences in NumPy, ``J^T J`` and ``-J^T r`` formed
densely. The kernel leaves out the rows that weigh nothing and forms ``J^T J`` four rows by
four; neither may change what it computes beyond rounding."""

from __future__ import annotations

import numpy as np
import pytest

from myoface.analysis._fitkernels import _gram, landmark_cost, normal_equations
from myoface.analysis.camera import rotmat


def _rows(x, rot, trans, shape, dsdc, free, f, cx, cy, p, use_z, w, mxy, kxy, inv_ds, k):
    """The weighted residual rows (2 V x, y rows, then V depth rows with their weighted mean
    taken out) at the step ``x`` (omega, dt, dc[free]), the weights ``w`` held fixed."""
    r = rotmat(x[:3]) @ rot
    t = trans + x[3:6]
    s = shape + np.einsum("vim,m->vi", dsdc[:, :, free], x[6:])
    pc = s @ r.T + t
    d = np.maximum(-pc[:, 2], 1e-6)
    u = cx + f * pc[:, 0] / d
    v = cy - f * pc[:, 1] / d
    sxy = np.sqrt(w * mxy)
    out = [(u - p[:, 0]) * kxy * sxy, (v - p[:, 1]) * kxy * sxy]
    if use_z:
        dz = -pc[:, 2] - k * p[:, 2]
        dz = dz - (w * dz).sum() / w.sum()
        out.append(dz * inv_ds * np.sqrt(w))
    return np.concatenate(out)


def _problem(rng, nv, m, use_z):
    rot = rotmat(rng.normal(0, 0.2, 3))
    trans = np.array([3.0, -2.0, -480.0])
    shape = rng.normal(0, 40.0, (nv, 3))
    dsdc = rng.normal(0, 2.0, (nv, 3, m))
    f, cx, cy = 900.0, 320.0, 180.0
    pc = shape @ rot.T + trans
    uv = np.column_stack([cx + f * pc[:, 0] / -pc[:, 2], cy - f * pc[:, 1] / -pc[:, 2]])
    p = np.column_stack([uv + rng.normal(0, 1.5, (nv, 2)), rng.normal(0, 5.0, nv)])
    if not use_z:
        p[:, 2] = np.nan
    w0 = rng.uniform(0.2, 1.0, nv)
    w0[rng.uniform(size=nv) < 0.3] = 0.0  # (vertices that weigh nothing: none of their rows)
    mxy = rng.uniform(0.0, 1.0, nv)
    mxy[rng.uniform(size=nv) < 0.4] = 0.0  # (x, y read by another term: the depth row stays)
    return rot, trans, shape, dsdc, f, cx, cy, p, w0, mxy


@pytest.mark.parametrize("use_z", [True, False])
@pytest.mark.parametrize("n_free", [0, 5, 11])
def test_normal_equations_are_the_dense_jacobians(use_z, n_free):
    rng = np.random.default_rng(7 + n_free + 100 * use_z)
    nv, m = 41, 11
    rot, trans, shape, dsdc, f, cx, cy, p, w0, mxy = _problem(rng, nv, m, use_z)
    free = np.sort(rng.choice(m, n_free, replace=False)).astype(np.int64)
    kxy, inv_ds, k, huber = 0.8, 0.25, 0.6, 1.5
    # the Huber weights at this estimate (what the kernel reweights with), then held fixed
    r0 = _rows(np.zeros(6 + n_free), rot, trans, shape, dsdc, free, f, cx, cy, p, use_z,
               np.ones(nv), np.ones(nv), kxy, inv_ds, k)  # fmt: skip
    dist = np.hypot(r0[:nv], r0[nv : 2 * nv])
    w = w0 * np.where(dist > huber, huber / np.maximum(dist, 1e-12), 1.0)
    assert (dist > huber).any() and (dist <= huber).any()  # (both sides of Huber's corner)
    args = (rot, trans, shape, dsdc, free, f, cx, cy, p, use_z, w)
    jac = np.empty((2 * nv + (nv if use_z else 0), 6 + n_free))
    for j in range(6 + n_free):
        e = np.zeros(6 + n_free)
        e[j] = 1e-6
        jac[:, j] = (
            _rows(e, *args, mxy, kxy, inv_ds, k) - _rows(-e, *args, mxy, kxy, inv_ds, k)
        ) / 2e-6
    res = _rows(np.zeros(6 + n_free), *args, mxy, kxy, inv_ds, k)
    h, b = normal_equations(rot, trans, shape, dsdc, free, f, cx, cy, p, use_z, w0, mxy, kxy,
                            inv_ds, k, huber)  # fmt: skip
    h_ref, b_ref = jac.T @ jac, -jac.T @ res
    scale = np.abs(h_ref).max()
    np.testing.assert_allclose(h, h_ref, rtol=1e-5, atol=1e-6 * scale)
    np.testing.assert_allclose(b, b_ref, rtol=1e-5, atol=1e-6 * np.abs(b_ref).max())
    np.testing.assert_array_equal(h, h.T)
    # (the cost is the same rows' Huber loss: inside Huber's corner the sum of squares)
    cost = landmark_cost(rot, trans, shape, f, cx, cy, p, use_z, w0, mxy, kxy, inv_ds, k, huber)
    assert np.isfinite(cost) and cost > 0


@pytest.mark.parametrize("n", [1, 3, 4, 6, 9, 45])
def test_gram_is_the_product(n):
    """Four rows by four, and the rows left over when ``n`` is not a multiple of four."""
    rng = np.random.default_rng(n)
    jt = rng.normal(size=(n, 37))
    r = rng.normal(size=37)
    h, b = _gram(jt, r)
    np.testing.assert_allclose(h, jt @ jt.T, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(b, -(jt @ r), rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(h, h.T)
    h0, _ = _gram(np.zeros((n, 0)), np.zeros(0))  # (no rows: nothing weighs)
    np.testing.assert_array_equal(h0, np.zeros((n, n)))
