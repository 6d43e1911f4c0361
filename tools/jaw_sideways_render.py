"""Does the 3-D fit read a sideways jaw it is given? The head-motion benchmark's clip
(:mod:`myoface.bench.headmotion`: the person's face from the sample's photo, its expression
programme, the head moving, degraded as a webcam's) with a known sideways jaw added (the left
lateral pterygoid rising to 0.3 over frames 20-50, the right to 0.25 over 55-85), analysed with
``FitSettings.jaw_sideways`` on or off: prints the pterygoids' truth and estimates, their RMSE
and correlation, and the benchmark's summary.

Usage::

    PYTHONPATH=src python tools/jaw_sideways_render.py [--on] [--still] [--plain]

``--plain``: the benchmark's clip without the sideways jaw (the same programme otherwise).
"""

from __future__ import annotations

import argparse

import numpy as np

from myoface.analysis.weights import FitSettings
from myoface.bench import headmotion as H


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--on", action="store_true", help="FitSettings(jaw_sideways=True)")
    ap.add_argument("--still", action="store_true", help="the head still")
    ap.add_argument("--plain", action="store_true", help="no sideways jaw in the truth")
    a = ap.parse_args(argv)
    n = 90
    fm = H._model()
    truth, poses, _ = H.make_sequence(fm, n, a.still)
    truth = truth.copy()
    il, ir = fm.ids.index("lateral_pterygoid_l"), fm.ids.index("lateral_pterygoid_r")
    if not a.plain:
        t = np.arange(n)
        truth[:, il] = 0.3 * np.sin(np.pi * np.clip(t - 20, 0, 30) / 30)
        truth[:, ir] = 0.25 * np.sin(np.pi * np.clip(t - 55, 0, 30) / 30)
    skins = H.relaxed_skins(fm, truth)
    frames, _ = H.degraded_sequence(fm.face, poses, skins)
    points, _ = H.detect_sequence(frames)
    settings = FitSettings(jaw_sideways=a.on)
    r = H.run_headmotion(fm, points, truth, poses, skins, frames=frames, settings=settings)
    np.set_printoptions(precision=2, suppress=True, linewidth=120)
    rmse, corr = r.rmse(), r.corr()
    for j in (il, ir):
        print(f"{fm.ids[j]}: truth {truth[::6, j]}")
        print(f"{' ' * len(fm.ids[j])}  est   {r.estimate[::6, j]}")
        print(f"{' ' * len(fm.ids[j])}  RMSE {rmse[j]:.3f}, correlation {corr[j]:.2f}")
    print({k: (round(v, 3) if isinstance(v, float) else v) for k, v in r.summary().items()})


if __name__ == "__main__":
    main()
