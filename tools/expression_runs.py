"""Cache the fitted readings of synthetic expression clips, to try the expression rule on them
without refitting (:mod:`myoface.bench.expression` runs one of them end to end; the others are
held out: other orders, intensities, faces and phases of the head's loop).

    python tools/expression_runs.py OUTDIR [RUN ...] [--points]

Each run is saved as ``OUTDIR/RUN.npz``: the fitted contractions (``estimate``), the true ones
(``truth``), the fit's and the true head angles, and per frame the played expression, its
phase and intensity. Runs (all with the head moving along the benchmark's loop unless said):

- ``bench``: the benchmark's clip (its episodes, the person's face from single_face.mp4).
- ``heldp``: the person's face, another order, intensities 0.6-0.9 (camera seed 1).
- ``p2``: the person's face, a third order, intensities 0.5-1.0, the head's loop started a
  third of the way round (other poses meet each expression; camera seed 2).

``bench``, ``heldp`` and ``p2`` are the benchmark's three clips
(:data:`myoface.bench.expression.CLIPS`, since 2026-12-06; before, ``heldp`` and ``p2`` had
the camera's seed 0).
- ``held``: the default face (not the person's), ``heldp``'s episodes.
- ``small``: the person's face, the head's loop at 0.5 of its amplitude, longer apexes.
- ``still``: the benchmark's clip with the head still.
- ``exact``: the benchmark's clip with the fit given the model's own projected vertices.

Every run but ``exact`` is fitted as the benchmark fits (the default analysis: MediaPipe's
points and the photometric term, :class:`~myoface.analysis.weights.FitSettings`); with
``--points``, on MediaPipe's points alone (until 2026-12-05 the tool fitted every run so,
also after the photometric fit became the default).

About a minute a run on a loaded 2-core machine.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np


def trajectory(n, phase=0.0, amplitude=1.0):
    """The benchmark's head loop (headmotion.head_trajectory), started ``phase`` of the way
    round and scaled by ``amplitude``."""
    from myoface.bench.headmotion import head_trajectory

    return head_trajectory(n, phase=phase, amplitude=amplitude)


def face_model(face: str):
    """The face a run plays on: ``"default"`` the bundled face's model, else the head-motion
    benchmark's personal face (from the sample video's photo)."""
    if face == "default":
        from myoface.face import load_default_face
        from myoface.model import build_face_model

        return build_face_model(load_default_face())
    from myoface.bench import headmotion as hm

    return hm._model()


def save_run(path: Path, fm, res, truth, played, ph, intensity) -> None:
    """One run's fit beside its truth, as ``tools/expression_ceiling.py`` and
    ``tools/expression_trackers.py score`` read it."""
    np.savez(
        path,
        ids=np.array(fm.ids),
        estimate=res.estimate,
        truth=truth,
        angles_est=res.angles_est,
        angles_true=res.angles_true,
        played=np.array(played),
        phase=np.array(ph),
        intensity=np.array(intensity),
    )


def run(name: str, out: Path) -> None:
    from dataclasses import replace

    from myoface.bench import headmotion as hm
    from myoface.bench.expression import (
        CLIPS,
        EPISODES,
        HELDP,
        P2,
        PHASES,
        _intensities,
        episode_programme,
    )
    from myoface.render.degrade import CameraDegradation

    episodes, phases, face, still, exact = EPISODES, PHASES, "person", False, False
    phase, amp, seed = 0.0, 1.0, 0
    if name in CLIPS:  # (the benchmark's clips, as it plays them)
        episodes, phase, seed = CLIPS[name]
    elif name == "held":
        episodes, face = HELDP, "default"
    elif name == "small":
        episodes, amp, phases = P2, 0.5, (20, 6, 12, 6, 12)
    elif name == "still":
        still = True
    elif name == "exact":
        exact = True
    elif name != "bench":
        raise SystemExit(f"unknown run {name}")
    fm = face_model(face)
    truth, played, ph = episode_programme(fm.ids, episodes, phases)
    inten = _intensities(episodes, phases)
    poses = hm.head_trajectory(len(truth), True) if still else trajectory(len(truth), phase, amp)
    skins = hm.relaxed_skins(fm, truth)
    settings, frames = None, None
    if exact:
        from myoface.bench.expression import model_landmarks

        points = model_landmarks(poses, skins)
    else:
        frames, _ = hm.degraded_sequence(
            fm.face, poses, skins, replace(CameraDegradation(), seed=seed)
        )
        points, _ = hm.detect_sequence(frames)
        if not POINTS_ONLY:
            from myoface.analysis.weights import FitSettings

            settings = FitSettings()  # (the default analysis': its photometric term)
        else:
            frames = None
    res = hm.run_headmotion(fm, points, truth, poses, skins, settings=settings, frames=frames)
    save_run(out / f"{name}.npz", fm, res, truth, played, ph, inten)
    print(name, "saved", flush=True)


#: the runs fitted on MediaPipe's points alone (``--points``), as the tool did before the
#: photometric fit was the default (2026-12-05): the default analysis' fit otherwise
POINTS_ONLY = False


def main() -> None:
    global POINTS_ONLY
    if "--points" in sys.argv:
        sys.argv.remove("--points")
        POINTS_ONLY = True
    out = Path(sys.argv[1])
    out.mkdir(parents=True, exist_ok=True)
    for name in sys.argv[2:] or ["bench", "heldp", "p2", "held", "small", "still", "exact"]:
        run(name, out)


if __name__ == "__main__":
    main()
