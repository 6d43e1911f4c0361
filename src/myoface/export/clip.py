"""What an export animates: a :class:`Clip` (contractions per frame at a frame rate, with the
eyes' gaze and the head pose where the source has them), from an analysis' ``contractions.csv``,
a timeline file or a list of expressions, and its simulation (:func:`simulate_clip`: the
model's own quasi-static physics, as ``myoface synth`` and ``myoface resynth`` run it).
"""

from __future__ import annotations

import csv
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from myoface.errors import MyofaceValueError

#: the rest (s) before the first and after the last expression of :func:`clip_from_expressions`,
#: as ``myoface synth --expression`` has around its event
REST_S = 0.25
#: the default length (s) of each expression of :func:`clip_from_expressions` (``synth``'s)
EXPRESSION_S = 1.5
#: the default frame rate (frames per second) of a timeline's or an expression's clip
DEFAULT_FPS = 30.0


@dataclass(frozen=True, eq=False)
class Clip:
    """An animation to export, frame by frame at ``fps``.

    Attributes
    ----------
    contractions : (T, M) ndarray — over the model's ``ids`` (the jaw last), in [0, 1].
    fps : float — frames per second; frame ``k`` is at ``k / fps`` s.
    gaze : (T, 2) ndarray rad, or None — both eyes' ``(yaw, pitch)``
        (:func:`myoface.render.renderer.gaze_rotation`), None: straight ahead throughout.
    poses : list of (rotation (3, 3), translation (3,) mm), or None — the head's rigid motion
        per frame (a video's, :func:`~myoface.analysis.contractions_csv.display_poses`).
    source : str — what it came from, for messages and the file's metadata.
    """

    contractions: np.ndarray
    fps: float
    gaze: np.ndarray | None = None
    poses: list | None = None
    source: str = ""

    def __post_init__(self):
        c = np.asarray(self.contractions, dtype=np.float64)
        if c.ndim != 2 or len(c) == 0:
            raise MyofaceValueError(f"a clip needs (T, M) contractions; got shape {c.shape}")
        object.__setattr__(self, "contractions", c)
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise MyofaceValueError(f"fps must be > 0; got {self.fps}")
        if self.gaze is not None:
            g = np.asarray(self.gaze, dtype=np.float64)
            if g.shape != (len(c), 2) or not np.isfinite(g).all():
                raise MyofaceValueError(f"gaze must be finite ({len(c)}, 2) rad; got {g.shape}")
            object.__setattr__(self, "gaze", g)
        if self.poses is not None and len(self.poses) != len(c):
            raise MyofaceValueError(
                f"poses must be one per frame ({len(c)}); got {len(self.poses)}"
            )

    @property
    def n_frames(self) -> int:
        return len(self.contractions)

    @property
    def times(self) -> np.ndarray:
        """(T,) s: frame ``k`` at ``k / fps``."""
        return np.arange(self.n_frames) / self.fps

    @property
    def duration_s(self) -> float:
        """The animation's length (s): from the first frame to the last."""
        return (self.n_frames - 1) / self.fps


def _csv_header(path) -> list[str]:
    from myoface._io import read_text

    text = read_text(path, "contractions CSV")
    return next(csv.reader(text.splitlines()), [])


def clip_from_csv(path: str | os.PathLike, model) -> Clip:
    """The clip of an analysis' ``contractions.csv``
    (:func:`~myoface.analysis.resynthesis.read_performance`, as ``myoface resynth`` reads it):
    one frame per row at the CSV's frame rate, with the head pose where the CSV has the 3-D
    fit's pose columns and the eyes' gaze where it has the gaze columns."""
    from myoface.analysis.contractions_csv import POSE_COLUMNS
    from myoface.analysis.resynthesis import read_performance

    has_pose = set(POSE_COLUMNS) <= set(_csv_header(path))
    perf = read_performance(path, model, pose=has_pose)
    return Clip(perf.contractions, perf.fps, perf.gaze, perf.poses, str(Path(path).name))


def clip_from_timeline(timeline, model, fps: float = DEFAULT_FPS) -> Clip:
    """The clip of a :class:`~myoface.control.Timeline` sampled at ``fps`` from 0 to its end
    (as :meth:`myoface.synth.Synthesizer.video` samples it), its gaze events turning the eyes."""
    n = max(1, int(round(timeline.duration * fps)) + 1)
    times = np.arange(n) / fps
    table = timeline.contractions(times, model.ids)
    gaze = timeline.gaze(times) if timeline.has_gaze else None
    return Clip(table, float(fps), gaze, None, timeline.source or "timeline")


def parse_expression(text: str) -> tuple[str, float]:
    """``"NAME"`` or ``"NAME=INTENSITY"`` (intensity in [0, 1] or a FACS letter A-E; default 1)
    -> ``(name, intensity)``, both checked (:func:`myoface.control.facs.expression_aus`)."""
    from myoface.control.facs import expression_aus, parse_intensity

    name, _, value = text.partition("=")
    name = name.strip()
    k = parse_intensity(value.strip() if value.strip() else 1.0, f"expression {name}")
    expression_aus(name, k)  # an unknown name: the error lists the known ones
    return name, k


def expressions_timeline(expressions, duration_s: float = EXPRESSION_S):
    """A :class:`~myoface.control.Timeline` playing ``expressions`` (``[(name, intensity)]``)
    one after another, each over ``duration_s`` s with its own onset and offset, after
    :data:`REST_S` s at rest and followed by as much."""
    from myoface.control import Timeline

    events = [
        {
            "kind": "expression",
            "name": name,
            "intensity": float(k),
            "start": REST_S + i * duration_s,
            "duration": float(duration_s),
        }
        for i, (name, k) in enumerate(expressions)
    ]
    total = 2 * REST_S + len(events) * duration_s
    label = " ".join(f"{n}={k:g}" for n, k in expressions)
    return Timeline.from_dict({"duration": total, "event": events}, f"expressions {label}")


def clip_from_expressions(
    expressions, model, fps: float = DEFAULT_FPS, duration_s: float = EXPRESSION_S
) -> Clip:
    """The clip of ``expressions`` (``[(name, intensity)]``) played one after another
    (:func:`expressions_timeline`) at ``fps``. An expression the model brings itself (e.g.
    Waters' macros of his geoface, ``model.expressions``) is played as the model has it, under
    the same envelope, as ``myoface synth --expression`` does."""
    if not expressions:
        raise MyofaceValueError("give at least one expression")
    timeline = expressions_timeline(expressions, duration_s)
    if not any(name in model.expressions for name, _ in expressions):
        return clip_from_timeline(timeline, model, fps)
    n = max(1, int(round(timeline.duration * fps)) + 1)
    times = np.arange(n) / fps
    keep = np.ones((n, model.n_muscles))
    for event, (name, k) in zip(timeline.events, expressions, strict=True):
        if name in model.expressions:
            c = np.clip(np.asarray(model.expressions[name], dtype=np.float64) * k, 0.0, 1.0)
        else:
            c = event.contractions(model.ids)
        keep *= 1.0 - event.weight(times)[:, None] * c[None, :]
    return Clip(1.0 - keep, float(fps), None, None, timeline.source)


@dataclass(frozen=True, eq=False)
class SimulatedClip:
    """The model's response to a :class:`Clip` (:func:`simulate_clip`).

    Attributes
    ----------
    skin : (T, V, 3) ndarray mm — the skin vertices of each frame
        (:meth:`~myoface.model.FaceModel.skin_vertices`: the lids placed by the lid muscles, the
        lips kept out of the teeth), head frame.
    jaw : list of (rotation (3, 3), translation (3,) mm) — the mandible's rigid motion per
        frame (:meth:`~myoface.model.FaceModel.jaw_pose`), what the lower teeth and the tongue
        follow.
    unconverged : int — frames whose relaxation did not converge (warned about).
    """

    skin: np.ndarray
    jaw: list
    unconverged: int = 0


def simulate_clip(model, clip: Clip, *, show_progress: bool = False) -> SimulatedClip:
    """Run the model's physics through ``clip``: each frame the tissue's equilibrium for that
    frame's contractions (:meth:`~myoface.model.FaceModel.relax` at
    :data:`myoface.synth.SYNTH_TOL_MM`), warm-started from the previous frame's, a frame that
    holds the previous frame's contractions keeping its equilibrium, as
    :class:`~myoface.synth.Synthesizer` runs ``myoface synth`` and ``myoface resynth``."""
    from myoface.render import progress
    from myoface.synth import SYNTH_TOL_MM
    from myoface.tissue import RelaxWarning

    if clip.contractions.shape[1] != model.n_muscles:
        raise MyofaceValueError(
            f"the clip has {clip.contractions.shape[1]} contractions per frame; the model "
            f"{model.n_muscles}"
        )
    state = model.rest_state()
    settled = state
    skin = np.empty((clip.n_frames, model.face.n_vertices, 3))
    jaw, unconverged = [], 0
    rows = progress(
        clip.contractions, total=clip.n_frames, desc="simulating", enabled=show_progress
    )
    for k, c in enumerate(rows):
        c = model.validate(c)
        if not (state is settled and np.array_equal(c, state.contractions)):
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", RelaxWarning)
                res = model.relax(c, state, tol_mm=SYNTH_TOL_MM)
            state = res.state
            if res.converged and not any(issubclass(w.category, RelaxWarning) for w in caught):
                settled = state
            else:
                unconverged += 1
        skin[k] = model.skin_vertices(state)
        jaw.append(model.jaw_pose(state))
    if unconverged:
        from myoface.errors import MyofaceWarning

        warnings.warn(
            f"the tissue did not fully converge on {unconverged} frame(s) of {clip.n_frames}",
            MyofaceWarning,
            stacklevel=2,
        )
    return SimulatedClip(skin, jaw, unconverged)
