"""The photometric fit's settings tried on the known answers and on a real video (issue 30).

Two modes, each with the fit's settings overridden (``--set``: FitSettings fields, JSON) and
module constants (``--const``: ``module.NAME`` under ``myoface.analysis``, JSON; e.g.
``{"photometric.MOUTH_RIM_WEIGHT": 1.0}``):

- ``warp``: the known-warp clips (:func:`myoface.bench.knownwarp.run_known_warp`, the
  photometric fit unless ``--set '{"photometric": false}'``), head still or moving, plain or
  with the look the expressions add (``--look``), some expressions (``--expressions``):
  prints each region's gain / explained and the leak;
- ``video``: ``myoface analyze VIDEO --photometric --report`` into ``--out`` with the same
  overrides: prints the validated fidelity per region (explained / gain);
- ``headmotion``: the head-motion renders (:func:`myoface.bench.headmotion.run_headmotion`,
  the benchmark's clip), head moving unless ``--still``, degraded by the camera unless
  ``--clean``: prints the benchmark's summary (worst and median RMSE, worst correlation,
  the paper's muscles' median and least gain, skin mm, its rest and expression frames apart,
  head deg and its mean error yaw / pitch / roll) and the appearance's parallax turn
  (``modelfit.PARALLAX_REFINE``). ``--only
  PARTS``: the camera's degradation with only these of its parts (comma-separated among
  :data:`PARTS`: ``texture``, ``light``, ``background``, ``blur``, ``noise``, ``h264``;
  ``none``: the renders as drawn); ``--points-from clean``: MediaPipe's points read on the
  renders as drawn while the fit's pixels are the degraded frames (which of the two, the
  points or the pixels, a degradation costs); ``--table``: every muscle's RMSE,
  correlation and gain; ``--specular S``: the renders' skin with a specular lobe of
  strength ``S`` (the renderer's default 0.10; 0, a matte skin, what the fit's Lambertian
  light models); ``--identity exact``: the calibration's identity offset zero (an oracle:
  the rendered face is the fitted model, so its neutral is the truth's);
- ``expression``: the expression benchmark's synthetic clip (:func:`myoface.bench.expression.
  _synthetic`, the default analysis with the overrides; ``--clip NAME`` another of
  :data:`~myoface.bench.expression.CLIPS`, ``--clip all`` each and their pool, as the benchmark
  pools them): prints the apex and rest accuracy and the contractions' median RMSE;
  ``--only PARTS``, ``--specular`` and ``--identity`` as for ``headmotion`` (the clips
  rendered and degraded afresh).

    python tools/photometric_ablation.py warp --look --expressions happiness \\
        --set '{"photo_landmark_weight": 0.01}'
    python tools/photometric_ablation.py video --out /tmp/pm \\
        --const '{"photometric.SHADE_FIELD_ORDER": 2}'
    python tools/photometric_ablation.py headmotion --const '{"modelfit.PARALLAX_REFINE": false}'
    python tools/photometric_ablation.py headmotion --only background --points-from clean
    python tools/photometric_ablation.py expression --set '{"photo_rate_per_s": 4.0}'
    python tools/photometric_ablation.py expression --clip all --only texture,light,noise
    python tools/photometric_ablation.py headmotion --clean --specular 0 \\
        --set '{"photo_model_error": 0.0}'
    python tools/photometric_ablation.py expression --clip all --identity exact

The numbers of issue 30's report (2026-12-02) were taken this way.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import importlib
import json

#: the camera's degradation by parts (``headmotion --only``): each part's fields of
#: :class:`~myoface.render.degrade.CameraDegradation` as its defaults have them; a part left
#: out takes the values in ``OFF``; ``texture`` is the renders' texture at
#: :data:`~myoface.bench.headmotion.TEXTURE_FACTOR` of its resolution
PARTS = {
    "texture": (),
    "light": ("light_amplitude", "exposure_drift"),
    "background": ("background",),
    "blur": ("blur_sigma_px",),
    "noise": ("full_scale_electrons", "read_noise_electrons"),
    "h264": ("crf",),
}
OFF = {
    "light_amplitude": 0.0, "exposure_drift": 0.0, "background": False, "blur_sigma_px": 0.0,
    "full_scale_electrons": None, "read_noise_electrons": 0.0, "crf": None,
}  # fmt: skip


def _constants(consts: dict) -> None:
    for key, value in consts.items():
        mod, name = key.rsplit(".", 1)
        m = importlib.import_module("myoface.analysis." + mod)
        if not hasattr(m, name):
            raise SystemExit(f"myoface.analysis.{mod} has no {name}")
        setattr(m, name, tuple(value) if isinstance(value, list) else value)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mode", choices=("warp", "video", "headmotion", "expression"))
    ap.add_argument("--set", default="{}", help="FitSettings fields (JSON)")
    ap.add_argument("--const", default="{}", help="module constants (JSON)")
    ap.add_argument("--moving", action="store_true", help="warp: with fake head motion")
    ap.add_argument("--still", action="store_true", help="headmotion: the head still")
    ap.add_argument("--clean", action="store_true", help="headmotion: the renderer's frames")
    ap.add_argument(
        "--only", default=None, help="headmotion, expression: the camera's parts kept (PARTS)"
    )
    ap.add_argument(
        "--clip",
        default="bench",
        help="expression: a clip of myoface.bench.expression.CLIPS, or all",
    )
    ap.add_argument(
        "--points-from",
        default="same",
        choices=("same", "clean"),
        help="headmotion: MediaPipe on the degraded frames or the clean renders",
    )
    ap.add_argument("--table", action="store_true", help="headmotion: every muscle's numbers")
    ap.add_argument(
        "--specular",
        type=float,
        default=None,
        help="headmotion, expression: the renders' specular strength (SkinMaterial.specular)",
    )
    ap.add_argument(
        "--identity",
        default="fitted",
        choices=("fitted", "exact"),
        help="headmotion, expression: exact, the person's neutral the model's own (an oracle)",
    )
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
    only = None if a.only is None else tuple(p for p in a.only.split(",") if p != "none")
    if only is not None and set(only) - set(PARTS):
        raise SystemExit(f"--only takes some of {', '.join(PARTS)} or none; got {a.only}")
    if a.mode in ("headmotion", "expression"):
        # (the renders' and the calibration's overrides printed with the constants)
        if a.specular is not None:
            consts = {**consts, "specular": a.specular}
        if a.identity != "fitted":
            consts = {**consts, "identity": a.identity}
        with _specular(a.specular), _identity(a.identity):
            if a.mode == "expression":
                _expression(a.clip, fs, consts, only)
                return
            if only is not None and a.clean:
                raise SystemExit("--only and --clean: --clean is --only none")
            _headmotion(a.still, not a.clean, fs, consts, only, a.points_from, a.table)
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


@contextlib.contextmanager
def _specular(strength: float | None):
    """The renders' skin with a specular lobe of ``strength`` (the renderer's
    :class:`~myoface.render.renderer.SkinMaterial` default, 0.10, unless given) while in the
    context: how much of what the fit reads as the turning head's look is the highlight's,
    which its Lambertian light does not model."""
    from myoface.render.renderer import SkinMaterial

    if strength is None:
        yield
        return
    names = [f.name for f in dataclasses.fields(SkinMaterial)]
    before = SkinMaterial.__init__.__defaults__
    after = list(before)
    after[names.index("specular") - (len(names) - len(before))] = float(strength)
    SkinMaterial.__init__.__defaults__ = tuple(after)
    try:
        yield
    finally:
        SkinMaterial.__init__.__defaults__ = before


@contextlib.contextmanager
def _identity(kind: str):
    """``exact``: the calibration's identity offset replaced by zero, the poses fitted again
    on the model's own neutral (an oracle: the benchmarks' rendered face is the fitted model,
    so its neutral is the truth's), while in the context; ``fitted``: unchanged."""
    import numpy as np

    from myoface.analysis.modelfit import ModelFit

    if kind == "fitted":
        yield
        return
    fitted = ModelFit._fit_identity

    def exact(self, frames):
        ident, poses, resid = fitted(self, frames)
        poses = [self._pose_only(p, q, self.neutral) for p, q in zip(frames, poses, strict=True)]
        return np.zeros_like(ident), poses, resid

    ModelFit._fit_identity = exact
    try:
        yield
    finally:
        ModelFit._fit_identity = fitted


def _parts_off(only: tuple) -> dict:
    """The fields of :class:`~myoface.render.degrade.CameraDegradation` that turn off every
    part of :data:`PARTS` but ``only`` (their values in :data:`OFF`; the parts kept take
    the class's defaults, or what they are given)."""
    kept = {f for p in only for f in PARTS[p]}
    return {f: v for f, v in OFF.items() if f not in kept}


@contextlib.contextmanager
def _camera_parts(only: tuple | None):
    """The benchmarks' camera (:mod:`myoface.render.degrade`, as
    :func:`myoface.bench.headmotion.degraded_sequence` applies it) with only ``only`` of its
    :data:`PARTS` while in the context (None: all of them, unchanged)."""
    import myoface.bench.headmotion as hm
    import myoface.render.degrade as degrade

    if only is None:
        yield
        return
    whole, sequence = degrade.CameraDegradation, hm.degraded_sequence
    off = _parts_off(only)

    class Partial(whole):
        # (dataclasses.replace makes its copies through __init__: the parts kept take what
        # they are given there, e.g. the H.264 round trip's crf=None, the others stay off)
        def __init__(self, *args, **kw):
            super().__init__(*args, **kw)
            for f, v in off.items():
                object.__setattr__(self, f, v)

    def partial_sequence(face, poses, skins, degradation=None, texture_factor=None):
        factor = hm.TEXTURE_FACTOR if "texture" in only else None
        return sequence(face, poses, skins, degradation, texture_factor=factor)

    degrade.CameraDegradation, hm.degraded_sequence = Partial, partial_sequence
    try:
        yield
    finally:
        degrade.CameraDegradation, hm.degraded_sequence = whole, sequence


def _expression(clip: str, fs: dict, consts: dict, only) -> None:
    from myoface.bench.expression import CLIPS, _synthetic

    names = list(CLIPS) if clip == "all" else [clip]
    if set(names) - set(CLIPS):
        raise SystemExit(f"--clip takes one of {', '.join(CLIPS)} or all; got {clip}")
    camera = "" if only is None else f" only {only}"
    apex = rest = n_apex = n_rest = 0
    with _camera_parts(only):
        for name in names:
            r = _synthetic(False, overrides=tuple(fs.items()), clip=name)
            print(
                f"expression {name}{camera} {fs} {consts}: apex {r['apex_accuracy']:.3f} rest "
                f"{r['rest_accuracy']:.3f} median RMSE {r['contraction_rmse_median']:.4f}",
                flush=True,
            )
            apex += r["apex_accuracy"] * r["apex_frames"]
            rest += r["rest_accuracy"] * r["rest_frames"]
            n_apex, n_rest = n_apex + r["apex_frames"], n_rest + r["rest_frames"]
    if len(names) > 1:
        print(f"expression pooled{camera} {fs} {consts}: apex {apex / n_apex:.3f} "
              f"rest {rest / n_rest:.3f}")  # fmt: skip


def _camera_frames(still: bool, only: tuple):
    """The head-motion clip's frames degraded by ``only`` of the camera's :data:`PARTS`."""
    from myoface.bench import headmotion as hm

    fm = hm._model()
    truth, poses, skins = hm._truth(False, still)
    with _camera_parts(only):
        return hm.degraded_sequence(fm.face, poses, skins)[0]


def _headmotion(still: bool, degraded: bool, fs: dict, consts: dict, only=None,
                points_from: str = "same", table: bool = False) -> None:  # fmt: skip
    import numpy as np

    from myoface.analysis import modelfit
    from myoface.analysis.weights import FitSettings
    from myoface.bench import headmotion as hm

    if only is not None:
        fm, truth, poses, skins, _, _ = hm._sequence(False, still, False, False)
        frames = _camera_frames(still, only)
        points = hm.detect_sequence(frames)[0]
    else:
        fm, truth, poses, skins, points, _ = hm._sequence(False, still, False, degraded)
        frames = hm._frames(False, still, degraded)
    if points_from == "clean":
        points = hm._sequence(False, still, False, False)[4]
    turned = {}
    take = modelfit.ModelFit.set_appearance

    def kept(fit, *args, **kw):  # (the calibration's record of the parallax)
        take(fit, *args, **kw)
        turned.update(fit.calibration.extra.get("appearance_parallax") or {})

    modelfit.ModelFit.set_appearance = kept
    try:
        s = FitSettings(**{"photometric": True, **fs})
        r = hm.run_headmotion(fm, points, truth, poses, skins, settings=s, frames=frames)
    finally:
        modelfit.ModelFit.set_appearance = take
    m = r.summary()
    ok = np.isfinite(r.estimate).all(axis=1)
    act = truth.max(axis=1) > 0.05
    skin = r.skin_rms_mm

    def rms(sel):
        return float(np.sqrt(np.nanmean(skin[ok & sel] ** 2)))

    camera = ("degraded" if degraded else "clean") if only is None else f"only {only}"
    if points_from == "clean":
        camera += ", MediaPipe on the clean renders"
    print(
        f"headmotion {'still' if still else 'moving'} {camera} "
        f"{fs} {consts}: worst {m['rmse_worst']:.3f} median {m['rmse_median_all']:.3f} "
        f"corr {m['corr_worst']:.2f} gain {m['gain_median']:.2f} (least {m['gain_least']:.2f}) "
        f"skin {m['skin_mm']:.3f} mm (rest {rms(~act):.3f}, "
        f"expressions {rms(act):.3f}) head {m['pose_deg']:.3f} deg (mean error "
        f"{m['pose_err_mean_deg']}); parallax turn {turned.get('rotation_deg')}"
    )
    if table:
        print(r.table())


if __name__ == "__main__":
    main()
