"""The expression rule on held-out synthetic clips, per tracker and with or without the fit's
AU-space prior (docs/expression_readings.md): what the better trackers and the prior give
on clips that are not the benchmark's.

    python tools/expression_trackers.py fit OUTDIR [RUN ...]   # render, detect, fit, cache
    python tools/expression_trackers.py score OUTDIR             # apex / rest per run

``fit`` renders each run of ``tools/expression_runs.py`` (``bench``, ``heldp``, ``p2``,
``held``, ``small``; the head moving, the camera's degradation), reads it with MediaPipe
once, then fits it six ways (the default fit, the anchored flow ``--flow``, the photometric
term ``--photometric``; each without and with ``FitSettings(au_prior_sigma=0.1)``) and saves
``OUTDIR/RUN_TRACKER_PRIOR.npz`` (the arrays of ``tools/expression_runs.py``). About 6-10
minutes a run on a loaded 2-core machine. ``score`` labels every cached fit as
contractions.csv does (:func:`~myoface.analysis.expressions.expression_sequence`) and prints
apex / rest (%) per run, and the held-out runs' means (every run but ``bench``).
"""

from __future__ import annotations

import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

TRACKERS = ("fit", "flow", "photometric")
PRIORS = (None, 0.1)
RUNS = ("bench", "heldp", "p2", "held", "small")


def fit(out: Path, names) -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import expression_runs as er

    from myoface.analysis.weights import FitSettings
    from myoface.bench import headmotion as hm
    from myoface.bench.expression import EPISODES, PHASES, _intensities, episode_programme

    for name in names:
        episodes, phases, face, phase, amp = EPISODES, PHASES, "person", 0.0, 1.0
        if name == "heldp":
            episodes = er.HELDP
        elif name == "p2":
            episodes, phase = er.P2, 1 / 3
        elif name == "held":
            episodes, face = er.HELDP, "default"
        elif name == "small":
            episodes, amp, phases = er.P2, 0.5, (20, 6, 12, 6, 12)
        elif name != "bench":
            raise SystemExit(f"unknown run {name}")
        fm = er.face_model(face)
        truth, played, ph = episode_programme(fm.ids, episodes, phases)
        poses = (
            hm.head_trajectory(len(truth), False)
            if name == "bench"
            else er.trajectory(len(truth), phase, amp)
        )
        skins = hm.relaxed_skins(fm, truth)
        frames, _ = hm.degraded_sequence(fm.face, poses, skins)
        points, _ = hm.detect_sequence(frames)
        for tracker in TRACKERS:
            for prior in PRIORS:
                t0 = time.time()
                settings = FitSettings(photometric=tracker == "photometric", au_prior_sigma=prior)
                res = hm.run_headmotion(
                    fm, points, truth, poses, skins, settings=settings,
                    frames=frames if tracker != "fit" else None,
                    anchored_flow=tracker == "flow",
                )  # fmt: skip
                er.save_run(
                    out / f"{name}_{tracker}_{prior}.npz", fm, res, truth, played, ph,
                    _intensities(episodes, phases),
                )  # fmt: skip
                print(name, tracker, prior, f"{time.time() - t0:.0f} s", flush=True)
        del frames


def _cell(ar) -> str:
    return f"{100 * ar[0]:3.0f}/{100 * ar[1]:3.0f}"


def score(out: Path) -> None:
    from myoface.analysis.expressions import expression_sequence
    from myoface.bench.expression import score_labels

    rows: dict = defaultdict(dict)
    for f in sorted(out.glob("*.npz")):
        run, tracker, prior = f.stem.split("_")
        d = dict(np.load(f))
        ids = [str(i) for i in d["ids"]]
        _, labels = expression_sequence(d["estimate"], ids, d["angles_est"])
        s = score_labels(labels, list(d["played"]), list(d["phase"]))
        rows[f"{tracker}, prior {prior}"][run] = (s["apex_accuracy"], s["rest_accuracy"])
    print(
        f"{'variant':24s}" + "".join(f"{r:>10s}" for r in RUNS) + "   held out: apex / rest (lower)"
    )
    for k in sorted(rows):
        v = rows[k]
        held = [v[r] for r in RUNS[1:] if r in v]
        cells = "".join(f"{_cell(v[r]) if r in v else '-':>10s}" for r in RUNS)
        mean = (
            f"{100 * np.mean([a for a, _ in held]):.0f} / {100 * np.mean([b for _, b in held]):.0f}"
            f" ({100 * np.mean([min(a, b) for a, b in held]):.0f}), {len(held)} runs"
            if held
            else "-"
        )
        print(f"{k:24s}{cells}   {mean}")


def main() -> None:
    if len(sys.argv) < 3 or sys.argv[1] not in ("fit", "score"):
        raise SystemExit(__doc__)
    out = Path(sys.argv[2])
    out.mkdir(parents=True, exist_ok=True)
    if sys.argv[1] == "fit":
        fit(out, sys.argv[3:] or RUNS)
    else:
        score(out)


if __name__ == "__main__":
    main()
