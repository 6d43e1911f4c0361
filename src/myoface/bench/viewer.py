"""Benchmark of the viewer (name stable across releases)."""

from __future__ import annotations

import time

import numpy as np

from myoface.bench import Measurement, benchmark


@benchmark("viewer.update_ms", "ms", higher_is_better=False)
def bench_update(quick: bool) -> Measurement:
    """A muscle slider moved by 0.1 (as the GUI callback does it) until the worker has relaxed
    the tissue and pushed the new mesh to the viser scene; server running, no client."""
    try:
        from myoface.viewer.app import FaceViewer
    except ImportError:  # pragma: no cover - viser missing
        return Measurement(float("nan"), 0)
    from myoface.model import build_face_model

    v = FaceViewer(build_face_model(), port=0)
    try:
        slider = v._sliders["zygomaticus_major_l"]
        n = 8 if quick else 30
        times = []
        for k in range(n + 2):
            value = round(0.1 * (k % 10), 2)
            t0 = time.perf_counter()
            v.state.set_muscle("zygomaticus_major_l", value)
            slider.value = value
            v._update()
            time.sleep(0.0005)
            v.worker.settled.wait(30)
            if k >= 2:  # the first two include JIT and factorisations
                times.append((time.perf_counter() - t0) * 1e3)
    finally:
        v.close()
    return Measurement(float(np.median(times)), n)


@benchmark("viewer.drag_updates_per_s", "1/s", higher_is_better=True)
def bench_drag(quick: bool) -> Measurement:
    """A slider dragged smoothly from 0 to 1 and back, one GUI event every 1/60 s (as a browser
    sends them), for 2 s: new meshes pushed to the scene per second during the drag (the
    target is 30 or more: a smooth drag); server running, no client."""
    try:
        from myoface.viewer.app import FaceViewer
    except ImportError:  # pragma: no cover - viser missing
        return Measurement(float("nan"), 0)
    from myoface.model import build_face_model

    v = FaceViewer(build_face_model(), port=0)
    published = []
    update = v.scene.update

    def counting(x):
        update(x)
        published.append(time.perf_counter())

    v.worker.publish = counting
    try:
        v.apply(v.model.validate({}))  # JIT and factorisations outside the timed drag
        rates = []
        for _ in range(2 if quick else 5):
            published.clear()
            events = np.concatenate([np.linspace(0, 1, 60), np.linspace(1, 0, 60)])
            t0 = time.perf_counter()
            for k, value in enumerate(events):
                v.state.set_muscle("zygomaticus_major_l", round(float(value), 2))
                v._update()
                time.sleep(max(0.0, t0 + (k + 1) / 60 - time.perf_counter()))
            t1 = time.perf_counter()
            rates.append(sum(t0 <= t <= t1 for t in published) / (t1 - t0))
            v.worker.settled.wait(30)
    finally:
        v.close()
    return Measurement(float(np.median(rates)), len(rates))
