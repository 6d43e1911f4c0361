"""Stiffness (Hessian) matrices of the lattice's potential energy over the free nodes.

Two of them:

* the stiffness matrix (:func:`stiffness_matrix`; :class:`HessianPattern`,
  :func:`assemble_hessian_numba`): each spring's block projected to be positive semi-definite
  (its compressive geometric term clipped) and the volume term in Gauss-Newton form
  (2 kv g g^T), in a fixed scalar CSR pattern built once per model (:func:`hessian_pattern`):
  the lattice's slowest mode (:func:`myoface.tissue.assemble.lowest_frequency`) and the L-BFGS
  reference's preconditioner, a sparse LU;
* the Newton solver's exact Hessian (:class:`SymmetricPattern`), in symmetric 3x3-block storage,
  over the springs and prisms that touch a free node. One pass over the springs
  (:func:`_spring_pass`) and one over the prisms (:func:`_prism_pass`) compute the energy, its
  gradient and this Hessian, each on request; every kernel of the Newton solver's is made of
  them (:func:`energy_gradient_hessian`, :func:`energy_gradient_free`,
  :func:`add_spring_hessian`, :func:`add_prism_hessian`).

References: Terzopoulos & Waters 1993, eq. (1)-(4).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit
from scipy.sparse.csgraph import reverse_cuthill_mckee

from myoface.tissue.forces import (
    LAW_CONTINUOUS,
    MIN_SPRING_LENGTH,
    PRISM_PAIRS,
    PRISM_TETS,
    _tet_gradient,
    spring_magnitude,
)
from myoface.tissue.model import TissueModel


def kernel_args(model: TissueModel, materials: np.ndarray | None = None) -> tuple:
    """The packed arrays every force kernel takes, in kernel argument order; ``materials``
    (M, 3) [alpha, beta, strain_c] in place of the model's, if given."""
    return (
        model.spring_i,
        model.spring_j,
        model.rest_length,
        model.spring_material,
        model.materials if materials is None else materials,
        model.spring_law,
        model.elements,
        model.rest_volume,
        model.volume_weight,
        model.volume_sign,
    )


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


def _kernel_positions(x: np.ndarray) -> np.ndarray:
    """``x`` as the kernels are compiled for: C-contiguous, float64 and writeable (a copy of a
    read-only array such as a model's rest positions), so that numba compiles each kernel
    once rather than again for read-only arrays (a kernel's compilation is seconds, on every
    new install: measured 2026-12-08, the Hessian's kernels were compiled for both)."""
    return np.require(x, np.float64, ("C", "W"))


def hessian_pattern(model: TissueModel) -> HessianPattern:
    """The model's :class:`HessianPattern`, built once (kept in ``model.memo``)."""
    return model.memo(
        "hessian_pattern",
        lambda: HessianPattern(model.n_nodes, model.free_index, model.spring_i, model.spring_j),
    )


def stiffness_matrix(model: TissueModel, x: np.ndarray, materials: np.ndarray | None = None):
    """The projected stiffness matrix over the free nodes at ``x`` (N, 3) mm (scipy CSR,
    3F x 3F, g/s^2), with the model's materials or ``materials`` (M, 3) in their place."""
    pat = hessian_pattern(model)
    data = np.empty(pat.nnz)
    assemble_hessian_numba(
        _kernel_positions(x),
        *kernel_args(model, materials),
        pat.fmap,
        pat.block_indptr,
        pat.block_indices,
        pat.indptr,
        pat.spring_slots,
        data,
    )
    return pat.matrix(data)


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
# the exact Hessian, symmetric storage (the Newton solver's, :mod:`myoface.tissue.solver`)
# ---------------------------------------------------------------------------------------------


def _local_order(free, n_nodes, si, sj, elems) -> np.ndarray:
    """The free nodes ``free`` in reverse Cuthill-McKee order of the graph of their springs and
    prisms: nodes joined by a spring or a prism get nearby numbers, so the Hessian's blocks of a
    spring or a prism, and a node's neighbours in the Gauss-Seidel sweeps, lie close together in
    memory (numbered by layer, the nodes of one prism are hundreds of rows apart)."""
    fmap = -np.ones(n_nodes, np.int64)
    fmap[free] = np.arange(len(free))
    pairs = [np.stack([si, sj], axis=1)] + [elems[:, [a, b]] for a, b in PRISM_PAIRS]
    pr = fmap[np.concatenate(pairs)]
    pr = pr[(pr >= 0).all(axis=1)]
    nf = len(free)
    g = sp.coo_matrix((np.ones(len(pr)), (pr[:, 0], pr[:, 1])), shape=(nf, nf)).tocsr()
    g = (g + g.T).tocsr()
    return free[reverse_cuthill_mckee(g, symmetric_mode=True)]


class SymmetricPattern:
    """The free-node Hessian in symmetric 3x3-block storage, and the packed arrays of the springs
    and prisms that touch a free node (the others add a constant to the energy and nothing to
    its gradient or Hessian).

    Storage: the diagonal blocks ``dvals`` (F*9,), and the strictly lower blocks ``lvals``
    (nl*9,) in block CSR by row (``lptr`` (F+1,), ``lcol`` (nl,), int32, columns sorted, each <
    its row); blocks row-major. (Every index table is 32-bit: they are streamed at every
    assembly and CG sweep, and the smaller footprint measured faster.) A spring's blocks are symmetric; a prism pair (a, b) whose nodes
    are numbered the other way round (free number of a < that of b) adds the transpose of its
    block H_ab, i.e. H_ba.

    Attributes (besides the storage)
    --------------------------------
    n_free : int; fmap : (N,) int64 — free number of each node, -1 for a kinematic one;
    free_nodes : (F,) int64 — the node of each free number (:func:`_local_order`: the free
        nodes in reverse Cuthill-McKee order, not in node order). The gradient and every vector
        of the Newton solver's are in this order.
    si, sj, rest, alpha, beta, ec : (S',) — the active springs (by their larger free number;
        the prisms likewise): ends (int32), rest length l
        (mm), stiffnesses (g/s^2), threshold extension e^c = strain_c l (mm);
    sfi, sfj : (S',) int32 — free numbers of the ends; soff : (S',) int32 — lower block or -1.
    elems : (E', 6) int32; efree : (E', 6) int32; rest_volume, kv : (E',) — the active prisms
        (nonzero volume weight);
    pslots : (E', 15) int32 — per prism and node pair (a, b) of :data:`PRISM_PAIRS`, its lower
        block, or -1 when a node of the pair is kinematic; prev : (E',) int32 — bit p set when
        pair p's nodes are numbered the other way round (the stored block is then H_ba).
    law : int; vsign : float — the model's.
    """

    def __init__(self, model):
        n = model.n_nodes
        si_all = np.asarray(model.spring_i, np.int64)
        sj_all = np.asarray(model.spring_j, np.int64)
        el_all = np.asarray(model.elements, np.int64).reshape(-1, 6)
        free = _local_order(np.flatnonzero(~np.asarray(model.kinematic)), n, si_all, sj_all, el_all)
        fmap = -np.ones(n, np.int64)
        fmap[free] = np.arange(len(free))
        nf = len(free)
        fs = np.maximum(fmap[si_all], fmap[sj_all])
        # the springs and prisms in the order of their nodes' free numbers: each pass then
        # writes the Hessian's storage (and reads the positions) from one band of rows to the next
        k = np.flatnonzero(fs >= 0)
        k = k[np.argsort(fs[k], kind="stable")]
        fe_all = fmap[el_all]
        eact = (fe_all >= 0).any(axis=1) & (np.asarray(model.volume_weight) != 0)
        e = np.flatnonzero(eact)
        e = e[np.argsort(fe_all[e].max(axis=1), kind="stable")]
        fi, fj = fmap[si_all[k]], fmap[sj_all[k]]
        fe = fmap[el_all[e]]
        rows = [np.maximum(fi, fj)] + [np.maximum(fe[:, a], fe[:, b]) for a, b in PRISM_PAIRS]
        cols = [np.minimum(fi, fj)] + [np.minimum(fe[:, a], fe[:, b]) for a, b in PRISM_PAIRS]
        r, c = np.concatenate(rows), np.concatenate(cols)
        ok = c >= 0
        key = np.unique(r[ok] * nf + c[ok])

        def slot(a, b):
            out = -np.ones(len(a), np.int64)
            both = (a >= 0) & (b >= 0)
            out[both] = np.searchsorted(
                key, np.maximum(a[both], b[both]) * nf + np.minimum(a[both], b[both])
            )
            return out

        mat = np.asarray(model.materials)[np.asarray(model.spring_material)[k]]
        rest = np.asarray(model.rest_length, np.float64)[k]
        self.n_free = nf
        self.fmap = fmap
        self.free_nodes = free
        # 32-bit indices throughout: the tables are streamed at every assembly and CG sweep
        self.lptr = np.searchsorted(key // max(nf, 1), np.arange(nf + 1)).astype(np.int32)
        self.lcol = (key % max(nf, 1)).astype(np.int32)
        self.nl = len(key)
        self.si = si_all[k].astype(np.int32)
        self.sj = sj_all[k].astype(np.int32)
        self.rest = rest
        self.alpha = mat[:, 0].copy()
        self.beta = mat[:, 1].copy()
        self.ec = mat[:, 2] * rest
        self.sfi = fi.astype(np.int32)
        self.sfj = fj.astype(np.int32)
        self.soff = slot(fi, fj).astype(np.int32)
        self.elems = el_all[e].astype(np.int32)
        self.efree = fe.astype(np.int32)
        pslots = np.stack([slot(fe[:, a], fe[:, b]) for a, b in PRISM_PAIRS], axis=1)
        prev = np.zeros(len(e), np.int64)
        for p, (a, b) in enumerate(PRISM_PAIRS):
            rev = (pslots[:, p] >= 0) & (fe[:, a] < fe[:, b])  # stored block (row > col) is H_ba
            prev |= rev.astype(np.int64) << p
        self.pslots = pslots.astype(np.int32)
        self.prev = prev.astype(np.int32)
        self.rest_volume = np.asarray(model.rest_volume, np.float64)[e]
        self.kv = np.asarray(model.volume_weight, np.float64)[e]
        self.law = int(model.spring_law)
        self.vsign = float(model.volume_sign)
        for name, val in vars(self).items():
            if isinstance(val, np.ndarray):
                val = np.ascontiguousarray(val)
                val.flags.writeable = False
                setattr(self, name, val)

    @property
    def springs(self) -> tuple:
        """The springs' arrays, as the kernels take them: (si, sj, rest, alpha, beta, ec, law,
        sfi, sfj, soff)."""
        return (
            self.si,
            self.sj,
            self.rest,
            self.alpha,
            self.beta,
            self.ec,
            self.law,
            self.sfi,
            self.sfj,
            self.soff,
        )

    @property
    def prisms(self) -> tuple:
        """The prisms' arrays, as the kernels take them: (elems, efree, rest_volume, kv, vsign,
        pslots, prev)."""
        return (
            self.elems,
            self.efree,
            self.rest_volume,
            self.kv,
            self.vsign,
            self.pslots,
            self.prev,
        )

    def assemble(self, x, dvals, lvals) -> None:
        """Fill ``dvals``, ``lvals`` with the exact Hessian at ``x`` (N, 3) mm."""
        dvals[:] = 0.0
        lvals[:] = 0.0
        x = _kernel_positions(x)
        add_spring_hessian(x, self.springs, dvals, lvals)
        add_prism_hessian(x, self.prisms, dvals, lvals)

    def matrix(self, dvals, lvals) -> sp.csr_matrix:
        """The full (3F, 3F) scipy CSR matrix of the storage (a reference for tests)."""
        nf = self.n_free
        d = sp.bsr_matrix(
            (np.asarray(dvals).reshape(-1, 3, 3), np.arange(nf), np.arange(nf + 1)),
            shape=(3 * nf, 3 * nf),
        )
        lo = sp.bsr_matrix(
            (np.asarray(lvals).reshape(-1, 3, 3), self.lcol, self.lptr), shape=(3 * nf, 3 * nf)
        )
        return (d + lo + lo.T).tocsr()


# ------------------------------------------------- energy, gradient and Hessian: one pass each ----
#
# One loop over the springs (:func:`_spring_pass`) and one over the prisms (:func:`_prism_pass`)
# compute, on request, the energy, its gradient and the exact Hessian in the symmetric storage;
# every kernel below is one of them or both.


@njit(cache=True, nogil=True)
def _add_sym6(arr, slot, h0, h1, h2, h4, h5, h8):
    """Add the symmetric block [[h0, h1, h2], [h1, h4, h5], [h2, h5, h8]] to block ``slot``
    of ``arr`` (nothing if slot < 0)."""
    if slot >= 0:
        o = 9 * slot
        arr[o] += h0
        arr[o + 1] += h1
        arr[o + 2] += h2
        arr[o + 3] += h1
        arr[o + 4] += h4
        arr[o + 5] += h5
        arr[o + 6] += h2
        arr[o + 7] += h5
        arr[o + 8] += h8


@njit(cache=True, nogil=True)
def _add_upper6(arr, slot, h0, h1, h2, h4, h5, h8):
    """Add the upper triangle of the symmetric block [[h0, h1, h2], [h1, h4, h5], [h2, h5, h8]]
    to diagonal block ``slot`` of ``arr`` (nothing if slot < 0); its lower triangle is left
    for :func:`symmetrize_diagonal` (the passes write a third fewer values)."""
    if slot >= 0:
        o = 9 * slot
        arr[o] += h0
        arr[o + 1] += h1
        arr[o + 2] += h2
        arr[o + 4] += h4
        arr[o + 5] += h5
        arr[o + 8] += h8


@njit(cache=True, nogil=True)
def symmetrize_diagonal(dvals):
    """Copy the upper triangle of each 3x3 block of ``dvals`` (F*9,) to its lower triangle: the
    passes accumulate only the upper one (:func:`_add_upper6`, :func:`_add_outer`)."""
    for i in range(dvals.shape[0] // 9):
        o = 9 * i
        dvals[o + 3] = dvals[o + 1]
        dvals[o + 6] = dvals[o + 2]
        dvals[o + 7] = dvals[o + 5]


@njit(cache=True, nogil=True, fastmath=True)
def _spring_pass(x, springs, grad, want_g, dvals, lvals, want_h):
    """The springs' energy (nJ, returned), their gradient dE/dx (uN) added to ``grad`` (F, 3)
    when ``want_g``, and their Hessian added to ``dvals``, ``lvals`` when ``want_h``: per
    spring ``(c - g) u u^T + g I`` on both diagonal blocks and its negative on the off-diagonal
    one (c the tangent stiffness, alpha or beta (eq. 2); g = |s| / d, negative for a compressed
    spring and not clipped; u the unit direction). ``springs``: :attr:`SymmetricPattern.springs`.
    """
    si, sj, rest, alpha, beta, ec, law, sfi, sfj, soff = springs
    en = 0.0
    for k in range(si.shape[0]):
        i = si[k]
        j = sj[k]
        rx = x[j, 0] - x[i, 0]
        ry = x[j, 1] - x[i, 1]
        rz = x[j, 2] - x[i, 2]
        d = np.sqrt(rx * rx + ry * ry + rz * rz)
        e = d - rest[k]
        a = alpha[k]
        c = ec[k]
        if e <= c:
            en += 0.5 * a * e * e
            s = a * e
            cs = a
        elif law == 1:  # LAW_PAPER
            en += 0.5 * a * c * c + 0.5 * beta[k] * (e * e - c * c)
            s = beta[k] * e
            cs = beta[k]
        else:
            de = e - c
            en += a * c * (0.5 * c + de) + 0.5 * beta[k] * de * de
            s = a * c + beta[k] * de
            cs = beta[k]
        if (want_g or want_h) and d >= MIN_SPRING_LENGTH:
            inv = 1.0 / d
            g = s * inv
            fi = sfi[k]
            fj = sfj[k]
            if want_g:
                if fi >= 0:
                    grad[fi, 0] -= g * rx
                    grad[fi, 1] -= g * ry
                    grad[fi, 2] -= g * rz
                if fj >= 0:
                    grad[fj, 0] += g * rx
                    grad[fj, 1] += g * ry
                    grad[fj, 2] += g * rz
            if want_h:
                w = (cs - g) * inv * inv
                h0 = w * rx * rx + g
                h1 = w * rx * ry
                h2 = w * rx * rz
                h4 = w * ry * ry + g
                h5 = w * ry * rz
                h8 = w * rz * rz + g
                _add_upper6(dvals, fi, h0, h1, h2, h4, h5, h8)
                _add_upper6(dvals, fj, h0, h1, h2, h4, h5, h8)
                _add_sym6(lvals, soff[k], -h0, -h1, -h2, -h4, -h5, -h8)
    return en


@njit(cache=True, nogil=True, fastmath=True)
def _prism_pass(x, prisms, grad, want_g, dvals, lvals, want_h):
    """The volume penalty Q = kv (V - V0)^2 of the prisms: its energy (nJ, returned), its
    gradient added to ``grad`` (F, 3) when ``want_g``, and its Hessian added to ``dvals``,
    ``lvals`` when ``want_h`` (:func:`add_one_prism_hessian`). A prism's volume is the sum of
    its three tetrahedra's (nodes t .. t+3, :data:`~myoface.tissue.forces.PRISM_TETS`), each a
    sixth of a triple product. ``prisms``: :attr:`SymmetricPattern.prisms`."""
    elems, efree, rest_vol, kv, vsign, pslots, prev = prisms
    gr = np.empty((6, 3))
    pts = np.empty((6, 3))
    en = 0.0
    for q in range(elems.shape[0]):
        el = elems[q]
        for a in range(6):  # the prism's nodes, loaded once
            i = el[a]
            pts[a, 0] = x[i, 0]
            pts[a, 1] = x[i, 1]
            pts[a, 2] = x[i, 2]
            gr[a, 0] = 0.0
            gr[a, 1] = 0.0
            gr[a, 2] = 0.0
        vol = 0.0
        for t in range(3):
            vol6, g1x, g1y, g1z, g2x, g2y, g2z, g3x, g3y, g3z = _tet_gradient(
                pts, t, t + 1, t + 2, t + 3
            )
            vol += vol6
            if want_g or want_h:  # the triple product's gradient over the four nodes
                gr[t + 1, 0] += g1x
                gr[t + 1, 1] += g1y
                gr[t + 1, 2] += g1z
                gr[t + 2, 0] += g2x
                gr[t + 2, 1] += g2y
                gr[t + 2, 2] += g2z
                gr[t + 3, 0] += g3x
                gr[t + 3, 1] += g3y
                gr[t + 3, 2] += g3z
                gr[t, 0] -= g1x + g2x + g3x
                gr[t, 1] -= g1y + g2y + g3y
                gr[t, 2] -= g1z + g2z + g3z
        dv = vsign * vol / 6.0 - rest_vol[q]
        en += kv[q] * dv * dv
        fr = efree[q]
        if want_g:
            coef = 2.0 * kv[q] * dv * vsign / 6.0
            for a in range(6):
                fa = fr[a]
                if fa >= 0:
                    grad[fa, 0] += coef * gr[a, 0]
                    grad[fa, 1] += coef * gr[a, 1]
                    grad[fa, 2] += coef * gr[a, 2]
        if want_h:
            add_one_prism_hessian(pts, gr, dv, kv[q], vsign, fr, pslots[q], prev[q], dvals, lvals)
    return en


@njit(cache=True, nogil=True, fastmath=True)
def _add_outer(dvals, fa, a0, a1, a2):
    """Add the upper triangle of ``a a^T`` to diagonal block ``fa`` of ``dvals`` (nothing if
    fa < 0; the lower one is left for :func:`symmetrize_diagonal`)."""
    _add_upper6(dvals, fa, a0 * a0, a0 * a1, a0 * a2, a1 * a1, a1 * a2, a2 * a2)


@njit(cache=True, nogil=True, fastmath=True)
def _add_pair(lvals, slot, rev, a0, a1, a2, b0, b1, b2, w0, w1, w2):
    """Add ``H_ab = a b^T + [w]x`` (``[w]x`` the cross-product matrix of w) to lower block
    ``slot`` of ``lvals``, or its transpose ``H_ba`` if ``rev``; nothing if slot < 0."""
    if slot >= 0:
        o = 9 * slot
        if rev:
            lvals[o] += b0 * a0
            lvals[o + 1] += b0 * a1 + w2
            lvals[o + 2] += b0 * a2 - w1
            lvals[o + 3] += b1 * a0 - w2
            lvals[o + 4] += b1 * a1
            lvals[o + 5] += b1 * a2 + w0
            lvals[o + 6] += b2 * a0 + w1
            lvals[o + 7] += b2 * a1 - w0
            lvals[o + 8] += b2 * a2
        else:
            lvals[o] += a0 * b0
            lvals[o + 1] += a0 * b1 - w2
            lvals[o + 2] += a0 * b2 + w1
            lvals[o + 3] += a1 * b0 + w2
            lvals[o + 4] += a1 * b1
            lvals[o + 5] += a1 * b2 - w0
            lvals[o + 6] += a2 * b0 - w1
            lvals[o + 7] += a2 * b1 + w0
            lvals[o + 8] += a2 * b2


@njit(cache=True, nogil=True, fastmath=True)
def add_one_prism_hessian(pts, gr, dv, kvq, vsign, fr, sl, rv, dvals, lvals):
    """One prism's Hessian ``2 kv (dV/dx_a)(dV/dx_b)^T + 2 kv (V - V0) d2V/dx_a dx_b`` (the
    second a skew 3x3 block, zero on the diagonal) added to the symmetric storage: its nodes
    ``pts`` (6, 3) mm, the gradient of 6 times its volume ``gr`` (6, 3), its volume change
    ``dv`` (mm^3) and weight ``kvq``, the free numbers of its nodes ``fr`` (6,), its lower
    blocks ``sl`` (15,) and reversal mask ``rv`` (see :class:`SymmetricPattern`).

    Written out pair by pair (no tables, every index a constant): the second derivative of the
    prism's 6 V for its node pair (a, b) of :data:`PRISM_PAIRS` is the sum of ``[x_k - x_l]x``
    over the prism's tetrahedra that hold both nodes, (a, b, k, l) an even permutation of the
    tetrahedron's nodes (the tests hold the Hessian against finite differences of the forces);
    pairs (0, 4), (0, 5) and (1, 5) share no tetrahedron.
    On the default face the prisms' pass with the Hessian 364 -> 235 us (thread CPU, fastest of
    20 runs, alternating with the table-driven loop it replaces)."""
    sw = np.sqrt(2.0 * kvq) * abs(vsign) / 6.0
    g00 = gr[0, 0] * sw
    g01 = gr[0, 1] * sw
    g02 = gr[0, 2] * sw
    g10 = gr[1, 0] * sw
    g11 = gr[1, 1] * sw
    g12 = gr[1, 2] * sw
    g20 = gr[2, 0] * sw
    g21 = gr[2, 1] * sw
    g22 = gr[2, 2] * sw
    g30 = gr[3, 0] * sw
    g31 = gr[3, 1] * sw
    g32 = gr[3, 2] * sw
    g40 = gr[4, 0] * sw
    g41 = gr[4, 1] * sw
    g42 = gr[4, 2] * sw
    g50 = gr[5, 0] * sw
    g51 = gr[5, 1] * sw
    g52 = gr[5, 2] * sw
    _add_outer(dvals, fr[0], g00, g01, g02)
    _add_outer(dvals, fr[1], g10, g11, g12)
    _add_outer(dvals, fr[2], g20, g21, g22)
    _add_outer(dvals, fr[3], g30, g31, g32)
    _add_outer(dvals, fr[4], g40, g41, g42)
    _add_outer(dvals, fr[5], g50, g51, g52)
    c = 2.0 * kvq * dv * vsign / 6.0  # the skew vectors w_ab = c (x_k - x_l)
    d23x = c * (pts[2, 0] - pts[3, 0])
    d23y = c * (pts[2, 1] - pts[3, 1])
    d23z = c * (pts[2, 2] - pts[3, 2])
    d31x = c * (pts[3, 0] - pts[1, 0])
    d31y = c * (pts[3, 1] - pts[1, 1])
    d31z = c * (pts[3, 2] - pts[1, 2])
    d04x = c * (pts[0, 0] - pts[4, 0])
    d04y = c * (pts[0, 1] - pts[4, 1])
    d04z = c * (pts[0, 2] - pts[4, 2])
    d05x = c * (pts[0, 0] - pts[5, 0])
    d05y = c * (pts[0, 1] - pts[5, 1])
    d05z = c * (pts[0, 2] - pts[5, 2])
    d51x = c * (pts[5, 0] - pts[1, 0])
    d51y = c * (pts[5, 1] - pts[1, 1])
    d51z = c * (pts[5, 2] - pts[1, 2])
    d34x = c * (pts[3, 0] - pts[4, 0])
    d34y = c * (pts[3, 1] - pts[4, 1])
    d34z = c * (pts[3, 2] - pts[4, 2])
    d42x = c * (pts[4, 0] - pts[2, 0])
    d42y = c * (pts[4, 1] - pts[2, 1])
    d42z = c * (pts[4, 2] - pts[2, 2])
    d12x = -(d23x + d31x)  # x_1 - x_2 = -((x_2 - x_3) + (x_3 - x_1))
    d12y = -(d23y + d31y)
    d12z = -(d23z + d31z)
    # pair: (0, 1) (0, 2) (0, 3) (0, 4) (0, 5) (1, 2) (1, 3) (1, 4) (1, 5) (2, 3) (2, 4) (2, 5)
    # (3, 4) (3, 5) (4, 5); x_k - x_l: 2-3, 3-1, 1-2, -, -, 0-4, 4-0, 2-3, -, 0-5, 5-1, 3-4,
    # 1-5, 4-2, 2-3
    _add_pair(lvals, sl[0], rv & 1, g00, g01, g02, g10, g11, g12, d23x, d23y, d23z)
    _add_pair(lvals, sl[1], rv >> 1 & 1, g00, g01, g02, g20, g21, g22, d31x, d31y, d31z)
    _add_pair(lvals, sl[2], rv >> 2 & 1, g00, g01, g02, g30, g31, g32, d12x, d12y, d12z)
    _add_pair(lvals, sl[3], rv >> 3 & 1, g00, g01, g02, g40, g41, g42, 0.0, 0.0, 0.0)
    _add_pair(lvals, sl[4], rv >> 4 & 1, g00, g01, g02, g50, g51, g52, 0.0, 0.0, 0.0)
    _add_pair(lvals, sl[5], rv >> 5 & 1, g10, g11, g12, g20, g21, g22, d04x, d04y, d04z)
    _add_pair(lvals, sl[6], rv >> 6 & 1, g10, g11, g12, g30, g31, g32, -d04x, -d04y, -d04z)
    _add_pair(lvals, sl[7], rv >> 7 & 1, g10, g11, g12, g40, g41, g42, d23x, d23y, d23z)
    _add_pair(lvals, sl[8], rv >> 8 & 1, g10, g11, g12, g50, g51, g52, 0.0, 0.0, 0.0)
    _add_pair(lvals, sl[9], rv >> 9 & 1, g20, g21, g22, g30, g31, g32, d05x, d05y, d05z)
    _add_pair(lvals, sl[10], rv >> 10 & 1, g20, g21, g22, g40, g41, g42, d51x, d51y, d51z)
    _add_pair(lvals, sl[11], rv >> 11 & 1, g20, g21, g22, g50, g51, g52, d34x, d34y, d34z)
    _add_pair(lvals, sl[12], rv >> 12 & 1, g30, g31, g32, g40, g41, g42, -d51x, -d51y, -d51z)
    _add_pair(lvals, sl[13], rv >> 13 & 1, g30, g31, g32, g50, g51, g52, d42x, d42y, d42z)
    _add_pair(lvals, sl[14], rv >> 14 & 1, g40, g41, g42, g50, g51, g52, d23x, d23y, d23z)


# ------------------------------------------------ the prisms' energy and gradient, vectorised ----
#
# Without the Hessian, the prisms' pass is made in chunks of PRISM_CHUNK prisms: their nodes'
# coordinates gathered into a scratch array, the arithmetic done there lane by lane (the compiler
# vectorises it, four prisms at a time), the gradient's terms then added to the free nodes (as
# :func:`myoface.tissue.forces.prism_volume_forces_split` and the RK2 kernel's chunks do). On the
# default face 74 -> 54 us a pass.

#: prisms per chunk of :func:`prism_energy_gradient` (its scratch, 38 rows of this many float64,
#: ~20 kB, stays in the L1 cache)
PRISM_CHUNK = 64


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _chunk_tet(w, q, o0, o1, o2, o3):
    """:func:`~myoface.tissue.forces._tet_gradient` of the tetrahedron whose nodes' coordinates
    are rows 3 o0 .. 3 o3 + 2 of the chunk ``w``, lane q."""
    c = PRISM_CHUNK
    ax = w[(3 * o1) * c + q] - w[(3 * o0) * c + q]
    ay = w[(3 * o1 + 1) * c + q] - w[(3 * o0 + 1) * c + q]
    az = w[(3 * o1 + 2) * c + q] - w[(3 * o0 + 2) * c + q]
    bx = w[(3 * o2) * c + q] - w[(3 * o0) * c + q]
    by = w[(3 * o2 + 1) * c + q] - w[(3 * o0 + 1) * c + q]
    bz = w[(3 * o2 + 2) * c + q] - w[(3 * o0 + 2) * c + q]
    cx = w[(3 * o3) * c + q] - w[(3 * o0) * c + q]
    cy = w[(3 * o3 + 1) * c + q] - w[(3 * o0 + 1) * c + q]
    cz = w[(3 * o3 + 2) * c + q] - w[(3 * o0 + 2) * c + q]
    g1x = by * cz - bz * cy
    g1y = bz * cx - bx * cz
    g1z = bx * cy - by * cx
    g2x = cy * az - cz * ay
    g2y = cz * ax - cx * az
    g2z = cx * ay - cy * ax
    g3x = ay * bz - az * by
    g3y = az * bx - ax * bz
    g3z = ax * by - ay * bx
    vol6 = ax * g1x + ay * g1y + az * g1z
    return vol6, g1x, g1y, g1z, g2x, g2y, g2z, g3x, g3y, g3z


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _chunk_energy_gradient(w, vsign):
    """The volume penalty's energy (returned) and gradient of a chunk of prisms, lane by lane:
    rows 0..17 of ``w`` (the six nodes' coordinates), 18 (rest volume), 19 (weight) in, rows
    20..37 (the six nodes' gradient terms) out."""
    c = PRISM_CHUNK
    en = 0.0
    for q in range(c):
        v0, a1x, a1y, a1z, a2x, a2y, a2z, a3x, a3y, a3z = _chunk_tet(w, q, 0, 1, 2, 3)
        v1, b1x, b1y, b1z, b2x, b2y, b2z, b3x, b3y, b3z = _chunk_tet(w, q, 1, 2, 3, 4)
        v2, c1x, c1y, c1z, c2x, c2y, c2z, c3x, c3y, c3z = _chunk_tet(w, q, 2, 3, 4, 5)
        dv = vsign * (v0 + v1 + v2) / 6.0 - w[18 * c + q]
        kv = w[19 * c + q]
        en += kv * dv * dv
        coef = 2.0 * kv * dv * vsign / 6.0
        w[20 * c + q] = -coef * (a1x + a2x + a3x)
        w[21 * c + q] = -coef * (a1y + a2y + a3y)
        w[22 * c + q] = -coef * (a1z + a2z + a3z)
        w[23 * c + q] = coef * (a1x - (b1x + b2x + b3x))
        w[24 * c + q] = coef * (a1y - (b1y + b2y + b3y))
        w[25 * c + q] = coef * (a1z - (b1z + b2z + b3z))
        w[26 * c + q] = coef * (a2x + b1x - (c1x + c2x + c3x))
        w[27 * c + q] = coef * (a2y + b1y - (c1y + c2y + c3y))
        w[28 * c + q] = coef * (a2z + b1z - (c1z + c2z + c3z))
        w[29 * c + q] = coef * (a3x + b2x + c1x)
        w[30 * c + q] = coef * (a3y + b2y + c1y)
        w[31 * c + q] = coef * (a3z + b2z + c1z)
        w[32 * c + q] = coef * (b3x + c2x)
        w[33 * c + q] = coef * (b3y + c2y)
        w[34 * c + q] = coef * (b3z + c2z)
        w[35 * c + q] = coef * c3x
        w[36 * c + q] = coef * c3y
        w[37 * c + q] = coef * c3z
    return en


@njit(cache=True, nogil=True, fastmath=True)
def prism_energy_gradient(x, prisms, grad):
    """:func:`_prism_pass` without the Hessian, vectorised: the prisms' energy (nJ, returned)
    and their gradient (uN) added to ``grad`` (F, 3)."""
    elems, efree, rest_vol, kv, vsign, _, _ = prisms
    c = PRISM_CHUNK
    w = np.empty(38 * c)
    ne = elems.shape[0]
    en = 0.0
    for c0 in range(0, ne, c):
        n = min(c, ne - c0)
        for q in range(n):
            e = c0 + q
            for s in range(6):
                m = elems[e, s]
                w[(3 * s) * c + q] = x[m, 0]
                w[(3 * s + 1) * c + q] = x[m, 1]
                w[(3 * s + 2) * c + q] = x[m, 2]
            w[18 * c + q] = rest_vol[e]
            w[19 * c + q] = kv[e]
        for q in range(n, c):  # lanes past the end: zero weight, no energy
            w[19 * c + q] = 0.0
            w[18 * c + q] = 0.0
        en += _chunk_energy_gradient(w, vsign)
        for q in range(n):
            e = c0 + q
            for s in range(6):
                fa = efree[e, s]
                if fa >= 0:
                    grad[fa, 0] += w[(20 + 3 * s) * c + q]
                    grad[fa, 1] += w[(21 + 3 * s) * c + q]
                    grad[fa, 2] += w[(22 + 3 * s) * c + q]
    return en


@njit(cache=True, nogil=True, fastmath=True)
def energy_gradient_hessian(x, springs, prisms, grad, want_h, dvals, lvals, want_p, dprism, lprism):
    """The potential energy E over the springs and prisms that touch a free node (nJ; E less
    a constant: the parts between kinematic nodes) and its gradient dE/dx (uN) into ``grad``
    (F, 3) in free-node order; in the same passes, when ``want_p``, the prisms' Hessian into
    ``dprism``, ``lprism``, and when ``want_h`` the Hessian into ``dvals``, ``lvals``: the
    springs' part plus the prisms' in ``dprism``, ``lprism`` (new, or as given). Symmetric
    storage of :class:`SymmetricPattern`, whose ``springs`` and ``prisms`` these are.
    Eq. (1)-(4) of Terzopoulos & Waters 1993."""
    grad[:, :] = 0.0
    if want_p:
        dprism[:] = 0.0
        lprism[:] = 0.0
    if want_p:
        en = _prism_pass(x, prisms, grad, True, dprism, lprism, True)
        symmetrize_diagonal(dprism)
    else:
        en = prism_energy_gradient(x, prisms, grad)
    if want_h:
        dvals[:] = dprism
        lvals[:] = lprism
    en += _spring_pass(x, springs, grad, True, dvals, lvals, want_h)
    if want_h:
        symmetrize_diagonal(dvals)
    return en


@njit(cache=True, nogil=True, fastmath=True)
def energy_gradient_free(x, springs, prisms, grad):
    """:func:`energy_gradient_hessian` without the Hessian: the energy (nJ, returned) and its
    gradient (uN) into ``grad`` (F, 3)."""
    grad[:, :] = 0.0
    none = np.empty(0)
    en = _spring_pass(x, springs, grad, True, none, none, False)
    return en + prism_energy_gradient(x, prisms, grad)


@njit(cache=True, nogil=True, fastmath=True)
def add_spring_hessian(x, springs, dvals, lvals):
    """Add the springs' Hessian at ``x`` (N, 3) mm to the symmetric storage (see
    :func:`_spring_pass`)."""
    _spring_pass(x, springs, np.empty((0, 3)), False, dvals, lvals, True)
    symmetrize_diagonal(dvals)


@njit(cache=True, nogil=True, fastmath=True)
def add_prism_hessian(x, prisms, dvals, lvals):
    """Add the volume penalty's Hessian at ``x`` (N, 3) mm to the symmetric storage (see
    :func:`add_one_prism_hessian`)."""
    _prism_pass(x, prisms, np.empty((0, 3)), False, dvals, lvals, True)
    symmetrize_diagonal(dvals)


@njit(cache=True, nogil=True, fastmath=True)
def symmetric_matvec(lptr, lcol, dvals, lvals, v, out):
    """``out = A v`` for A in the symmetric storage of :class:`SymmetricPattern`."""
    nf = lptr.shape[0] - 1
    for i in range(3 * nf):
        out[i] = 0.0
    for i in range(nf):
        o = 9 * i
        v0 = v[3 * i]
        v1 = v[3 * i + 1]
        v2 = v[3 * i + 2]
        s0 = dvals[o] * v0 + dvals[o + 1] * v1 + dvals[o + 2] * v2
        s1 = dvals[o + 3] * v0 + dvals[o + 4] * v1 + dvals[o + 5] * v2
        s2 = dvals[o + 6] * v0 + dvals[o + 7] * v1 + dvals[o + 8] * v2
        for k in range(lptr[i], lptr[i + 1]):
            j = 3 * lcol[k]
            o = 9 * k
            u0 = v[j]
            u1 = v[j + 1]
            u2 = v[j + 2]
            s0 += lvals[o] * u0 + lvals[o + 1] * u1 + lvals[o + 2] * u2
            s1 += lvals[o + 3] * u0 + lvals[o + 4] * u1 + lvals[o + 5] * u2
            s2 += lvals[o + 6] * u0 + lvals[o + 7] * u1 + lvals[o + 8] * u2
            out[j] += lvals[o] * v0 + lvals[o + 3] * v1 + lvals[o + 6] * v2
            out[j + 1] += lvals[o + 1] * v0 + lvals[o + 4] * v1 + lvals[o + 7] * v2
            out[j + 2] += lvals[o + 2] * v0 + lvals[o + 5] * v1 + lvals[o + 8] * v2
        out[3 * i] += s0
        out[3 * i + 1] += s1
        out[3 * i + 2] += s2
