"""The fit's point trackers side by side on a real video, in one run (issue 30): the default
analysis (MediaPipe's points), ``--flow`` with the model-anchored tracker
(:mod:`myoface.analysis.modelflow`) and with the chained flow
(:class:`~myoface.analysis.flow.FlowRefiner`, ``FitTracker(flow_method="chained")``).

- ``fidelity``: each analysis of VIDEO (default: the sample, ``single_face.mp4``) judged by
  the validated fidelity (:func:`myoface.analysis.fidelity.write_fidelity_report`, DIS flow
  from the calibration frame; not the fit's reader): overall and per region explained / gain;
- ``fps``: each analysis' frames a second (decode included, no output files, as
  ``analysis.fps`` runs it) and MediaPipe's alone, the repeats interleaved so that the
  machine's load falls on all alike; the median, the ratio to MediaPipe, process CPU a frame.

    python tools/flow_compare.py fidelity
    python tools/flow_compare.py fps --repeats 5

``--set`` overrides :class:`~myoface.analysis.modelflow.ModelFlow`'s parameters (JSON), e.g.
``--set '{"levels": 0}'``; ``--variant NAME=JSON`` adds a kind NAME, the anchored tracker
with those parameters (and ``"lag"``: :data:`~myoface.analysis.modelflow.PREDICTION_LAG`),
to compare settings in one run (``--kinds default,anchored,NAME``), e.g. ``--variant
'lag1={"lag": 1}'``. The numbers of issue 30's report on the anchored tracker
(2026-12-02) were taken this way.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

KINDS = ("default", "anchored", "chained")


#: ModelFlow's parameters over its defaults: ``--set`` (every anchored kind) and each
#: ``--variant NAME=JSON``'s (the kind NAME, the anchored tracker with those)
_PARAMS: dict = {"": {}}
_LAG: dict = {}


def _overrides(params: dict) -> None:
    from myoface.analysis import modelflow

    _PARAMS[""] = dict(params)
    _PARAMS["active"] = dict(params)
    init = modelflow.ModelFlow.__init__

    def patched(self, **kw):
        init(self, **{**kw, **_PARAMS["active"]})

    modelflow.ModelFlow.__init__ = patched


def _method(kind: str) -> str:
    """The point tracker of ``kind`` (a variant's: the anchored), and its parameters set
    (``"lag"``: :data:`~myoface.analysis.modelflow.PREDICTION_LAG`, the fit's frame the
    tracking predicts from, k - lag)."""
    from myoface.analysis import modelflow

    params = {**_PARAMS[""], **_PARAMS.get(kind, {})}
    _LAG.setdefault("default", modelflow.PREDICTION_LAG)
    modelflow.PREDICTION_LAG = int(params.pop("lag", _LAG["default"]))
    _PARAMS["active"] = params
    return "anchored" if kind in _PARAMS else kind


def _analyzer(model, video, kind: str):
    from myoface.analysis import modelflow
    from myoface.analysis.pipeline import make_analyzer

    if kind != "default":
        modelflow.FLOW_METHOD = _method(kind)
    return make_analyzer(model, video, "landmarks", calibration_frame=None, flow=kind != "default")


def fidelity(path, kinds) -> None:
    from myoface.analysis import modelflow
    from myoface.analysis.fidelity import write_fidelity_report
    from myoface.analysis.outputs import analyze_to_folder
    from myoface.model import build_face_model

    model = build_face_model()
    for kind in kinds:
        if kind != "default":
            modelflow.FLOW_METHOD = _method(kind)
        with tempfile.TemporaryDirectory() as tmp:
            res = analyze_to_folder(
                path, Path(tmp) / "a", model=model, tracker="landmarks", flow=kind != "default"
            )
            fid = write_fidelity_report(res.folder, path, mediapipe_on_both=False)
        regs = " ".join(f"{k} {r.explained:.3f}/{r.gain:.2f}" for k, r in fid.regions.items())
        print(f"{kind:9s} fidelity {fid.overall.explained:.4f} (gain {fid.overall.gain:.3f}) | "
              f"{regs}", flush=True)  # fmt: skip


def fps(path, kinds, repeats: int) -> None:
    from myoface.analysis.pipeline import measure_frames
    from myoface.analysis.video import open_video
    from myoface.facemesh import FaceMeshDetector
    from myoface.model import build_face_model

    model = build_face_model()

    def run(kind):
        video = open_video(path)
        t0, c0 = time.perf_counter(), time.process_time()
        an, first = _analyzer(model, video, kind)
        try:
            n = sum(1 for _ in measure_frames(video, an, first, None))
        finally:
            an.close()
        return n, time.perf_counter() - t0, time.process_time() - c0

    def mediapipe():
        n = 0
        t0, c0 = time.perf_counter(), time.process_time()
        with FaceMeshDetector(video=True) as det:
            for frame in open_video(path):
                det.detect(frame)
                n += 1
        return n, time.perf_counter() - t0, time.process_time() - c0

    for kind in kinds:  # the warm-up: compiles, sets the model up, fills the file cache
        run(kind)
    mediapipe()
    got = {k: [] for k in (*kinds, "mediapipe")}
    for _ in range(repeats):
        for kind in kinds:
            got[kind].append(run(kind))
        got["mediapipe"].append(mediapipe())
    mp = float(np.median([n / w for n, w, _ in got["mediapipe"]]))
    for kind, runs in got.items():
        f = float(np.median([n / w for n, w, _ in runs]))
        cpu = float(np.median([1e3 * c / n for n, _, c in runs]))
        print(f"{kind:9s} {f:6.1f} frames/s, {f / mp:.3f}x MediaPipe, process CPU {cpu:.1f} ms "
              "a frame", flush=True)  # fmt: skip


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mode", choices=("fidelity", "fps"))
    ap.add_argument("video", nargs="?", default=None, help="default: the sample video")
    ap.add_argument("--kinds", default=",".join(KINDS), help=f"some of {','.join(KINDS)}")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--set", default="{}", help="ModelFlow's parameters, JSON")
    ap.add_argument("--variant", action="append", default=[], metavar="NAME=JSON",
                    help="a kind NAME: the anchored tracker with these parameters (repeatable; "
                    "list NAME in --kinds)")  # fmt: skip
    args = ap.parse_args(argv)
    _overrides(json.loads(args.set))
    for v in args.variant:
        name, _, params = v.partition("=")
        _PARAMS[name] = json.loads(params or "{}")
    path = args.video
    if path is None:
        from myoface.analysis.sample import fetch_sample_video

        path = fetch_sample_video(quiet=True)
    kinds = [k for k in args.kinds.split(",") if k]
    if args.mode == "fidelity":
        fidelity(path, kinds)
    else:
        fps(path, kinds, args.repeats)


if __name__ == "__main__":
    main()
