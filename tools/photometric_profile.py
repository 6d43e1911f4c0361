"""What the photometric term of the 3-D fit costs per Gauss-Newton step and per frame.

One pass of ``myoface analyze --photometric`` over the sample video (as the benchmark runs it:
``myoface.bench.analysis._analysis_pass(path, "landmarks", None, photometric=True)``, no
output files), after a short warm-up pass (numba's compilation, the model's build). The
term's ``prepare``, ``normal_equations`` and ``cost`` are timed in CPU time of the thread that
calls them (``time.thread_time``: the machine is shared), and the fit's CPU per frame is the
fit's own timing (``ModelFit.timings["fit_cpu_s"] / fits``: the fit's thread; the
photometric channels' second thread, :class:`~myoface.analysis.photometric.ChannelTerms`, is
in the process CPU), and the pass's wall time a frame. ``--repeats N`` runs the pass N
times and prints each and their medians; ``--cprofile`` adds the pass's cProfile (the top
functions by own time, of the photometric module and what it calls; cProfile's overhead
inflates small calls); ``--parts`` times the term's pieces (its private steps, the compiled
kernels, the image reads) in CPU time, nested (a piece's time includes those it calls).

Usage::

    PYTHONPATH=src python tools/photometric_profile.py [--repeats 3] [--parts] [--cprofile]
"""

from __future__ import annotations

import argparse
import statistics
import time


def _timed(cls, name, acc):
    orig = getattr(cls, name)

    def wrapper(self, *args, **kwargs):
        t0 = time.thread_time()
        try:
            return orig(self, *args, **kwargs)
        finally:
            rec = acc[name]
            rec[0] += 1
            rec[1] += time.thread_time() - t0
            if name == "prepare" and getattr(self, "channel", "grey") == "grey":
                acc.setdefault("steps", [0, 0.0])[0] += 1  # (one brightness prepare a step)

    setattr(cls, name, wrapper)
    return orig


#: with ``--parts``: the term's pieces timed too (those that exist in the tree profiled)
PARTS = ("_crop", "_light_basis", "_read_at", "_at", "_weighted_rows", "_rows", "_reading")
KERNELS = ("camera_points", "sample_pixels", "facing", "clear_of_polyline", "shading_basis",
           "light_system", "light_apply", "step_weights", "step_light", "weighted_rows",
           "weighted_cost")  # fmt: skip


def one_pass(path, cprofile: bool = False, parts: bool = False) -> dict:
    import myoface.analysis.photometric as ph
    from myoface.analysis.photometric import PhotometricTerm
    from myoface.bench import analysis as bench

    names = ("prepare", "normal_equations", "cost", "occlusion")
    acc = {n: [0, 0.0] for n in names}
    origs = {n: _timed(PhotometricTerm, n, acc) for n in names}
    patched = []  # (owner, name, original)
    if parts:
        module = ("unoccluded", "_gram", "distance_to_polyline", "facing", "sample_normals")
        owners = [(PhotometricTerm, PARTS), (ph, (*module, "_sample"))]
        pk = getattr(ph, "_pk", None)
        if pk is not None:
            owners.append((pk, KERNELS))
        for owner, keys in owners:
            for k in keys:
                if hasattr(owner, k):
                    acc.setdefault(k, [0, 0.0])
                    patched.append((owner, k, _timed(owner, k, acc)))
    prof = None
    try:
        if cprofile:
            import cProfile

            prof = cProfile.Profile()
            prof.enable()
        c0 = time.process_time()
        n = bench._analysis_pass(path, "landmarks", None, photometric=True)
        cpu = time.process_time() - c0
        if prof is not None:
            prof.disable()
    finally:
        for k, f in origs.items():
            setattr(PhotometricTerm, k, f)
        for owner, k, f in reversed(patched):
            setattr(owner, k, f)
    t = bench._cache[("timings", "landmarks", None, True)]
    # (a Gauss-Newton step prepares each channel's term: the brightness's count the steps)
    steps = acc.get("steps", acc["prepare"])[0]
    out = {
        "frames": n,
        "steps": steps,
        "steps_per_frame": steps / max(n, 1),
        "process_cpu_s": cpu,
        "fit_cpu_ms_per_frame": 1e3 * t["fit_cpu_s"] / max(t["fits"], 1),
        "wall_ms_per_frame": 1e3 * t["wall_s"] / max(n, 1),
    }
    for k in names:
        calls, s = acc[k]
        out[f"{k}_calls"] = calls
        out[f"{k}_ms"] = 1e3 * s / max(calls, 1)
    # the term's share of a step: prepare + normal equations + every cost call, per step
    out["term_ms_per_step"] = (
        1e3 * (acc["prepare"][1] + acc["normal_equations"][1] + acc["cost"][1]) / max(steps, 1)
    )
    out["profile"] = prof
    out["parts"] = {k: v for k, v in acc.items() if k not in (*names, "steps")}
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--cprofile", action="store_true")
    ap.add_argument("--top", type=int, default=25)
    ap.add_argument("--parts", action="store_true", help="time the term's pieces too")
    a = ap.parse_args(argv)
    from myoface.bench import analysis as bench

    path = bench._sample_video()
    bench._analysis_pass(path, "landmarks", 3, photometric=True)  # (warm-up: compiles, builds)
    runs = []
    for _ in range(a.repeats):
        r = one_pass(path)
        runs.append(r)
        print(
            f"frames {r['frames']}  steps {r['steps']} ({r['steps_per_frame']:.2f}/frame)  "
            f"prepare {r['prepare_ms']:.3f} ms  normal_equations {r['normal_equations_ms']:.3f} "
            f"ms  cost {r['cost_ms']:.3f} ms x {r['cost_calls'] / max(r['steps'], 1):.2f}/step  "
            f"term {r['term_ms_per_step']:.3f} ms/step  occlusion {r['occlusion_ms']:.2f} "
            f"ms/frame  fit CPU {r['fit_cpu_ms_per_frame']:.1f} ms/frame  "
            f"process CPU {r['process_cpu_s']:.2f} s  wall {r['wall_ms_per_frame']:.1f} ms/frame"
        )
    if a.repeats > 1:
        keys = ("prepare_ms", "normal_equations_ms", "cost_ms", "term_ms_per_step",
                "fit_cpu_ms_per_frame", "process_cpu_s", "wall_ms_per_frame")  # fmt: skip
        print("median: " + "  ".join(f"{k} {statistics.median(r[k] for r in runs):.3f}"
                                     for k in keys))  # fmt: skip
    if a.parts:
        r = one_pass(path, parts=True)
        steps = max(r["steps"], 1)
        print("the term's pieces (thread CPU; calls per step, ms per call, ms per step):")
        for k, (calls, sec) in sorted(r["parts"].items(), key=lambda kv: -kv[1][1]):
            if calls:
                print(f"  {k:22s} {calls / steps:6.2f}  {1e3 * sec / calls:7.3f}  "
                      f"{1e3 * sec / steps:7.3f}")  # fmt: skip
    if a.cprofile:
        import pstats

        r = one_pass(path, cprofile=True)
        pstats.Stats(r["profile"]).sort_stats("tottime").print_stats(a.top)


if __name__ == "__main__":
    main()
