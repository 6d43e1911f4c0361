"""Fast equilibrium of the tissue lattice: inexact Newton on the exact Hessian.

The equilibrium with the kinematic nodes held at their targets is the minimum of the lattice's
potential energy E (springs, eq. 1-2, plus the volume penalty Q) over the free nodes. This
module finds it by Newton's method on the *exact* Hessian of E, each Newton system
``H s = -grad E`` solved inexactly by preconditioned conjugate gradients:

1. **initial guess** — from a state made by a relax (it records the positions it was relaxed
   from, ``previous_x``), the part of the kinematic nodes' new move along their last move
   repeats the free nodes' last move (:func:`extrapolated_start`: the secant of the last
   frame, which knows which springs turned stiff on the way); for the rest of the move, the
   free nodes' linear response (static condensation: ``dx_f = -K_ff^-1 K_fk dx_k``, K the rest
   stiffness, factorised once per model as a block LDL^T). From rest this is the small-strain
   solution; in a video it leaves 0.03-0.1 mm to Newton instead of 0.06-0.36 mm (a 25 fps
   smile, frames moving 0.41-0.51 mm);
2. **Newton steps** — the Hessian (springs with their tangent stiffness and unclipped geometric
   term, the volume penalty with its second-derivative term) assembled in symmetric 3x3-block
   storage over the springs and prisms that touch a free node (:mod:`myoface.tissue.hessian`:
   one pass over the springs and one over the prisms give the energy, its gradient and the
   Hessian, each on request; the Hessian in the same passes as the energy and gradient at the
   point, when the step that reached it was too long for the next one to keep the Hessian; the
   prisms' part, two thirds of the cost, is kept from step to step until a node has moved by
   PRISM_LAG_MM); CG on it preconditioned by a symmetric block Gauss-Seidel sweep of the
   Hessian itself, to a relative accuracy eta that tightens as the gradient falls (Eisenstat &
   Walker 1996, choice 2, between ETA_MIN and ETA_MAX); a direction of negative curvature ends
   the CG early (Steihaug 1983); an Armijo backtracking line search on E keeps every step a
   descent step;
3. **the last step** — once a Newton step is short (< CHORD_RATIO * tol) and cut the gradient
   as a Newton step does where the Hessian hardly changes (by CHORD_RATE), the next step reuses
   that Hessian (no new assembly): it is nearly a Newton step, and most often the last one (when
   it is not, the Hessian at its end is made in the line search's pass there).
   Converged when a step (CG to ETA_MAX = 0.1 or better, not stopped by curvature) moves no
   node by more than tol: the step estimates the distance left, and is taken.

Why Gauss-Seidel on H rather than the rest factor: the rest stiffness is a poor match where
springs have switched to their stiffer phase (beta = 10 alpha) or are compressed (a negative
geometric term), and it gives CG a condition number of 50-90 at an expression; a symmetric
block Gauss-Seidel sweep of H sees those changes exactly and halves the CG iterations, at a
third of the cost of a triangular solve with the factor (measured on the default face: 143 vs
287 iterations over the Newton systems of a cold and seven warm relaxes, 0.07 vs 0.21 ms per
application). The Hessian assembly is then the largest cost of a Newton step.

The measurements behind these choices, and what was tried and did not pay, are in
``docs/notes/solver.md``.

The exact Hessian matters: with the compressive geometric term clipped (a positive
semi-definite "projected" Hessian) Newton converges only linearly here, since thousands of
springs are compressed in an expression; with it, quadratically.

Thread safety: everything a model keeps (:class:`NewtonData`) is built once, under a lock, and
is read-only afterwards; every solve allocates its own work arrays.

References: Terzopoulos & Waters 1993, eq. (1)-(4); Nocedal & Wright 2006, Numerical
Optimization, ch. 7 (inexact / Newton-CG methods); Saad 2003, Iterative Methods for Sparse
Linear Systems, ch. 10 (SSOR / symmetric Gauss-Seidel preconditioning)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
from numba import njit
from scipy.sparse.linalg import splu

from myoface.errors import MyofaceSimulationError
from myoface.tissue.hessian import (
    SymmetricPattern,
    add_prism_hessian,
    add_spring_hessian,
    energy_gradient_hessian,
)
from myoface.tissue.model import TissueModel

#: default equilibrium tolerance of the Newton solver: the largest node move of the last Newton
#: step, mm. The step estimates the distance to the equilibrium and is taken; the error left
#: after it is about the CG's relative accuracy (ETA_MIN = 0.05) times the step, plus the
#: quadratic term, so 0.01 mm leaves about 1e-3 mm — a hundredth of the 0.1 mm that is visible
#: on a face model of this size.
NEWTON_TOL_MM = 0.01
#: the largest CG relative residual (forcing term) of a Newton system, and the smallest: a CG
#: iteration costs a tenth of a Hessian assembly, so the systems are solved accurately, and every
#: step is an estimate of the distance to the equilibrium (the convergence test). (At 0.5, a
#: one-iteration step could stop the solver 0.011 mm from the equilibrium with tol 0.01.)
ETA_MAX = 0.1
ETA_MIN = 0.05
#: CG iterations per Newton system at most
CG_MAX_ITER = 200
#: a Newton step whose largest node move was below CHORD_RATIO * tol_mm is followed by a step
#: with the same Hessian (no new assembly): near the equilibrium the Hessian hardly changes, and
#: that step is most often the last one, which only has to show that the next move is < tol
CHORD_RATIO = 10.0
#: ... provided that full step cut the gradient's norm to below this fraction: where springs
#: cross their threshold during the steps the Hessian changes, and a step with the old one
#: underestimates the distance left
CHORD_RATE = 0.1
#: the volume penalty's part of the Hessian is kept until a node has moved by this much (mm)
#: since it was assembled: it changes with the prisms' shape, slowly (a 0.3 mm move changes
#: a prism's edges, 2-10 mm long, by a few per cent), while the springs' part, which switches
#: with their phase, is assembled at every Newton step. (On the default face this leaves the
#: Newton iterations as they are and skips one or two of the prisms' assemblies, two thirds of
#: the cost of one, per relax; at 1 mm, cold starts take more Newton steps.)
PRISM_LAG_MM = 0.3
#: Armijo sufficient-decrease constant of the line search (Nocedal & Wright 2006, eq. 3.4)
ARMIJO_C = 1e-4
#: relative size of an energy change that is at the level of its rounding error: a Newton step
#: that predicts less decrease than this is taken without the (meaningless) energy test
ENERGY_ROUNDOFF = 1e-12

#: the rest stiffness is factorised with this fraction of its mean diagonal added (so a lattice
#: without kinematic nodes, whose stiffness is singular, still gets a preconditioner)
PRECOND_SHIFT = 1e-9

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
def _inverse_spd3(a, o, out):
    """The inverse of the symmetric 3x3 block ``a[o:o+9]`` into ``out[o:o+9]`` (its adjugate over
    its determinant) if the block is positive definite (its leading minors positive: Sylvester's
    criterion); returns whether it is (``out`` is then left as it was)."""
    a00 = a[o]
    a01 = a[o + 1]
    a02 = a[o + 2]
    a11 = a[o + 4]
    a12 = a[o + 5]
    a22 = a[o + 8]
    m2 = a00 * a11 - a01 * a01
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    det = a00 * c00 + a01 * c01 + a02 * c02
    if not (a00 > 0.0 and m2 > 0.0 and det > 0.0):
        return False
    r = 1.0 / det
    out[o] = c00 * r
    out[o + 1] = c01 * r
    out[o + 2] = c02 * r
    out[o + 3] = c01 * r
    out[o + 4] = (a00 * a22 - a02 * a02) * r
    out[o + 5] = (a01 * a02 - a00 * a12) * r
    out[o + 6] = c02 * r
    out[o + 7] = out[o + 5]
    out[o + 8] = m2 * r
    return True


@njit(cache=True, nogil=True)
def diagonal_blocks(dvals, fallback, dused, dinv, emat):
    """The diagonal blocks the Gauss-Seidel preconditioner uses, into ``dused`` (F*9,), their
    inverses into ``dinv``, and ``emat = 2 dused - dvals`` (for :func:`pcg`): the Hessian's
    ``dvals`` where a block is positive definite, else the rest stiffness's block ``fallback``
    (always positive definite), so that the preconditioner is SPD whatever the Hessian."""
    for i in range(dvals.shape[0] // 9):
        o = 9 * i
        src = dvals
        if not _inverse_spd3(dvals, o, dinv):
            src = fallback
            _inverse_spd3(fallback, o, dinv)
        for q in range(9):
            dused[o + q] = src[o + q]
            emat[o + q] = 2.0 * src[o + q] - dvals[o + q]


@njit(cache=True, nogil=True, fastmath=True)
def sgs_precond(lptr, lcol, dused, lvals, dinv, r, z, w):
    """``z = (D + L^T)^-1 D (D + L)^-1 r``: symmetric block Gauss-Seidel on the matrix with
    diagonal blocks D (``dused``, inverses ``dinv``) and strictly lower blocks L (``lvals`` in
    the storage of :class:`~myoface.tissue.hessian.SymmetricPattern`); SPD when D is. ``w``:
    work (3F,). (:func:`pcg` applies it in Eisenstat's form; this is its reference.)"""
    _lower_solve(lptr, lcol, lvals, dinv, r, z)
    dz = np.empty_like(z)
    _block_mul(dused, z, dz)
    _upper_solve(lptr, lcol, lvals, dinv, np.empty(0), dz, z, w)


@njit(cache=True, nogil=True, fastmath={"contract"})
def _lower_solve(lptr, lcol, lvals, dinv, r, y):
    """``y = (D + L)^-1 r`` (block forward substitution, gathering each row's lower blocks;
    ``dinv``: the inverses of D's blocks). Products fused into adds, but no reassociation: each
    block's three sums are then made apart and subtracted from the row's (with ``fastmath=True``
    the compiler chains all nine products into the row's sums, and the sweep waits on them:
    28 -> 22 us on the default face)."""
    nf = lptr.shape[0] - 1
    for i in range(nf):
        s0 = r[3 * i]
        s1 = r[3 * i + 1]
        s2 = r[3 * i + 2]
        for k in range(lptr[i], lptr[i + 1]):
            j = 3 * lcol[k]
            o = 9 * k
            y0 = y[j]
            y1 = y[j + 1]
            y2 = y[j + 2]
            s0 -= lvals[o] * y0 + lvals[o + 1] * y1 + lvals[o + 2] * y2
            s1 -= lvals[o + 3] * y0 + lvals[o + 4] * y1 + lvals[o + 5] * y2
            s2 -= lvals[o + 6] * y0 + lvals[o + 7] * y1 + lvals[o + 8] * y2
        o = 9 * i
        y[3 * i] = dinv[o] * s0 + dinv[o + 1] * s1 + dinv[o + 2] * s2
        y[3 * i + 1] = dinv[o + 3] * s0 + dinv[o + 4] * s1 + dinv[o + 5] * s2
        y[3 * i + 2] = dinv[o + 6] * s0 + dinv[o + 7] * s1 + dinv[o + 8] * s2


@njit(cache=True, nogil=True, fastmath=True)
def _upper_solve(lptr, lcol, lvals, dinv, emat, r, z, w):
    """``z = (D + L^T)^-1 r`` (block back substitution, scattering each row's lower blocks
    transposed into ``w`` (3F,), which starts as a copy of ``r``). With ``emat`` (F*9,) not
    empty, ``w`` ends as ``r - E z`` (E the blocks of ``emat``), for :func:`pcg`: a row's part
    of ``w`` is written once the row is solved, when nothing reads it any more."""
    nf = lptr.shape[0] - 1
    with_e = emat.shape[0] > 0
    for i in range(3 * nf):
        w[i] = r[i]
    for i in range(nf - 1, -1, -1):
        o = 9 * i
        s0 = w[3 * i]
        s1 = w[3 * i + 1]
        s2 = w[3 * i + 2]
        z0 = dinv[o] * s0 + dinv[o + 1] * s1 + dinv[o + 2] * s2
        z1 = dinv[o + 3] * s0 + dinv[o + 4] * s1 + dinv[o + 5] * s2
        z2 = dinv[o + 6] * s0 + dinv[o + 7] * s1 + dinv[o + 8] * s2
        z[3 * i] = z0
        z[3 * i + 1] = z1
        z[3 * i + 2] = z2
        if with_e:
            w[3 * i] = r[3 * i] - (emat[o] * z0 + emat[o + 1] * z1 + emat[o + 2] * z2)
            w[3 * i + 1] = r[3 * i + 1] - (emat[o + 3] * z0 + emat[o + 4] * z1 + emat[o + 5] * z2)
            w[3 * i + 2] = r[3 * i + 2] - (emat[o + 6] * z0 + emat[o + 7] * z1 + emat[o + 8] * z2)
        for k in range(lptr[i], lptr[i + 1]):
            j = 3 * lcol[k]
            o = 9 * k
            w[j] -= lvals[o] * z0 + lvals[o + 3] * z1 + lvals[o + 6] * z2
            w[j + 1] -= lvals[o + 1] * z0 + lvals[o + 4] * z1 + lvals[o + 7] * z2
            w[j + 2] -= lvals[o + 2] * z0 + lvals[o + 5] * z1 + lvals[o + 8] * z2


@njit(cache=True, nogil=True, fastmath=True)
def _block_mul(blocks, v, out):
    """``out = B v`` for B block diagonal (``blocks`` (F*9,))."""
    for i in range(v.shape[0] // 3):
        o = 9 * i
        v0 = v[3 * i]
        v1 = v[3 * i + 1]
        v2 = v[3 * i + 2]
        out[3 * i] = blocks[o] * v0 + blocks[o + 1] * v1 + blocks[o + 2] * v2
        out[3 * i + 1] = blocks[o + 3] * v0 + blocks[o + 4] * v1 + blocks[o + 5] * v2
        out[3 * i + 2] = blocks[o + 6] * v0 + blocks[o + 7] * v1 + blocks[o + 8] * v2


@njit(cache=True, nogil=True, fastmath=True)
def pcg(lptr, lcol, dused, lvals, dinv, emat, b, eta, max_iter, x, work):
    """CG on ``H x = b`` preconditioned by :func:`sgs_precond`, ``M = A D^-1 A^T`` with
    ``A = D + L``, in Eisenstat's form (Eisenstat 1981): CG on ``A^-1 H A^-T y = A^-1 b``
    preconditioned by D, ``x = A^-T y``, whose operator is
    ``A^-1 H A^-T v = t + A^-1 (v - E t)``, ``t = A^-T v``, ``E = 2 D - D_H`` (``emat``; D_H
    the Hessian's diagonal blocks, D the ones the preconditioner uses): one forward and one back
    substitution per iteration and no product with H. The iterates, residual norms
    ``r.M^-1 r`` and curvatures are those of the plain preconditioned CG. x itself is updated
    with each step ``a p`` of y as ``a A^-T p``, the iteration's t: no back substitution at the
    end.

    From x = 0, until ``sqrt(r.z) <= eta sqrt(r0.z0)`` (z = M^-1 r). Stops early on a direction
    of negative or zero curvature: x keeps the last iterate, or the preconditioned residual if
    that happens at once (Steihaug 1983). ``work``: (6, n) or more rows. Returns (iterations, 1
    if it stopped on curvature)."""
    n = b.shape[0]
    r = work[0]
    z = work[1]
    p = work[2]
    q = work[3]
    t = work[4]
    w = work[5]
    _lower_solve(lptr, lcol, lvals, dinv, b, r)
    x[:] = 0.0
    t[:] = 0.0
    q[:] = 0.0
    rz = _step_residual(x, r, z, t, q, 0.0, dused)  # z = D r
    p[:] = z
    stop = eta * eta * rz
    for it in range(max_iter):
        _upper_solve(lptr, lcol, lvals, dinv, emat, p, t, w)  # t = A^-T p, w = p - E t
        _lower_solve(lptr, lcol, lvals, dinv, w, q)
        pq = 0.0
        for i in range(n):
            q[i] += t[i]
            pq += p[i] * q[i]
        if not pq > 0.0:
            if it == 0:  # x = M^-1 b = A^-T z, and p = z
                x[:] = t
            return it + 1, 1  # else x is the last iterate
        a = rz / pq
        rz_new = _step_residual(x, r, z, t, q, a, dused)  # x += a A^-T p
        if rz_new <= stop:
            return it + 1, 0
        beta = rz_new / rz
        rz = rz_new
        for i in range(n):
            p[i] = z[i] + beta * p[i]
    return max_iter, 0


@njit(cache=True, nogil=True, fastmath=True)
def _step_residual(x, r, z, t, q, a, dblocks):
    """One CG update in one pass: ``x += a t``, ``r -= a q``, ``z = D r`` (D block diagonal,
    ``dblocks`` (F*9,)); returns ``r.z``."""
    rz = 0.0
    for i in range(r.shape[0] // 3):
        o = 9 * i
        i0 = 3 * i
        x[i0] += a * t[i0]
        x[i0 + 1] += a * t[i0 + 1]
        x[i0 + 2] += a * t[i0 + 2]
        r0 = r[i0] - a * q[i0]
        r1 = r[i0 + 1] - a * q[i0 + 1]
        r2 = r[i0 + 2] - a * q[i0 + 2]
        r[i0] = r0
        r[i0 + 1] = r1
        r[i0 + 2] = r2
        z0 = dblocks[o] * r0 + dblocks[o + 1] * r1 + dblocks[o + 2] * r2
        z1 = dblocks[o + 3] * r0 + dblocks[o + 4] * r1 + dblocks[o + 5] * r2
        z2 = dblocks[o + 6] * r0 + dblocks[o + 7] * r1 + dblocks[o + 8] * r2
        z[i0] = z0
        z[i0 + 1] = z1
        z[i0 + 2] = z2
        rz += r0 * z0 + r1 * z1 + r2 * z2
    return rz


# ------------------------------------------------------------------------- per-model data ----


@dataclass(frozen=True)
class NewtonData:
    """What the Newton solver keeps per model (read-only arrays, built once).

    Attributes
    ----------
    pattern : SymmetricPattern — the free-node Hessian's storage and the active springs and
        prisms.
    precond : BlockLDL — the rest stiffness over the free nodes, factorised.
    coupling : scipy CSR (3F x 3K) — the rest stiffness between free and kinematic dofs, K_fk.
    rest_diag : (F*9,) — the rest stiffness's diagonal blocks (the preconditioner's fallback).
    """

    pattern: SymmetricPattern
    precond: BlockLDL
    coupling: sp.csr_matrix
    rest_diag: np.ndarray


def newton_data(model: TissueModel) -> NewtonData:
    """The model's :class:`NewtonData`, built on first use and kept in ``model.memo``."""
    return model.memo("newton_data", lambda: _build_newton_data(model))


def _build_newton_data(model: TissueModel) -> NewtonData:
    pat = SymmetricPattern(model)
    nf = pat.n_free
    dvals = np.empty(9 * nf)
    lvals = np.empty(9 * pat.nl)
    pat.assemble(model.rest_positions, dvals, lvals)
    k = pat.matrix(dvals, lvals)
    # a rest stiffness that is singular (a lattice with no kinematic node has rigid motions) is
    # made definite by a shift far below its stiffness; the factor only preconditions
    shift = PRECOND_SHIFT * float(np.abs(k.diagonal()).mean() or 1.0)
    k = (k + shift * sp.eye(3 * nf)).tocsc()
    lo = sp.csr_matrix((np.ones(pat.nl), pat.lcol, pat.lptr), shape=(nf, nf))
    node_graph = (lo + lo.T + sp.eye(nf)).tocsr()
    precond = block_ldl(k, nf, node_graph)
    # K_fk at rest: the Hessian of a copy of the model in which every node is free
    allfree = SymmetricPattern(replace(model, kinematic=np.zeros(model.n_nodes, bool)))
    dall = np.empty(9 * allfree.n_free)
    lall = np.empty(9 * allfree.nl)
    allfree.assemble(model.rest_positions, dall, lall)
    kall = allfree.matrix(dall, lall)
    # (that copy numbers its nodes in an order of its own: allfree.fmap)
    fd = (3 * allfree.fmap[pat.free_nodes][:, None] + np.arange(3)).reshape(-1)
    kd = (3 * allfree.fmap[model.kinematic_index][:, None] + np.arange(3)).reshape(-1)
    coupling = kall[fd][:, kd].tocsr()
    coupling.data.flags.writeable = False
    return NewtonData(pat, precond, coupling, _ro(dvals))


# -------------------------------------------------------------------------------- solver ----


#: a kinematic move (mm) below which the linear response is not worth its solve: what is left
#: of a move that repeats the last one (round-off), or none at all; it would move the free nodes
#: by about as much, a millionth of what Newton resolves
LINEAR_RESPONSE_MIN_MM = 1e-9
#: a relax whose last step moved less than the tolerance but left a free node with a larger
#: net force than this (uN) has not converged: its line search stalled far from equilibrium
#: (a converged relax of the default face leaves at most about 1 uN; a warm start extrapolated
#: past Newton's basin once "converged" with 2e95 uN left and nodes at 1e19 mm)
EQUILIBRIUM_FORCE_MAX_UN = 1e3
#: the last move is repeated at most this many times over (and reversed at most once): beyond
#: that the secant of one frame says little about the response
EXTRAPOLATE_MAX = 2.0


def extrapolated_start(
    model: TissueModel, x: np.ndarray, x_kin_start: np.ndarray, previous_x: np.ndarray
) -> np.ndarray:
    """Repeat the start state's last move for the part of the kinematic nodes' new move that
    goes the same way, in place on the free nodes of ``x`` (N, 3) mm; returns the rest of the
    kinematic move (K, 3) mm, for the linear response.

    The start state (free nodes ``x``, kinematic nodes at ``x_kin_start``) is an equilibrium
    relaxed from ``previous_x``. Its last move ``m = x_start - previous_x`` is a secant of the
    (nonlinear) map from the kinematic targets to the equilibrium; the new kinematic move ``dk``
    is split as ``a m_k + r`` (least squares, ``a`` in [-1, :data:`EXTRAPOLATE_MAX`]) and the
    free nodes move by ``a m_f``. In a video, successive frames move the targets much the same
    way, and the secant knows which springs have turned stiff on the way, which the rest
    stiffness's linear response does not (on a 25 fps smile it leaves 0.03-0.1 mm to Newton
    instead of 0.06-0.36 mm). Between unrelated moves ``a`` is about 0 and nothing changes; a
    move reversed (``a`` = -1) returns to the previous equilibrium."""
    kin = model.kinematic_index
    dk = np.empty((len(kin), 3))
    _extrapolate(x, model.free_index, kin, x_kin_start, previous_x, EXTRAPOLATE_MAX, dk)
    return dk


@njit(cache=True, nogil=True)
def _extrapolate(x, free, kin, x_kin_start, previous_x, a_max, dk):
    """:func:`extrapolated_start` on the index arrays: ``x`` in place, the rest of the kinematic
    move into ``dk`` (K, 3); returns its largest coordinate (mm)."""
    nn = 0.0
    md = 0.0
    for a in range(kin.shape[0]):
        i = kin[a]
        for c in range(3):
            m = x_kin_start[a, c] - previous_x[i, c]
            d = x[i, c] - x_kin_start[a, c]
            dk[a, c] = d
            nn += m * m
            md += m * d
    if nn > 0.0:
        s = min(max(md / nn, -1.0), a_max)
        for a in range(free.shape[0]):
            i = free[a]
            for c in range(3):
                x[i, c] += s * (x[i, c] - previous_x[i, c])
        for a in range(kin.shape[0]):
            i = kin[a]
            for c in range(3):
                dk[a, c] -= s * (x_kin_start[a, c] - previous_x[i, c])
    return np.abs(dk).max() if dk.size > 0 else 0.0


@njit(cache=True, nogil=True)
def _kinematic_move(x, kin, x_kin_start, dk):
    """The kinematic nodes' move from ``x_kin_start`` (K, 3) to where they are in ``x`` (N, 3)
    into ``dk`` (K, 3); returns its largest coordinate (mm)."""
    m = 0.0
    for a in range(kin.shape[0]):
        for c in range(3):
            d = x[kin[a], c] - x_kin_start[a, c]
            dk[a, c] = d
            m = max(m, abs(d))
    return m


@njit(cache=True, nogil=True)
def _add_linear_response(x, free, cptr, cidx, cval, dk, ptr, rows, vals, diag, dinv, perm):
    """Add the free nodes' linear response ``-K_ff^-1 K_fk dk`` to the move ``dk`` (K, 3) of
    the kinematic nodes to ``x`` (N, 3), in place: K_fk in CSR (``cptr``, ``cidx``, ``cval``),
    K_ff^-1 by the :class:`BlockLDL` (``ptr`` .. ``perm``); ``free`` in the factor's order."""
    n = cptr.shape[0] - 1
    d = dk.reshape(-1)
    b = np.empty(n)
    for i in range(n):
        acc = 0.0
        for k in range(cptr[i], cptr[i + 1]):
            acc += cval[k] * d[cidx[k]]
        b[i] = -acc
    out = np.empty(n)
    ldl_solve(ptr, rows, vals, diag, dinv, perm, b, out, np.empty(n))
    for a in range(free.shape[0]):
        i = free[a]
        x[i, 0] += out[3 * a]
        x[i, 1] += out[3 * a + 1]
        x[i, 2] += out[3 * a + 2]


#: the Newton loop's parameters, in the order :func:`_newton` takes them
_PARAMS = np.array(
    [
        ETA_MAX,
        ETA_MIN,
        CHORD_RATIO,
        CHORD_RATE,
        PRISM_LAG_MM,
        ARMIJO_C,
        ENERGY_ROUNDOFF,
        CG_MAX_ITER,
    ],
    dtype=np.float64,
)
_PARAMS.flags.writeable = False


def relax_newton(
    model: TissueModel,
    x: np.ndarray,
    x_kin_start: np.ndarray,
    tol_mm: float,
    max_iter: int,
    stats: np.ndarray | None = None,
    previous_x: np.ndarray | None = None,
) -> tuple[np.ndarray, bool, int, float, int, float]:
    """Newton-CG from ``x`` (N, 3) mm, whose kinematic nodes are already at their targets;
    ``x_kin_start`` (K, 3) is where they were in the start state (the initial guess adds the
    linear response of the free nodes to that move). ``previous_x`` (N, 3) mm, optional: the
    positions the start state was relaxed from (:attr:`TissueState.previous_x`); the part of
    the kinematic nodes' move along their last move repeats the free nodes' last move
    (:func:`extrapolated_start`).

    Returns (x, converged, Newton iterations, largest node move of the last step in mm,
    CG iterations in all, largest net internal force on a free node at x in uN). An iteration
    is one Newton step; the steps that reuse the last Hessian (see :data:`CHORD_RATIO`) count
    as iterations too. ``stats`` (9,), if given, receives the counts of :func:`_newton`.
    """
    data = newton_data(model)
    pat = data.pattern
    free = pat.free_nodes  # in the pattern's order
    kin = model.kinematic_index
    x = np.array(x, dtype=np.float64, order="C")
    if len(free) == 0:
        return x, True, 0, 0.0, 0, 0.0

    # 1. the initial guess: the last move repeated (in a video) and the linear response of the
    # free nodes to the rest of the kinematic nodes' move
    x_kin_start = np.ascontiguousarray(x_kin_start, dtype=np.float64)
    dk = np.empty((len(kin), 3))
    if previous_x is None:
        left = _kinematic_move(x, kin, x_kin_start, dk)
    else:
        prev = np.ascontiguousarray(previous_x, dtype=np.float64)
        left = _extrapolate(x, free, kin, x_kin_start, prev, EXTRAPOLATE_MAX, dk)
    if left > LINEAR_RESPONSE_MIN_MM:
        c, f = data.coupling, data.precond
        _add_linear_response(
            x, free, c.indptr, c.indices, c.data, dk, f.ptr, f.rows, f.vals, f.diag, f.dinv, f.perm
        )

    # 2. Newton steps (one compiled loop: no Python between the kernels)
    out = np.zeros(9) if stats is None else stats
    _newton(
        x,
        free,
        pat.springs,
        pat.prisms,
        pat.lptr,
        pat.lcol,
        data.rest_diag,
        float(tol_mm),
        int(max_iter),
        _PARAMS,
        out,
    )
    it, ok, move, cg = int(out[0]), bool(out[1]), float(out[2]), int(out[3])
    if out[7] < 0:
        raise MyofaceSimulationError(f"newton relax: non-finite energy or forces at iteration {it}")
    fmax = float(out[8])
    if not (np.isfinite(fmax) and fmax <= EQUILIBRIUM_FORCE_MAX_UN and np.isfinite(x).all()):
        ok = False  # a stalled line search, not an equilibrium (the caller falls back)
    return x, ok, it, move, cg, fmax


@njit(cache=True, nogil=True)
def _newton(x, free, springs, prisms, lptr, lcol, rest_diag, tol, max_iter, params, stats):
    """The Newton iterations of :func:`relax_newton` on ``x`` (N, 3) mm, in place (see the
    module docstring). ``springs``, ``prisms``: the pattern's (:class:`~myoface.tissue.hessian.
    SymmetricPattern`). ``params``: :data:`_PARAMS`. ``stats`` (9,) receives [iterations,
    converged, last move (mm), CG iterations, Hessian assemblies, of which with the prisms'
    part, energy evaluations, status (-1: non-finite energy or forces), largest force on a free
    node (uN)]."""
    eta_max = params[0]
    eta_min = params[1]
    chord_ratio = params[2]
    chord_rate = params[3]
    prism_lag = params[4]
    armijo_c = params[5]
    roundoff = params[6]
    cg_max = int(params[7])
    nf = free.shape[0]
    n = 3 * nf
    nl = lcol.shape[0]
    dvals = np.empty(9 * nf)
    lvals = np.empty(9 * nl)
    dprism = np.empty(9 * nf)
    lprism = np.empty(9 * nl)
    dused = np.empty(9 * nf)
    dinv = np.empty(9 * nf)
    emat = np.empty(9 * nf)
    work = np.empty((6, n))
    step = np.empty(n)
    rhs = np.empty(n)
    grad = np.empty((nf, 3))
    xn = x.copy()  # the line search's point: its kinematic nodes are x's throughout
    x_prism = x.copy()  # where the prisms' part of the Hessian was assembled
    # the Hessian at x, assembled with the energy and gradient there (the first one, and at a
    # point where the last step was too long for the next one to keep the Hessian)
    energy = energy_gradient_hessian(
        x, springs, prisms, grad, True, dvals, lvals, True, dprism, lprism
    )
    g = grad.reshape(n)
    have_h = True
    gnorm_prev = np.sqrt(g @ g)
    eta = eta_max
    move = np.inf
    t = 1.0
    rate = 1.0  # the last full step's gradient reduction, |g_new| / |g_old|
    cg = 0
    n_asm = 0
    n_prism = 1
    n_energy = 1
    converged = False
    it = 0
    while it < max_iter:
        it += 1
        if not (np.isfinite(energy) and np.isfinite(gnorm_prev)):
            stats[7] = -1.0
            break
        # the Newton system, solved to a relative accuracy eta; close to the equilibrium (the
        # last full step was short and cut the gradient as a Newton step does where the Hessian
        # hardly changes) the Hessian of the last step is kept: a step with it is nearly a
        # Newton step, and most often the last one
        chord = it > 1 and t == 1.0 and move < chord_ratio * tol and rate < chord_rate
        if not chord:
            if not have_h:  # the prisms' part kept unless a node has moved by PRISM_LAG_MM
                if _largest_move(x, free, x_prism) > prism_lag:
                    dprism[:] = 0.0
                    lprism[:] = 0.0
                    add_prism_hessian(x, prisms, dprism, lprism)
                    _copy_free(x, free, x_prism)
                    n_prism += 1
                dvals[:] = dprism
                lvals[:] = lprism
                add_spring_hessian(x, springs, dvals, lvals)
            diagonal_blocks(dvals, rest_diag, dused, dinv, emat)
            n_asm += 1
        have_h = False
        for i in range(n):
            rhs[i] = -g[i]
        eta_k = eta_min if chord else eta
        k, curved = pcg(lptr, lcol, dused, lvals, dinv, emat, rhs, eta_k, cg_max, step, work)
        cg += k
        slope = g @ step
        if not slope < 0.0:  # cannot happen with an SPD preconditioner, unless g is ~0
            move = 0.0
            converged = True
            break
        move = np.abs(step).max()
        # a step too long for the next one to keep this Hessian (see CHORD_RATIO), or a step
        # with the kept Hessian that does not end the solve, needs the Hessian at its end:
        # assembled with the energy there, in the same pass
        last = move < tol and curved == 0
        want_h = move >= chord_ratio * tol or (chord and not last)
        # line search: Armijo backtracking with a safeguarded quadratic step
        t = 1.0
        small = -slope <= roundoff * max(abs(energy), 1.0)
        while True:
            _moved(x, free, step, t, xn)
            fuse = want_h and t == 1.0
            due = fuse and _largest_move(xn, free, x_prism) > prism_lag
            en = energy_gradient_hessian(
                xn, springs, prisms, grad, fuse, dvals, lvals, due, dprism, lprism
            )
            if due:
                _copy_free(xn, free, x_prism)
                n_prism += 1
            n_energy += 1
            if small or en <= energy + armijo_c * t * slope or t < 1e-4:
                have_h = fuse
                break
            curv = en - energy - slope * t
            tq = -slope * t * t / (2.0 * curv) if curv > 0 else 0.5 * t
            t = min(max(tq, 0.1 * t), 0.5 * t)
        _copy_free(xn, free, x)
        energy = en
        # the step (to a relative accuracy of ETA_MAX or better, not cut short by negative
        # curvature) estimates the distance left
        if last:
            move *= t
            converged = True
            break
        gnorm = np.sqrt(g @ g)
        if chord:
            move = np.inf  # the kept Hessian did not finish: assemble a new one next
        else:
            rate = gnorm / gnorm_prev
        # forcing term, Eisenstat & Walker (1996) choice 2 with their safeguard
        eta_new = 0.9 * (gnorm / gnorm_prev) ** 2
        if 0.9 * eta * eta > 0.1:
            eta_new = max(eta_new, 0.9 * eta * eta)
        eta = min(max(eta_new, eta_min), eta_max)
        gnorm_prev = gnorm
    stats[0] = it
    stats[1] = 1.0 if converged else 0.0
    stats[2] = move
    stats[3] = cg
    stats[4] = n_asm
    stats[5] = n_prism
    stats[6] = n_energy
    stats[8] = np.abs(g).max() if n > 0 else 0.0


@njit(cache=True, nogil=True)
def _moved(x, free, step, t, out):
    """The free nodes of ``out`` (N, 3) = those of ``x`` moved by ``t * step`` ((3F,), free
    order); its kinematic nodes are left as they are."""
    for a in range(free.shape[0]):
        i = free[a]
        out[i, 0] = x[i, 0] + t * step[3 * a]
        out[i, 1] = x[i, 1] + t * step[3 * a + 1]
        out[i, 2] = x[i, 2] + t * step[3 * a + 2]


@njit(cache=True, nogil=True)
def _copy_free(src, free, dst):
    """The free nodes of ``src`` (N, 3) into ``dst``."""
    for a in range(free.shape[0]):
        i = free[a]
        dst[i, 0] = src[i, 0]
        dst[i, 1] = src[i, 1]
        dst[i, 2] = src[i, 2]


@njit(cache=True, nogil=True)
def _largest_move(x, free, x0):
    """The largest coordinate change of a free node between ``x0`` and ``x`` (N, 3), mm."""
    m = 0.0
    for a in range(free.shape[0]):
        i = free[a]
        for c in range(3):
            m = max(m, abs(x[i, c] - x0[i, c]))
    return m
