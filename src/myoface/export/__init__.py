"""Export: a myoface animation into the tools animators use, as one binary glTF 2.0 file.

The animation (:class:`Clip`: an analysis' ``contractions.csv``, a timeline, or expressions)
is simulated by the model's own physics (:func:`simulate_clip`), the skin's motion turned into
morph targets that reproduce it (:mod:`myoface.export.morph`: one per muscle plus correctives
baked from the frames), and written with the eyes, the teeth, the tongue, the jaw, the gaze and
the head pose (:mod:`myoface.export.gltf`; units metres, +Y up)::

    from myoface.export import clip_from_csv, export_glb
    report = export_glb(model, clip_from_csv("out/contractions.csv", model), "anim.glb")
    report.max_rms_mm        # the worst frame's RMS from the simulated skin, read from the file

See docs/export.md.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from myoface.export.clip import (
    Clip,
    SimulatedClip,
    clip_from_csv,
    clip_from_expressions,
    clip_from_timeline,
    expressions_timeline,
    parse_expression,
    simulate_clip,
)
from myoface.export.gltf import GlbSkin, read_glb_skin, write_glb
from myoface.export.morph import (
    DEFAULT_TOL_MM,
    MorphAnimation,
    fit_morph_animation,
    frame_rms_mm,
    muscle_responses,
)

__all__ = [
    "DEFAULT_TOL_MM",
    "Clip",
    "ExportReport",
    "GlbSkin",
    "MorphAnimation",
    "SimulatedClip",
    "clip_from_csv",
    "clip_from_expressions",
    "clip_from_timeline",
    "export_glb",
    "expressions_timeline",
    "fit_morph_animation",
    "frame_rms_mm",
    "muscle_responses",
    "parse_expression",
    "read_glb_skin",
    "simulate_clip",
    "write_glb",
]


@dataclass(frozen=True, eq=False)
class ExportReport:
    """What :func:`export_glb` wrote and how close it is.

    Attributes
    ----------
    path : Path
    n_frames, fps : the animation's frames and rate.
    n_muscle_targets, n_corrective_targets : the skin's morph targets.
    frame_rms_mm : (T,) — each frame's skin read back from the file (float32, metres) against
        the simulated skin: the RMS over the vertices, mm.
    linear_rms_mm : (T,) — the same for the muscle targets alone (how far from linear).
    size_bytes : int — the file's size.
    sim : SimulatedClip — the simulated skin it was made from.
    animation_bytes : int — the part of the file that grows with the clip's length (the
        keyframes); the rest (meshes, morph targets, texture) does not.
    """

    path: Path
    n_frames: int
    fps: float
    n_muscle_targets: int
    n_corrective_targets: int
    frame_rms_mm: np.ndarray
    linear_rms_mm: np.ndarray
    size_bytes: int
    sim: SimulatedClip
    animation_bytes: int = 0

    @property
    def max_rms_mm(self) -> float:
        return float(self.frame_rms_mm.max())

    @property
    def duration_s(self) -> float:
        return (self.n_frames - 1) / self.fps

    @property
    def bytes_per_s(self) -> float:
        """The file's size per second of animation (a clip of one frame: per 1 / fps s)."""
        return self.size_bytes / max(self.duration_s, 1.0 / self.fps)

    @property
    def animation_bytes_per_s(self) -> float:
        """What one more second of this animation adds to the file: its keyframes' bytes per
        second (the weights of every target, the jaw's, the eyes' and the head's motion)."""
        return self.animation_bytes / max(self.duration_s, 1.0 / self.fps)

    def summary(self) -> str:
        return (
            f"{self.n_frames} frames at {self.fps:.1f} fps; skin: {self.n_muscle_targets} muscle "
            f"+ {self.n_corrective_targets} corrective morph targets, worst frame "
            f"{self.max_rms_mm:.3f} mm RMS from the simulated skin (muscles alone "
            f"{float(self.linear_rms_mm.max()):.2f} mm); {self.size_bytes / 1e3:.0f} kB"
        )


def export_glb(
    model,
    clip: Clip,
    path: str | os.PathLike,
    *,
    tol_mm: float = DEFAULT_TOL_MM,
    show_progress: bool = False,
) -> ExportReport:
    """Simulate ``clip`` on ``model``, fit the skin's morph targets within ``tol_mm`` RMS per
    frame (:func:`fit_morph_animation`), write the binary glTF ``path`` (:func:`write_glb`),
    and read it back to measure each frame against the simulated skin."""
    if not (np.isfinite(tol_mm) and tol_mm > 0):
        from myoface.errors import MyofaceValueError

        raise MyofaceValueError(f"tol_mm must be a finite number > 0 (mm); got {tol_mm}")
    sim = simulate_clip(model, clip, show_progress=show_progress)
    morph = fit_morph_animation(
        sim.skin,
        model.skin_vertices(),
        clip.contractions,
        muscle_responses(model),
        model.ids,
        tol_mm=tol_mm,
    )
    out = write_glb(path, model, clip, sim, morph)
    back = read_glb_skin(out)
    err = frame_rms_mm(back.skin * 1e3, sim.skin)
    return ExportReport(
        out,
        clip.n_frames,
        clip.fps,
        morph.n_muscle_targets,
        morph.n_targets - morph.n_muscle_targets,
        err,
        morph.linear_rms_mm,
        out.stat().st_size,
        sim,
        back.animation_bytes,
    )
