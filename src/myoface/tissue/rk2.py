"""The paper's explicit integrator: midpoint RK2 on ``m x'' + gamma x' + g + q = 0``, all cores.

Two force evaluations per step (Terzopoulos & Waters 1993, Section III-B, eq. (3)-(4): explicit
Euler was not stable enough). :func:`step_rk2` advances a state in time; :func:`run_rk2` runs the
kernel on arrays in place (``relax(..., method="rk2")`` runs it to rest).

The parallel kernel cuts the free nodes into slabs (blocks) along the lattice's long axis, one
per thread; each block computes the prisms that touch its nodes, with the springs they hold
(every spring of the layered lattice joins two nodes of some prism), into a buffer of its own,
so nothing is written by two threads and the trajectory does not depend on the number of
threads, bit for bit (:class:`Rk2Plan`). A team of threads started once per call runs the
half-steps' blocks in order (:func:`_rk2_run_team`; a waiting thread spins, with x86's
``pause`` hint on x86 machines and without one elsewhere, then yields its core). Threads that
wait for each other twice a step only pay while the cores are free, so the number of threads is
chosen by measurement as the run goes (:class:`_Pace`). The plans and that chooser are owned by
one :class:`Rk2Integrator` per model (:func:`rk2_integrator`, kept in the model's memo).
:func:`_rk2_run_serial`, the single-thread kernel the parallel one replaced, is the reference
the tests hold it against.

The design's longer account, what a step costs on the default face, the measurements and what
was tried and dropped: ``docs/notes/rk2.md``.

References: Terzopoulos & Waters 1993, eq. (1)-(4) and Section III-B.
"""

from __future__ import annotations

import platform
import sys
import threading
import time
import weakref
from dataclasses import dataclass

import numba
import numpy as np
from llvmlite import ir
from numba import njit, prange, types
from numba.core import cgutils
from numba.extending import intrinsic

from myoface.errors import MyofaceSimulationError, MyofaceValueError
from myoface.tissue.forces import (
    LAW_PAPER,
    MIN_SPRING_LENGTH,
    PRISM_CHUNK,
    PRISM_PAIRS,
    PRISM_WORK,
    _prism_chunk_forces,
    internal_forces_numba,
    spring_magnitude,
)
from myoface.tissue.model import TissueModel, targets_array

#: fewest free nodes per thread: below this a block's work (~0.1 ms a step) no longer pays for
#: the two thread barriers of every step, so small lattices run on fewer threads (or one)
MIN_NODES_PER_BLOCK = 256
#: steps per kernel call when :func:`run_rk2` picks the thread count by measurement (~10 ms: the
#: return to Python between calls costs well under 1 % of that)
CHUNK_STEPS = 64
#: a short run (PROBE_STEPS) tries the thread count not in use, first after PROBE_MIN_S seconds,
#: then, while it keeps losing, after twice as long each time, up to PROBE_MAX_S. Long enough
#: that what a switch costs once (waking the team's sleeping thread, moving a block's arrays into
#: the other core's cache: ~0.1-0.2 ms) does not decide it: probes of 4 steps made the team
#: (~130 us a step on the quiet 2-core machine) lose to one thread (~200 us), so a run that
#: started on one thread under load stayed there once the machine was quiet
PROBE_STEPS = 32
PROBE_MIN_S = 1.0
PROBE_MAX_S = 60.0


# ------------------------------------------------- atomics for the persistent team of threads ----
# numba has no atomics on the CPU; these intrinsics emit LLVM's own instructions.


def _item_pointer(context, builder, aryty, ary, idx, idxty):
    a = context.make_array(aryty)(context, builder, ary)
    i = context.cast(builder, idx, idxty, types.intp)
    return cgutils.get_item_pointer(context, builder, aryty, a, [i])


def _is_int64_vector(arr) -> bool:
    return isinstance(arr, types.Array) and arr.dtype == types.int64 and arr.ndim == 1


@intrinsic
def _atomic_add(typingctx, arr, idx, val):
    """``arr[idx] += val`` as one atomic read-modify-write (sequentially consistent: every
    write before it is seen by a thread that sees its result); returns the old value."""
    if not _is_int64_vector(arr):
        return None
    sig = types.int64(arr, idx, val)

    def codegen(context, builder, sig, args):
        ptr = _item_pointer(context, builder, sig.args[0], args[0], args[1], sig.args[1])
        v = context.cast(builder, args[2], sig.args[2], types.int64)
        return builder.atomic_rmw("add", ptr, v, "seq_cst")

    return sig, codegen


@intrinsic
def _atomic_load(typingctx, arr, idx):
    """``arr[idx]`` read with acquire order (what another thread wrote before its atomic add
    of this value is visible after it)."""
    if not _is_int64_vector(arr):
        return None
    sig = types.int64(arr, idx)

    def codegen(context, builder, sig, args):
        ptr = _item_pointer(context, builder, sig.args[0], args[0], args[1], sig.args[1])
        return builder.load_atomic(ptr, "acquire", 8)

    return sig, codegen


@intrinsic
def _atomic_cas(typingctx, arr, idx, expected, new):
    """``arr[idx] = new`` if ``arr[idx] == expected``, as one atomic compare-and-swap
    (sequentially consistent); returns whether it swapped."""
    if not _is_int64_vector(arr):
        return None
    sig = types.boolean(arr, idx, expected, new)

    def codegen(context, builder, sig, args):
        ptr = _item_pointer(context, builder, sig.args[0], args[0], args[1], sig.args[1])
        old = context.cast(builder, args[2], sig.args[2], types.int64)
        val = context.cast(builder, args[3], sig.args[3], types.int64)
        res = builder.cmpxchg(ptr, old, val, "seq_cst", "seq_cst")
        return builder.extract_value(res, 1)

    return sig, codegen


#: whether this machine is an x86 one, whose spin loops take the ``pause`` hint (an x86
#: instruction: LLVM has no such intrinsic for other machines)
X86 = platform.machine().lower() in ("x86_64", "amd64", "i386", "i486", "i586", "i686", "x86")


@intrinsic
def _spin_pause(typingctx):
    """The x86 ``pause`` hint of a spin loop; nothing elsewhere (a plain spin)."""
    sig = types.void()

    def codegen(context, builder, sig, args):
        if X86:
            fnty = ir.FunctionType(ir.VoidType(), [])
            builder.call(
                cgutils.get_or_insert_function(builder.module, fnty, "llvm.x86.sse2.pause"), []
            )
        return context.get_dummy_value()

    return sig, codegen


#: the C function that gives a waiting thread's core to another runnable thread: POSIX's
#: ``sched_yield``, Windows' ``SwitchToThread`` (kernel32; both take nothing and return an int)
_YIELD_SYMBOL = "SwitchToThread" if sys.platform == "win32" else "sched_yield"


@intrinsic
def _os_yield(typingctx):
    """Give the core to another runnable thread (:data:`_YIELD_SYMBOL`)."""
    sig = types.void()

    def codegen(context, builder, sig, args):
        fnty = ir.FunctionType(ir.IntType(32), [])
        builder.call(cgutils.get_or_insert_function(builder.module, fnty, _YIELD_SYMBOL), [])
        return context.get_dummy_value()

    return sig, codegen


#: spins of a waiting thread before it starts to yield its core (~1 us of x86 ``pause``)
SPINS_BEFORE_YIELD = 200
_DONE = 8  # slot of the count of tasks done in the team's counters (a cache line of its own)
_LINE = 8  # float64 or int64 a cache line: per-block flags this far apart share no line


@njit(cache=True)
def _wait_done(counters, target):
    """Wait until ``target`` tasks are done: spin a little, then yield the core while waiting
    (on a busy machine the thread we wait for may need it)."""
    n = 0
    while _atomic_load(counters, _DONE) < target:
        n += 1
        if n < SPINS_BEFORE_YIELD:
            _spin_pause()
        else:
            _os_yield()


# ------------------------------------------------------------------------ the parallel kernel ----

#: rows of a (chunk, pair)'s spring constants: l_k, alpha, beta, e^c (= strain_c * l_k)
SPRING_ROWS = 4
#: a pair's springs are computed from its first lane with a spring to its last, widened to
#: whole groups of this many lanes (a vector of four float64)
PAIR_LANE_STEP = 4


@dataclass(frozen=True)
class Rk2Plan:
    """The packed arrays of the parallel kernel for one model and one number of blocks, built
    once by :meth:`Rk2Integrator.plan`.

    The free nodes are cut into ``n_blocks`` slabs along the lattice's longest axis, one per
    thread, and numbered ``q = 0 .. F-1`` block by block (``free[q]`` is the node; the kernel
    works on the nodes in this order, the kinematic ones after them: ``node_order``). Block b
    evaluates every prism that has a node of its own (its private copy, in *lanes*: a chunk of
    :data:`~myoface.tissue.forces.PRISM_CHUNK` prisms computed side by side), and each spring
    with a free end is *owned* by one prism that contains both its nodes (one of the 15 pairs
    :data:`~myoface.tissue.forces.PRISM_PAIRS`), so it is computed with that prism, from the coordinates the prism
    gathered, and added into the prism's per-node sums; then the sums of the prism's nodes that
    are the block's own are added into the block's buffer (rows ``q - q0``). A spring no prism
    owns (a lattice without prisms) is evaluated on its own after the prisms.
    Nothing is written by two threads, and each node adds the same terms in the same order
    whatever the number of blocks, so the trajectory does not depend on the number of threads.

    Attributes
    ----------
    free : (F,) int64 — node index of each free node.
    node_order : (N,) int64 — the model's node at each row of the kernel's numbering: ``free``,
        then the kinematic nodes.
    inv_mass, damping : (F,) float64 — 1/m (1/g) and gamma (g/s) of each free node.
    block_nodes : (B+1,) int64 — where each block's nodes q start.
    block_chunks : (B+1,) int64 — where each block's chunks start.
    chunk_lanes : (C+1,) int64 — where each chunk's lanes (prisms) start.
    gather : (6, L) uint32 — for each of a prism's six nodes (slot) and lane, 3 x the node's
        row in the kernel's numbering (its offset in the positions, flat); unsigned: no test for
        a negative index.
    chunk_scatter : (C+1,) int64 — where each chunk's additions into its block's buffer start.
    scatter_src, scatter_dst : (K,) uint32 — each addition: where the x component of a slot's
        force sits in the chunk's lanes ((20 + 3 slot) PRISM_CHUNK + lane), and the row of the
        block's buffer it goes into; lane by lane, slot by slot, only the slots of the block's
        own nodes (a quarter of them, on the face, are kinematic or another block's: no work).
    rest_volume, volume_weight : (L,) float64 — V0 (mm^3) and kv of each lane's prism.
    chunk_pairs : (C+1,) int64 — where each chunk's list of pairs with a spring starts.
    pair : (P,) int64 — a row of :data:`PRISM_PAIRS` with a spring in some lane of the chunk.
    pair_q0, pair_q1 : (P,) int64 — the lanes its loop runs over: from the first to the last
        lane with such a spring, widened to multiples of four (a vector's lanes); the prisms
        are in an order that gathers alike ones, so a pair held by a few prisms of a chunk
        runs over a few lanes, not all 64 (on the face: 10,904 lanes, not 13,056).
    pair_consts : (P * SPRING_ROWS * PRISM_CHUNK,) float64 — per (chunk, pair) and lane:
        l_k (mm), alpha, beta (g/s^2), e^c = strain_c * l_k (mm); zeros in a lane without
        that spring (it adds exactly nothing).
    block_springs : (B+1,) int64 — where each block's springs without a prism start.
    spring_i, spring_j, spring_ti, spring_tj, rest_length, spring_material : (S',) — those
        springs (rows of their nodes in the kernel's numbering, rows of the block buffer (its
        last row for a node not the block's), l_k, material), block by block, model order.
    """

    free: np.ndarray
    node_order: np.ndarray
    inv_mass: np.ndarray
    damping: np.ndarray
    block_nodes: np.ndarray
    block_chunks: np.ndarray
    chunk_lanes: np.ndarray
    gather: np.ndarray
    chunk_scatter: np.ndarray
    scatter_src: np.ndarray
    scatter_dst: np.ndarray
    rest_volume: np.ndarray
    volume_weight: np.ndarray
    chunk_pairs: np.ndarray
    pair: np.ndarray
    pair_q0: np.ndarray
    pair_q1: np.ndarray
    pair_consts: np.ndarray
    block_springs: np.ndarray
    spring_i: np.ndarray
    spring_j: np.ndarray
    spring_ti: np.ndarray
    spring_tj: np.ndarray
    rest_length: np.ndarray
    spring_material: np.ndarray

    @property
    def n_blocks(self) -> int:
        return len(self.block_nodes) - 1

    @property
    def rows(self) -> int:
        """Rows of a block's force buffer: its largest block's nodes, plus the discard row."""
        return int(np.diff(self.block_nodes).max(initial=0)) + 1


def _offsets(counts) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


def _spring_owners(model: TissueModel, prisms: np.ndarray):
    """For each spring, the prism (an index into ``model.elements``, one of ``prisms``) and the
    pair (row of :data:`PRISM_PAIRS`) that computes it, or -1, -1. A spring goes to the first
    pair (in :data:`PRISM_PAIRS` order), then the first prism, that joins its two nodes and does
    not already hold a spring: few distinct pairs per chunk, all springs of a layer alike."""
    n, el = model.n_nodes, model.elements
    a, b = PRISM_PAIRS[:, 0], PRISM_PAIRS[:, 1]
    u, v = el[prisms][:, a], el[prisms][:, b]  # (E', 15)
    ckey = (np.minimum(u, v) * n + np.maximum(u, v)).ravel()
    cpair = np.tile(np.arange(len(PRISM_PAIRS)), len(prisms))
    cprism = np.repeat(prisms, len(PRISM_PAIRS))
    co = np.lexsort((cprism, cpair, ckey))
    ckey, cpair, cprism = ckey[co], cpair[co], cprism[co]
    si, sj = model.spring_i, model.spring_j
    skey = np.minimum(si, sj) * n + np.maximum(si, sj)
    so = np.lexsort((np.arange(len(si)), skey))
    # rank of each spring among the springs of its node pair, matched to the candidate of that rank
    first = np.searchsorted(skey[so], skey[so], side="left")
    rank = np.arange(len(so)) - first
    start = np.searchsorted(ckey, skey[so], side="left")
    count = np.searchsorted(ckey, skey[so], side="right") - start
    ok = rank < count
    owner = np.full(len(si), -1, np.int64)
    opair = np.full(len(si), -1, np.int64)
    owner[so[ok]] = cprism[start[ok] + rank[ok]]
    opair[so[ok]] = cpair[start[ok] + rank[ok]]
    return owner, opair


def _build_plan(model: TissueModel, n_blocks: int) -> Rk2Plan:
    lanes = PRISM_CHUNK
    kin = model.kinematic
    free = np.flatnonzero(~kin)
    nf = len(free)
    # slabs of equal node count along the principal axis of the free nodes
    block = np.zeros(nf, np.int64)
    if n_blocks > 1 and nf > 0:
        p = model.rest_positions[free] - model.rest_positions[free].mean(axis=0)
        axis = np.linalg.svd(p, full_matrices=False)[2][0]
        rank = np.empty(nf, np.int64)
        rank[np.argsort(p @ axis, kind="stable")] = np.arange(nf)
        block = rank * n_blocks // nf
    order = np.lexsort((free, block))
    free, block = free[order].astype(np.int64), block[order]
    block_nodes = _offsets(np.bincount(block, minlength=n_blocks))
    node_block = np.full(model.n_nodes, -1, np.int64)
    node_block[free] = block
    local = np.full(model.n_nodes, -1, np.int64)
    local[free] = np.arange(nf) - block_nodes[block]
    # the kernel's own numbering of the nodes: the free ones block by block, then the kinematic
    node_order = np.concatenate([free, np.flatnonzero(kin)]).astype(np.int64)
    row_of = np.empty(model.n_nodes, np.int64)
    row_of[node_order] = np.arange(model.n_nodes)

    si, sj, el = model.spring_i, model.spring_j, model.elements
    live = ~(kin[si] & kin[sj])  # springs that move a free node
    prisms = np.flatnonzero(~kin[el].all(axis=1))  # prisms with a free node
    owner, opair = _spring_owners(model, prisms)
    owner[~live] = -1
    # each prism's springs: (prism, pair) -> spring, and a bit mask of its pairs
    pos_of = np.full(len(el), -1, np.int64)
    pos_of[prisms] = np.arange(len(prisms))
    owned = np.full((len(prisms), len(PRISM_PAIRS)), -1, np.int64)
    has = owner >= 0
    owned[pos_of[owner[has]], opair[has]] = np.flatnonzero(has)
    mask = ((owned >= 0) << np.arange(len(PRISM_PAIRS))).sum(axis=1)
    # one global order of the prisms (alike masks together: few pairs per chunk); each block
    # takes the prisms with a node of its own in that order
    prisms_sorted = np.lexsort((prisms, mask))
    mat, rest, mid = model.materials, model.rest_length, model.spring_material

    chunk_counts, lane_rows, chunk_npairs, pairs, consts, q0s, q1s = [], [], [], [], [], [], []
    scatter_counts, scatter_src, scatter_dst = [], [], []
    block_chunks = [0]
    spring_lists, spring_t = [], []
    for b in range(n_blocks):
        nloc = block_nodes[b + 1] - block_nodes[b]
        mine = prisms_sorted[(node_block[el[prisms[prisms_sorted]]] == b).any(axis=1)]
        for c0 in range(0, len(mine), lanes):
            ch = mine[c0 : c0 + lanes]  # positions in ``prisms``
            e = prisms[ch]
            chunk_counts.append(len(ch))
            lane_rows.append(e)
            own = node_block[el[e]] == b  # (lanes, 6): the slots that add into the block
            lane, slot = np.nonzero(own)  # lane by lane, slot by slot
            scatter_counts.append(len(lane))
            scatter_src.append((20 + 3 * slot) * lanes + lane)
            scatter_dst.append(local[el[e]][lane, slot])
            union = np.flatnonzero((owned[ch] >= 0).any(axis=0))
            chunk_npairs.append(len(union))
            for p_ in union:
                k = owned[ch, p_]
                c = np.zeros((SPRING_ROWS, lanes))
                h = k >= 0
                kk = k[h]
                c[0, : len(ch)][h] = rest[kk]
                c[1, : len(ch)][h] = mat[mid[kk], 0]
                c[2, : len(ch)][h] = mat[mid[kk], 1]
                c[3, : len(ch)][h] = mat[mid[kk], 2] * rest[kk]  # as spring_magnitude forms it
                pairs.append(p_)
                consts.append(c.ravel())
                held = np.flatnonzero(h)
                q0s.append(held[0] // PAIR_LANE_STEP * PAIR_LANE_STEP)
                q1s.append(-(-(held[-1] + 1) // PAIR_LANE_STEP) * PAIR_LANE_STEP)
        block_chunks.append(len(chunk_counts))
        # springs that move a node of this block and that no prism computes
        ks = np.flatnonzero(live & (owner < 0) & ((node_block[si] == b) | (node_block[sj] == b)))
        spring_lists.append(ks)
        spring_t.append(
            (
                np.where(node_block[si[ks]] == b, local[si[ks]], nloc),
                np.where(node_block[sj[ks]] == b, local[sj[ks]], nloc),
            )
        )
    lane_e = np.concatenate(lane_rows) if lane_rows else np.zeros(0, np.int64)
    ks = np.concatenate(spring_lists).astype(np.int64)

    def c(a, dtype):
        return np.ascontiguousarray(a, dtype=dtype)

    return Rk2Plan(
        free=free,
        node_order=node_order,
        inv_mass=c(1.0 / model.mass[free], np.float64),
        damping=c(model.damping[free], np.float64),
        block_nodes=block_nodes,
        block_chunks=np.array(block_chunks, np.int64),
        chunk_lanes=_offsets(chunk_counts),
        gather=c(3 * row_of[el[lane_e]].T, np.uint32).reshape(6, -1),
        chunk_scatter=_offsets(scatter_counts),
        scatter_src=c(np.concatenate(scatter_src) if scatter_src else np.zeros(0), np.uint32),
        scatter_dst=c(np.concatenate(scatter_dst) if scatter_dst else np.zeros(0), np.uint32),
        rest_volume=c(model.rest_volume[lane_e], np.float64),
        volume_weight=c(model.volume_weight[lane_e], np.float64),
        chunk_pairs=_offsets(chunk_npairs),
        pair=np.array(pairs, np.int64),
        pair_q0=np.array(q0s, np.int64),
        pair_q1=np.array(q1s, np.int64),
        pair_consts=c(np.concatenate(consts) if consts else np.zeros(0), np.float64),
        block_springs=_offsets([len(a) for a in spring_lists]),
        spring_i=c(row_of[si[ks]], np.int64),
        spring_j=c(row_of[sj[ks]], np.int64),
        spring_ti=c(np.concatenate([t[0] for t in spring_t]), np.int64),
        spring_tj=c(np.concatenate([t[1] for t in spring_t]), np.int64),
        rest_length=c(rest[ks], np.float64),
        spring_material=c(mid[ks], np.int64),
    )


@njit(cache=True, inline="always", error_model="numpy")
def _pair_lanes(w, k, a, b, law, n):
    """The springs of pair (a, b) of a chunk's prisms, lane by lane: their forces (eq. 1-2, the
    same arithmetic as :func:`~myoface.tissue.forces.spring_forces_range`) from the nodes'
    coordinates (rows 3a.., 3b.. of ``w``) and constants ``k`` (rows l_k, alpha, beta, e^c), added
    to the two nodes' force rows (20 + 3a.., 20 + 3b..), in lanes 0 .. n-1 of ``w`` and ``k``
    (views that start at the pair's first lane group: lanes from 0, so no index can be negative
    and the compiler sees only fixed offsets from one array). ``a``, ``b`` are constants where
    this is inlined, so every row is at a fixed offset and the loop is vectorised."""
    c = PRISM_CHUNK
    oa = 3 * a * c
    ob = 3 * b * c
    fa = (20 + 3 * a) * c
    fb = (20 + 3 * b) * c
    for q in range(n):
        rx = w[ob + q] - w[oa + q]
        ry = w[ob + c + q] - w[oa + c + q]
        rz = w[ob + 2 * c + q] - w[oa + 2 * c + q]
        d = np.sqrt(rx * rx + ry * ry + rz * rz)
        lk = k[q]
        alpha = k[c + q]
        beta = k[2 * c + q]
        ec = k[3 * c + q]
        e = d - lk
        if law == LAW_PAPER:
            hi = beta * e
        else:
            hi = alpha * ec + beta * (e - ec)
        s = (alpha * e if e <= ec else hi) / d
        s = s if d >= MIN_SPRING_LENGTH else 0.0
        fx = s * rx
        fy = s * ry
        fz = s * rz
        w[fa + q] += fx
        w[fa + c + q] += fy
        w[fa + 2 * c + q] += fz
        w[fb + q] -= fx
        w[fb + c + q] -= fy
        w[fb + 2 * c + q] -= fz


@njit(cache=True, error_model="numpy")
def _pair_springs(w, k, pair, law, q0, q1):
    """:func:`_pair_lanes` for pair ``pair`` (a row of :data:`PRISM_PAIRS`) in lanes q0 .. q1-1,
    with the pair's nodes as constants (one specialised loop per pair)."""
    w = w[q0:]
    k = k[q0:]
    n = q1 - q0
    if pair == 0:
        _pair_lanes(w, k, 0, 1, law, n)
    elif pair == 1:
        _pair_lanes(w, k, 0, 2, law, n)
    elif pair == 2:
        _pair_lanes(w, k, 0, 3, law, n)
    elif pair == 3:
        _pair_lanes(w, k, 0, 4, law, n)
    elif pair == 4:
        _pair_lanes(w, k, 0, 5, law, n)
    elif pair == 5:
        _pair_lanes(w, k, 1, 2, law, n)
    elif pair == 6:
        _pair_lanes(w, k, 1, 3, law, n)
    elif pair == 7:
        _pair_lanes(w, k, 1, 4, law, n)
    elif pair == 8:
        _pair_lanes(w, k, 1, 5, law, n)
    elif pair == 9:
        _pair_lanes(w, k, 2, 3, law, n)
    elif pair == 10:
        _pair_lanes(w, k, 2, 4, law, n)
    elif pair == 11:
        _pair_lanes(w, k, 2, 5, law, n)
    elif pair == 12:
        _pair_lanes(w, k, 3, 4, law, n)
    elif pair == 13:
        _pair_lanes(w, k, 3, 5, law, n)
    else:
        _pair_lanes(w, k, 4, 5, law, n)


@njit(cache=True, error_model="numpy")
def _block_forces(
    x, fb, nloc, ch0, ch1, chunk_lanes, gather, chunk_scatter, scatter_src, scatter_dst,
    rest_vol, kv, vsign, chunk_pairs, pair, pair_q0, pair_q1, consts, law, s0, s1, si, sj, ti,
    tj, rest, mat_id, mat, w,
):  # fmt: skip
    """Spring and volume forces on one block's nodes at x, into rows 0..nloc-1 of the block's
    buffer ``fb`` (row nloc takes what goes to other nodes): its chunks ch0..ch1-1 of prisms,
    each with the springs it owns, then its springs s0..s1-1 that no prism owns."""
    c = PRISM_CHUNK
    for r in range(nloc + 1):
        fb[r, 0] = 0.0
        fb[r, 1] = 0.0
        fb[r, 2] = 0.0
    kw = SPRING_ROWS * c
    xf = x.reshape(x.size)  # (N, 3) C-contiguous: node m's coordinates at 3m, 3m+1, 3m+2
    for ch in range(ch0, ch1):
        e0 = chunk_lanes[ch]
        n = chunk_lanes[ch + 1] - e0
        for s in range(6):
            ws = w[3 * s * c : 3 * (s + 1) * c]
            gs = gather[s, e0 : e0 + n]
            for q in range(n):
                m = gs[q]
                ws[q] = xf[m]
                ws[c + q] = xf[m + 1]
                ws[2 * c + q] = xf[m + 2]
        for q in range(n):
            w[18 * c + q] = rest_vol[e0 + q]
            w[19 * c + q] = kv[e0 + q]
        _prism_chunk_forces(w, vsign)  # rows 20..37: each node's volume force
        for t in range(chunk_pairs[ch], chunk_pairs[ch + 1]):
            _pair_springs(w, consts[t * kw : (t + 1) * kw], pair[t], law, pair_q0[t], pair_q1[t])
        # the slots of the block's own nodes, lane by lane (the lanes past n computed on stale
        # data, unused)
        for k in range(chunk_scatter[ch], chunk_scatter[ch + 1]):
            o = scatter_src[k]
            r = scatter_dst[k]
            fb[r, 0] += w[o]
            fb[r, 1] += w[o + c]
            fb[r, 2] += w[o + 2 * c]
    for k in range(s0, s1):
        i = si[k]
        j = sj[k]
        rx = x[j, 0] - x[i, 0]
        ry = x[j, 1] - x[i, 1]
        rz = x[j, 2] - x[i, 2]
        d = np.sqrt(rx * rx + ry * ry + rz * rz)
        if d < MIN_SPRING_LENGTH:
            continue
        s = spring_magnitude(d - rest[k], rest[k], mat_id[k], mat, law) / d
        a = ti[k]
        b = tj[k]
        fb[a, 0] += s * rx
        fb[a, 1] += s * ry
        fb[a, 2] += s * rz
        fb[b, 0] -= s * rx
        fb[b, 1] -= s * ry
        fb[b, 2] -= s * rz


@njit(cache=True)
def _rk2_task(
    phase, b, x, v, xm, vm, buf, vblock, dt, inv_m, damp, bnodes, bchunks, chunk_lanes, gather,
    chunk_scatter, scatter_src, scatter_dst, rest_vol, kv, vsign, chunk_pairs, pair, pair_q0,
    pair_q1, consts, law, bsprings, si, sj, ti, tj, rest, mat_id, mat, work,
):  # fmt: skip
    """One block's half of an RK2 step, on the kernel's own numbering of the nodes (the block's
    nodes are rows q0 .. q1-1): ``phase`` 0 evaluates the forces at (x, v) and writes the
    block's midpoint (x + dt/2 v, v + dt/2 a) into ``xm, vm``; ``phase`` 1 evaluates them at the
    midpoint, takes the full step with its slopes, and writes the block's largest |v|."""
    fb = buf[b]
    q0 = bnodes[b]
    nloc = bnodes[b + 1] - q0
    xe = x if phase == 0 else xm
    _block_forces(
        xe, fb, nloc, bchunks[b], bchunks[b + 1], chunk_lanes, gather, chunk_scatter,
        scatter_src, scatter_dst, rest_vol, kv, vsign, chunk_pairs, pair, pair_q0, pair_q1,
        consts, law, bsprings[b], bsprings[b + 1], si, sj, ti, tj, rest, mat_id, mat, work[b],
    )  # fmt: skip
    if phase == 0:
        h = 0.5 * dt
        for r in range(nloc):
            i = q0 + r
            g = damp[i]
            c = inv_m[i]
            for a in range(3):
                xm[i, a] = x[i, a] + h * v[i, a]
                vm[i, a] = v[i, a] + h * ((fb[r, a] - g * v[i, a]) * c)
        return
    vb = 0.0
    for r in range(nloc):
        i = q0 + r
        g = damp[i]
        c = inv_m[i]
        for a in range(3):
            x[i, a] += dt * vm[i, a]
            v[i, a] += dt * ((fb[r, a] - g * vm[i, a]) * c)
            av = abs(v[i, a])
            if av > vb:
                vb = av
            elif not av <= vb:  # NaN: mark the block as non-finite, for good
                vb = np.inf
    vblock[b * _LINE] = vb


@njit(cache=True)
def _largest(a):
    m = 0.0
    for i in range(0, a.shape[0], _LINE):
        m = max(m, a[i])
    return m


@njit(cache=True, parallel=True)
def _rk2_run_team(
    x, v, n_steps, dt, tol_mm, n_workers, rows, node_order, n_free, inv_m, damp, bnodes, bchunks,
    chunk_lanes, gather, chunk_scatter, scatter_src, scatter_dst, rest_vol, kv, vsign,
    chunk_pairs, pair, pair_q0, pair_q1, consts, law, bsprings, si, sj, ti, tj, rest, mat_id, mat,
):  # fmt: skip
    """Midpoint RK2 for up to n_steps, the plan's blocks shared by a team of ``n_workers``
    threads started once for the whole run; stops early when max |v| dt < tol_mm (tol_mm > 0).
    Returns (steps taken, last max |v| dt, step index of a non-finite value or -1). ``x``, ``v``
    (N, 3) are updated in place (free nodes only); the run works on copies in the plan's order
    of the nodes (``node_order``: each block's nodes side by side, the kinematic ones last).

    The run is a sequence of tasks, half-step by half-step (two a step), block by block. Each
    worker goes through the half-steps in order: it waits until every task of the earlier
    half-steps is done (a half-step needs its neighbours' midpoints, or their new positions),
    then claims the blocks of this half-step not yet claimed (an atomic compare-and-swap on the
    block's count of claimed half-steps), its own block first (block w for worker w: the
    block's arrays stay in that core's cache), runs each and counts it done. No thread launch
    per step, and no fixed owner of a block: a worker that is behind (descheduled on a busy
    machine) has its block run by another, and each task computes the same numbers whoever
    runs it. A team with fewer threads than asked (or one) still runs every task, in order."""
    nb = bnodes.shape[0] - 1
    n = node_order.shape[0]
    xk = np.empty((n, 3))  # x and v in the plan's order of the nodes
    vk = np.empty((n, 3))
    for r in range(n):
        i = node_order[r]
        for a in range(3):
            xk[r, a] = x[i, a]
            vk[r, a] = v[i, a]
    buf = np.zeros((nb, rows, 3))  # each block's force sums (and its discard row)
    xm = xk.copy()  # kinematic rows stay at x (their velocity is zero), free rows are written
    vm = vk.copy()
    vblock = np.zeros(nb * _LINE)  # each block's largest |v|, on a cache line of its own
    work = np.zeros((nb, PRISM_WORK * PRISM_CHUNK))  # each block's lanes
    counters = np.zeros(16, np.int64)  # [_DONE] on a cache line of its own
    claims = np.zeros(nb * _LINE, np.int64)  # half-steps claimed of each block, one a line
    stop = np.full(3, -1.0)  # the step the run stopped at, its max |v| dt, non-finite step
    n_halves = 2 * n_steps
    for w in prange(n_workers):
        quit_ = False
        for half in range(n_halves):
            # every task of the earlier half-steps done (a half-step needs its neighbours'
            # midpoints, or their new positions) before this one's blocks are claimed: a worker
            # that is behind leaves its block to one that waits for it
            _wait_done(counters, half * nb)
            if stop[0] >= 0.0:  # the run stopped at this half-step or an earlier one
                break
            for k in range(nb):
                b = (w + k) % nb
                if not _atomic_cas(claims, b * _LINE, half, half + 1):
                    continue  # another worker has it
                # a claimed task not yet counted done: no worker is past this half-step
                if stop[0] >= 0.0:  # the run stopped at this half-step
                    _atomic_add(counters, _DONE, 1)
                    quit_ = True
                    break
                step = half // 2
                if half % 2 == 0 and step > 0:
                    # the previous step is complete: test it (each task of this half-step
                    # computes the same answer from the same numbers)
                    last = _largest(vblock) * dt
                    if not np.isfinite(last) or (tol_mm > 0.0 and last < tol_mm):
                        stop[1] = last
                        stop[2] = step - 1 if not np.isfinite(last) else -1.0
                        stop[0] = step
                        _atomic_add(counters, _DONE, 1)
                        quit_ = True
                        break
                _rk2_task(
                    half % 2, b, xk, vk, xm, vm, buf, vblock, dt, inv_m, damp, bnodes, bchunks,
                    chunk_lanes, gather, chunk_scatter, scatter_src, scatter_dst, rest_vol, kv,
                    vsign, chunk_pairs, pair, pair_q0, pair_q1, consts, law, bsprings, si, sj, ti,
                    tj, rest, mat_id, mat, work,
                )  # fmt: skip
                _atomic_add(counters, _DONE, 1)
            if quit_:
                break
    for r in range(n_free):
        i = node_order[r]
        for a in range(3):
            x[i, a] = xk[r, a]
            v[i, a] = vk[r, a]
    if stop[0] >= 0.0:
        return int(stop[0]), stop[1], int(stop[2])
    last = _largest(vblock) * dt
    if not np.isfinite(last):
        return n_steps, last, n_steps - 1
    return n_steps, last, -1


class _Pace:
    """Measured seconds per step of one model's kernel with each thread count tried (the latest
    measurement of each), and when to try the one not in use. Switching away from a choice that
    has become slow is immediate (its own timings show it), and the one left is tried again
    after PROBE_MIN_S; trying the other costs a few steps, so it backs off while it loses. Shared
    by the threads that step the model: their races only mix up timings."""

    #: whether the kernel has run in this process (its first call may compile or load it)
    kernel_loaded = False

    def __init__(self):
        self.sec_per_step: dict[int, float] = {}
        #: steps run with each thread count (what a benchmark reports of the choice)
        self.steps_run: dict[int, int] = {}
        self.next_probe = 0.0
        self.interval = PROBE_MIN_S
        self.probe: int | None = None

    def choose(self, n_max: int, remaining: int) -> tuple[int, int]:
        known = self.sec_per_step
        if n_max not in known:
            return n_max, min(remaining, CHUNK_STEPS)
        best = min(known, key=known.get) if 1 in known else n_max
        if time.monotonic() >= self.next_probe:
            self.probe = 1 if best == n_max else n_max
            return self.probe, min(remaining, PROBE_STEPS)
        return best, min(remaining, CHUNK_STEPS)

    def record(self, n: int, seconds: float, steps: int) -> None:
        self.steps_run[n] = self.steps_run.get(n, 0) + steps
        if not _Pace.kernel_loaded:
            _Pace.kernel_loaded = True
            return
        if steps <= 0:
            return
        sec = seconds / steps
        known = self.sec_per_step
        was_best = n in known and all(known[n] <= t for t in known.values())
        known[n] = sec
        if self.probe != n and was_best and any(t < sec for t in known.values()):
            # the choice in use got slower than the other's (older) timing, perhaps for a
            # moment: the other runs now, and the one left is tried again soon, not after the
            # back-off its earlier probes earned (a single slow call kept the team off for
            # up to PROBE_MAX_S)
            self.interval = PROBE_MIN_S
            self.next_probe = min(self.next_probe, time.monotonic() + PROBE_MIN_S)
        if self.probe == n:
            self.probe = None
            others = [t for m, t in self.sec_per_step.items() if m != n]
            won = bool(others) and sec < min(others)
            self.interval = PROBE_MIN_S if won else min(2.0 * self.interval, PROBE_MAX_S)
            self.next_probe = time.monotonic() + self.interval


class Rk2Integrator:
    """The paper's RK2 on one model: the parallel kernel's plans, one per number of blocks
    (:class:`Rk2Plan`, built on first use), and its thread-count chooser (:class:`_Pace`).

    One per model: :func:`rk2_integrator` keeps it in the model's memo (and the integrator
    refers to its model weakly, so the two make no reference cycle). Safe to share between the
    threads that step the model: at worst two build the same plan and one is kept, and their
    races only mix up the chooser's timings."""

    def __init__(self, model: TissueModel):
        self._model = weakref.ref(model)
        self._plans: dict[int, Rk2Plan] = {}
        self._plans_lock = threading.Lock()
        self._pace = _Pace()

    @property
    def model(self) -> TissueModel:
        model = self._model()
        if model is None:
            raise ReferenceError("the model of this RK2 integrator no longer exists")
        return model

    @property
    def steps_run(self) -> dict[int, int]:
        """Steps run with each thread count where :meth:`run` chose it by measurement (what a
        benchmark reports of the choice); a copy."""
        return dict(self._pace.steps_run)

    def plan(self, n_blocks: int | None = None) -> Rk2Plan:
        """The kernel's packed arrays for the model cut into ``n_blocks`` blocks (default:
        numba's thread count), built on first use and kept."""
        nb = numba.get_num_threads() if n_blocks is None else int(n_blocks)
        if nb < 1:
            raise MyofaceValueError(f"n_blocks must be >= 1; got {nb}")
        plan = self._plans.get(nb)
        if plan is None:
            plan = _build_plan(self.model, nb)
            with self._plans_lock:
                plan = self._plans.setdefault(nb, plan)
        return plan

    def run(
        self,
        x: np.ndarray,
        v: np.ndarray,
        n_steps: int,
        dt: float,
        tol_mm: float = 0.0,
        *,
        n_blocks: int | None = None,
    ) -> tuple[int, float, int]:
        """:func:`run_rk2` on this integrator's model."""
        n_steps = int(n_steps)
        if n_blocks is not None:
            return self._run_blocks(x, v, n_steps, dt, tol_mm, int(n_blocks))
        n_free = len(self.model.free_index)
        n_max = max(1, min(numba.get_num_threads(), n_free // MIN_NODES_PER_BLOCK))
        if n_max == 1:
            return self._run_blocks(x, v, n_steps, dt, tol_mm, 1)
        pace = self._pace
        done, last = 0, 0.0
        while done < n_steps:
            nb, chunk = pace.choose(n_max, n_steps - done)
            t0 = time.perf_counter()
            d, last, bad = self._run_blocks(x, v, chunk, dt, tol_mm, nb)
            pace.record(nb, time.perf_counter() - t0, d)
            if bad >= 0:
                return done + d, last, done + bad
            done += d
            if d < chunk or (tol_mm > 0.0 and last < tol_mm):  # converged
                break
        return done, last, -1

    def _run_blocks(self, x, v, n_steps, dt, tol_mm, n_blocks) -> tuple[int, float, int]:
        threads = numba.get_num_threads()
        p = self.plan(n_blocks)
        workers = min(threads, p.n_blocks)
        if workers < threads:
            numba.set_num_threads(workers)  # this thread only; no idle threads in the team
        try:
            done, last, bad = _rk2_kernel(p, self.model, x, v, n_steps, dt, tol_mm, workers)
        finally:
            numba.set_num_threads(threads)
        return int(done), float(last), int(bad)


def rk2_integrator(model: TissueModel) -> Rk2Integrator:
    """The model's :class:`Rk2Integrator`, made on first use and kept in ``model.memo``."""
    return model.memo("rk2_integrator", lambda: Rk2Integrator(model))


def run_rk2(
    model: TissueModel,
    x: np.ndarray,
    v: np.ndarray,
    n_steps: int,
    dt: float,
    tol_mm: float = 0.0,
    *,
    n_blocks: int | None = None,
) -> tuple[int, float, int]:
    """Run the parallel kernel on ``x``, ``v`` ((N, 3) float64, C-contiguous, updated in place;
    the kinematic rows must already hold their targets and zero velocity).

    ``n_blocks`` is the number of slabs the free nodes are cut into, one thread each; the result
    is the same, bit for bit, for any number. By default it is numba's thread count (fewer for a
    small lattice, see :data:`MIN_NODES_PER_BLOCK`) or one, whichever the kernel measures to be
    faster: the steps run in calls of :data:`CHUNK_STEPS`, and now and then a few steps try the
    other choice (see :data:`PROBE_MIN_S`). Threads waiting for each other at every step only
    pay while the cores are free; on a machine busy with other work one thread is faster.

    Returns (steps taken, last ``max |v| dt`` in mm, step index of the first non-finite value or
    -1). Stops early once ``max |v| dt < tol_mm`` when ``tol_mm > 0``."""
    return rk2_integrator(model).run(x, v, n_steps, dt, tol_mm, n_blocks=n_blocks)


def _rk2_kernel(p: Rk2Plan, model: TissueModel, x, v, n_steps, dt, tol_mm, workers):
    return _rk2_run_team(
        x,
        v,
        int(n_steps),
        float(dt),
        float(tol_mm),
        int(workers),
        p.rows,
        p.node_order,
        len(p.free),
        p.inv_mass,
        p.damping,
        p.block_nodes,
        p.block_chunks,
        p.chunk_lanes,
        p.gather,
        p.chunk_scatter,
        p.scatter_src,
        p.scatter_dst,
        p.rest_volume,
        p.volume_weight,
        model.volume_sign,
        p.chunk_pairs,
        p.pair,
        p.pair_q0,
        p.pair_q1,
        p.pair_consts,
        model.spring_law,
        p.block_springs,
        p.spring_i,
        p.spring_j,
        p.spring_ti,
        p.spring_tj,
        p.rest_length,
        p.spring_material,
        model.materials,
    )


# ------------------------------------------------------------- the serial reference kernel ----


@njit(cache=True)
def _acc_serial(
    x, v, si, sj, rest, mat_id, mat, law, elems, rest_vol, kv, vsign, inv_m, damp, free, f, out
):
    internal_forces_numba(x, si, sj, rest, mat_id, mat, law, elems, rest_vol, kv, vsign, f)
    for i in range(x.shape[0]):
        if free[i]:
            for a in range(3):
                out[i, a] = (f[i, a] - damp[i] * v[i, a]) * inv_m[i]
        else:
            for a in range(3):
                out[i, a] = 0.0


@njit(cache=True)
def _rk2_run_serial(
    x,
    v,
    n_steps,
    dt,
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
    inv_m,
    damp,
    free,
    tol_mm,
):
    """The previous, single-thread kernel (kept as the reference): midpoint RK2 for up to n_steps
    with a scatter over every spring and element; stops early when max |v| dt < tol_mm
    (tol_mm > 0). Returns (steps taken, last max |v| dt, step index of a non-finite value or -1)."""
    n = x.shape[0]
    f = np.zeros((n, 3))
    a1 = np.zeros((n, 3))
    a2 = np.zeros((n, 3))
    xm = x.copy()
    vm = v.copy()
    h = 0.5 * dt
    last = 0.0
    for step in range(n_steps):
        _acc_serial(
            x,
            v,
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
            inv_m,
            damp,
            free,
            f,
            a1,
        )
        for i in range(n):
            for a in range(3):
                xm[i, a] = x[i, a] + h * v[i, a]
                vm[i, a] = v[i, a] + h * a1[i, a]
        _acc_serial(
            xm,
            vm,
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
            inv_m,
            damp,
            free,
            f,
            a2,
        )
        vmax = 0.0
        for i in range(n):
            if free[i]:
                for a in range(3):
                    x[i, a] += dt * vm[i, a]
                    v[i, a] += dt * a2[i, a]
                    av = abs(v[i, a])
                    if not av <= vmax:  # also catches NaN
                        vmax = av
        last = vmax * dt
        if not np.isfinite(last):
            return step + 1, last, step
        if tol_mm > 0.0 and last < tol_mm:
            return step + 1, last, -1
    return n_steps, last, -1


def run_rk2_serial(
    model: TissueModel, x: np.ndarray, v: np.ndarray, n_steps: int, dt: float, tol_mm: float = 0.0
) -> tuple[int, float, int]:
    """:func:`run_rk2` with the previous single-thread kernel (the reference)."""
    done, last, bad = _rk2_run_serial(
        x,
        v,
        int(n_steps),
        float(dt),
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
        1.0 / model.mass,
        model.damping,
        ~model.kinematic,
        float(tol_mm),
    )
    return int(done), float(last), int(bad)


# ------------------------------------------------------------------------------ public API ----


#: :func:`step_rk2` with its default step retries a run that goes NaN/Inf in steps this many
#: times halved at most (risorius, buccinator, depressor anguli oris and the jaw all at 1 from
#: rest blew up at step 28 with the stable step of the rest lattice, ran at half of it)
AUTO_DT_HALVINGS = 3


def step_rk2(model: TissueModel, state, targets=None, dt: float | None = None, n_steps: int = 1):
    """Advance ``n_steps`` paper RK2 steps of size ``dt`` on all cores.

    Parameters
    ----------
    model : TissueModel
    state : TissueState — where to start (not modified).
    targets : (K, 3) float ndarray, optional
        Positions (mm) of the kinematic nodes, in ``model.kinematic_index`` order (default: their
        rest positions); set before the first step, velocities zero.
    dt : float, optional
        Time step, s (default ``model.stable_dt``, computed once per model; a run that goes
        NaN/Inf with it is run again in steps of half the size, twice as many, up to
        :data:`AUTO_DT_HALVINGS` times).
    n_steps : int

    Returns
    -------
    TissueState — a new state, ``t`` advanced by ``n_steps * dt``.

    Raises
    ------
    MyofaceSimulationError
        With the step index, if the state becomes NaN/Inf.

    References: Terzopoulos & Waters 1993, eq. (3)-(4) and Section III-B.
    """
    auto = dt is None
    dt = model.stable_dt if auto else float(dt)
    if not dt > 0:
        raise MyofaceValueError(f"dt must be > 0 s; got {dt}")
    tg = targets_array(model, targets)
    n = int(n_steps)
    # the default step is stable for the lattice near rest; a large step change can stretch
    # springs into their stiff phase, where it is not: then the same time is covered again
    # from the start in steps of half the size (at most AUTO_DT_HALVINGS times)
    for halving in range(AUTO_DT_HALVINGS + 1 if auto else 1):
        s = state.copy()
        s.x = np.ascontiguousarray(s.x, dtype=np.float64)
        s.v = np.ascontiguousarray(s.v, dtype=np.float64)
        s.x[model.kinematic_index] = tg
        s.v[model.kinematic_index] = 0.0
        done, _, bad = run_rk2(model, s.x, s.v, n << halving, dt / (1 << halving))
        if bad < 0:
            s.t += done * dt / (1 << halving)
            return s
    raise MyofaceSimulationError(
        f"RK2 produced NaN/Inf at step {bad} (dt = {dt / (1 << halving):g} s); reduce dt"
    )
