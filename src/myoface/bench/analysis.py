"""Benchmarks of the analysis loop (names fixed by BENCH.md)."""

from __future__ import annotations

import numpy as np

from myoface.bench import Measurement, benchmark

_cache: dict = {}


def _closed_loop(quick: bool):
    key = bool(quick)
    if key not in _cache:
        from myoface.analysis.closed_loop import run_closed_loop
        from myoface.model import build_face_model

        _cache[key] = run_closed_loop(build_face_model(), n_frames=12 if quick else 48)
    return _cache[key]


@benchmark("analysis.closed_loop_rmse", "contraction", higher_is_better=False)
def bench_closed_loop_rmse(quick: bool) -> Measurement:
    """Worst per-muscle RMSE of recovered vs true contractions (the paper's 12 muscles + jaw)
    on a synthetic sequence rendered by the model with make-up (256x256, frontal,
    orthographic), analysed by snakes + fiducials + the model-based estimator."""
    res = _closed_loop(quick)
    return Measurement(float(np.nanmax(res.rmse())), len(res.truth))


@benchmark("analysis.closed_loop_corr", "-", higher_is_better=True)
def bench_closed_loop_corr(quick: bool) -> Measurement:
    """Worst per-muscle correlation of recovered vs true contractions on the same sequence
    (every muscle moves in it)."""
    res = _closed_loop(quick)
    c = res.corr()
    return Measurement(
        float(np.nanmin(c)) if np.isfinite(c).any() else float("nan"), len(res.truth)
    )
