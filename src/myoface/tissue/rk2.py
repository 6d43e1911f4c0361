"""The paper's explicit integrator: midpoint RK2 on ``m x'' + gamma x' + g + q = 0``, all cores.

Two force evaluations per step (Terzopoulos & Waters 1993, Section III-B: explicit Euler was not
stable enough). The free nodes are cut into slabs (blocks) along the lattice's long axis, once
per model (:func:`rk2_plan`); each block keeps private copies of the springs and prisms that
touch its nodes and adds their forces into a buffer of its own, then takes its nodes' midpoint
(or full) update from it. Nothing is written by two threads, and each node adds the same terms
in the same order whatever the number of blocks, so the trajectory does not depend on the number
of threads, bit for bit.

What one step costs (default face, measured): 1,072 free nodes of 1,872; 10,211 springs with a
free end (of 13,302) and 2,026 prisms with a free node and a volume weight, each evaluated twice
(with 2 blocks 10,524 and 2,165: those across the cut twice); no muscle force (the muscles move
kinematic nodes, set before the run). On one thread, a step is ~240 us of spring
forces, ~130 us of prisms (their gradients now computed four prisms at a time, see
:func:`~myoface.tissue.forces.prism_volume_forces_split`) and ~25 us for the rest.

The team (:func:`_rk2_run_team`): one parallel region per call, not two per step. The run is a
sequence of tasks (step, half-step, block); a thread takes the next one from an atomic counter,
waits (spinning ~1 us, then yielding its core) until every task of the earlier half-steps is
done, runs it and counts it done. numba's region launch (OpenMP layer here) cost ~10 us each on
an idle machine and up to milliseconds on a busy one; the wait costs well under 1 us when the
other thread is running. Any thread may run any task, so a team smaller than asked still
finishes, in order.

Measured on this repository's 2-core machine (AMD EPYC, while other jobs ran: load 2-3),
``myoface bench --only tissue.rk2`` and interleaved runs of 200 steps against the previous
kernel in the same process: 2 threads ~3,000 steps/s median (best 4,100; previous kernel 2,800,
best 3,300), 1 thread ~1,800-2,250 (previous 1,700), the single-thread reference ~1,400-1,550.
The paper's 5,000 steps/s (200 us a step) is not reached: the two force evaluations alone are
~400 us of one core's time, so even a perfect split over two cores leaves ~200 us.

Tried and dropped (measured, same values to the last bit): springs in three passes (gather the
vectors, vectorised square roots and divisions, scatter; per-spring constants) — 30 % faster
alone, slower inside the step (the extra arrays' memory traffic: 418 vs 385 us a step); the
same in L1-sized chunks (slower still); keeping a node's sum in registers over the springs that
start at it (no gain: the scatter is not bound by store forwarding).

:func:`_rk2_run_serial` is the single-thread kernel the parallel one replaced (a scatter over
every spring and element); it stays as the reference the tests hold the parallel one against,
and as the benchmark's peer.

Threads that wait for each other twice a step only pay while the cores are free: on a machine
busy with other work, a thread that waits for one the system has descheduled loses time, and one
thread can be faster. So :func:`run_rk2` measures both as it goes and uses the faster (the
result is the same, bit for bit).

References: Terzopoulos & Waters 1993, eq. (1)-(4) and Section III-B.
"""

from __future__ import annotations

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
    PRISM_CHUNK,
    PRISM_WORK,
    internal_forces_numba,
    prism_volume_forces_split,
    spring_forces_range,
)
from myoface.tissue.model import TissueModel

#: RK2 safety factor on the stability limit (see :func:`stable_time_step`)
STABLE_DT_SAFETY = 0.5
#: fewest free nodes per thread: below this a block's work (~0.1 ms a step) no longer pays for
#: the two thread barriers of every step, so small lattices run on fewer threads (or one)
MIN_NODES_PER_BLOCK = 256
#: steps per kernel call when :func:`run_rk2` picks the thread count by measurement (~10 ms: the
#: return to Python between calls costs well under 1 % of that)
CHUNK_STEPS = 64
#: a short run (PROBE_STEPS) tries the thread count not in use, first after PROBE_MIN_S seconds,
#: then, while it keeps losing, after twice as long each time, up to PROBE_MAX_S
PROBE_STEPS = 4
PROBE_MIN_S = 1.0
PROBE_MAX_S = 60.0


def stable_time_step(model: TissueModel, safety: float = STABLE_DT_SAFETY) -> float:
    """A time step (s) inside the explicit scheme's stability limit, from each free node's
    stiffest local oscillator (beta springs) and its damping (see the comments for the two
    limits: the oscillator's, and the slow growth of lightly damped modes under RK2).

    Computed afresh on every call; ``model.stable_dt`` holds the default one, computed once per
    model."""
    stiff = np.zeros(model.n_nodes)
    kb = model.materials[model.spring_material, 1]
    np.add.at(stiff, model.spring_i, kb)
    np.add.at(stiff, model.spring_j, kb)
    free = ~model.kinematic
    w = np.sqrt(stiff[free] / model.mass[free])
    g = model.damping[free] / model.mass[free]
    # for x'' + g x' + w^2 x = 0, midpoint RK2 is stable for dt below about 2 / (g/2 + w) ...
    dt_osc = safety * np.min(2.0 / (0.5 * g + w))
    # ... but its amplification factor on an undamped mode is sqrt(1 + (w dt)^4 / 4) > 1: the
    # lightly damped high modes grow by about (w dt)^4 / 8 per step unless the damping takes away
    # more (g dt / 2). Keep that growth to half the damping's decay: (w dt)^4 / 8 < g dt / 4.
    dt_weak = np.min(np.cbrt(2.0 * g / w**4)) if np.all(g > 0) else np.inf
    return float(min(dt_osc, dt_weak))


# ------------------------------------------------- atomics for the persistent team of threads ----
# numba has no atomics on the CPU; these four intrinsics emit LLVM's own instructions.


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
def _spin_pause(typingctx):
    """The x86 ``pause`` hint of a spin loop."""
    sig = types.void()

    def codegen(context, builder, sig, args):
        fnty = ir.FunctionType(ir.VoidType(), [])
        builder.call(
            cgutils.get_or_insert_function(builder.module, fnty, "llvm.x86.sse2.pause"), []
        )
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def _os_yield(typingctx):
    """``sched_yield()``: give the core to another runnable thread (POSIX)."""
    sig = types.void()

    def codegen(context, builder, sig, args):
        fnty = ir.FunctionType(ir.IntType(32), [])
        builder.call(cgutils.get_or_insert_function(builder.module, fnty, "sched_yield"), [])
        return context.get_dummy_value()

    return sig, codegen


#: spins of a waiting thread before it starts to yield its core (~1 us of ``pause``)
SPINS_BEFORE_YIELD = 200
_CLAIMED = 0  # slot of the task counter in the team's counters (its own cache line) ...
_DONE = 8  # ... and of the count of tasks done


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


@dataclass(frozen=True)
class Rk2Plan:
    """The packed arrays of the parallel kernel for one model and one number of blocks, built
    once by :func:`rk2_plan`.

    The free nodes are cut into ``n_blocks`` slabs along the lattice's longest axis, one per
    thread. Block b owns its nodes and a private copy of every spring and prism that touches
    them (only those: springs with a free end, prisms with a free node and a volume weight; the
    rest push on kinematic nodes only), so a thread adds up the forces on its nodes in a buffer
    of its own, with no atomics and nothing shared, and updates them; the springs and prisms
    that straddle the cut between two slabs are evaluated by both, the price of that.
    Free nodes are numbered ``q = 0 .. F-1`` block by block (``free[q]`` is the node).

    Attributes
    ----------
    free : (F,) int64 — node index of each free node.
    inv_mass, damping : (F,) float64 — 1/m (1/g) and gamma (g/s) of each free node.
    block_nodes, block_springs, block_prisms : (B+1,) int64 — where each block's nodes q, springs
        and prisms start.
    spring_i, spring_j, rest_length, spring_material : (S',) — the springs, block by block, in
        model order within a block.
    elements, rest_volume, volume_weight : (E', 6), (E',), (E',) — the prisms, likewise.

    A node's force is summed over the same springs, then the same prisms, in the same order
    whatever the number of blocks, so the trajectory does not depend on the number of threads.
    """

    free: np.ndarray
    inv_mass: np.ndarray
    damping: np.ndarray
    block_nodes: np.ndarray
    block_springs: np.ndarray
    block_prisms: np.ndarray
    spring_i: np.ndarray
    spring_j: np.ndarray
    rest_length: np.ndarray
    spring_material: np.ndarray
    elements: np.ndarray
    rest_volume: np.ndarray
    volume_weight: np.ndarray

    @property
    def n_blocks(self) -> int:
        return len(self.block_nodes) - 1


def _offsets(counts) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


def _build_plan(model: TissueModel, n_blocks: int) -> Rk2Plan:
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
    node_block = np.full(model.n_nodes, -1, np.int64)
    node_block[free] = block

    si, sj, el = model.spring_i, model.spring_j, model.elements
    keep_e = ~kin[el].all(axis=1) & (model.volume_weight != 0.0)
    ks = [np.flatnonzero((node_block[si] == b) | (node_block[sj] == b)) for b in range(n_blocks)]
    ke = [np.flatnonzero(keep_e & (node_block[el] == b).any(axis=1)) for b in range(n_blocks)]
    k, e = np.concatenate(ks).astype(np.int64), np.concatenate(ke).astype(np.int64)

    def c(a, dtype):
        return np.ascontiguousarray(a, dtype=dtype)

    return Rk2Plan(
        free=free,
        inv_mass=c(1.0 / model.mass[free], np.float64),
        damping=c(model.damping[free], np.float64),
        block_nodes=_offsets(np.bincount(block, minlength=n_blocks)),
        block_springs=_offsets([len(a) for a in ks]),
        block_prisms=_offsets([len(a) for a in ke]),
        spring_i=c(si[k], np.int64),
        spring_j=c(sj[k], np.int64),
        rest_length=c(model.rest_length[k], np.float64),
        spring_material=c(model.spring_material[k], np.int64),
        elements=c(el[e], np.int64).reshape(-1, 6),
        rest_volume=c(model.rest_volume[e], np.float64),
        volume_weight=c(model.volume_weight[e], np.float64),
    )


_PLANS: weakref.WeakKeyDictionary[TissueModel, dict[int, Rk2Plan]] = weakref.WeakKeyDictionary()
_PLANS_LOCK = threading.Lock()


def rk2_plan(model: TissueModel, n_blocks: int | None = None) -> Rk2Plan:
    """The kernel's packed arrays for ``model`` cut into ``n_blocks`` blocks (default: numba's
    thread count), built on first use and kept as long as the model lives (keyed by the model
    object: a model made with ``replace`` or ``with_kinematic`` gets its own). Safe to call from
    several threads (at worst two build the same plan, and one is kept)."""
    nb = numba.get_num_threads() if n_blocks is None else int(n_blocks)
    if nb < 1:
        raise MyofaceValueError(f"n_blocks must be >= 1; got {nb}")
    plans = _PLANS.get(model)
    plan = None if plans is None else plans.get(nb)
    if plan is None:
        plan = _build_plan(model, nb)
        with _PLANS_LOCK:
            plan = _PLANS.setdefault(model, {}).setdefault(nb, plan)
    return plan


@njit(cache=True)
def _block_forces(
    x, fb, si, sj, rest, mat_id, mat, law, elems, rest_vol, kv, vsign, s0, s1, e0, e1, work,
):  # fmt: skip
    """Spring and volume forces of one block's springs s0..s1-1 and prisms e0..e1-1 at x, into
    the block's own buffer ``fb`` (N, 3), zeroed first."""
    for i in range(fb.shape[0]):
        fb[i, 0] = 0.0
        fb[i, 1] = 0.0
        fb[i, 2] = 0.0
    spring_forces_range(x, si, sj, rest, mat_id, mat, law, s0, s1, fb)
    prism_volume_forces_split(x, elems, rest_vol, kv, vsign, e0, e1, fb, work)


@njit(cache=True)
def _rk2_task(
    phase, b, x, v, xm, vm, buf, vblock, dt, free, inv_m, damp, bnodes, bsprings, bprisms,
    si, sj, rest, mat_id, mat, law, elems, rest_vol, kv, vsign, work,
):  # fmt: skip
    """One block's half of an RK2 step: ``phase`` 0 evaluates the forces at (x, v) and writes
    the block's midpoint (x + dt/2 v, v + dt/2 a) into ``xm, vm``; ``phase`` 1 evaluates them at
    the midpoint, takes the full step with its slopes, and writes the block's largest |v|."""
    fb = buf[b]
    xe = x if phase == 0 else xm
    _block_forces(
        xe, fb, si, sj, rest, mat_id, mat, law, elems, rest_vol, kv, vsign,
        bsprings[b], bsprings[b + 1], bprisms[b], bprisms[b + 1], work[b],
    )  # fmt: skip
    if phase == 0:
        h = 0.5 * dt
        for q in range(bnodes[b], bnodes[b + 1]):
            i = free[q]
            g = damp[q]
            c = inv_m[q]
            for a in range(3):
                xm[i, a] = x[i, a] + h * v[i, a]
                vm[i, a] = v[i, a] + h * ((fb[i, a] - g * v[i, a]) * c)
        return
    vb = 0.0
    for q in range(bnodes[b], bnodes[b + 1]):
        i = free[q]
        g = damp[q]
        c = inv_m[q]
        for a in range(3):
            x[i, a] += dt * vm[i, a]
            v[i, a] += dt * ((fb[i, a] - g * vm[i, a]) * c)
            av = abs(v[i, a])
            if av > vb:
                vb = av
            elif not av <= vb:  # NaN: mark the block as non-finite, for good
                vb = np.inf
    vblock[b] = vb


@njit(cache=True)
def _largest(a):
    m = 0.0
    for i in range(a.shape[0]):
        m = max(m, a[i])
    return m


@njit(cache=True, parallel=True)
def _rk2_run_team(
    x, v, n_steps, dt, tol_mm, n_workers, free, inv_m, damp, bnodes, bsprings, bprisms,
    si, sj, rest, mat_id, mat, law, elems, rest_vol, kv, vsign,
):  # fmt: skip
    """Midpoint RK2 for up to n_steps, the plan's blocks shared by a team of ``n_workers``
    threads started once for the whole run; stops early when max |v| dt < tol_mm (tol_mm > 0).
    Returns (steps taken, last max |v| dt, step index of a non-finite value or -1). ``x``, ``v``
    (N, 3) are updated in place (free nodes only).

    The run is a sequence of tasks, numbered step by step, half-step (phase) by half-step,
    block by block; a thread takes the next number from a shared counter, waits until every task
    of the earlier half-steps is done (a half-step needs its neighbours' midpoints, or their new
    positions), runs it and counts it done. No thread launch per step, no fixed owner of a block:
    any thread may run any task, and each task computes the same numbers whoever runs it. A team
    with fewer threads than asked (or one) still runs every task, in order."""
    nb = bnodes.shape[0] - 1
    buf = np.zeros((nb, x.shape[0], 3))
    xm = x.copy()  # kinematic rows stay at x (their velocity is zero), free rows are written
    vm = v.copy()
    vblock = np.zeros(nb)
    work = np.zeros((nb, PRISM_WORK * PRISM_CHUNK))  # each block's scratch for its prisms
    counters = np.zeros(16, np.int64)  # [_CLAIMED], [_DONE] on cache lines of their own
    stop = np.full(3, -1.0)  # the step the run stopped at, its max |v| dt, non-finite step
    n_tasks = 2 * n_steps * nb
    for _w in prange(n_workers):
        while True:
            t = _atomic_add(counters, _CLAIMED, 1)
            if t >= n_tasks:
                break
            half = t // nb
            b = t - half * nb
            _wait_done(counters, half * nb)
            if stop[0] >= 0.0:  # the run stopped at an earlier half-step
                _atomic_add(counters, _DONE, 1)
                break
            step = half // 2
            if half % 2 == 0 and step > 0:
                # the previous step is complete: test it (each task of this half-step computes
                # the same answer from the same numbers)
                last = _largest(vblock) * dt
                if not np.isfinite(last) or (tol_mm > 0.0 and last < tol_mm):
                    stop[1] = last
                    stop[2] = step - 1 if not np.isfinite(last) else -1.0
                    stop[0] = step
                    _atomic_add(counters, _DONE, 1)
                    break
            _rk2_task(
                half % 2, b, x, v, xm, vm, buf, vblock, dt, free, inv_m, damp, bnodes, bsprings,
                bprisms, si, sj, rest, mat_id, mat, law, elems, rest_vol, kv, vsign, work,
            )  # fmt: skip
            _atomic_add(counters, _DONE, 1)
    if stop[0] >= 0.0:
        return int(stop[0]), stop[1], int(stop[2])
    last = _largest(vblock) * dt
    if not np.isfinite(last):
        return n_steps, last, n_steps - 1
    return n_steps, last, -1


class _Pace:
    """Measured seconds per step of one model's kernel with each thread count tried (the latest
    measurement of each), and when to try the one not in use. Switching away from a choice that
    has become slow is immediate (its own timings show it); trying the other costs a few steps,
    so it backs off while it loses. Shared by the threads that step the model: their races only
    mix up timings."""

    #: whether the kernel has run in this process (its first call may compile or load it)
    kernel_loaded = False

    def __init__(self):
        self.sec_per_step: dict[int, float] = {}
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
        if not _Pace.kernel_loaded:
            _Pace.kernel_loaded = True
            return
        if steps <= 0:
            return
        sec = seconds / steps
        self.sec_per_step[n] = sec
        if self.probe == n:
            self.probe = None
            others = [t for m, t in self.sec_per_step.items() if m != n]
            won = bool(others) and sec < min(others)
            self.interval = PROBE_MIN_S if won else min(2.0 * self.interval, PROBE_MAX_S)
            self.next_probe = time.monotonic() + self.interval


_PACES: weakref.WeakKeyDictionary[TissueModel, _Pace] = weakref.WeakKeyDictionary()


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
    n_steps = int(n_steps)
    if n_blocks is not None:
        return _run_blocks(model, x, v, n_steps, dt, tol_mm, int(n_blocks))
    n_max = max(1, min(numba.get_num_threads(), len(model.free_index) // MIN_NODES_PER_BLOCK))
    if n_max == 1:
        return _run_blocks(model, x, v, n_steps, dt, tol_mm, 1)
    pace = _PACES.get(model)
    if pace is None:
        pace = _PACES.setdefault(model, _Pace())
    done, last = 0, 0.0
    while done < n_steps:
        nb, chunk = pace.choose(n_max, n_steps - done)
        t0 = time.perf_counter()
        d, last, bad = _run_blocks(model, x, v, chunk, dt, tol_mm, nb)
        pace.record(nb, time.perf_counter() - t0, d)
        if bad >= 0:
            return done + d, last, done + bad
        done += d
        if d < chunk or (tol_mm > 0.0 and last < tol_mm):  # converged
            break
    return done, last, -1


def _run_blocks(model, x, v, n_steps, dt, tol_mm, n_blocks) -> tuple[int, float, int]:
    threads = numba.get_num_threads()
    p = rk2_plan(model, n_blocks)
    workers = min(threads, p.n_blocks)
    if workers < threads:
        numba.set_num_threads(workers)  # this thread only; no idle threads in the team
    try:
        done, last, bad = _rk2_kernel(p, model, x, v, n_steps, dt, tol_mm, workers)
    finally:
        numba.set_num_threads(threads)
    return int(done), float(last), int(bad)


def _rk2_kernel(p: Rk2Plan, model: TissueModel, x, v, n_steps, dt, tol_mm, workers):
    return _rk2_run_team(
        x,
        v,
        int(n_steps),
        float(dt),
        float(tol_mm),
        int(workers),
        p.free,
        p.inv_mass,
        p.damping,
        p.block_nodes,
        p.block_springs,
        p.block_prisms,
        p.spring_i,
        p.spring_j,
        p.rest_length,
        p.spring_material,
        model.materials,
        model.spring_law,
        p.elements,
        p.rest_volume,
        p.volume_weight,
        model.volume_sign,
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
        Time step, s (default ``model.stable_dt``, computed once per model).
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
    # integrate.py re-exports this module's API, so its helpers are imported here, not at the top
    from myoface.tissue.integrate import _targets_array

    dt = model.stable_dt if dt is None else float(dt)
    if not dt > 0:
        raise MyofaceValueError(f"dt must be > 0 s; got {dt}")
    s = state.copy()
    s.x = np.ascontiguousarray(s.x, dtype=np.float64)
    s.v = np.ascontiguousarray(s.v, dtype=np.float64)
    s.x[model.kinematic_index] = _targets_array(model, targets)
    s.v[model.kinematic_index] = 0.0
    done, _, bad = run_rk2(model, s.x, s.v, int(n_steps), dt)
    if bad >= 0:
        raise MyofaceSimulationError(
            f"RK2 produced NaN/Inf at step {bad} (dt = {dt:g} s); reduce dt"
        )
    s.t += done * dt
    return s
