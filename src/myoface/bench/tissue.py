"""Benchmarks of the physics level (names fixed by BENCH.md)."""

from __future__ import annotations

import time

import numba
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


@benchmark("tissue.ns_per_spring_1m", "ns", higher_is_better=False)
def bench_ns_per_spring(quick: bool) -> Measurement:
    """One spring-force evaluation on a synthetic ~1,000,000-spring lattice, per spring, all cores."""
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
    return Measurement(t / len(si) * 1e9, n)


def _default_face_model():
    from myoface.model import build_face_model

    return build_face_model()


@benchmark("tissue.rk2_steps_per_s", "1/s", higher_is_better=True)
def bench_rk2(quick: bool) -> Measurement:
    """Paper RK2 steps per second on the default face model (muscles bound), one thread."""
    from myoface.tissue import rest_state, step_rk2

    fm = _default_face_model()
    model = fm.tissue
    steps = 200 if quick else 1000
    prev = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        state = rest_state(model)
        targets = fm.targets(fm.muscles.validate({}))
        dt = fm.stable_dt()

        def run():
            step_rk2(model, state, targets, dt, n_steps=steps)

        n = 3 if quick else 7
        t = time_median(run, n)
    finally:
        numba.set_num_threads(prev)
    return Measurement(steps / t, n)


#: the peer of the relax benchmarks: the L-BFGS solver it replaced, kept as ``method="lbfgs"``
RELAX_PEER = "myoface L-BFGS (method='lbfgs', the reference)"
#: the reference equilibria the benchmarks measure their distance to: L-BFGS to this step, mm
RELAX_REFERENCE_TOL_MM = 1e-7


def _timed_relax(tm, state, targets, n, **kw):
    """Median wall time (s) and CPU time of the calling thread (s) of ``n`` relaxes, the iteration
    count and the result (the last one)."""
    from myoface.tissue import relax

    relax(tm, state, targets, **kw)  # warm-up: JIT, cached factorisation
    wall, cpu = [], []
    for _ in range(n):
        t0, c0 = time.perf_counter(), time.thread_time()
        res = relax(tm, state, targets, **kw)
        cpu.append(time.thread_time() - c0)
        wall.append(time.perf_counter() - t0)
        assert res.converged
    return float(np.median(wall)), float(np.median(cpu)), res


def _relax_detail(new, peer) -> dict:
    """``{solver: {row: {column: value}}}`` for BENCHMARKS.md's detail table."""
    return {
        solver: {
            "median wall": {"ms": d["wall"] * 1e3},
            "median thread CPU": {"ms": d["cpu"] * 1e3},
            "iterations": {"ms": d["iterations"]},
            "max distance to the reference equilibrium, mm": {"ms": d["err_mm"]},
        }
        for solver, d in (("newton", new), ("lbfgs", peer))
    }


@benchmark("tissue.relax_ms", "ms", higher_is_better=False, peer=RELAX_PEER)
def bench_relax(quick: bool) -> Measurement:
    """From neutral (rest), a step change of contractions to surprise (intensity 1), to
    equilibrium with the default solver (Newton, ``method="newton"``), default face; peer: the
    L-BFGS reference (default tolerance) on the same step in the same run. The detail gives both
    solvers' iterations, thread CPU time, and largest node distance to the equilibrium found by
    L-BFGS to a 1e-7 mm step."""
    from myoface.control import expression_contractions
    from myoface.tissue import relax

    fm = _default_face_model()
    tm = fm.tissue
    tg = fm.targets(expression_contractions("surprise", 1.0, fm.ids))
    ref = relax(tm, None, tg, method="lbfgs", tol_mm=RELAX_REFERENCE_TOL_MM, max_iter=5000)
    n = 3 if quick else 15
    out = {}
    for method in ("newton", "lbfgs"):
        wall, cpu, res = _timed_relax(
            tm, None, tg, n if method == "newton" else max(3, n // 3), method=method
        )
        out[method] = {
            "wall": wall,
            "cpu": cpu,
            "iterations": res.iterations,
            "err_mm": float(np.abs(res.state.x - ref.state.x).max()),
        }
    return Measurement(
        out["newton"]["wall"] * 1e3,
        n,
        out["lbfgs"]["wall"] * 1e3,
        detail=_relax_detail(out["newton"], out["lbfgs"]),
    )


@benchmark("tissue.relax_warm_ms", "ms", higher_is_better=False, peer=RELAX_PEER)
def bench_relax_warm(quick: bool) -> Measurement:
    """One frame of a 25 fps smile (AU12 = k/25, AU6 = k/50, k = 0..25: 0 -> 1 in 1 s), relaxed
    from the previous frame's equilibrium, default solver, default face: median over the frames
    (each timed as the median of repeats); peer: the L-BFGS reference on the same frames. The
    detail gives both solvers' median iterations, thread CPU time and largest node distance to
    the frame's equilibrium found by L-BFGS to a 1e-7 mm step."""
    from myoface.control import au_contractions
    from myoface.tissue import relax, rest_state

    fm = _default_face_model()
    tm = fm.tissue
    frames = range(0, 25, 6) if quick else range(25)
    reps = 3 if quick else 5
    tgs = {k: fm.targets(au_contractions({12: k / 25, 6: k / 50}, fm.ids)) for k in range(26)}
    # the start of each frame: the previous frame's equilibrium (the reference's, so both solvers
    # start from the same state)
    eq = {}
    state = rest_state(tm)
    for k in range(26):
        state = relax(
            tm, state, tgs[k], method="lbfgs", tol_mm=RELAX_REFERENCE_TOL_MM, max_iter=5000
        ).state
        eq[k] = state
    out = {}
    for method in ("newton", "lbfgs"):
        walls, cpus, its, errs = [], [], [], []
        for k in frames:
            wall, cpu, res = _timed_relax(tm, eq[k], tgs[k + 1], reps, method=method)
            walls.append(wall)
            cpus.append(cpu)
            its.append(res.iterations)
            errs.append(float(np.abs(res.state.x - eq[k + 1].x).max()))
        out[method] = {
            "wall": float(np.median(walls)),
            "cpu": float(np.median(cpus)),
            "iterations": float(np.median(its)),
            "err_mm": max(errs),
        }
    return Measurement(
        out["newton"]["wall"] * 1e3,
        len(frames) * reps,
        out["lbfgs"]["wall"] * 1e3,
        detail=_relax_detail(out["newton"], out["lbfgs"]),
    )
