"""The photometric fit's settings tried on the known answers and on a real video (issue 30).

Two modes, each with the fit's settings overridden (``--set``: FitSettings fields, JSON) and
module constants (``--const``: ``module.NAME`` under ``myoface.analysis``, JSON; e.g.
``{"photometric.MOUTH_RIM_WEIGHT": 1.0}``):

- ``warp``: the known-warp clips (:func:`myoface.bench.knownwarp.run_known_warp`, the
  photometric fit unless ``--set '{"photometric": false}'``), head still or moving, plain or
  with the look the expressions add (``--look``), some expressions (``--expressions``):
  prints each region's gain / explained and the leak;
- ``video``: ``myoface analyze VIDEO --photometric --report`` into ``--out`` with the same
  overrides: prints the validated fidelity per region (explained / gain).

    python tools/photometric_ablation.py warp --look --expressions happiness \\
        --set '{"photo_landmark_weight": 0.01}'
    python tools/photometric_ablation.py video --out /tmp/pm \\
        --const '{"photometric.SHADE_FIELD_ORDER": 2}'

The numbers of issue 30's report (2026-12-02) were taken this way.
"""

from __future__ import annotations

import argparse
import importlib
import json


def _constants(consts: dict) -> None:
    for key, value in consts.items():
        mod, name = key.rsplit(".", 1)
        m = importlib.import_module("myoface.analysis." + mod)
        if not hasattr(m, name):
            raise SystemExit(f"myoface.analysis.{mod} has no {name}")
        setattr(m, name, tuple(value) if isinstance(value, list) else value)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mode", choices=("warp", "video"))
    ap.add_argument("--set", default="{}", help="FitSettings fields (JSON)")
    ap.add_argument("--const", default="{}", help="module constants (JSON)")
    ap.add_argument("--moving", action="store_true", help="warp: with fake head motion")
    ap.add_argument("--look", action="store_true", help="warp: with the expressions' look")
    ap.add_argument("--expressions", default="happiness,surprise")
    ap.add_argument("--video", default=None, help="video: default the sample video")
    ap.add_argument("--out", default="photometric_ablation_out")
    a = ap.parse_args(argv)
    fs, consts = json.loads(a.set), json.loads(a.const)
    _constants(consts)
    if a.mode == "warp":
        from dataclasses import replace

        from myoface.analysis.weights import FitSettings
        from myoface.bench.knownwarp import run_known_warp

        s = replace(FitSettings(), **{"photometric": True, **fs})
        exprs = tuple(a.expressions.split(","))
        r = run_known_warp(a.moving, False, s, look=a.look, expressions=exprs)
        regions = " ".join(
            f"{k} {v['gain']:.2f}/{v['explained']:.2f}" for k, v in r["regions"].items()
        )
        print(
            f"warp {'moving' if a.moving else 'still'} {'look' if a.look else 'plain'} "
            f"{exprs} {fs} {consts}: {regions} leak {r['leak']:.3f}"
        )
        return
    import myoface.analysis.pipeline as pipeline
    from myoface.analysis.sample import fetch_sample_video
    from myoface.analysis.weights import FitSettings
    from myoface.cli import main as cli

    def settings(**kw):
        return FitSettings(**{**kw, **fs})

    pipeline.FitSettings = settings  # (the pipeline makes the fit's settings with it)
    video = a.video or str(fetch_sample_video(quiet=True))
    args = ["analyze", video, "--report", "-o", a.out, "--quiet"]
    if fs.get("photometric", True):
        args.insert(2, "--photometric")
    try:
        cli(args)
    except SystemExit as exc:
        if exc.code:
            raise
    d = json.load(open(f"{a.out}/fidelity.json"))
    regions = " ".join(f"{k} {v['explained']:.2f}/{v['gain']:.2f}" for k, v in d["regions"].items())
    print(f"video {fs} {consts}: fidelity {d['overall']['explained']:.3f} ({regions})")


if __name__ == "__main__":
    main()
