"""Internal forces of the tissue lattice: biphasic springs (eq. 1-2) and volume preservation.

Every kernel exists twice: a numba implementation (``*_numba``, used by the integrators) and a
plain numpy reference (``*_numpy``) that the tests hold the numba one against.

Units: positions in mm, stiffness in g/s^2 (= uN/mm), forces in g*mm/s^2 (= uN), energies in
g*mm^2/s^2 (= nJ).

References: Terzopoulos & Waters 1993, eq. (1)-(4).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

# ---------------------------------------------------------------------------------------------
# springs, eq. (1)-(2):  s_k = (c_k e_k / |r_k|) r_k,  c_k = alpha if e_k <= e^c_k else beta,
# with e^c_k = strain_c * l_k (the threshold is a strain, so one value serves every spring of a
# layer whatever its length).
# material table rows: [alpha, beta, strain_c]
#
# ``law`` selects how the two phases join:
#   LAW_CONTINUOUS (default): the *stiffness* switches at e^c, the force stays continuous:
#       |s| = alpha e  (e <= e^c),   alpha e^c + beta (e - e^c)  (e > e^c)
#     — the two-slope stress-strain curve of collagenous tissue; it has a smooth energy, so an
#     equilibrium exists and Newton's method converges on it.
#   LAW_PAPER: eq. (2) literally, |s| = c_k e with c_k jumping from alpha to beta; the force is
#     discontinuous at e^c (usable with the explicit RK2 integrator only).
# ---------------------------------------------------------------------------------------------

#: below this length (mm) a spring is treated as degenerate (no direction) and exerts no force
MIN_SPRING_LENGTH = 1e-12
LAW_CONTINUOUS = 0
LAW_PAPER = 1


def _magnitude_numpy(e, rest, mat_id, mat, law):
    a, b, ec = mat[mat_id, 0], mat[mat_id, 1], mat[mat_id, 2] * rest
    if law == LAW_PAPER:
        return np.where(e <= ec, a * e, b * e)
    return np.where(e <= ec, a * e, a * ec + b * (e - ec))


def spring_forces_numpy(x, si, sj, rest, mat_id, mat, law=LAW_CONTINUOUS):
    """Reference: total spring force on every node, (N, 3). See :func:`spring_forces_numba`."""
    r = x[sj] - x[si]
    d = np.linalg.norm(r, axis=1)
    e = d - rest
    s = (_magnitude_numpy(e, rest, mat_id, mat, law) / np.maximum(d, MIN_SPRING_LENGTH))[
        :, None
    ] * r
    f = np.zeros_like(x)
    np.add.at(f, si, s)  # a stretched spring pulls node i towards j ...
    np.add.at(f, sj, -s)  # ... and j towards i
    return f


def spring_energy_numpy(x, si, sj, rest, mat_id, mat, law=LAW_CONTINUOUS):
    """Reference: total elastic energy of the biphasic springs (the integral of eq. 1-2)."""
    d = np.linalg.norm(x[sj] - x[si], axis=1)
    e = d - rest
    a, b, ec = mat[mat_id, 0], mat[mat_id, 1], mat[mat_id, 2] * rest
    low = 0.5 * a * e**2
    if law == LAW_PAPER:
        high = 0.5 * a * ec**2 + 0.5 * b * (e**2 - ec**2)
    else:
        high = 0.5 * a * ec**2 + a * ec * (e - ec) + 0.5 * b * (e - ec) ** 2
    return float(np.sum(np.where(e <= ec, low, high)))


@njit(cache=True, inline="always")
def spring_magnitude(e, lk, m, mat, law):
    """|s_k| of eq. (1)-(2) for extension e of a spring of rest length lk and material m."""
    ec = mat[m, 2] * lk
    if e <= ec:
        return mat[m, 0] * e
    if law == LAW_PAPER:
        return mat[m, 1] * e
    return mat[m, 0] * ec + mat[m, 1] * (e - ec)


@njit(cache=True)
def spring_forces_range(x, si, sj, rest, mat_id, mat, law, k0, k1, f):
    """Add the forces of springs ``k0 .. k1-1`` to ``f`` (N, 3): a spring pulls its node
    ``si[k]`` by s_k (eq. 1) and ``sj[k]`` by -s_k, in spring order. See
    :func:`spring_forces_numba` for the arguments."""
    for k in range(k0, k1):
        i = si[k]
        j = sj[k]
        rx = x[j, 0] - x[i, 0]
        ry = x[j, 1] - x[i, 1]
        rz = x[j, 2] - x[i, 2]
        d = np.sqrt(rx * rx + ry * ry + rz * rz)
        if d < MIN_SPRING_LENGTH:
            continue
        s = spring_magnitude(d - rest[k], rest[k], mat_id[k], mat, law) / d
        fx = s * rx
        fy = s * ry
        fz = s * rz
        f[i, 0] += fx
        f[i, 1] += fy
        f[i, 2] += fz
        f[j, 0] -= fx
        f[j, 1] -= fy
        f[j, 2] -= fz


@njit(cache=True)
def spring_forces_numba(x, si, sj, rest, mat_id, mat, law, f):
    """Add the spring forces on every node to ``f`` (N, 3), one thread.

    Parameters
    ----------
    x : (N, 3) float64 — node positions, mm.
    si, sj : (S,) int — end nodes of each spring.
    rest : (S,) float64 — natural lengths l_k, mm.
    mat_id : (S,) int — row of ``mat`` for each spring.
    mat : (M, 3) float64 — [alpha, beta, strain_c] per material (g/s^2, g/s^2, -).
    law : int — :data:`LAW_CONTINUOUS` or :data:`LAW_PAPER`.
    f : (N, 3) float64 — accumulated into (not zeroed).
    """
    spring_forces_range(x, si, sj, rest, mat_id, mat, law, 0, len(si), f)


@njit(cache=True, parallel=True)
def spring_forces_parallel(x, si, sj, rest, mat_id, mat, law, f, buffers):
    """Like :func:`spring_forces_numba` on all cores: each thread owns a contiguous range of
    springs and a private force buffer (``buffers``: (T, N, 3)), summed at the end."""
    nt = buffers.shape[0]
    n = x.shape[0]
    ns = si.shape[0]
    for t in prange(nt):
        b = buffers[t]
        for q in range(n):
            b[q, 0] = 0.0
            b[q, 1] = 0.0
            b[q, 2] = 0.0
        k0 = (ns * t) // nt
        k1 = (ns * (t + 1)) // nt
        spring_forces_range(x, si, sj, rest, mat_id, mat, law, k0, k1, b)
    # reduce over threads, parallel over nodes
    for q in prange(n):
        for t in range(nt):
            f[q, 0] += buffers[t, q, 0]
            f[q, 1] += buffers[t, q, 1]
            f[q, 2] += buffers[t, q, 2]


def make_thread_buffers(n_nodes: int) -> np.ndarray:
    """Per-thread force buffers for :func:`spring_forces_parallel`, (T, N, 3)."""
    return np.zeros((numba.get_num_threads(), n_nodes, 3))


# ---------------------------------------------------------------------------------------------
# volume preservation:  Q = sum_j kv_j (V_j - V0_j)^2,  force on node i = -dQ/dx_i
# elements are triangular prisms (6 nodes: top a0 b0 c0, bottom a1 b1 c1), each split into three
# tetrahedra; the signed volume is multiplied by the model's orientation sign so rest volumes > 0.
# ---------------------------------------------------------------------------------------------

#: the three tetrahedra of a prism [a0, b0, c0, a1, b1, c1] (indices into the element's 6 nodes)
PRISM_TETS = np.array([[0, 1, 2, 3], [1, 2, 3, 4], [2, 3, 4, 5]], dtype=np.int64)
#: the 15 node pairs (a, b), a < b, of a prism (its edges and face diagonals), in row-major
#: order: every spring of the layered lattice joins the two nodes of one of them
PRISM_PAIRS = np.array([(a, b) for a in range(6) for b in range(a + 1, 6)], dtype=np.int64)


def element_volumes_numpy(x, elems, sign=1.0):
    """Reference: volume of each prism element, (E,), mm^3."""
    vol = np.zeros(len(elems))
    for t in PRISM_TETS:
        p0, p1, p2, p3 = (x[elems[:, t[q]]] for q in range(4))
        vol += np.einsum("ij,ij->i", p1 - p0, np.cross(p2 - p0, p3 - p0)) / 6.0
    return sign * vol


def volume_energy_numpy(x, elems, rest_vol, kv, sign=1.0):
    """Reference: Q = sum_j kv_j (V_j - V0_j)^2 (Terzopoulos & Waters 1993, Section III-B)."""
    dv = element_volumes_numpy(x, elems, sign) - rest_vol
    return float(np.sum(kv * dv * dv))


def volume_forces_numpy(x, elems, rest_vol, kv, sign=1.0):
    """Reference: -dQ/dx for every node, (N, 3)."""
    dv = element_volumes_numpy(x, elems, sign) - rest_vol
    coef = -2.0 * kv * dv * sign / 6.0
    f = np.zeros_like(x)
    for t in PRISM_TETS:
        p0, p1, p2, p3 = (x[elems[:, t[q]]] for q in range(4))
        g1 = np.cross(p2 - p0, p3 - p0)
        g2 = np.cross(p3 - p0, p1 - p0)
        g3 = np.cross(p1 - p0, p2 - p0)
        g0 = -(g1 + g2 + g3)
        for q, g in zip(t, (g0, g1, g2, g3), strict=True):
            np.add.at(f, elems[:, q], coef[:, None] * g)
    return f


@njit(cache=True)
def _prism_volume(x, el, sign):
    v = 0.0
    for t in range(3):
        p0 = el[PRISM_TETS_NB[t, 0]]
        p1 = el[PRISM_TETS_NB[t, 1]]
        p2 = el[PRISM_TETS_NB[t, 2]]
        p3 = el[PRISM_TETS_NB[t, 3]]
        ax = x[p1, 0] - x[p0, 0]
        ay = x[p1, 1] - x[p0, 1]
        az = x[p1, 2] - x[p0, 2]
        bx = x[p2, 0] - x[p0, 0]
        by = x[p2, 1] - x[p0, 1]
        bz = x[p2, 2] - x[p0, 2]
        cx = x[p3, 0] - x[p0, 0]
        cy = x[p3, 1] - x[p0, 1]
        cz = x[p3, 2] - x[p0, 2]
        v += ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx)
    return sign * v / 6.0


PRISM_TETS_NB = PRISM_TETS  # a module-level constant numba freezes into the compiled code


@njit(cache=True)
def volume_forces_numba(x, elems, rest_vol, kv, sign, f):
    """Add -dQ/dx (volume preservation) to ``f`` (N, 3). ``elems``: (E, 6) prism nodes.

    One pass per element: the cross products of each tetrahedron's edges give both its volume
    (a . (b x c) / 6) and its volume gradient, so they are computed once and kept in ``g``."""
    g = np.empty((3, 3, 3))  # [tet, vertex 1..3, axis]: dV/dp of the tetrahedron's last 3 nodes
    for e in range(elems.shape[0]):
        el = elems[e]
        vol = 0.0
        for t in range(3):
            i0 = el[PRISM_TETS_NB[t, 0]]
            i1 = el[PRISM_TETS_NB[t, 1]]
            i2 = el[PRISM_TETS_NB[t, 2]]
            i3 = el[PRISM_TETS_NB[t, 3]]
            ax = x[i1, 0] - x[i0, 0]
            ay = x[i1, 1] - x[i0, 1]
            az = x[i1, 2] - x[i0, 2]
            bx = x[i2, 0] - x[i0, 0]
            by = x[i2, 1] - x[i0, 1]
            bz = x[i2, 2] - x[i0, 2]
            cx = x[i3, 0] - x[i0, 0]
            cy = x[i3, 1] - x[i0, 1]
            cz = x[i3, 2] - x[i0, 2]
            # dV/dp1 = b x c, dV/dp2 = c x a, dV/dp3 = a x b, dV/dp0 = -(sum)
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
        dv = sign * vol / 6.0 - rest_vol[e]
        coef = -2.0 * kv[e] * dv * sign / 6.0
        if coef == 0.0:
            continue
        for t in range(3):
            i0 = el[PRISM_TETS_NB[t, 0]]
            for q in range(3):
                iq = el[PRISM_TETS_NB[t, q + 1]]
                for d in range(3):
                    f[iq, d] += coef * g[t, q, d]
                    f[i0, d] -= coef * g[t, q, d]


@njit(cache=True, inline="always")
def _tet_gradient(x, i0, i1, i2, i3):
    """6 x the signed volume of tetrahedron (i0, i1, i2, i3) and its gradient with respect to
    nodes i1, i2, i3 (b x c, c x a, a x b with a, b, c its edges from i0; that of i0 is minus
    their sum)."""
    ax = x[i1, 0] - x[i0, 0]
    ay = x[i1, 1] - x[i0, 1]
    az = x[i1, 2] - x[i0, 2]
    bx = x[i2, 0] - x[i0, 0]
    by = x[i2, 1] - x[i0, 1]
    bz = x[i2, 2] - x[i0, 2]
    cx = x[i3, 0] - x[i0, 0]
    cy = x[i3, 1] - x[i0, 1]
    cz = x[i3, 2] - x[i0, 2]
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


@njit(cache=True)
def prism_volume_forces_range(x, elems, rest_vol, kv, sign, e0, e1, f):
    """Add -dQ_e/dx of prisms ``e0 .. e1-1`` to ``f`` (N, 3), in prism order, each node's
    gradient summed over the prism's three tetrahedra (slots (0 1 2 3), (1 2 3 4), (2 3 4 5) of
    :data:`PRISM_TETS`) and added once: the arithmetic, and the order of the sums, of the
    parallel RK2's chunked prisms (:func:`_prism_chunk_forces`), one prism at a time; the tests
    hold :func:`prism_volume_forces_split` to it bit for bit. Same value as
    :func:`volume_forces_numba`, which adds each tetrahedron's terms one by one."""
    for e in range(e0, e1):
        n0 = elems[e, 0]
        n1 = elems[e, 1]
        n2 = elems[e, 2]
        n3 = elems[e, 3]
        n4 = elems[e, 4]
        n5 = elems[e, 5]
        v0, a1x, a1y, a1z, a2x, a2y, a2z, a3x, a3y, a3z = _tet_gradient(x, n0, n1, n2, n3)
        v1, b1x, b1y, b1z, b2x, b2y, b2z, b3x, b3y, b3z = _tet_gradient(x, n1, n2, n3, n4)
        v2, c1x, c1y, c1z, c2x, c2y, c2z, c3x, c3y, c3z = _tet_gradient(x, n2, n3, n4, n5)
        dv = sign * ((v0 + v1) + v2) / 6.0 - rest_vol[e]
        coef = -2.0 * kv[e] * dv * sign / 6.0
        f[n0, 0] += coef * -((a1x + a2x) + a3x)
        f[n0, 1] += coef * -((a1y + a2y) + a3y)
        f[n0, 2] += coef * -((a1z + a2z) + a3z)
        f[n1, 0] += coef * (a1x - ((b1x + b2x) + b3x))
        f[n1, 1] += coef * (a1y - ((b1y + b2y) + b3y))
        f[n1, 2] += coef * (a1z - ((b1z + b2z) + b3z))
        f[n2, 0] += coef * ((a2x + b1x) - ((c1x + c2x) + c3x))
        f[n2, 1] += coef * ((a2y + b1y) - ((c1y + c2y) + c3y))
        f[n2, 2] += coef * ((a2z + b1z) - ((c1z + c2z) + c3z))
        f[n3, 0] += coef * ((a3x + b2x) + c1x)
        f[n3, 1] += coef * ((a3y + b2y) + c1y)
        f[n3, 2] += coef * ((a3z + b2z) + c1z)
        f[n4, 0] += coef * (b3x + c2x)
        f[n4, 1] += coef * (b3y + c2y)
        f[n4, 2] += coef * (b3z + c2z)
        f[n5, 0] += coef * c3x
        f[n5, 1] += coef * c3y
        f[n5, 2] += coef * c3z


@njit(cache=True)
def internal_forces_numba(x, si, sj, rest, mat_id, mat, law, elems, rest_vol, kv, vsign, f):
    """-(g + q) of eq. (3)-(4) on every node into ``f`` (N, 3) (zeroed first), one thread."""
    f[:, :] = 0.0
    spring_forces_numba(x, si, sj, rest, mat_id, mat, law, f)
    volume_forces_numba(x, elems, rest_vol, kv, vsign, f)


# ---------------------------------------------------------------------------------------------
# the RK2 kernel's form of the volume forces (:mod:`myoface.tissue.rk2`): the arithmetic is split
# from the gather and scatter so that the compiler vectorises it (four float64 at a time), with no
# change to any value (no product is fused into an add: numba does not contract without
# fastmath). ``error_model="numpy"``: no Python exception's test in the loop, which would stop
# the vectorisation.
# ---------------------------------------------------------------------------------------------


#: prisms per chunk of :func:`prism_volume_forces_split` (its scratch, PRISM_WORK rows of this
#: many float64, ~20 kB, stays in the L1 cache)
PRISM_CHUNK = 64
#: rows of that scratch: 18 coordinates, rest volume, weight, 18 force components
PRISM_WORK = 38


@njit(cache=True, inline="always")
def _chunk_tet(w, q, o0, o1, o2, o3):
    """:func:`_tet_gradient` of the tetrahedron whose nodes' coordinates sit in rows
    3 o0 .. 3 o3 + 2 of the chunk ``w``, lane q."""
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


@njit(cache=True, error_model="numpy")
def _prism_chunk_forces(w, sign):
    """The volume force terms of a chunk of PRISM_CHUNK prisms, lane by lane: rows 0..17 of
    ``w`` (the six nodes' coordinates), 18 (rest volume), 19 (weight) in, rows 20..37 (the six
    nodes' force terms) out. One array, rows at constant offsets: the compiler sees that the
    lanes are independent and vectorises the loop with no run-time overlap test."""
    c = PRISM_CHUNK
    for q in range(c):
        v0, a1x, a1y, a1z, a2x, a2y, a2z, a3x, a3y, a3z = _chunk_tet(w, q, 0, 1, 2, 3)
        v1, b1x, b1y, b1z, b2x, b2y, b2z, b3x, b3y, b3z = _chunk_tet(w, q, 1, 2, 3, 4)
        v2, c1x, c1y, c1z, c2x, c2y, c2z, c3x, c3y, c3z = _chunk_tet(w, q, 2, 3, 4, 5)
        dv = sign * ((v0 + v1) + v2) / 6.0 - w[18 * c + q]
        coef = -2.0 * w[19 * c + q] * dv * sign / 6.0
        w[20 * c + q] = coef * -((a1x + a2x) + a3x)
        w[21 * c + q] = coef * -((a1y + a2y) + a3y)
        w[22 * c + q] = coef * -((a1z + a2z) + a3z)
        w[23 * c + q] = coef * (a1x - ((b1x + b2x) + b3x))
        w[24 * c + q] = coef * (a1y - ((b1y + b2y) + b3y))
        w[25 * c + q] = coef * (a1z - ((b1z + b2z) + b3z))
        w[26 * c + q] = coef * ((a2x + b1x) - ((c1x + c2x) + c3x))
        w[27 * c + q] = coef * ((a2y + b1y) - ((c1y + c2y) + c3y))
        w[28 * c + q] = coef * ((a2z + b1z) - ((c1z + c2z) + c3z))
        w[29 * c + q] = coef * ((a3x + b2x) + c1x)
        w[30 * c + q] = coef * ((a3y + b2y) + c1y)
        w[31 * c + q] = coef * ((a3z + b2z) + c1z)
        w[32 * c + q] = coef * (b3x + c2x)
        w[33 * c + q] = coef * (b3y + c2y)
        w[34 * c + q] = coef * (b3z + c2z)
        w[35 * c + q] = coef * c3x
        w[36 * c + q] = coef * c3y
        w[37 * c + q] = coef * c3z


@njit(cache=True, error_model="numpy")
def prism_volume_forces_split(x, elems, rest_vol, kv, sign, e0, e1, f, work):
    """Add -dQ_e/dx of prisms ``e0 .. e1-1`` to ``f`` (N, 3): the same values, added in the same
    order, as :func:`prism_volume_forces_range`, a chunk of :data:`PRISM_CHUNK` prisms at a time:
    their nodes' coordinates gathered into ``work`` ((PRISM_WORK * PRISM_CHUNK,) float64
    scratch), their force terms computed there four prisms at a time
    (:func:`_prism_chunk_forces`), then added to the nodes."""
    c = PRISM_CHUNK
    for c0 in range(e0, e1, c):
        n = min(c, e1 - c0)
        for q in range(n):
            e = c0 + q
            for s in range(6):
                m = elems[e, s]
                work[(3 * s) * c + q] = x[m, 0]
                work[(3 * s + 1) * c + q] = x[m, 1]
                work[(3 * s + 2) * c + q] = x[m, 2]
            work[18 * c + q] = rest_vol[e]
            work[19 * c + q] = kv[e]
        _prism_chunk_forces(work, sign)  # the lanes past n compute on stale data, unused
        for q in range(n):
            e = c0 + q
            for s in range(6):
                m = elems[e, s]
                f[m, 0] += work[(20 + 3 * s) * c + q]
                f[m, 1] += work[(21 + 3 * s) * c + q]
                f[m, 2] += work[(22 + 3 * s) * c + q]
