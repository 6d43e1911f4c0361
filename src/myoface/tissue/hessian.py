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


# ---------------------------------------------------------------------------------------------
# the exact Hessian in 3x3 blocks (the Newton solver's, :mod:`myoface.tissue.solver`)
# ---------------------------------------------------------------------------------------------


class BlockPattern:
    """Block CSR pattern (3x3 blocks) of the Hessian over the free nodes, and where each
    spring's and each prism's blocks go in it.

    Attributes
    ----------
    n_free : int; fmap : (N,) int64 — free-node number of each node, -1 for kinematic ones.
    indptr : (F+1,) int64; indices : (nnzb,) int64 — block rows, sorted columns.
    nnzb : int
    spring_slots : (S, 4) int64 — block of (i,i), (j,j), (i,j), (j,i) of each spring, -1 where
        a node is not free.
    element_slots : (E, 36) int64 — block of (node a, node b) of each prism (a, b in 0..5, row
        major), -1 where a node is not free.
    """

    def __init__(self, n_nodes, free_index, si, sj, elements):
        fmap = -np.ones(n_nodes, np.int64)
        fmap[free_index] = np.arange(len(free_index))
        nf = len(free_index)
        pi = [np.arange(nf), fmap[si], fmap[sj]]
        pj = [np.arange(nf), fmap[sj], fmap[si]]
        el = np.asarray(elements, np.int64).reshape(-1, 6)
        fe = fmap[el]
        for a in range(6):
            for b in range(6):
                pi.append(fe[:, a])
                pj.append(fe[:, b])
        rows, cols = np.concatenate(pi), np.concatenate(pj)
        ok = (rows >= 0) & (cols >= 0)
        blk = sp.coo_matrix((np.ones(int(ok.sum())), (rows[ok], cols[ok])), shape=(nf, nf)).tocsr()
        blk.sum_duplicates()
        blk.sort_indices()
        self.n_free = nf
        self.fmap = fmap
        self.indptr = blk.indptr.astype(np.int64)
        self.indices = blk.indices.astype(np.int64)
        self.nnzb = len(self.indices)
        fi, fj = fmap[si], fmap[sj]
        self.spring_slots = np.stack(
            [
                _block_slots(self.indptr, self.indices, fi, fi),
                _block_slots(self.indptr, self.indices, fj, fj),
                _block_slots(self.indptr, self.indices, fi, fj),
                _block_slots(self.indptr, self.indices, fj, fi),
            ],
            axis=1,
        )
        es = np.empty((len(el), 36), np.int64)
        for a in range(6):
            for b in range(6):
                es[:, 6 * a + b] = _block_slots(self.indptr, self.indices, fe[:, a], fe[:, b])
        self.element_slots = es
        for arr in (self.fmap, self.indptr, self.indices, self.spring_slots, self.element_slots):
            arr.flags.writeable = False

    def scalar_matrix(self, bvals) -> sp.csr_matrix:
        """The (3F, 3F) scipy CSR matrix of block values ``bvals`` (nnzb*9,)."""
        b = sp.bsr_matrix(
            (np.asarray(bvals).reshape(-1, 3, 3), self.indices, self.indptr),
            shape=(3 * self.n_free, 3 * self.n_free),
        )
        return b.tocsr()


def _block_slots(indptr, indices, a, b):
    """Index in ``indices`` of block (a[q], b[q]) for each q, -1 where a or b is -1."""
    out = -np.ones(len(a), np.int64)
    ok = np.flatnonzero((a >= 0) & (b >= 0))
    if len(ok):
        r0 = indptr[a[ok]]
        r1 = indptr[a[ok] + 1]
        # the rows are sorted: a vectorised binary search row by row via a global key
        key = a[ok] * (len(indptr)) + b[ok]
        rows_of = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
        allkey = rows_of * (len(indptr)) + indices
        pos = np.searchsorted(allkey, key)
        if np.any(pos >= r1) or np.any(pos < r0) or np.any(allkey[pos] != key):
            raise ValueError("block not in the pattern")
        out[ok] = pos
    return out


@njit(cache=True, nogil=True, inline="always")
def _add9(bvals, slot, h, sgn):
    if slot >= 0:
        o = 9 * slot
        for q in range(9):
            bvals[o + q] += sgn * h[q]


@njit(cache=True, nogil=True, fastmath=True)
def assemble_block_hessian(
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
    spring_slots,
    element_slots,
    bvals,
):
    """Fill ``bvals`` (nnzb*9,) with the exact Hessian of the potential energy over the free
    nodes at ``x`` (N, 3) mm, in the block pattern of :class:`BlockPattern`.

    Springs: ``(c - g) u u^T + g I`` on (i,i), (j,j) and its negative on (i,j), (j,i), with u the
    unit direction, c = d|s|/de the tangent stiffness (alpha or beta, eq. 2) and g = |s|/d the
    geometric term — negative for a compressed spring, and not clipped: this is the true
    Hessian, which may be indefinite away from an equilibrium. Volume penalty
    Q_j = kv_j (V_j - V0_j)^2: ``2 kv (dV/dx)(dV/dx)^T + 2 kv (V - V0) d2V/dx2``, with d2V of each
    tetrahedron from its triple product (bilinear in each pair of its edge vectors).
    """
    bvals[:] = 0.0
    h = np.empty(9)
    for k in range(si.shape[0]):
        if spring_slots[k, 0] < 0 and spring_slots[k, 1] < 0:
            continue
        i = si[k]
        j = sj[k]
        rx = x[j, 0] - x[i, 0]
        ry = x[j, 1] - x[i, 1]
        rz = x[j, 2] - x[i, 2]
        d = np.sqrt(rx * rx + ry * ry + rz * rz)
        if d < 1e-12:
            continue
        lk = rest[k]
        e = d - lk
        m = mat_id[k]
        c = mat[m, 0] if e <= mat[m, 2] * lk else mat[m, 1]
        g = spring_magnitude(e, lk, m, mat, law) / d
        u0 = rx / d
        u1 = ry / d
        u2 = rz / d
        w = c - g
        h[0] = w * u0 * u0 + g
        h[1] = w * u0 * u1
        h[2] = w * u0 * u2
        h[3] = h[1]
        h[4] = w * u1 * u1 + g
        h[5] = w * u1 * u2
        h[6] = h[2]
        h[7] = h[5]
        h[8] = w * u2 * u2 + g
        _add9(bvals, spring_slots[k, 0], h, 1.0)
        _add9(bvals, spring_slots[k, 1], h, 1.0)
        _add9(bvals, spring_slots[k, 2], h, -1.0)
        _add9(bvals, spring_slots[k, 3], h, -1.0)
    grad = np.empty((6, 3))
    wv = np.empty((6, 6, 3))
    pts = np.empty((4, 3))
    for q in range(elems.shape[0]):
        if kv[q] == 0.0:
            continue
        es = element_slots[q]
        anyfree = False
        for s in range(36):
            if es[s] >= 0:
                anyfree = True
                break
        if not anyfree:
            continue
        el = elems[q]
        grad[:, :] = 0.0
        wv[:, :, :] = 0.0
        vol = 0.0
        for t in range(3):  # tetrahedron t: prism slots t, t+1, t+2, t+3 (PRISM_TETS)
            for r in range(4):
                for c3 in range(3):
                    pts[r, c3] = x[el[t + r], c3]
            ax = pts[1, 0] - pts[0, 0]
            ay = pts[1, 1] - pts[0, 1]
            az = pts[1, 2] - pts[0, 2]
            bx = pts[2, 0] - pts[0, 0]
            by = pts[2, 1] - pts[0, 1]
            bz = pts[2, 2] - pts[0, 2]
            cx = pts[3, 0] - pts[0, 0]
            cy = pts[3, 1] - pts[0, 1]
            cz = pts[3, 2] - pts[0, 2]
            g1 = (by * cz - bz * cy, bz * cx - bx * cz, bx * cy - by * cx)
            g2 = (cy * az - cz * ay, cz * ax - cx * az, cx * ay - cy * ax)
            g3 = (ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx)
            vol += ax * g1[0] + ay * g1[1] + az * g1[2]
            for r in range(3):
                grad[t + 1, r] += g1[r]
                grad[t + 2, r] += g2[r]
                grad[t + 3, r] += g3[r]
                grad[t, r] -= g1[r] + g2[r] + g3[r]
            # the triple product is linear in each vertex, so d2T/dp_m2 = 0, and
            # d2T/dp_m dp_n = [p_k - p_l]x for (m, n, k, l) an even permutation of (0, 1, 2, 3)
            for pr in range(6):
                m = _PAIRS[pr, 0]
                n = _PAIRS[pr, 1]
                kk = _PAIRS[pr, 2]
                ll = _PAIRS[pr, 3]
                for c3 in range(3):
                    dw = pts[kk, c3] - pts[ll, c3]
                    wv[t + m, t + n, c3] += dw
                    wv[t + n, t + m, c3] -= dw
        dv = vsign * vol / 6.0 - rest_vol[q]
        wg = 2.0 * kv[q] * (vsign / 6.0) ** 2
        w2 = 2.0 * kv[q] * dv * vsign / 6.0
        for a in range(6):
            for b in range(6):
                slot = es[6 * a + b]
                if slot < 0:
                    continue
                o = 9 * slot
                for r in range(3):
                    for c3 in range(3):
                        bvals[o + 3 * r + c3] += wg * grad[a, r] * grad[b, c3]
                # + w2 [w]x, [w]x = [[0, -w2, w1], [w2, 0, -w0], [-w1, w0, 0]]
                w0 = w2 * wv[a, b, 0]
                w1 = w2 * wv[a, b, 1]
                w2_ = w2 * wv[a, b, 2]
                bvals[o + 1] -= w2_
                bvals[o + 2] += w1
                bvals[o + 3] += w2_
                bvals[o + 5] -= w0
                bvals[o + 6] -= w1
                bvals[o + 7] += w0


#: (m, n, k, l): the six vertex pairs (m, n) of a tetrahedron with the other two (k, l) in the
#: order that makes (m, n, k, l) an even permutation of (0, 1, 2, 3)
_PAIRS = np.array(
    [[1, 2, 0, 3], [2, 3, 0, 1], [3, 1, 0, 2], [1, 0, 3, 2], [2, 0, 1, 3], [3, 0, 2, 1]],
    dtype=np.int64,
)
