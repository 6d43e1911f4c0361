"""Fast equilibrium of the tissue lattice: inexact Newton with a factorisation kept per model.

The equilibrium with the kinematic nodes held at their targets is the minimum of the lattice's
potential energy E (springs, eq. 1-2, plus the volume penalty Q) over the free nodes. This
module finds it by Newton's method on the *exact* Hessian of E, each Newton system
``H s = -grad E`` solved inexactly by conjugate gradients preconditioned with one sparse
factorisation of the rest stiffness that is computed once per model:

1. **initial guess** — the free nodes' linear response to the move of the kinematic nodes
   (static condensation: ``dx_f = -K_ff^-1 K_fk dx_k``, K the rest stiffness). From rest this is
   the small-strain solution; from a previous equilibrium it is the linear correction for the
   change of targets;
2. **Newton steps** — the Hessian (springs with their tangent stiffness and unclipped geometric
   term, the volume penalty with its second-derivative term) assembled in 3x3 blocks straight
   into a fixed block-CSR pattern; PCG on it with the rest factor as preconditioner, to a relative
   accuracy eta that tightens as the gradient falls (Eisenstat & Walker 1996, choice 2); a
   direction of negative curvature ends the CG early (Steihaug 1983); an Armijo backtracking line
   search on E keeps every step a descent step. The factor is matched to the current Hessian by
   a 3x3 scaling per node, ``M^T K^-1 M`` with ``M_i = C_K,i C_H,i^-1`` (C: Cholesky factors of
   the nodes' diagonal blocks), which gives the preconditioner H's diagonal blocks exactly and
   takes a springs' stiffening past its threshold (beta = 10 alpha) out of the CG's work: it
   halves the condition number at an expression (71 -> 28 at "surprise") and the CG iterations.

The exact Hessian matters: with the compressive geometric term clipped (a positive
semi-definite "projected" Hessian) Newton converges only linearly here, since thousands of
springs are compressed in an expression; with it, quadratically.

The rest factor is a block (3x3) LDL^T in a node-level minimum-degree order (SuperLU's, on the
node graph), extracted once into flat arrays, so a preconditioner application is two sweeps of
a numba loop over about 27,000 3x3 blocks on the default face.

Thread safety: everything a model keeps (:class:`NewtonData`) is built once, under a lock, and
is read-only afterwards; every solve allocates its own work arrays.

References: Terzopoulos & Waters 1993, eq. (1)-(4); Nocedal & Wright 2006, Numerical
Optimization, ch. 7 (inexact / Newton-CG methods).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
from numba import njit
from scipy.sparse.linalg import splu

from myoface.errors import MyofaceSimulationError
from myoface.tissue.forces import MIN_SPRING_LENGTH, spring_magnitude
from myoface.tissue.hessian import BlockPattern, assemble_block_hessian
from myoface.tissue.model import TissueModel

#: default equilibrium tolerance of the Newton solver: the largest node move of the last Newton
#: step, mm. The step estimates the distance to the equilibrium and is taken; the error left
#: after it is about the CG's relative accuracy (ETA_MIN = 0.1) times the step, plus the
#: quadratic term, so 0.01 mm leaves about 1e-3 mm — a hundredth of the 0.1 mm that is visible
#: on a face model of this size.
NEWTON_TOL_MM = 0.01
#: the largest CG relative residual (forcing term) of a Newton system, and the smallest
ETA_MAX = 0.5
ETA_MIN = 0.1
#: CG iterations per Newton system at most
CG_MAX_ITER = 200
#: Armijo sufficient-decrease constant of the line search (Nocedal & Wright 2006, eq. 3.4)
ARMIJO_C = 1e-4
#: relative size of an energy change that is at the level of its rounding error: a Newton step
#: that predicts less decrease than this is taken without the (meaningless) energy test
ENERGY_ROUNDOFF = 1e-12

#: the rest stiffness is factorised with this fraction of its mean diagonal added (so a lattice
#: without kinematic nodes, whose stiffness is singular, still gets a preconditioner)
PRECOND_SHIFT = 1e-9

_CACHE_LOCK = threading.RLock()


def cached(model: TissueModel, key: str, build):
    """``model.cache[key]``, built by ``build()`` once: the first caller builds it under a lock
    (others asking at the same time wait and then share it); afterwards a plain lookup."""
    val = model.cache.get(key)
    if val is None:
        with _CACHE_LOCK:
            val = model.cache.get(key)
            if val is None:
                val = build()
                model.cache[key] = val
    return val


def kernel_args(model: TissueModel) -> tuple:
    """The packed arrays the energy, force and Hessian kernels take, in their argument order."""
    return (
        model.spring_i,
        model.spring_j,
        model.rest_length,
        model.spring_material,
        model.materials,
        model.spring_law,
        model.elements,
        model.rest_volume,
        model.volume_weight,
        model.volume_sign,
    )


# ---------------------------------------------------------------------- energy + gradient ----


@njit(cache=True, nogil=True)
def energy_gradient(x, si, sj, rest, mat_id, mat, law, elems, rest_vol, kv, vsign, grad):
    """Potential energy E (nJ) at ``x`` (N, 3) mm, and its gradient dE/dx = -(g + q) into
    ``grad`` (N, 3) uN, in one pass over springs and prisms (eq. 1-4)."""
    grad[:, :] = 0.0
    en = 0.0
    for k in range(si.shape[0]):
        i = si[k]
        j = sj[k]
        rx = x[j, 0] - x[i, 0]
        ry = x[j, 1] - x[i, 1]
        rz = x[j, 2] - x[i, 2]
        d = np.sqrt(rx * rx + ry * ry + rz * rz)
        lk = rest[k]
        e = d - lk
        m = mat_id[k]
        ec = mat[m, 2] * lk
        a = mat[m, 0]
        if e <= ec:
            en += 0.5 * a * e * e
        elif law == 1:  # LAW_PAPER
            en += 0.5 * a * ec * ec + 0.5 * mat[m, 1] * (e * e - ec * ec)
        else:
            en += 0.5 * a * ec * ec + a * ec * (e - ec) + 0.5 * mat[m, 1] * (e - ec) ** 2
        if d < MIN_SPRING_LENGTH:
            continue
        s = spring_magnitude(e, lk, m, mat, law) / d
        grad[i, 0] -= s * rx
        grad[i, 1] -= s * ry
        grad[i, 2] -= s * rz
        grad[j, 0] += s * rx
        grad[j, 1] += s * ry
        grad[j, 2] += s * rz
    g = np.empty((3, 3, 3))
    for q in range(elems.shape[0]):
        el = elems[q]
        vol = 0.0
        for t in range(3):
            i0 = el[t]
            i1 = el[t + 1]
            i2 = el[t + 2]
            i3 = el[t + 3]
            ax = x[i1, 0] - x[i0, 0]
            ay = x[i1, 1] - x[i0, 1]
            az = x[i1, 2] - x[i0, 2]
            bx = x[i2, 0] - x[i0, 0]
            by = x[i2, 1] - x[i0, 1]
            bz = x[i2, 2] - x[i0, 2]
            cx = x[i3, 0] - x[i0, 0]
            cy = x[i3, 1] - x[i0, 1]
            cz = x[i3, 2] - x[i0, 2]
            g[t, 0, 0] = by * cz - bz * cy
            g[t, 0, 1] = bz * cx - bx * cz
            g[t, 0, 2] = bx * cy - by * cx
            g[t, 1, 0] = cy * az - cz * ay
            g[t, 1, 1] = cz * ax - cx * az
            g[t, 1, 2] = cx * ay - cy * ax
            g[t, 2, 0] = ay * bz - az * by
            g[t, 2, 1] = az * bx - ax * bz
            g[t, 2, 2] = ax * by - ay * bx
            vol += ax * g[t, 0, 0] + ay * g[t, 0, 1] + az * g[t, 0, 2]
        dv = vsign * vol / 6.0 - rest_vol[q]
        en += kv[q] * dv * dv
        coef = 2.0 * kv[q] * dv * vsign / 6.0
        if coef == 0.0:
            continue
        # tetrahedron t of the prism is slots (t, t+1, t+2, t+3) (PRISM_TETS)
        for t in range(3):
            i0 = el[t]
            for r in range(3):
                iq = el[t + 1 + r]
                for c in range(3):
                    grad[iq, c] += coef * g[t, r, c]
                    grad[i0, c] -= coef * g[t, r, c]
    return en


@njit(cache=True, nogil=True)
def _energy_only(x, si, sj, rest, mat_id, mat, law, elems, rest_vol, kv, vsign):
    en = 0.0
    for k in range(si.shape[0]):
        i = si[k]
        j = sj[k]
        rx = x[j, 0] - x[i, 0]
        ry = x[j, 1] - x[i, 1]
        rz = x[j, 2] - x[i, 2]
        lk = rest[k]
        e = np.sqrt(rx * rx + ry * ry + rz * rz) - lk
        m = mat_id[k]
        ec = mat[m, 2] * lk
        a = mat[m, 0]
        if e <= ec:
            en += 0.5 * a * e * e
        elif law == 1:
            en += 0.5 * a * ec * ec + 0.5 * mat[m, 1] * (e * e - ec * ec)
        else:
            en += 0.5 * a * ec * ec + a * ec * (e - ec) + 0.5 * mat[m, 1] * (e - ec) ** 2
    for q in range(elems.shape[0]):
        el = elems[q]
        vol = 0.0
        for t in range(3):
            i0 = el[t]
            i1 = el[t + 1]
            i2 = el[t + 2]
            i3 = el[t + 3]
            ax = x[i1, 0] - x[i0, 0]
            ay = x[i1, 1] - x[i0, 1]
            az = x[i1, 2] - x[i0, 2]
            bx = x[i2, 0] - x[i0, 0]
            by = x[i2, 1] - x[i0, 1]
            bz = x[i2, 2] - x[i0, 2]
            cx = x[i3, 0] - x[i0, 0]
            cy = x[i3, 1] - x[i0, 1]
            cz = x[i3, 2] - x[i0, 2]
            vol += ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx)
        dv = vsign * vol / 6.0 - rest_vol[q]
        en += kv[q] * dv * dv
    return en


# ------------------------------------------------------------------ block LDL^T and PCG ----


@dataclass(frozen=True)
class BlockLDL:
    """A symmetric positive definite matrix over F nodes factorised as P^T L D L^T P in 3x3
    blocks: ``perm`` (F,) the node order, L unit lower triangular — its diagonal blocks in
    ``diag`` (F*9,), its off-diagonal blocks by block column (``ptr`` (F+1,), ``rows``,
    ``vals`` (nnzb*9,), row-major 3x3) — and ``dinv`` (3F,) the inverse of D."""

    perm: np.ndarray
    ptr: np.ndarray
    rows: np.ndarray
    vals: np.ndarray
    diag: np.ndarray
    dinv: np.ndarray

    def solve(self, b: np.ndarray) -> np.ndarray:
        out = np.empty(len(b))
        ldl_solve(
            self.ptr,
            self.rows,
            self.vals,
            self.diag,
            self.dinv,
            self.perm,
            b,
            out,
            np.empty(len(b)),
        )
        return out


def block_ldl(a: sp.spmatrix, n_nodes: int, node_graph: sp.spmatrix) -> BlockLDL:
    """Factorise the SPD matrix ``a`` (3F x 3F, dofs node-major) as a :class:`BlockLDL`.

    The node order is SuperLU's multiple minimum degree on the node graph (so the three dofs of
    a node stay together and L is made of full 3x3 blocks); the numeric factorisation is
    SuperLU's without pivoting in that order, in its symmetric mode, whose ``U`` is ``D L^T``."""
    f = n_nodes
    g = (abs(node_graph) + sp.eye(f) * f).tocsc()  # diagonally dominant: no pivoting needed
    order = np.argsort(
        splu(
            g, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
        ).perm_c
    )
    p = (3 * order[:, None] + np.arange(3)).reshape(-1)
    lu = splu(
        sp.csc_matrix(a)[p][:, p].tocsc(),
        permc_spec="NATURAL",
        diag_pivot_thresh=0.0,
        options={"SymmetricMode": True},
    )
    if not (np.all(lu.perm_r == np.arange(3 * f)) and np.all(lu.perm_c == np.arange(3 * f))):
        raise MyofaceSimulationError("block LDL^T: SuperLU pivoted; the matrix is not SPD")
    d = lu.U.diagonal()
    if not np.all(d > 0):
        raise MyofaceSimulationError("block LDL^T: a non-positive pivot; the matrix is not SPD")
    lc = lu.L.tocoo()
    r, c, v = lc.row, lc.col, lc.data
    br, bc = r // 3, c // 3
    on = br == bc
    diag = np.zeros((f, 3, 3))
    diag[br[on], r[on] % 3, c[on] % 3] = v[on]
    off = ~on
    key = bc[off].astype(np.int64) * f + br[off]
    uk, inv = np.unique(key, return_inverse=True)
    vals = np.zeros((len(uk), 3, 3))
    np.add.at(vals, (inv, r[off] % 3, c[off] % 3), v[off])
    ptr = np.zeros(f + 1, np.int64)
    np.add.at(ptr, uk // f + 1, 1)
    return BlockLDL(
        perm=_ro(order.astype(np.int64)),
        ptr=_ro(np.cumsum(ptr)),
        rows=_ro((uk % f).astype(np.int64)),
        vals=_ro(vals.reshape(-1)),
        diag=_ro(diag.reshape(-1)),
        dinv=_ro(1.0 / d),
    )


def _ro(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.flags.writeable = False
    return a


@njit(cache=True, nogil=True)
def ldl_solve(ptr, rows, vals, diag, dinv, perm, b, out, y):
    """``out = A^-1 b`` for A = P^T L D L^T P in 3x3 blocks (see :class:`BlockLDL`); ``y`` is
    work space of the size of ``b``."""
    nb = perm.shape[0]
    for J in range(nb):
        p = 3 * perm[J]
        y[3 * J] = b[p]
        y[3 * J + 1] = b[p + 1]
        y[3 * J + 2] = b[p + 2]
    for J in range(nb):  # L y = b
        o = 9 * J
        y0 = y[3 * J]
        y1 = y[3 * J + 1] - diag[o + 3] * y0
        y2 = y[3 * J + 2] - diag[o + 6] * y0 - diag[o + 7] * y1
        y[3 * J + 1] = y1
        y[3 * J + 2] = y2
        for k in range(ptr[J], ptr[J + 1]):
            i = 3 * rows[k]
            o = 9 * k
            y[i] -= vals[o] * y0 + vals[o + 1] * y1 + vals[o + 2] * y2
            y[i + 1] -= vals[o + 3] * y0 + vals[o + 4] * y1 + vals[o + 5] * y2
            y[i + 2] -= vals[o + 6] * y0 + vals[o + 7] * y1 + vals[o + 8] * y2
    for i in range(3 * nb):  # D
        y[i] *= dinv[i]
    for J in range(nb - 1, -1, -1):  # L^T y = ...
        y0 = y[3 * J]
        y1 = y[3 * J + 1]
        y2 = y[3 * J + 2]
        for k in range(ptr[J], ptr[J + 1]):
            i = 3 * rows[k]
            o = 9 * k
            a0 = y[i]
            a1 = y[i + 1]
            a2 = y[i + 2]
            y0 -= vals[o] * a0 + vals[o + 3] * a1 + vals[o + 6] * a2
            y1 -= vals[o + 1] * a0 + vals[o + 4] * a1 + vals[o + 7] * a2
            y2 -= vals[o + 2] * a0 + vals[o + 5] * a1 + vals[o + 8] * a2
        o = 9 * J
        y1 -= diag[o + 7] * y2
        y0 -= diag[o + 3] * y1 + diag[o + 6] * y2
        y[3 * J] = y0
        y[3 * J + 1] = y1
        y[3 * J + 2] = y2
    for J in range(nb):
        p = 3 * perm[J]
        out[p] = y[3 * J]
        out[p + 1] = y[3 * J + 1]
        out[p + 2] = y[3 * J + 2]


@njit(cache=True, nogil=True)
def bsr_matvec(indptr, indices, bvals, v, out):
    """``out = A v`` for A in block CSR with 3x3 blocks (``bvals`` (nnzb*9,), row-major)."""
    for i in range(indptr.shape[0] - 1):
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            j = 3 * indices[k]
            o = 9 * k
            v0 = v[j]
            v1 = v[j + 1]
            v2 = v[j + 2]
            s0 += bvals[o] * v0 + bvals[o + 1] * v1 + bvals[o + 2] * v2
            s1 += bvals[o + 3] * v0 + bvals[o + 4] * v1 + bvals[o + 5] * v2
            s2 += bvals[o + 6] * v0 + bvals[o + 7] * v1 + bvals[o + 8] * v2
        out[3 * i] = s0
        out[3 * i + 1] = s1
        out[3 * i + 2] = s2


@njit(cache=True, nogil=True)
def _chol3(a, o, out):
    """Lower Cholesky factor of the symmetric 3x3 block ``a[o:o+9]`` into ``out`` (9,);
    False if the block is not positive definite."""
    l00 = a[o]
    if not l00 > 0.0:
        return False
    l00 = np.sqrt(l00)
    l10 = a[o + 3] / l00
    l20 = a[o + 6] / l00
    d1 = a[o + 4] - l10 * l10
    if not d1 > 0.0:
        return False
    l11 = np.sqrt(d1)
    l21 = (a[o + 7] - l20 * l10) / l11
    d2 = a[o + 8] - l20 * l20 - l21 * l21
    if not d2 > 0.0:
        return False
    out[0] = l00
    out[1] = 0.0
    out[2] = 0.0
    out[3] = l10
    out[4] = l11
    out[5] = 0.0
    out[6] = l20
    out[7] = l21
    out[8] = np.sqrt(d2)
    return True


@njit(cache=True, nogil=True)
def block_scaling(indptr, indices, bvals, rest_chol, scale):
    """Per free node the 3x3 matrix ``M_i = C_K,i C_H,i^-1`` (C: lower Cholesky factors of the
    diagonal blocks of the rest stiffness K, given, and of the Hessian H, from ``bvals``) into
    ``scale`` (F*9,): the preconditioner ``M^T K^-1 M`` then has exactly H's diagonal blocks.
    Where H's block is not positive definite, M_i = C_K,i C_K,i^-1 = I."""
    ch = np.empty(9)
    for i in range(indptr.shape[0] - 1):
        # the diagonal block of row i
        d = -1
        for k in range(indptr[i], indptr[i + 1]):
            if indices[k] == i:
                d = k
                break
        o = 9 * i
        if d < 0 or not _chol3(bvals, 9 * d, ch):
            for q in range(9):
                scale[o + q] = 1.0 if q % 4 == 0 else 0.0
            continue
        # inverse of the lower triangular ch
        i00 = 1.0 / ch[0]
        i11 = 1.0 / ch[4]
        i22 = 1.0 / ch[8]
        i10 = -ch[3] * i00 * i11
        i21 = -ch[7] * i11 * i22
        i20 = -(ch[6] * i00 + ch[7] * i10) * i22
        c = rest_chol
        # M = C_K (lower) @ inv(C_H) (lower): lower triangular
        scale[o] = c[o] * i00
        scale[o + 1] = 0.0
        scale[o + 2] = 0.0
        scale[o + 3] = c[o + 3] * i00 + c[o + 4] * i10
        scale[o + 4] = c[o + 4] * i11
        scale[o + 5] = 0.0
        scale[o + 6] = c[o + 6] * i00 + c[o + 7] * i10 + c[o + 8] * i20
        scale[o + 7] = c[o + 7] * i11 + c[o + 8] * i21
        scale[o + 8] = c[o + 8] * i22


@njit(cache=True, nogil=True)
def _precond(ptr, rows, vals, diag, dinv, perm, scale, r, z, y, t):
    """z = M^T K^-1 M r (see :func:`block_scaling`); t, y: work."""
    nb = perm.shape[0]
    for i in range(nb):
        o = 9 * i
        r0 = r[3 * i]
        r1 = r[3 * i + 1]
        r2 = r[3 * i + 2]
        t[3 * i] = scale[o] * r0
        t[3 * i + 1] = scale[o + 3] * r0 + scale[o + 4] * r1
        t[3 * i + 2] = scale[o + 6] * r0 + scale[o + 7] * r1 + scale[o + 8] * r2
    ldl_solve(ptr, rows, vals, diag, dinv, perm, t, z, y)
    for i in range(nb):
        o = 9 * i
        z0 = z[3 * i]
        z1 = z[3 * i + 1]
        z2 = z[3 * i + 2]
        z[3 * i] = scale[o] * z0 + scale[o + 3] * z1 + scale[o + 6] * z2
        z[3 * i + 1] = scale[o + 4] * z1 + scale[o + 7] * z2
        z[3 * i + 2] = scale[o + 8] * z2


@njit(cache=True, nogil=True)
def pcg(
    indptr, indices, bvals, ptr, rows, vals, diag, dinv, perm, scale, b, eta, max_iter, x, work
):
    """Preconditioned CG on ``A x = b`` (A block CSR, preconditioner the block LDL^T), from 0,
    until ``sqrt(r.z) <= eta sqrt(r0.z0)`` (z = M^-1 r). Stops early on a direction of negative
    or zero curvature: x keeps the last iterate, or the preconditioned residual if that happens
    at once (Steihaug 1983). ``work``: (6, n). Returns (iterations, 1 if it stopped on curvature)."""
    n = b.shape[0]
    r = work[0]
    z = work[1]
    p = work[2]
    q = work[3]
    y = work[4]
    t = work[5]
    for i in range(n):
        x[i] = 0.0
        r[i] = b[i]
    _precond(ptr, rows, vals, diag, dinv, perm, scale, r, z, y, t)
    rz = 0.0
    for i in range(n):
        p[i] = z[i]
        rz += r[i] * z[i]
    stop = eta * eta * rz
    for it in range(max_iter):
        bsr_matvec(indptr, indices, bvals, p, q)
        pq = 0.0
        for i in range(n):
            pq += p[i] * q[i]
        if not pq > 0.0:
            if it == 0:
                for i in range(n):
                    x[i] = z[i]
            return it + 1, 1
        a = rz / pq
        for i in range(n):
            x[i] += a * p[i]
            r[i] -= a * q[i]
        _precond(ptr, rows, vals, diag, dinv, perm, scale, r, z, y, t)
        rz_new = 0.0
        for i in range(n):
            rz_new += r[i] * z[i]
        if rz_new <= stop:
            return it + 1, 0
        beta = rz_new / rz
        rz = rz_new
        for i in range(n):
            p[i] = z[i] + beta * p[i]
    return max_iter, 0


# ------------------------------------------------------------------------- per-model data ----


@dataclass(frozen=True)
class NewtonData:
    """What the Newton solver keeps per model (read-only arrays, built once).

    Attributes
    ----------
    pattern : BlockPattern — the block CSR pattern of the free-node Hessian.
    precond : BlockLDL — the rest stiffness over the free nodes, factorised.
    coupling : scipy CSR (3F x 3K) — the rest stiffness between free and kinematic dofs, K_fk.
    """

    pattern: BlockPattern
    precond: BlockLDL
    coupling: sp.csr_matrix
    rest_chol: np.ndarray


def newton_data(model: TissueModel) -> NewtonData:
    """The model's :class:`NewtonData`, built on first use (under a lock) and kept in its cache."""
    return cached(model, "newton_data", lambda: _build_newton_data(model))


def _build_newton_data(model: TissueModel) -> NewtonData:
    pat = BlockPattern(
        model.n_nodes, model.free_index, model.spring_i, model.spring_j, model.elements
    )
    x0 = model.rest_positions
    bvals = np.empty(pat.nnzb * 9)
    assemble_block_hessian(
        x0, *kernel_args(model), pat.fmap, pat.spring_slots, pat.element_slots, bvals
    )
    k = pat.scalar_matrix(bvals)
    nf = pat.n_free
    # a rest stiffness that is singular (a lattice with no kinematic node has rigid motions) is
    # made definite by a shift far below its stiffness; the factor only preconditions
    shift = PRECOND_SHIFT * float(np.abs(k.diagonal()).mean() or 1.0)
    k = (k + shift * sp.eye(3 * nf)).tocsc()
    node_graph = sp.csr_matrix((np.ones(len(pat.indices)), pat.indices, pat.indptr), shape=(nf, nf))
    precond = block_ldl(k, nf, node_graph)
    # K_fk at rest: the Hessian of a copy of the model in which every node is free
    allfree = replace(model, kinematic=np.zeros(model.n_nodes, bool), cache={})
    pat_all = BlockPattern(
        model.n_nodes, np.arange(model.n_nodes), model.spring_i, model.spring_j, model.elements
    )
    ball = np.empty(pat_all.nnzb * 9)
    assemble_block_hessian(
        x0, *kernel_args(allfree), pat_all.fmap, pat_all.spring_slots, pat_all.element_slots, ball
    )
    kall = pat_all.scalar_matrix(ball).tocsr()
    fd = (3 * model.free_index[:, None] + np.arange(3)).reshape(-1)
    kd = (3 * model.kinematic_index[:, None] + np.arange(3)).reshape(-1)
    coupling = kall[fd][:, kd].tocsr()
    coupling.data.flags.writeable = False
    rest_chol = np.empty(9 * nf)
    ident = np.tile(np.eye(3).reshape(-1), nf)
    block_scaling(pat.indptr, pat.indices, bvals, ident, rest_chol)  # C_K^-1
    rest_chol = np.linalg.inv(rest_chol.reshape(nf, 3, 3)).reshape(-1)  # C_K
    return NewtonData(pat, precond, coupling, _ro(rest_chol))


# -------------------------------------------------------------------------------- solver ----


def relax_newton(
    model: TissueModel,
    x: np.ndarray,
    x_kin_start: np.ndarray,
    tol_mm: float,
    max_iter: int,
) -> tuple[np.ndarray, bool, int, float, int]:
    """Newton-CG from ``x`` (N, 3) mm, whose kinematic nodes are already at their targets;
    ``x_kin_start`` (K, 3) is where they were in the start state (the initial guess adds the
    linear response of the free nodes to that move).

    Returns (x, converged, Newton iterations, largest node move of the last step in mm,
    CG iterations in all).
    """
    data = newton_data(model)
    pat = data.pattern
    pre = data.precond
    free = model.free_index
    kin = model.kinematic_index
    args = kernel_args(model)
    nf = len(free)
    x = np.array(x, dtype=np.float64, order="C")
    if nf == 0:
        return x, True, 0, 0.0, 0
    n = 3 * nf
    work = np.empty((6, n))
    scale = np.empty(9 * nf)
    step = np.empty(n)
    bvals = np.empty(pat.nnzb * 9)
    grad = np.empty_like(x)

    # 1. the linear response of the free nodes to the move of the kinematic ones
    dk = (x[kin] - x_kin_start).reshape(-1)
    if np.any(dk):
        x[free] += pre.solve(-(data.coupling @ dk)).reshape(-1, 3)

    energy = energy_gradient(x, *args, grad)
    g = grad[free].reshape(-1)
    gnorm_prev = float(np.sqrt(g @ g))
    eta = ETA_MAX
    move = np.inf
    cg_total = 0
    for it in range(1, max_iter + 1):
        if not (np.isfinite(energy) and np.isfinite(gnorm_prev)):
            raise MyofaceSimulationError(
                f"newton relax: non-finite energy or forces at iteration {it}"
            )
        # 2. the Newton system, solved to a relative accuracy eta
        assemble_block_hessian(x, *args, pat.fmap, pat.spring_slots, pat.element_slots, bvals)
        block_scaling(pat.indptr, pat.indices, bvals, data.rest_chol, scale)
        k, _ = pcg(
            pat.indptr,
            pat.indices,
            bvals,
            pre.ptr,
            pre.rows,
            pre.vals,
            pre.diag,
            pre.dinv,
            pre.perm,
            scale,
            -g,
            eta,
            CG_MAX_ITER,
            step,
            work,
        )
        cg_total += k
        slope = float(g @ step)
        if not slope < 0.0:  # cannot happen with an SPD preconditioner, unless g is ~0
            move = 0.0
            return x, True, it, move, cg_total
        move = float(np.abs(step).max())
        # 3. line search: Armijo backtracking with a safeguarded quadratic step
        t = 1.0
        small = -slope <= ENERGY_ROUNDOFF * max(abs(energy), 1.0)
        while True:
            xn = x.copy()
            xn[free] += (t * step).reshape(-1, 3)
            en = energy_gradient(xn, *args, grad)
            if small or en <= energy + ARMIJO_C * t * slope or t < 1e-4:
                break
            curv = en - energy - slope * t
            tq = -slope * t * t / (2.0 * curv) if curv > 0 else 0.5 * t
            t = min(max(tq, 0.1 * t), 0.5 * t)
        x, energy = xn, en
        g = grad[free].reshape(-1)
        move *= t
        if t == 1.0 and move < tol_mm:
            return x, True, it, move, cg_total
        # forcing term, Eisenstat & Walker (1996) choice 2 with their safeguard
        gnorm = float(np.sqrt(g @ g))
        eta_new = 0.9 * (gnorm / gnorm_prev) ** 2
        if 0.9 * eta * eta > 0.1:
            eta_new = max(eta_new, 0.9 * eta * eta)
        eta = min(max(eta_new, ETA_MIN), ETA_MAX)
        gnorm_prev = gnorm
    return x, False, max_iter, move, cg_total
