"""Deformable contours ("snakes") and tracking them through a video.

Terzopoulos & Waters 1993, Section V, eq. (7)-(13). A set of contours (open or closed) is one
system of n nodes x_i (pixels, (x, y) = (column, row)) joined in series by springs:

- tension (eq. 7): spring i between nodes i and i+1 pulls with ``a_i e_i r_i / |r_i|``,
  e_i = |r_i| - l_i;
- viscoelastic rest lengths (eq. 8): ``dl_i/dt = nu_i e_i`` (a held stretch relaxes);
- rigidity (eq. 9): ``K x`` with K = D^T diag(b) D, D the second difference;
- dynamics (eq. 10-11), semi-implicit: rigidity at t + dt, tension and external forces at t::

      (gamma/dt + K) x^{t+dt} = (gamma/dt) x^t + F_tension(x^t) + f(x^t)

- external force (eq. 12): ``f_i = -p grad P(x_i) + f_i^u`` (descending the potential P of eq.
  (13), whose ravines are edges; f^u are user forces, e.g. a dragged node).

Contours are separated by breaks (a = b = 0 across them), so any number of open and closed
contours live in one system. The matrix (gamma/dt I + K) is constant: it is factorized once
(banded Cholesky; closed contours are interleaved so the cyclic matrix becomes banded) and each
step costs one forward and one backward substitution.

Time: ``dt`` is one iteration with gamma = 1, so gamma/dt = ``gamma_over_dt`` and eq. (8)
advances rest lengths by ``nu e / gamma_over_dt`` per iteration.

Equilibrium: a contour is at rest when none of its nodes moved more than ``tol_px`` across it
(along the contour's normal) over the last ``WINDOW`` (10) iterations, and stays there while
the others go on; the relaxation stops when all are at rest (``converged=True``) or after
``max_iter``. (A per-iteration test would stop a
contour that creeps slowly towards a distant edge. Motion along the contour is left out: nodes
slide along the edge they sit on for many iterations after the contour has found it, and where
they sit along it changes neither the contour's shape nor what is read off it.)

Nodes that leave the image (or the window of it the potential was computed on, see
:class:`~myoface.analysis.potentials.PotentialField`) are held on its border and reported lost
(:attr:`SnakeResult.lost`), so that a tracker can re-initialise their contour; only
:func:`relax_contours`, which starts from contours a user gave, refuses nodes outside.

Parameter defaults are the paper's (Section V-E): gamma/dt = 0.5, a = 1.0, b = 0.5, nu = 0.2,
p = 0.001, nodes about 1 pixel apart.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from myoface.analysis.potentials import (
    PotentialField,
    bilinear,
    image_potential,
)
from myoface.errors import MyofaceValueError


@dataclass(frozen=True)
class SnakeParams:
    """Snake parameters; scalars, or arrays per node (a, nu: per spring i -> i+1; b: per node).

    Defaults: Terzopoulos & Waters 1993, Section V-E.
    """

    a: float | np.ndarray = 1.0  # T&W 1993 §V-E: tension
    b: float | np.ndarray = 0.5  # T&W 1993 §V-E: rigidity
    nu: float | np.ndarray = 0.2  # T&W 1993 §V-E: viscoelasticity of rest lengths
    gamma_over_dt: float = 0.5  # T&W 1993 §V-E: damping / time step
    p: float = 0.001  # T&W 1993 §V-E: image force strength (8-bit grey levels)
    max_iter: int = 300
    tol_px: float = 0.1  # equilibrium: largest node move across its contour over WINDOW its, px
    escape_ratio: float = 0.25  # a node has escaped when |P| < this x the contour's reference

    def __post_init__(self):
        if not (np.isfinite(self.gamma_over_dt) and self.gamma_over_dt > 0):
            raise MyofaceValueError(f"gamma_over_dt must be > 0; got {self.gamma_over_dt}")
        if not (np.isfinite(self.p) and self.p >= 0):
            raise MyofaceValueError(f"p must be >= 0; got {self.p}")
        if not (isinstance(self.max_iter, int | np.integer) and self.max_iter >= 1):
            raise MyofaceValueError(f"max_iter must be an integer >= 1; got {self.max_iter}")
        if not (np.isfinite(self.tol_px) and self.tol_px > 0):
            raise MyofaceValueError(f"tol_px must be > 0; got {self.tol_px}")
        for k in ("a", "b", "nu"):
            v = np.asarray(getattr(self, k), dtype=np.float64)
            if not np.isfinite(v).all() or (v < 0).any():
                raise MyofaceValueError(f"{k} must be finite and >= 0")


@dataclass
class Contours:
    """Several contours packed into one node array.

    Attributes
    ----------
    nodes : (N, 2) float64 — (x, y) pixels, contour after contour.
    offsets : (K + 1,) int — contour k is ``nodes[offsets[k]:offsets[k + 1]]``.
    closed : (K,) bool
    names : tuple of str
    """

    nodes: np.ndarray
    offsets: np.ndarray
    closed: np.ndarray
    names: tuple

    @property
    def n_contours(self) -> int:
        return len(self.closed)

    def split(self, nodes: np.ndarray | None = None) -> list[np.ndarray]:
        x = self.nodes if nodes is None else nodes
        return [x[self.offsets[k] : self.offsets[k + 1]] for k in range(self.n_contours)]

    def with_nodes(self, nodes: np.ndarray) -> Contours:
        return Contours(np.asarray(nodes, float).copy(), self.offsets, self.closed, self.names)


def make_contours(
    contours: Sequence[np.ndarray], closed: bool | Sequence[bool] = False, names=None
) -> Contours:
    """Pack contours ((K_i, 2) arrays of (x, y) pixels) into one :class:`Contours`."""
    if isinstance(contours, np.ndarray) and contours.ndim == 2:
        contours = [contours]
    if len(contours) == 0:
        raise MyofaceValueError("no contours given")
    cl = [bool(closed)] * len(contours) if isinstance(closed, bool | np.bool_) else list(closed)
    if len(cl) != len(contours):
        raise MyofaceValueError(f"closed must have one flag per contour ({len(contours)})")
    names = (
        tuple(names) if names is not None else tuple(f"contour{k}" for k in range(len(contours)))
    )
    if len(names) != len(contours):
        raise MyofaceValueError("names must have one entry per contour")
    arrs = []
    for k, c in enumerate(contours):
        a = np.asarray(c, dtype=np.float64)
        if a.ndim != 2 or a.shape[1] != 2:
            raise MyofaceValueError(
                f"contour {names[k]!r} must be a (K, 2) array of (x, y); got shape {a.shape}"
            )
        if len(a) < (4 if cl[k] else 3):
            raise MyofaceValueError(
                f"contour {names[k]!r} needs at least {4 if cl[k] else 3} nodes; got {len(a)}"
            )
        if not np.isfinite(a).all():
            raise MyofaceValueError(f"contour {names[k]!r} has NaN or infinite coordinates")
        arrs.append(a)
    offsets = np.concatenate([[0], np.cumsum([len(a) for a in arrs])]).astype(np.int64)
    return Contours(np.concatenate(arrs), offsets, np.array(cl), names)


def resample_polyline(points: np.ndarray, spacing_px: float = 1.0, closed: bool = False):
    """Nodes about ``spacing_px`` apart along a polyline through ``points`` (M, 2)."""
    p = np.asarray(points, dtype=np.float64)
    if closed:
        p = np.vstack([p, p[:1]])
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    s = np.concatenate([[0], np.cumsum(seg)])
    n = max(3, int(round(s[-1] / spacing_px)) + (0 if closed else 1))
    t = np.linspace(0, s[-1], n, endpoint=not closed)
    return np.column_stack([np.interp(t, s, p[:, 0]), np.interp(t, s, p[:, 1])])


# ------------------------------------------------------------------------------ the system


def _per(v, n: int, name: str) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64)
    if a.ndim == 0:
        return np.full(n, float(a))
    if a.shape != (n,):
        raise MyofaceValueError(f"{name} must be a scalar or have shape ({n},); got {a.shape}")
    return a.copy()


def _topology(contours: Contours, params: SnakeParams):
    """Springs (i, j, a, nu) and rigidity rows (i-1, i, i+1, b) of all contours."""
    n = len(contours.nodes)
    a_n = _per(params.a, n, "a")
    b_n = _per(params.b, n, "b")
    nu_n = _per(params.nu, n, "nu")
    si, sj, rows = [], [], []
    for k in range(contours.n_contours):
        o0, o1 = contours.offsets[k], contours.offsets[k + 1]
        m = o1 - o0
        idx = np.arange(o0, o1)
        if contours.closed[k]:
            si.append(idx)
            sj.append(np.roll(idx, -1))
            rows.append(np.column_stack([np.roll(idx, 1), idx, np.roll(idx, -1)]))
        else:
            si.append(idx[:-1])
            sj.append(idx[1:])
            if m >= 3:
                rows.append(np.column_stack([idx[:-2], idx[1:-1], idx[2:]]))
    si, sj = np.concatenate(si), np.concatenate(sj)
    rows = np.concatenate(rows) if rows else np.zeros((0, 3), np.int64)
    return si, sj, a_n[si], nu_n[si], rows, b_n[rows[:, 1]]


def system_matrix_dense(contours: Contours, params: SnakeParams) -> np.ndarray:
    """The constant matrix gamma/dt I + K (N, N), dense (the test oracle)."""
    n = len(contours.nodes)
    _, _, _, _, rows, bw = _topology(contours, params)
    a = np.eye(n) * params.gamma_over_dt
    d = np.array([1.0, -2.0, 1.0])
    for r, b in zip(rows, bw, strict=True):
        a[np.ix_(r, r)] += b * np.outer(d, d)
    return a


def _interleave(m: int) -> np.ndarray:
    """Order 0, m-1, 1, m-2, ... : a cyclic band matrix becomes a plain band matrix."""
    order = np.empty(m, np.int64)
    order[0::2] = np.arange((m + 1) // 2)
    order[1::2] = m - 1 - np.arange(m // 2)
    return order


@njit(cache=True, nogil=True)
def _band_cholesky(a_band, bw):
    """In-place banded Cholesky: a_band[i, k] holds A[i, i - k] (k = 0..bw) on input, L[i, i-k]
    on output (A = L L^T)."""
    n = a_band.shape[0]
    for i in range(n):
        for k in range(min(i, bw), -1, -1):
            j = i - k
            s = a_band[i, k]
            for m in range(1, bw + 1 - k):
                if j - m < 0:
                    break
                s -= a_band[i, k + m] * a_band[j, m]
            if k == 0:
                if s <= 0.0:
                    return False
                a_band[i, 0] = np.sqrt(s)
            else:
                a_band[i, k] = s / a_band[j, 0]
    return True


@njit(cache=True, nogil=True)
def _band_solve(lb, bw, rhs, out):
    """Solve L L^T x = rhs (columns solved together; rhs (n, c)) into ``out``."""
    n, c = rhs.shape
    for q in range(c):
        for i in range(n):
            s = rhs[i, q]
            for k in range(1, min(i, bw) + 1):
                s -= lb[i, k] * out[i - k, q]
            out[i, q] = s / lb[i, 0]
        for i in range(n - 1, -1, -1):
            s = out[i, q]
            for k in range(1, min(n - 1 - i, bw) + 1):
                s -= lb[i + k, k] * out[i + k, q]
            out[i, q] = s / lb[i, 0]


class SnakeSystem:
    """The factorized system of a set of contours (build once, reuse every step and frame)."""

    def __init__(self, contours: Contours, params: SnakeParams | None = None):
        self.params = params or SnakeParams()
        self.contours = contours
        si, sj, a_s, nu_s, rows, b_r = _topology(contours, self.params)
        self.si, self.sj, self.a_s, self.nu_s = si, sj, a_s, nu_s
        # each node's neighbours along its contour (an open end: itself), for its normal
        prv, nxt = [], []
        for k in range(contours.n_contours):
            idx = np.arange(contours.offsets[k], contours.offsets[k + 1])
            if contours.closed[k]:
                prv.append(np.roll(idx, 1))
                nxt.append(np.roll(idx, -1))
            else:
                prv.append(np.concatenate([idx[:1], idx[:-1]]))
                nxt.append(np.concatenate([idx[1:], idx[-1:]]))
        self.prev = np.concatenate(prv).astype(np.int64)
        self.next = np.concatenate(nxt).astype(np.int64)
        # contour k's springs are si[spring_offsets[k]:spring_offsets[k + 1]] (si ascending)
        self.spring_offsets = np.searchsorted(si, contours.offsets).astype(np.int64)
        perm = []
        for k in range(contours.n_contours):
            o0, o1 = contours.offsets[k], contours.offsets[k + 1]
            local = _interleave(o1 - o0) if contours.closed[k] else np.arange(o1 - o0)
            perm.append(o0 + local)
        self.perm = np.concatenate(perm).astype(np.int64)  # position -> node
        pos = np.empty_like(self.perm)
        pos[self.perm] = np.arange(len(self.perm))  # node -> position
        self.pos = pos
        n = len(contours.nodes)
        # assemble (gamma/dt + K) in band storage of the permuted order
        entries = {}
        for i in range(n):
            entries[(pos[i], pos[i])] = self.params.gamma_over_dt
        d = (1.0, -2.0, 1.0)
        for r, b in zip(rows, b_r, strict=True):
            if b == 0:
                continue
            for u in range(3):
                for v in range(3):
                    key = (pos[r[u]], pos[r[v]])
                    entries[key] = entries.get(key, 0.0) + b * d[u] * d[v]
        bw = max((abs(i - j) for (i, j) in entries), default=0)
        band = np.zeros((n, bw + 1))
        for (i, j), v in entries.items():
            if i >= j:
                band[i, i - j] += v
        if not _band_cholesky(band, bw):
            raise MyofaceValueError("the snake system is not positive definite (bad parameters)")
        self.band, self.bw = band, bw

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve (gamma/dt + K) x = rhs for rhs (N, 2) in node order."""
        r = np.ascontiguousarray(rhs[self.perm])
        out = np.empty_like(r)
        _band_solve(self.band, self.bw, r, out)
        x = np.empty_like(out)
        x[self.perm] = out
        return x


#: iterations over which the equilibrium test measures the motion
WINDOW = 10
#: a node this close to the image's (or the potential window's) border is on it: lost (nodes held
#: there by the clamped interpolation creep a little way in and out)
BORDER_PX = 0.5


@njit(cache=True, nogil=True, inline="always")
def _gradient_at(gx, gy, lay, x, y):
    """Bilinear samples of layer ``lay`` of the gradient stacks (L, H, W) at (x, y)."""
    h, w = gx.shape[1], gx.shape[2]
    x = min(max(x, 0.0), w - 1.0)
    y = min(max(y, 0.0), h - 1.0)
    x0 = min(int(x), w - 2)
    y0 = min(int(y), h - 2)
    fx, fy = x - x0, y - y0
    w00 = (1 - fx) * (1 - fy)
    w01 = fx * (1 - fy)
    w10 = (1 - fx) * fy
    w11 = fx * fy
    a = (
        w00 * gx[lay, y0, x0]
        + w01 * gx[lay, y0, x0 + 1]
        + w10 * gx[lay, y0 + 1, x0]
        + w11 * gx[lay, y0 + 1, x0 + 1]
    )
    b = (
        w00 * gy[lay, y0, x0]
        + w01 * gy[lay, y0, x0 + 1]
        + w10 * gy[lay, y0 + 1, x0]
        + w11 * gy[lay, y0 + 1, x0 + 1]
    )
    return a, b


@njit(cache=True, nogil=True)
def _iterate(
    x,
    rest,
    si,
    sj,
    a_s,
    nu_s,
    layer,
    gx,
    gy,
    p,
    user,
    g_dt,
    max_iter,
    tol,
    perm,
    band,
    bw,
    prv,
    nxt,
    offsets,
    spring_offsets,
):
    """Eq. (11) iterated: the nodes ``x`` (N, 2) and rest lengths ``rest`` in place; returns
    (iterations, the largest move across the contours over the last WINDOW of them). Works in
    the band's node order (``perm``: position -> node; contour k at positions ``offsets[k]``
    to ``offsets[k + 1]``, its springs ``spring_offsets[k]`` to ``spring_offsets[k + 1]``),
    so that the solve needs no copies. The matrix is block-diagonal, one block per contour
    (breaks between contours), so a contour at rest stops while the others go on."""
    n = x.shape[0]
    nc = offsets.shape[0] - 1
    pos = np.empty(n, np.int64)
    for q in range(n):
        pos[perm[q]] = q
    xp = np.empty((n, 2))
    lay = np.empty(n, np.int64)
    up = np.empty((n, 2))
    prvp = np.empty(n, np.int64)
    nxtp = np.empty(n, np.int64)
    inv = np.empty(n)
    for q in range(n):
        i = perm[q]
        xp[q, 0] = x[i, 0]
        xp[q, 1] = x[i, 1]
        lay[q] = layer[i]
        up[q, 0] = user[i, 0]
        up[q, 1] = user[i, 1]
        prvp[q] = pos[prv[i]]
        nxtp[q] = pos[nxt[i]]
        inv[q] = 1.0 / band[q, 0]
    ns = si.shape[0]
    sip = np.empty(ns, np.int64)
    sjp = np.empty(ns, np.int64)
    for m in range(ns):
        sip[m] = pos[si[m]]
        sjp[m] = pos[sj[m]]
    f = np.empty((n, 2))
    ref = xp.copy()  # positions WINDOW iterations ago
    active = np.ones(nc, np.bool_)
    last = np.zeros(nc)  # each contour's last move across it over a WINDOW
    done = max_iter
    for it in range(max_iter):
        for k in range(nc):
            if not active[k]:
                continue
            o0, o1 = offsets[k], offsets[k + 1]
            # right-hand side of eq. (11): (gamma/dt) x + image forces (eq. 12) + tension
            # (eq. 7)
            for q in range(o0, o1):
                sx, sy = _gradient_at(gx, gy, lay[q], xp[q, 0], xp[q, 1])
                f[q, 0] = g_dt * xp[q, 0] - p * sx + up[q, 0]
                f[q, 1] = g_dt * xp[q, 1] - p * sy + up[q, 1]
            for m in range(spring_offsets[k], spring_offsets[k + 1]):
                i, j = sip[m], sjp[m]
                rx = xp[j, 0] - xp[i, 0]
                ry = xp[j, 1] - xp[i, 1]
                d = np.sqrt(rx * rx + ry * ry)
                e = d - rest[m]
                if d > 1e-12 and a_s[m] != 0.0:
                    c = a_s[m] * e / d
                    f[i, 0] += c * rx
                    f[i, 1] += c * ry
                    f[j, 0] -= c * rx
                    f[j, 1] -= c * ry
                rest[m] += nu_s[m] * e / g_dt  # eq. (8), dt = 1 / (gamma/dt), gamma = 1
            # (gamma/dt + K) x' = f on this contour's block: forward and backward
            # substitution with the band factor
            for i in range(o0, o1):
                s0 = f[i, 0]
                s1 = f[i, 1]
                for kk in range(1, min(i - o0, bw) + 1):
                    lk = band[i, kk]
                    s0 -= lk * f[i - kk, 0]
                    s1 -= lk * f[i - kk, 1]
                f[i, 0] = s0 * inv[i]
                f[i, 1] = s1 * inv[i]
            for i in range(o1 - 1, o0 - 1, -1):
                s0 = f[i, 0]
                s1 = f[i, 1]
                for kk in range(1, min(o1 - 1 - i, bw) + 1):
                    lk = band[i + kk, kk]
                    s0 -= lk * f[i + kk, 0]
                    s1 -= lk * f[i + kk, 1]
                f[i, 0] = s0 * inv[i]
                f[i, 1] = s1 * inv[i]
            for q in range(o0, o1):
                xp[q, 0] = f[q, 0]
                xp[q, 1] = f[q, 1]
        if (it + 1) % WINDOW == 0:
            still = True
            for k in range(nc):
                if not active[k]:
                    continue
                moved = 0.0
                for q in range(offsets[k], offsets[k + 1]):
                    # the move across the contour: along the normal of its neighbours' chord
                    tx = xp[nxtp[q], 0] - xp[prvp[q], 0]
                    ty = xp[nxtp[q], 1] - xp[prvp[q], 1]
                    tl = np.sqrt(tx * tx + ty * ty)
                    dx = xp[q, 0] - ref[q, 0]
                    dy = xp[q, 1] - ref[q, 1]
                    if tl > 1e-9:
                        d = abs(dx * ty - dy * tx) / tl
                    else:
                        d = max(abs(dx), abs(dy))
                    if not d <= moved:  # also catches NaN
                        moved = d
                    ref[q, 0] = xp[q, 0]
                    ref[q, 1] = xp[q, 1]
                last[k] = moved
                if not np.isfinite(moved):
                    for q in range(n):
                        x[perm[q], 0] = xp[q, 0]
                        x[perm[q], 1] = xp[q, 1]
                    return it + 1, moved
                if moved < tol:
                    active[k] = False  # at rest: it stays where it is
                else:
                    still = False
            if still:
                done = it + 1
                break
    for q in range(n):
        x[perm[q], 0] = xp[q, 0]
        x[perm[q], 1] = xp[q, 1]
    worst = 0.0
    for k in range(nc):
        worst = max(worst, last[k])
    return done, worst


@njit(cache=True, nogil=True)
def _sample(pot, layer, x, out):
    for i in range(x.shape[0]):
        out[i] = bilinear(pot[layer[i]], x[i, 0], x[i, 1])


@dataclass
class SnakeResult:
    """Outcome of :func:`relax_contours` on one potential.

    Attributes
    ----------
    contours : Contours — with the equilibrium nodes.
    rest_lengths : (S,) — the springs' rest lengths after the relaxation (eq. 8).
    converged : bool; iterations : int; residual_px : float — the largest node move across
        its contour over the last WINDOW iterations.
    mean_potential : (K,) — mean P under each contour (more negative: on stronger edges).
    escaped : (K,) int — nodes per contour whose |P| fell below ``escape_ratio`` x the
        contour's reference level, or that left the image (or the potential's window).
    lost : (N,) bool — those nodes.
    """

    contours: Contours
    rest_lengths: np.ndarray
    converged: bool
    iterations: int
    residual_px: float
    mean_potential: np.ndarray
    escaped: np.ndarray
    node_potential: np.ndarray = field(repr=False, default=None)
    lost: np.ndarray = field(repr=False, default=None)

    @property
    def nodes(self) -> np.ndarray:
        return self.contours.nodes

    def split(self) -> list[np.ndarray]:
        return self.contours.split()


def _check_inside(x: np.ndarray, shape, names, offsets) -> None:
    h, w = shape
    bad = (x[:, 0] < 0) | (x[:, 0] > w - 1) | (x[:, 1] < 0) | (x[:, 1] > h - 1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        k = int(np.searchsorted(offsets, i, side="right") - 1)
        raise MyofaceValueError(
            f"contour {names[k]!r} has nodes outside the {w}x{h} image, e.g. node {i - offsets[k]} "
            f"at (x, y) = ({x[i, 0]:.1f}, {x[i, 1]:.1f})"
        )


class Snakes:
    """Contours with their factorized system and viscoelastic state, ready to relax on a
    sequence of potentials (the tracker's state between frames).

    ``layers`` (one int per contour, default all 0): which layer of a stacked potential
    (L, H, W) each contour moves in, so that different features can be tracked in different
    potentials (e.g. edges for the lips, a line detector for a furrow)."""

    def __init__(self, contours: Contours, params: SnakeParams | None = None, layers=None):
        self.params = params or SnakeParams()
        self.system = SnakeSystem(contours, self.params)
        self.contours = contours.with_nodes(contours.nodes)
        k = contours.n_contours
        lay = np.zeros(k, dtype=np.int64) if layers is None else np.asarray(layers, np.int64)
        if lay.shape != (k,) or (lay < 0).any():
            raise MyofaceValueError(f"layers must be {k} non-negative ints, one per contour")
        self.layers = lay
        self.node_layer = np.repeat(lay, np.diff(contours.offsets))
        s = self.system
        x = self.contours.nodes
        self.rest = np.linalg.norm(x[s.sj] - x[s.si], axis=1)  # l_i = initial spacings
        self.reference = None  # (K,) mean |P| per contour on the first relaxed frame

    def transform(self, a, b) -> None:
        """Move every node by the affine map x -> a x + b (e.g. the head's motion between two
        frames, applied before relaxing on the next one); rest lengths scale with it."""
        a = np.asarray(a, dtype=np.float64).reshape(2, 2)
        b = np.asarray(b, dtype=np.float64).reshape(2)
        if not (np.isfinite(a).all() and np.isfinite(b).all()):
            raise MyofaceValueError("the contour transform must be finite")
        x = self.contours.nodes
        x[:] = x @ a.T + b
        self.rest *= np.sqrt(abs(np.linalg.det(a)))

    def reset_contour(self, k: int, nodes: np.ndarray) -> None:
        """Put contour ``k`` at ``nodes`` ((K_k, 2) pixels, its node count) with their spacings
        as rest lengths: a lost contour re-initialised (e.g. from a model's prediction)."""
        c = self.contours
        o0, o1 = c.offsets[k], c.offsets[k + 1]
        q = np.asarray(nodes, dtype=np.float64)
        if q.shape != (o1 - o0, 2) or not np.isfinite(q).all():
            raise MyofaceValueError(f"contour {k} needs {o1 - o0} finite (x, y) nodes")
        c.nodes[o0:o1] = q
        s = self.system
        m = (s.si >= o0) & (s.si < o1)
        self.rest[m] = np.linalg.norm(c.nodes[s.sj[m]] - c.nodes[s.si[m]], axis=1)

    def relax(
        self,
        potential,
        user_forces: np.ndarray | None = None,
        *,
        outside: str = "clip",
    ) -> SnakeResult:
        """Let the contours settle in ``potential`` from where they are now: a
        :class:`~myoface.analysis.potentials.PotentialField` (a window of an image, its
        gradients computed once for several relaxations), or an array (H, W), or (L, H, W)
        with the layers given at construction, over the whole image.

        ``outside``: what to do with nodes outside the image (or the field's window) at the
        start: ``"clip"`` (default; a tracker's contours may leave the frame with the face)
        moves them onto its border, where they count as lost; ``"raise"`` refuses them.
        """
        if outside not in ("clip", "raise"):
            raise MyofaceValueError(f"outside must be 'clip' or 'raise'; got {outside!r}")
        fld = (
            potential
            if isinstance(potential, PotentialField)
            else PotentialField.from_potential(potential)
        )
        pot = fld.potential
        if self.layers.max() >= len(pot):
            raise MyofaceValueError(
                f"the contours use potential layer {self.layers.max()}; got {len(pot)} layer(s)"
            )
        c = self.contours
        wi, hi = fld.image_size
        if outside == "raise":
            _check_inside(c.nodes, (hi, wi), c.names, c.offsets)
        n = len(c.nodes)
        if user_forces is None:
            user = np.zeros((n, 2))
        else:
            user = np.asarray(user_forces, dtype=np.float64)
            if user.shape != (n, 2) or not np.isfinite(user).all():
                raise MyofaceValueError(f"user_forces must be a finite ({n}, 2) array")
        s, p = self.system, self.params
        h, w = pot.shape[1:]
        ox, oy = fld.origin
        x = c.nodes
        x -= (ox, oy)  # window coordinates
        np.clip(x[:, 0], 0, w - 1, out=x[:, 0])
        np.clip(x[:, 1], 0, h - 1, out=x[:, 1])
        it, moved = _iterate(
            x,
            self.rest,
            s.si,
            s.sj,
            s.a_s,
            s.nu_s,
            self.node_layer,
            fld.gx,
            fld.gy,
            float(p.p),
            user,
            float(p.gamma_over_dt),
            int(p.max_iter),
            float(p.tol_px),
            s.perm,
            s.band,
            s.bw,
            s.prev,
            s.next,
            c.offsets,
            s.spring_offsets,
        )
        if not np.isfinite(moved):
            x += (ox, oy)
            raise MyofaceValueError(
                "the contours diverged (NaN); reduce p or increase gamma_over_dt"
            )
        np.clip(x[:, 0], 0, w - 1, out=x[:, 0])
        np.clip(x[:, 1], 0, h - 1, out=x[:, 1])
        vals = np.empty(n)
        _sample(pot, self.node_layer, x, vals)
        e = BORDER_PX
        border = (x[:, 0] <= e) | (x[:, 0] >= w - 1 - e) | (x[:, 1] <= e) | (x[:, 1] >= h - 1 - e)
        x += (ox, oy)  # back to image coordinates
        k = c.n_contours
        mean = np.array([vals[c.offsets[j] : c.offsets[j + 1]].mean() for j in range(k)])
        if self.reference is None:
            self.reference = np.abs(mean)
        edge = np.repeat(self.reference, np.diff(c.offsets))
        lost = (np.abs(vals) < p.escape_ratio * edge) | border
        escaped = np.add.reduceat(lost.astype(np.int64), c.offsets[:-1])
        return SnakeResult(
            c.with_nodes(x),
            self.rest.copy(),
            bool(moved < p.tol_px),
            int(it),
            float(moved),
            mean,
            escaped,
            vals,
            lost,
        )


def relax_contours(
    potential: np.ndarray,
    contours: Contours,
    params: SnakeParams | None = None,
    user_forces: np.ndarray | None = None,
) -> SnakeResult:
    """Relax ``contours`` in ``potential`` (H, W) to equilibrium (one-shot; see :class:`Snakes`
    to keep the viscoelastic state across frames). Nodes outside the image are refused."""
    return Snakes(contours, params).relax(potential, user_forces, outside="raise")


@dataclass
class TrackFrame:
    """Per-frame tracking result: frame index and the :class:`SnakeResult` on it."""

    index: int
    result: SnakeResult


def track_contours(
    frames: Iterable[np.ndarray],
    contours: Contours,
    params: SnakeParams | None = None,
    *,
    sigma: float = 2.0,
    method: str = "gaussian",
) -> Iterator[TrackFrame]:
    """Track ``contours`` through ``frames`` ((H, W) or (H, W, 3) images): relax on frame k,
    continue on frame k + 1 from that equilibrium (T&W 1993, Section V-D). Yields one
    :class:`TrackFrame` per frame with its diagnostics."""
    snakes = Snakes(contours, params)
    for k, frame in enumerate(frames):
        f = np.asarray(frame)
        if f.size == 0:
            raise MyofaceValueError(f"frame {k} is empty")
        pot = image_potential(f, sigma=sigma, method=method)
        yield TrackFrame(k, snakes.relax(pot))
