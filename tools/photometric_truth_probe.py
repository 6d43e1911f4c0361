"""Where the photometric fit's reading of a turning head as expression comes from: the pixels
at the *true* state (issue 30's stage question, asked of the image term alone).

On the head-motion benchmark's renders (:mod:`myoface.bench.headmotion`; clean by default,
``--degraded`` for the camera's), the fit is given the truth everywhere it could be wrong
before its pixels are read: the person's neutral is the model's own (the identity offset held
at 0), the appearance is taken at the calibration frame's *true* pose, and each frame's
photometric terms (brightness and redness, on their finest level) are prepared at the true
pose, contractions and skin. For each frame it prints

- each channel's residual there (RMS over the samples that weigh, in the term's sigmas): what
  the appearance model does not reproduce of a frame whose geometry is exactly right;
- the **pull**: the skin's motion (RMS over the vertices, mm) of one Gauss-Newton solve of
  the pixels alone from the truth, with the head held at its true pose, and with it free:
  how far the pixels on their own would move the face from the truth.

A small residual with a large pull means the muscles' directions the pixels hardly see
amplify it (the priors and MediaPipe's weak term then decide); a large residual means the
appearance model is the limit. ``--lights one`` renders with the key light only and no
highlight, ``--lights flat`` with ambient light alone (no shading at all), to tell the
shading model from the geometry.

    PYTHONPATH=src python tools/photometric_truth_probe.py [--degraded] [--still]
        [--lights default|one|flat] [--frames 2,4,30,74]

Measured 2026-12-05 (head moving; the turn is from the calibration frame's pose): the
residual 0.19-0.35 sigma at 3-7 degrees of turn and 0.75-0.85 at 25-40; the pull with the head
held 0.17-0.44 mm at 3-7 degrees, 0.7-1.4 mm beyond 25; RMS over the clip's 89 frames 0.91 mm
(clean), 1.50 (``--degraded``), 1.02 (``--lights one``), 0.64 (``--lights flat``): the
shading model holds a third of it, the rest is there without any light. The photometric
module's docstring has what was tried on it.
"""

from __future__ import annotations

import argparse

import numpy as np


def _lights(kind: str) -> None:
    """Render the benchmark's frames with other lights (before anything is rendered)."""
    import myoface.render.renderer as rr

    if kind == "default":
        return
    base_lights = rr.default_lights
    init = rr.Renderer.__init__

    def patched(self, *a, **k):
        init(self, *a, **k)
        if kind == "one":
            self.material = rr.SkinMaterial(specular=0.0)
        else:
            self.material = rr.SkinMaterial(specular=0.0, ambient=(1.0, 1.0, 1.0))

    rr.Renderer.__init__ = patched
    if kind == "one":
        rr.default_lights = lambda: base_lights()[:1]
    else:
        rr.default_lights = lambda: [rr.Light((0.0, 0.0, 1.0), (1.0, 1.0, 1.0), 0.0)]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--degraded", action="store_true", help="the camera's renders (default: clean)")
    ap.add_argument("--still", action="store_true", help="the head still (default: moving)")
    ap.add_argument("--lights", choices=("default", "one", "flat"), default="default")
    ap.add_argument("--frames", default="", help="comma-separated frame numbers (default: all)")
    args = ap.parse_args(argv)
    _lights(args.lights)

    from myoface.analysis.camera import PinholeCamera
    from myoface.analysis.modelfit import CALIBRATION_WINDOW_S, ModelFit
    from myoface.analysis.terms import Estimate
    from myoface.analysis.weights import FitSettings
    from myoface.bench import headmotion as hm

    fm, truth, poses, skins, points, _ = hm._sequence(False, args.still, False, args.degraded)
    frames = hm._frames(False, args.still, args.degraded)
    cam = PinholeCamera.for_image(hm.SIZE[0], hm.SIZE[1], hm.FOV_DEG)
    fit = ModelFit(fm, cam, FitSettings(photometric=True), fps=30.0)
    fit.calibrate(points[: int(round(CALIBRATION_WINDOW_S * 30.0))])
    fit.identity_mm[:] = 0.0  # (the model's own neutral: the truth)
    fit._take_appearance(frames[0], poses[0])  # (at the calibration frame's true pose)
    jac = np.ascontiguousarray(fit.response)
    m = jac.shape[2]
    free = np.arange(m)
    picked = [int(k) for k in args.frames.split(",") if k] or range(1, len(truth))

    def skin_rms(dc):
        return float(np.sqrt(((jac @ dc) ** 2).sum(1).mean()))

    print(f"{'frame':>5s} {'turn':>5s} {'active':>6s} {'resid grey':>10s} {'redness':>8s} "
          f"{'pull held':>9s} {'pull free':>9s}  (sigmas; mm)")  # fmt: skip
    pulls, turns = [], []
    r0 = poses[0].rotation
    for k in picked:
        est = Estimate(poses[k], truth[k].copy(), skins[k], jac, free)
        h = b = None
        resid = {}
        for t in fit.photometric_term(frames[k]):
            while t.settling:  # (the finest level: where the fit's answer is made)
                t.advance()
            t.prepare(est)
            _, res, _ = t._rows(est)
            resid[t.channel] = float(np.sqrt(np.mean(res**2))) if len(res) else float("nan")
            hh, bb = t.normal_equations(est)
            h, b = (hh, bb) if h is None else (h + hh, b + bb)
        held = np.linalg.solve(h[6:, 6:] + 1e-6 * np.eye(m), b[6:])
        full = np.linalg.solve(h + 1e-6 * np.eye(len(b)), b)
        rel = poses[k].rotation @ r0.T
        turn = float(np.degrees(np.arccos(np.clip((np.trace(rel) - 1) / 2, -1, 1))))
        pulls.append(skin_rms(held))
        turns.append(turn)
        print(f"{k:5d} {turn:5.1f} {truth[k].max():6.2f} {resid.get('grey', np.nan):10.3f} "
              f"{resid.get('redness', np.nan):8.3f} {pulls[-1]:9.3f} {skin_rms(full[6:]):9.3f}")  # fmt: skip
    pulls, turns = np.array(pulls), np.array(turns)
    print(
        f"pull with the head held: RMS {np.sqrt(np.mean(pulls**2)):.3f} mm over "
        f"{len(pulls)} frames; correlation with the turn {np.corrcoef(pulls, turns)[0, 1]:+.2f}"
    )


if __name__ == "__main__":
    main()
