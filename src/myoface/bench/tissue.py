"""Benchmarks of the physics level (names stable across releases)."""

from __future__ import annotations

import time

import numpy as np

from myoface.bench import Measurement, benchmark, time_median


def grid_lattice(n_springs_target: int):
    """A cubic grid lattice with axis and face-diagonal springs (9 per node), ordered for locality.

    Returns (positions (N,3), springs (S,2)) with S close to ``n_springs_target``.
    """
    side = max(3, int(round((n_springs_target / 9.0) ** (1 / 3))))
    idx = np.arange(side**3).reshape(side, side, side)
    pos = np.stack(
        np.meshgrid(*(np.arange(side, dtype=float) * 2.0,) * 3, indexing="ij"), -1
    ).reshape(-1, 3)
    pairs = []
    offsets = [
        (1, 0, 0),
        (0, 1, 0),
        (0, 0, 1),
        (1, 1, 0),
        (1, -1, 0),
        (1, 0, 1),
        (1, 0, -1),
        (0, 1, 1),
        (0, 1, -1),
    ]
    for dx, dy, dz in offsets:
        a = idx[
            max(0, -dx) : side - max(0, dx),
            max(0, -dy) : side - max(0, dy),
            max(0, -dz) : side - max(0, dz),
        ]
        b = idx[
            max(0, dx) : side - max(0, -dx) or None,
            max(0, dy) : side - max(0, -dy) or None,
            max(0, dz) : side - max(0, -dz) or None,
        ]
        b = b[: a.shape[0], : a.shape[1], : a.shape[2]]
        pairs.append(np.stack([a.ravel(), b.ravel()], 1))
    springs = np.concatenate(pairs)
    springs = springs[np.argsort(springs[:, 0], kind="stable")]
    return pos, springs


WARP_PEER = "NVIDIA Warp (warp-lang), device cpu"


def _warp_spring_forces():
    """The biphasic spring force of :func:`myoface.tissue.forces.spring_magnitude`
    (``LAW_CONTINUOUS``) as a Warp kernel, float64, one thread per spring with atomic adds; or
    None when warp-lang is not installed (``pip install "myoface[bench]"``)."""
    try:
        import warp as wp
    except ImportError:
        return None
    wp.config.quiet = True  # older warp-lang; newer ones have log levels instead
    if hasattr(wp, "LOG_WARNING"):
        wp.config.log_level = wp.LOG_WARNING
    wp.init()

    @wp.kernel
    def spring_forces(
        x: wp.array(dtype=wp.vec3d),
        si: wp.array(dtype=wp.int64),
        sj: wp.array(dtype=wp.int64),
        rest: wp.array(dtype=wp.float64),
        mat_id: wp.array(dtype=wp.int64),
        mat: wp.array2d(dtype=wp.float64),
        f: wp.array(dtype=wp.vec3d),
    ):
        k = wp.tid()
        i = si[k]
        j = sj[k]
        r = x[j] - x[i]
        d = wp.length(r)
        if d < wp.float64(1.0e-12):  # MIN_SPRING_LENGTH
            return
        m = mat_id[k]
        lk = rest[k]
        e = d - lk
        ec = mat[m, 2] * lk
        mag = mat[m, 0] * e
        if e > ec:
            mag = mat[m, 0] * ec + mat[m, 1] * (e - ec)
        s = r * (mag / d)
        wp.atomic_add(f, i, s)
        wp.atomic_sub(f, j, s)

    def make(si, sj, rest, mat_id, mat, n_nodes):
        dev = "cpu"
        args = [
            wp.array(si, dtype=wp.int64, device=dev),
            wp.array(sj, dtype=wp.int64, device=dev),
            wp.array(rest, dtype=wp.float64, device=dev),
            wp.array(mat_id, dtype=wp.int64, device=dev),
            wp.array(mat, dtype=wp.float64, device=dev),
        ]
        f = wp.zeros(n_nodes, dtype=wp.vec3d, device=dev)

        def forces(x_wp):
            f.zero_()
            wp.launch(spring_forces, dim=len(si), inputs=[x_wp, *args, f], device=dev)
            return f

        def to_warp(x):
            return wp.array(x, dtype=wp.vec3d, device=dev)

        return forces, to_warp

    return make


@benchmark("tissue.ns_per_spring_1m", "ns", higher_is_better=False, peer=WARP_PEER)
def bench_ns_per_spring(quick: bool) -> Measurement:
    """One spring-force evaluation on a synthetic ~1,000,000-spring lattice, per spring, all cores
    (per-thread force buffers). Peer: the same biphasic force (``LAW_CONTINUOUS``, float64) as an
    NVIDIA Warp kernel on ``device="cpu"`` (one launch, atomic adds), on the same lattice and
    positions in the same run, after checking that its forces equal ours; no peer without
    warp-lang. The detail gives ours on one thread too (a Warp CPU launch runs on one)."""
    import numba

    from myoface.tissue.forces import LAW_CONTINUOUS, make_thread_buffers, spring_forces_parallel

    pos, springs = grid_lattice(1_000_000)
    rng = np.random.default_rng(0)
    x = pos + rng.normal(0, 0.05, pos.shape)
    si, sj = springs[:, 0].copy(), springs[:, 1].copy()
    rest = np.linalg.norm(pos[sj] - pos[si], axis=1)
    mat_id = np.zeros(len(si), np.int64)
    mat = np.array([[1000.0, 10000.0, 0.2]])
    f = np.zeros_like(x)
    buf = make_thread_buffers(len(x))

    def run():
        f[:] = 0.0
        spring_forces_parallel(x, si, sj, rest, mat_id, mat, LAW_CONTINUOUS, f, buf)

    n = 5 if quick else 21
    t = time_median(run, n)
    # the same on one thread, for the detail (Warp's CPU backend runs a launch on one thread)
    prev = numba.get_num_threads()
    buf1 = np.zeros((1, *x.shape))
    numba.set_num_threads(1)
    try:
        t1 = time_median(
            lambda: spring_forces_parallel(x, si, sj, rest, mat_id, mat, LAW_CONTINUOUS, f, buf1),
            n,
        )
    finally:
        numba.set_num_threads(prev)
    per = {f"myoface, {prev} threads": t, "myoface, 1 thread": t1}
    peer = None
    make_warp = _warp_spring_forces()
    if make_warp is not None:
        forces, to_warp = make_warp(si, sj, rest, mat_id, mat, len(x))
        # the same forces first, on positions stretched enough that both phases of the law occur
        xc = pos + rng.normal(0, 0.5, pos.shape)
        ref = np.zeros_like(xc)
        spring_forces_parallel(xc, si, sj, rest, mat_id, mat, LAW_CONTINUOUS, ref, buf)
        got = forces(to_warp(xc)).numpy()
        # float64 on both sides; only the order of the sums at a node differs
        if not np.allclose(got, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max()):
            raise AssertionError("Warp's spring forces differ from myoface's")
        xw = to_warp(x)
        per["NVIDIA Warp, cpu"] = time_median(lambda: forces(xw), n)
        peer = per["NVIDIA Warp, cpu"] / len(si) * 1e9
    detail = {"ns/spring": {k: {"median": v / len(si) * 1e9} for k, v in per.items()}}
    return Measurement(t / len(si) * 1e9, n, peer, detail)


def _default_face_model():
    from myoface.model import build_face_model

    return build_face_model()


RK2_PEER = "myoface's previous RK2 kernel (one thread)"


@benchmark("tissue.rk2_steps_per_s", "1/s", higher_is_better=True, peer=RK2_PEER)
def bench_rk2(quick: bool) -> Measurement:
    """Paper RK2 steps per second on the default face model (muscles bound), at its stable time
    step, all cores: the parallel kernel of ``myoface.tissue.rk2`` as ``step_rk2`` runs it (all
    threads, or one when it measures one to be faster: on a machine busy with other work).
    Peer: the previous single-thread kernel (kept as the reference) on the same steps from the
    same state, timed alternately with ours in the same run. The detail gives the parallel kernel
    with a fixed number of threads too, each run's best rate, the CPU time of all the process's
    threads per step (a thread waiting for another spins, then yields its core) and that of the
    calling thread (``time.thread_time``: on one thread, the kernel's own cost, which a busy
    machine changes least; with a team, the calling thread's share), and the share of the
    default's steps that ran on each number of threads (its choice, by measurement)."""
    import numba

    from myoface.tissue import rest_state, rk2, step_rk2
    from myoface.tissue.rk2 import run_rk2, run_rk2_serial

    fm = _default_face_model()
    tm = fm.tissue
    targets = fm.targets(fm.validate({}))
    state = rest_state(tm)
    dt = tm.stable_dt
    steps = 200 if quick else 1000
    nt = numba.get_num_threads()

    def start():
        x, v = state.x.copy(), state.v.copy()
        x[tm.kinematic_index] = targets
        return x, v

    runs = {
        "default (step_rk2)": lambda: step_rk2(tm, state, targets, dt, n_steps=steps),
        f"{nt} threads": lambda: run_rk2(tm, *start(), steps, dt, n_blocks=nt),
        "1 thread": lambda: run_rk2(tm, *start(), steps, dt, n_blocks=1),
        "previous kernel (peer)": lambda: run_rk2_serial(tm, *start(), steps, dt),
    }
    for fn in runs.values():  # warm-up: JIT (or its cache) and the kernel's per-model arrays
        fn()
    n = 3 if quick else 15
    times = {k: [] for k in runs}
    cpu = {k: [] for k in runs}
    tcpu = {k: [] for k in runs}
    steps_before = rk2.rk2_integrator(tm).steps_run
    for _ in range(n):  # alternate, so all see the same load on a shared machine
        for k, fn in runs.items():
            t0, c0, h0 = time.perf_counter(), time.process_time(), time.thread_time()
            fn()
            tcpu[k].append(time.thread_time() - h0)
            cpu[k].append(time.process_time() - c0)
            times[k].append(time.perf_counter() - t0)
    rate = {k: steps / float(np.median(ts)) for k, ts in times.items()}
    detail = {
        "steps/s": {k: {"median": rate[k], "best": steps / float(np.min(times[k]))} for k in runs},
        "CPU us/step (all threads)": {
            k: {"median": float(np.median(cpu[k])) / steps * 1e6} for k in runs
        },
        "CPU us/step (calling thread)": {
            k: {"median": float(np.median(tcpu[k])) / steps * 1e6} for k in runs
        },
    }
    steps_run = rk2.rk2_integrator(tm).steps_run
    if steps_run:  # which thread counts the default's timed steps ran on
        ran = {t: s - steps_before.get(t, 0) for t, s in sorted(steps_run.items())}
        total = sum(ran.values()) or 1
        detail["default (step_rk2): share of its steps"] = {
            f"{t} thread{'s' if t > 1 else ''}": {"share": s / total} for t, s in ran.items()
        }
    return Measurement(rate["default (step_rk2)"], n, rate["previous kernel (peer)"], detail)


#: the peer of the relax benchmarks: the L-BFGS solver it replaced, kept as ``method="lbfgs"``
RELAX_PEER = "myoface L-BFGS (method='lbfgs', the reference)"
#: the reference equilibria the benchmarks measure their distance to: L-BFGS to this step, mm
RELAX_REFERENCE_TOL_MM = 1e-7


def _timed_relaxes(tm, state, targets, reps: dict) -> dict:
    """``{method: (median wall s, median thread CPU s, last result, fastest thread CPU s)}`` of
    ``reps[method]``
    relaxes with each method, timed in turn (newton, lbfgs, newton, ...) so that both see the
    same load on a shared machine; each warmed up first (JIT, the model's cached data)."""
    from myoface.tissue import relax

    for method in reps:
        relax(tm, state, targets, method=method)
    times = {m: ([], []) for m in reps}
    res = {}
    for r in range(max(reps.values())):
        for method, n in reps.items():
            if r * n // max(reps.values()) == (r + 1) * n // max(reps.values()):
                continue  # the method with fewer repeats skips some rounds, evenly spread
            t0, c0 = time.perf_counter(), time.thread_time()
            res[method] = relax(tm, state, targets, method=method)
            times[method][1].append(time.thread_time() - c0)
            times[method][0].append(time.perf_counter() - t0)
            assert res[method].converged
    return {
        m: (float(np.median(w)), float(np.median(c)), res[m], float(np.min(c)))
        for m, (w, c) in times.items()
    }


#: the Newton solver's counts per relax in the detail, by their index in relax_newton's stats
NEWTON_COUNTS = {
    "CG iterations": 3,
    "Hessian assemblies": 4,
    "of which the prisms' part": 5,
    "energy and gradient passes": 6,
}


def _newton_counts(tm, state, targets) -> np.ndarray:
    """The Newton solver's counts (``relax_newton``'s stats, (9,)) on the relax that
    ``relax(tm, state, targets)`` makes (its start and guess), run once outside the timing."""
    from myoface.tissue import rest_state
    from myoface.tissue.solver import NEWTON_TOL_MM, relax_newton

    state = state if state is not None else rest_state(tm)
    kin = tm.kinematic_index
    x = state.x.copy()
    x_kin_start = x[kin].copy()
    x[kin] = targets
    stats = np.zeros(9)
    relax_newton(tm, x, x_kin_start, NEWTON_TOL_MM, 50, stats=stats, previous_x=state.previous_x)
    return stats


def _relax_detail(new, peer, counts=None) -> dict:
    """``{solver: {row: {column: value}}}`` for BENCHMARKS.md's detail table; ``counts``:
    the Newton solver's stats (mean over the relaxes), for the rows of :data:`NEWTON_COUNTS`."""
    out = {
        solver: {
            "median wall": {"ms": d["wall"] * 1e3},
            "median thread CPU": {"ms": d["cpu"] * 1e3},
            # the fastest of the repeats: what a busy machine (other processes sharing the
            # cores and caches) adds least to
            "fastest thread CPU": {"ms": d["cpu_min"] * 1e3},
            "iterations": {"ms": d["iterations"]},
            "max distance to the reference equilibrium, mm": {"ms": d["err_mm"]},
        }
        for solver, d in (("newton", new), ("lbfgs", peer))
    }
    if counts is not None:
        for row, i in NEWTON_COUNTS.items():
            out["newton"][row] = {"ms": float(counts[i])}
    return out


@benchmark("tissue.relax_ms", "ms", higher_is_better=False, peer=RELAX_PEER)
def bench_relax(quick: bool) -> Measurement:
    """From neutral (rest), a step change of contractions to surprise (intensity 1), to
    equilibrium with the default solver (Newton, ``method="newton"``), default face; peer: the
    L-BFGS reference (default tolerance) on the same step in the same run. The detail gives both
    solvers' iterations, thread CPU time (median and fastest of the repeats), and largest node
    distance to the equilibrium found by L-BFGS to a 1e-7 mm step. The two solvers are timed in turn, so they see the same load."""
    from myoface.control import expression_contractions
    from myoface.tissue import relax

    fm = _default_face_model()
    tm = fm.tissue
    tg = fm.targets(expression_contractions("surprise", 1.0, fm.ids))
    ref = relax(tm, None, tg, method="lbfgs", tol_mm=RELAX_REFERENCE_TOL_MM, max_iter=5000)
    n = 3 if quick else 15
    out = {}
    timed = _timed_relaxes(tm, None, tg, {"newton": n, "lbfgs": max(3, n // 3)})
    for method, (wall, cpu, res, cpu_min) in timed.items():
        out[method] = {
            "wall": wall,
            "cpu": cpu,
            "cpu_min": cpu_min,
            "iterations": res.iterations,
            "err_mm": float(np.abs(res.state.x - ref.state.x).max()),
        }
    return Measurement(
        out["newton"]["wall"] * 1e3,
        n,
        out["lbfgs"]["wall"] * 1e3,
        detail=_relax_detail(out["newton"], out["lbfgs"], _newton_counts(tm, None, tg)),
    )


@benchmark("tissue.relax_warm_ms", "ms", higher_is_better=False, peer=RELAX_PEER)
def bench_relax_warm(quick: bool) -> Measurement:
    """One frame of a 25 fps smile (AU12 = k/25, AU6 = k/50, k = 0..25: 0 -> 1 in 1 s), relaxed
    from the previous frame's equilibrium (a relaxed state, so it records the frame before:
    the Newton solver repeats that move), default solver, default face: median over the frames
    (each timed as the median of repeats); peer: the L-BFGS reference on the same frames. The
    detail gives both solvers' median iterations, thread CPU time (the median over the frames
    of each frame's median, and of each frame's fastest) and largest node distance to the
    frame's equilibrium found by L-BFGS to a 1e-7 mm step. The two solvers are timed in turn on
    each frame, so they see the same load."""
    from myoface.control import au_contractions
    from myoface.tissue import relax, rest_state

    fm = _default_face_model()
    tm = fm.tissue
    frames = range(0, 25, 6) if quick else range(25)
    reps = 3 if quick else 5
    tgs = {k: fm.targets(au_contractions({12: k / 25, 6: k / 50}, fm.ids)) for k in range(26)}
    # the start of each frame: the previous frame's equilibrium (the reference's, so both solvers
    # start from the same state); like every relaxed state it records the positions it was
    # relaxed from (previous_x), whose move the Newton solver repeats in its initial guess
    eq = {}
    state = rest_state(tm)
    for k in range(26):
        state = relax(
            tm, state, tgs[k], method="lbfgs", tol_mm=RELAX_REFERENCE_TOL_MM, max_iter=5000
        ).state
        eq[k] = state
    rows = {"newton": [], "lbfgs": []}
    for k in frames:
        timed = _timed_relaxes(tm, eq[k], tgs[k + 1], {"newton": reps, "lbfgs": max(2, reps // 2)})
        for method, (wall, cpu, res, cpu_min) in timed.items():
            err = float(np.abs(res.state.x - eq[k + 1].x).max())
            rows[method].append((wall, cpu, res.iterations, err, cpu_min))
    out = {}
    for method, r in rows.items():
        wall, cpu, its, errs, cpu_min = np.array(r).T
        out[method] = {
            "wall": float(np.median(wall)),
            "cpu": float(np.median(cpu)),
            "cpu_min": float(np.median(cpu_min)),
            "iterations": float(np.median(its)),
            "err_mm": float(errs.max()),
        }
    counts = np.mean([_newton_counts(tm, eq[k], tgs[k + 1]) for k in frames], axis=0)
    return Measurement(
        out["newton"]["wall"] * 1e3,
        len(frames) * reps,
        out["lbfgs"]["wall"] * 1e3,
        detail=_relax_detail(out["newton"], out["lbfgs"], counts),
    )
