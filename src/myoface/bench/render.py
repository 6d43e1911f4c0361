"""Benchmarks of the image level and of synthesis (names fixed by BENCH.md)."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from myoface.bench import Measurement, benchmark, time_median


def _render_fps(width: int, height: int, quick: bool) -> Measurement:
    from myoface.face import load_default_face
    from myoface.render import Camera, Renderer

    face = load_default_face()
    r = Renderer(face, Camera.front(face.vertices, width=width, height=height))
    rng = np.random.default_rng(0)
    frames = [face.vertices + rng.normal(0, 0.05, face.vertices.shape) for _ in range(8)]
    r.render(frames[0])  # JIT
    k = [0]

    def one():
        r.render(frames[k[0] % len(frames)])
        k[0] += 1

    n = 15 if quick else 60
    return Measurement(1.0 / time_median(one, n, warmup=3), n)


@benchmark("render.fps_640x480", "1/s", higher_is_better=True)
def bench_render_640(quick: bool) -> Measurement:
    """Default face, textured, lit (3 lights), eyes and mouth, 640x480, anti-aliased with 2x2
    coverage samples per pixel (each triangle shaded once per pixel it covers), new vertex
    positions every frame, to a uint8 sRGB image."""
    return _render_fps(640, 480, quick)


@benchmark("render.fps_256x256", "1/s", higher_is_better=True)
def bench_render_256(quick: bool) -> Measurement:
    """As render.fps_640x480 at 256x256."""
    return _render_fps(256, 256, quick)


@benchmark("synth.realtime_factor", "x", higher_is_better=True)
def bench_synth(quick: bool) -> Measurement:
    """Seconds of expression video produced per second of wall time: a 5 s surprise video
    (quasi-static physics per frame + render 512x512 + H.264 encode at 30 fps)."""
    from myoface.control import single_event_timeline
    from myoface.model import build_face_model
    from myoface.synth import Synthesizer

    fm = build_face_model()
    syn = Synthesizer(fm)
    duration = 1.0 if quick else 5.0
    tl = single_event_timeline("expression", "surprise", 1.0, duration)
    syn.image(np.zeros(len(fm.ids)))  # JIT and factorisations
    times = []
    n = 1 if quick else 3
    with tempfile.TemporaryDirectory() as d:
        for _ in range(n):
            t0 = time.perf_counter()
            syn.video(tl, Path(d) / "b.mp4", fps=30.0, show_progress=False)
            times.append(time.perf_counter() - t0)
    return Measurement(tl.duration / float(np.median(times)), n)
