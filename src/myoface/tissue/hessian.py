"""Sparse stiffness (Hessian) assembly for the implicit / quasi-static solver.

The matrix is the Hessian of the lattice's potential energy over the *free* nodes, with each
spring's block projected to be positive semi-definite (its compressive geometric term clipped)
and the volume term in Gauss-Newton form (2 kv g g^T). It is assembled straight into a fixed CSR
pattern (built once per model) by a numba kernel, so a refactorisation costs one pass over the
springs plus the sparse LU itself.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit

from myoface.tissue.forces import LAW_CONTINUOUS, PRISM_TETS, spring_magnitude


class HessianPattern:
    """CSR pattern of the free-node stiffness matrix and where each spring's blocks go in it."""

    def __init__(self, n_nodes, free_index, si, sj):
        fmap = -np.ones(n_nodes, np.int64)
        fmap[free_index] = np.arange(len(free_index))
        nf = len(free_index)
        fi, fj = fmap[si], fmap[sj]
        both = (fi >= 0) & (fj >= 0)
        rows = np.concatenate([np.arange(nf), fi[both], fj[both]])
        cols = np.concatenate([np.arange(nf), fj[both], fi[both]])
        blk = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(nf, nf)).tocsr()
        blk.sum_duplicates()
        blk.sort_indices()
        self.block_indptr = blk.indptr.astype(np.int64)
        self.block_indices = blk.indices.astype(np.int64)
        self.fmap = fmap
        self.n_free = nf
        # scalar CSR: block row n has (nb = indptr[n+1]-indptr[n]) blocks -> each scalar row 3*nb
        nb_row = np.diff(self.block_indptr)
        row_len = np.repeat(3 * nb_row, 3)
        self.indptr = np.concatenate([[0], np.cumsum(row_len)]).astype(np.int64)
        cols = []
        for n in range(nf):
            c = self.block_indices[self.block_indptr[n] : self.block_indptr[n + 1]]
            rowcols = (3 * c[:, None] + np.arange(3)[None, :]).reshape(-1)
            cols += [rowcols] * 3
        self.indices = np.concatenate(cols).astype(np.int32)
        self.nnz = len(self.indices)
        # block slot of (i,i), (j,j), (i,j), (j,i) for each spring; -1 where a node is not free
        self.spring_slots = np.stack(
            [
                _slots(self.block_indptr, self.block_indices, fi, fi),
                _slots(self.block_indptr, self.block_indices, fj, fj),
                _slots(self.block_indptr, self.block_indices, fi, fj),
                _slots(self.block_indptr, self.block_indices, fj, fi),
            ],
            axis=1,
        )

    def matrix(self, data):
        n = 3 * self.n_free
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(n, n))


def _slots(indptr, indices, a, b):
    out = -np.ones(len(a), np.int64)
    ok = (a >= 0) & (b >= 0)
    for q in np.flatnonzero(ok):
        r0, r1 = indptr[a[q]], indptr[a[q] + 1]
        out[q] = r0 + np.searchsorted(indices[r0:r1], b[q])
    return out


@njit(cache=True)
def _add_block(data, indptr, block_indptr, fmap_row, slot, blk, sgn):
    # block slot -> scalar positions: row 3*n+a, entries start at indptr[3n+a] + 3*(slot - bptr[n])
    n = fmap_row
    k = slot - block_indptr[n]
    for a in range(3):
        base = indptr[3 * n + a] + 3 * k
        for b in range(3):
            data[base + b] += sgn * blk[a, b]


@njit(cache=True)
def assemble_hessian_numba(
    x,
    si,
    sj,
    rest,
    mat_id,
    mat,
    law,
    elems,
    rest_vol,
    kv,
    vsign,
    fmap,
    block_indptr,
    block_indices,
    indptr,
    spring_slots,
    data,
):
    """Fill ``data`` (CSR values) with the projected Hessian at positions ``x``."""
    data[:] = 0.0
    blk = np.empty((3, 3))
    for k in range(si.shape[0]):
        i = si[k]
        j = sj[k]
        fi = fmap[i]
        fj = fmap[j]
        if fi < 0 and fj < 0:
            continue
        rx = x[j, 0] - x[i, 0]
        ry = x[j, 1] - x[i, 1]
        rz = x[j, 2] - x[i, 2]
        d = np.sqrt(rx * rx + ry * ry + rz * rz)
        if d < 1e-12:
            continue
        lk = rest[k]
        e = d - lk
        m = mat_id[k]
        # tangent stiffness along the spring, and the geometric term |s|/d across it
        c = mat[m, 0] if (e <= mat[m, 2] * lk or law != LAW_CONTINUOUS) else mat[m, 1]
        g = spring_magnitude(e, lk, m, mat, law) / d
        if g < 0.0:
            g = 0.0  # clip the compressive geometric stiffness: keeps the block PSD
        u0 = rx / d
        u1 = ry / d
        u2 = rz / d
        u = (u0, u1, u2)
        for a in range(3):
            for b in range(3):
                blk[a, b] = (c - g) * u[a] * u[b] + (g if a == b else 0.0)
        s_ii = spring_slots[k, 0]
        s_jj = spring_slots[k, 1]
        s_ij = spring_slots[k, 2]
        s_ji = spring_slots[k, 3]
        if s_ii >= 0:
            _add_block(data, indptr, block_indptr, fi, s_ii, blk, 1.0)
        if s_jj >= 0:
            _add_block(data, indptr, block_indptr, fj, s_jj, blk, 1.0)
        if s_ij >= 0:
            _add_block(data, indptr, block_indptr, fi, s_ij, blk, -1.0)
        if s_ji >= 0:
            _add_block(data, indptr, block_indptr, fj, s_ji, blk, -1.0)
    # volume term, Gauss-Newton: 2 kv (dV/dx_a)(dV/dx_b)^T for every node pair of the element
    grad = np.zeros((6, 3))
    for e in range(elems.shape[0]):
        if kv[e] == 0.0:
            continue
        el = elems[e]
        grad[:, :] = 0.0
        for t in range(3):
            q0 = PRISM_TETS_H[t, 0]
            q1 = PRISM_TETS_H[t, 1]
            q2 = PRISM_TETS_H[t, 2]
            q3 = PRISM_TETS_H[t, 3]
            p0 = el[q0]
            ax = x[el[q1], 0] - x[p0, 0]
            ay = x[el[q1], 1] - x[p0, 1]
            az = x[el[q1], 2] - x[p0, 2]
            bx = x[el[q2], 0] - x[p0, 0]
            by = x[el[q2], 1] - x[p0, 1]
            bz = x[el[q2], 2] - x[p0, 2]
            cx = x[el[q3], 0] - x[p0, 0]
            cy = x[el[q3], 1] - x[p0, 1]
            cz = x[el[q3], 2] - x[p0, 2]
            g1 = (by * cz - bz * cy, bz * cx - bx * cz, bx * cy - by * cx)
            g2 = (cy * az - cz * ay, cz * ax - cx * az, cx * ay - cy * ax)
            g3 = (ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx)
            for r in range(3):
                grad[q1, r] += g1[r]
                grad[q2, r] += g2[r]
                grad[q3, r] += g3[r]
                grad[q0, r] -= g1[r] + g2[r] + g3[r]
        w = 2.0 * kv[e] * (vsign / 6.0) ** 2
        for qa in range(6):
            na = fmap[el[qa]]
            if na < 0:
                continue
            for qb in range(6):
                nb = fmap[el[qb]]
                if nb < 0:
                    continue
                # find slot of (na, nb)
                r0 = block_indptr[na]
                r1 = block_indptr[na + 1]
                lo = r0
                hi = r1
                while lo < hi:
                    mid = (lo + hi) // 2
                    if block_indices[mid] < nb:
                        lo = mid + 1
                    else:
                        hi = mid
                for a in range(3):
                    for b in range(3):
                        blk[a, b] = w * grad[qa, a] * grad[qb, b]
                _add_block(data, indptr, block_indptr, na, lo, blk, 1.0)


PRISM_TETS_H = PRISM_TETS
