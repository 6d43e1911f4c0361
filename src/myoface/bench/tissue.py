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


@benchmark("tissue.relax_ms", "ms", higher_is_better=False)
def bench_relax(quick: bool) -> Measurement:
    """From neutral, a step change of contractions to surprise, to equilibrium (implicit relax)."""
    from myoface.control import expression_contractions

    fm = _default_face_model()
    c = expression_contractions("surprise", 1.0, fm.ids)
    fm.relax(c)  # warm-up: JIT and the cached factorisation
    times = []
    n = 3 if quick else 9
    for _ in range(n):
        t0 = time.perf_counter()
        res = fm.relax(c, start="rest")
        times.append(time.perf_counter() - t0)
        assert res.converged
    return Measurement(float(np.median(times)) * 1e3, n)
