"""Benchmarks of the image level and of synthesis (their names are the keys of BENCHMARKS.md and
of `myoface bench --json`; keep them)."""

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


def _demo_contractions(ids, fps: float = 25.0, duration_s: float = 3.0):
    """Times (T,) s and contractions (T, M) over ``ids`` of a short performance: a smile
    (zygomatici, with a little orbicularis oculi) rising and falling, a brow raise (frontalis)
    inside it and the jaw opening towards its end. The face moves in every frame after the
    first (no frame repeats its predecessor's contractions, which would need no physics)."""
    t = np.arange(int(round(duration_s * fps))) / fps

    def bump(t0, t1):  # 0 -> 1 -> 0 between t0 and t1 (s), smooth
        return np.sin(np.pi * np.clip((t - t0) / (t1 - t0), 0.0, 1.0)) ** 2

    table = np.zeros((len(t), len(ids)))
    for k, m in enumerate(ids):
        if m.startswith("zygomaticus_major"):
            table[:, k] = 0.8 * bump(0.0, 2.6)
        elif m.startswith("orbicularis_oculi"):
            table[:, k] = 0.25 * bump(0.0, 2.6)
        elif m.startswith("frontalis"):
            table[:, k] = 0.7 * bump(0.8, 2.2)
        elif m == "jaw":
            table[:, k] = 0.4 * bump(1.2, duration_s)
    return t, table


def write_demo_contractions_csv(path, model, fps: float = 25.0, duration_s: float = 3.0):
    """Write :func:`_demo_contractions` for ``model`` as a ``contractions.csv`` in the format
    ``myoface analyze`` writes (every frame measured, head still)."""
    from myoface.analysis.contractions_csv import write_contractions_csv
    from myoface.analysis.trackers.base import FrameMeasurement

    ids = list(model.ids)
    times, table = _demo_contractions(ids, fps, duration_s)
    frames = [
        FrameMeasurement(k, float(t), "ok", row, np.zeros(2))
        for k, (t, row) in enumerate(zip(times, table, strict=True))
    ]
    write_contractions_csv(path, ids, frames, model.muscles.jaw)


@benchmark("synth.resynth_fps_512", "1/s", higher_is_better=True)
def bench_resynth_fps_512(quick: bool) -> Measurement:
    """Frames per second of ``myoface resynth`` at 512x512, end to end: a 3 s, 25 fps
    contractions.csv (a smile rising and falling, a brow raise, the jaw opening) read, each
    frame's tissue equilibrium (warm-started from the previous frame), its render (textured,
    lit, anti-aliased) and its H.264 encoding to an MP4, through the command's own code
    (:mod:`myoface.analysis.resynthesis`: ``read_performance``, then ``resynthesize``); the
    model is built and the kernels compiled outside the timed region. The detail splits a
    frame into physics, render and encode (medians; the encoding runs in a background thread
    beside the next frame's physics and render)."""
    import statistics

    from myoface.analysis.resynthesis import read_performance, resynthesize
    from myoface.model import build_face_model

    t0 = time.perf_counter()
    fm = build_face_model()
    build_s = time.perf_counter() - t0
    stats = {"relax": [], "render": [], "encode": []}
    with tempfile.TemporaryDirectory() as d:
        csv = Path(d) / "contractions.csv"
        write_demo_contractions_csv(csv, fm)

        def one():
            perf = read_performance(csv, fm)
            out = Path(d) / "out.mp4"
            syn = resynthesize(
                fm, perf.times, perf.contractions, out, perf.fps, size=512, show_progress=False
            )
            stats["relax"] += syn.stats.relax_ms
            stats["render"] += syn.stats.render_ms
            stats["encode"] += syn.stats.encode_ms
            return perf.n_frames

        n_frames = one()  # JIT, factorisations
        for v in stats.values():
            v.clear()
        n = 1 if quick else 5
        per_run = time_median(one, n, warmup=0)
    med = statistics.median
    fps = n_frames / per_run
    detail = {
        "median": {
            "physics (relax) per frame": {"ms": round(med(stats["relax"]), 2)},
            "render per frame": {"ms": round(med(stats["render"]), 2)},
            "encode per frame (background thread)": {"ms": round(med(stats["encode"]), 2)},
            "wall per frame (1 / fps)": {"ms": round(1e3 / fps, 2)},
            "model build (once per command, not timed)": {"ms": round(1e3 * build_s, 1)},
        }
    }
    return Measurement(fps, n, detail=detail)
