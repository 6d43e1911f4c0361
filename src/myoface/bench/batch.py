"""Benchmark of ``myoface batch``: the local engine against Dask, in the same run."""

from __future__ import annotations

import shutil
import statistics
import tempfile
import time
from pathlib import Path

from myoface.bench import Measurement, benchmark

#: the clips: (muscles moved, peak contraction); one clip each
CLIPS = {
    "smile": (("zygomaticus_major_l", "zygomaticus_major_r"), 0.8),
    "brows": (("frontalis_inner_l", "frontalis_inner_r", "frontalis_major_l"), 0.8),
    "jaw": (("jaw",), 0.6),
    "sneer": (
        ("levator_labii_superioris_alaeque_nasi_l", "levator_labii_superioris_alaeque_nasi_r"),
        0.8,
    ),
}
SIZE = 160  # px
WORKERS = 2
_cache: dict = {}


def _clips(quick: bool) -> tuple[list[Path], Path]:
    """The synthetic clips (rendered once per process into a temporary folder) and their
    initial contours: the model at rest, then each clip's muscles ramping up and down."""
    key = bool(quick)
    if key not in _cache:
        from myoface.analysis.batch import cached_model
        from myoface.analysis.initfiles import save_init
        from myoface.analysis.sections import project_sections
        from myoface.render import Camera, Renderer, VideoWriter, to_srgb8
        from myoface.render.dressing import default_skin_texture

        d = Path(tempfile.mkdtemp(prefix="myoface-bench-batch-"))
        fm = cached_model()
        cam = Camera.front(fm.face.vertices, width=SIZE, height=SIZE, fov_deg=None)
        tex = to_srgb8(default_skin_texture(fm.face, 256, makeup=True))
        r = Renderer(fm.face, cam, texture=tex)
        levels = (0.0, 1.0) if quick else (0.0, 0.5, 1.0, 0.5) * 3  # 2 or 12 frames
        rest = r.render(fm.skin_vertices(fm.rest_state()))
        paths = []
        for name, (muscles, peak) in CLIPS.items():
            imgs = {0.0: rest}
            with VideoWriter(d / f"{name}.mp4", fps=10) as vw:
                for a in levels:
                    if a not in imgs:
                        st = fm.relax({m: a * peak for m in muscles}).state
                        imgs[a] = r.render(fm.skin_vertices(st))
                    vw.write(imgs[a])
            paths.append(d / f"{name}.mp4")
        save_init(d / "init.json", project_sections(fm, cam))
        _cache[key] = (paths, d / "init.json", len(levels))
    return _cache[key]


@benchmark(
    "batch.videos_per_min",
    "1/min",
    higher_is_better=True,
    peer=f"dask distributed LocalCluster ({WORKERS} workers)",
)
def bench_batch_videos_per_min(quick: bool) -> Measurement:
    """Videos per minute through ``myoface batch`` with the local engine (a pool of 2
    processes) over 4 synthetic clips (the model rendered at 160x160 with make-up, each clip a
    different muscle group ramping up and down; 12 frames, 2 with --quick), snakes from
    contours given (--init), every output file written. Peer: the same batch on a Dask
    LocalCluster of 2 single-threaded workers, in the same run. Both are measured warm: the
    pool and the cluster are started and each worker has built the face model before the
    timed batches (a long batch amortises that), which alternate between the engines (median
    of 3, 1 with --quick); each timed batch writes to a new folder. The
    detail adds (not with --quick) the cold time of one batch, start-up and model building
    included."""
    from myoface.analysis.batch import local_pool, run_batch, start_local_cluster, warm_model

    videos, init, _ = _clips(quick)
    reps = 1 if quick else 3
    root = Path(tempfile.mkdtemp(prefix="myoface-bench-batch-out-"))
    count = [0]

    def batch(**kw) -> float:
        count[0] += 1
        t0 = time.perf_counter()
        rows = run_batch(videos, root / f"run{count[0]}", init=init, **kw)
        dt = time.perf_counter() - t0
        bad = [r for r in rows if r["status"] != "ok"]
        if bad:
            raise RuntimeError(f"batch benchmark: {bad[0]['path']}: {bad[0]['error']}")
        return dt

    cold = {}
    if not quick:
        cold = {
            "local": batch(engine="local", workers=WORKERS),
            "dask": batch(engine="dask", workers=WORKERS),
        }
    # both engines up and warm at once, the timed batches alternating between them, so that
    # a change in the machine's load during the run falls on both alike
    times: dict[str, list[float]] = {"local": [], "dask": []}
    with local_pool(WORKERS, initializer=warm_model) as pool:
        cluster, client = start_local_cluster(WORKERS)
        try:
            client.run(warm_model)
            runs = {
                "local": lambda: batch(engine="local", executor=pool),
                "dask": lambda: batch(engine="dask", client=client),
            }
            for fn in runs.values():
                fn()  # warm-up: the pool's processes start; file caches fill
            for _ in range(reps):
                for k, fn in runs.items():
                    times[k].append(fn())
        finally:
            client.close()
            cluster.close()
            shutil.rmtree(root, ignore_errors=True)
    t_local, t_dask = statistics.median(times["local"]), statistics.median(times["dask"])
    n = len(videos)
    per_min = {"local": 60 * n / t_local, "dask": 60 * n / t_dask}
    warm = {"local": t_local, "dask": t_dask}
    detail = {}
    for k, name in (("local", "local pool"), ("dask", "dask LocalCluster")):
        detail[name] = {
            "warm": {"videos_per_min": round(per_min[k], 2), "batch_s": round(warm[k], 2)}
        }
        if k in cold:
            detail[name]["cold"] = {
                "videos_per_min": round(60 * n / cold[k], 2),
                "batch_s": round(cold[k], 2),
            }
    return Measurement(per_min["local"], reps, per_min["dask"], detail=detail)
