"""Synthesis: contractions or a timeline -> face model physics -> rendered images and video.

The physics per video frame is the paper's quasi-static scheme: at each frame the contractions
of that instant are applied and the tissue relaxes to its new equilibrium, starting from the
previous frame's (Terzopoulos & Waters 1993, Section V-G: "the model reaches equilibrium
quickly on each frame"). ``dynamics="rk2"`` integrates in time with the paper's RK2 instead.
"""

from __future__ import annotations

import os
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from myoface.control import Timeline
from myoface.errors import MyofaceValueError
from myoface.render import Camera, Renderer, VideoWriter, overlay_segments, progress
from myoface.tissue import RelaxWarning

VIEWS = ("front", "three_quarter", "profile")
#: equilibrium tolerance per frame (mm): the relax solver's last step (the Newton solver stops
#: after a full step smaller than this, which leaves a smaller error still). On the benchmark's
#: performance (``bench.render._demo_contractions``) the skin stays within 10 um of the exact
#: equilibrium, a thirty-fifth of a pixel at 512 px for a 180 mm face; its 512x512 renders
#: differ from the exact equilibrium's by 0.0002 grey levels on average (a few dozen pixels on
#: triangle edges), far below what H.264 changes (1-2 levels), for about 10% fewer Newton
#: iterations per frame than 5 um
SYNTH_TOL_MM = 2e-2
DYNAMICS = ("quasistatic", "rk2")


def make_camera(vertices: np.ndarray, view: str = "front", width: int = 512, height: int = 512):
    """A camera preset (``front``, ``three_quarter``, ``profile``) framing ``vertices``."""
    if view not in VIEWS:
        raise MyofaceValueError(f"view must be one of {VIEWS}; got {view!r}")
    return getattr(Camera, view)(vertices, width=width, height=height)


def muscle_segments(model) -> tuple[np.ndarray, np.ndarray]:
    """Insertion and origin points (N, 3) of the model's muscles (for overlays, Fig. 4)."""
    ins = np.array([m.insertion for m in model.muscles.muscles])
    org = np.array([m.origin for m in model.muscles.muscles])
    return ins, org


def render_face(
    model,
    state=None,
    *,
    view: str = "front",
    width: int = 512,
    height: int = 512,
    texture=None,
    gaze=None,
) -> np.ndarray:
    """The skin of ``model`` in ``state`` (default: rest) rendered as an (H, W, 3) uint8 image:
    lit, texture-mapped (``texture``: an image or path for the face's UVs; default the face's
    own), with eyes and mouth, seen from a camera preset ``view`` (:data:`VIEWS`) that frames
    the rest face; ``gaze``: the eyes turned by ``(yaw_rad, pitch_rad)`` (see
    :meth:`myoface.render.Renderer.render`)."""
    cam = make_camera(model.face.vertices, view, width, height)
    r = Renderer(model.face, cam, texture=texture)
    return r.render(model.skin_vertices(state), jaw=model.jaw_pose(state), gaze=gaze)


@dataclass
class FrameStats:
    """Per-frame wall times (ms) of a :class:`Synthesizer`'s physics, rendering and (for
    :meth:`Synthesizer.write_video`) video encoding, and how many relaxations did not converge."""

    relax_ms: list
    render_ms: list
    unconverged: int = 0
    encode_ms: list = field(default_factory=list)


class Synthesizer:
    """Drives a :class:`~myoface.model.FaceModel` and renders it.

    Parameters
    ----------
    model : FaceModel
    renderer : Renderer, optional (default: front view, 512x512)
    overlay : {None, "muscles"} — draw the muscle vectors over the image.
    dynamics : {"quasistatic", "rk2"}
    """

    def __init__(
        self, model, renderer: Renderer | None = None, overlay=None, dynamics="quasistatic"
    ):
        if dynamics not in DYNAMICS:
            raise MyofaceValueError(f"dynamics must be one of {DYNAMICS}; got {dynamics!r}")
        if overlay not in (None, "muscles"):
            raise MyofaceValueError(f"overlay must be None or 'muscles'; got {overlay!r}")
        self.model = model
        self.renderer = renderer or Renderer(model.face, make_camera(model.face.vertices))
        self.overlay = overlay
        self.dynamics = dynamics
        self.stats = FrameStats([], [])
        #: this synthesizer's own state of the (shared, immutable) model
        self.state = model.rest_state()
        # the last state known to be the equilibrium of its contractions (the rest state is)
        self._settled = self.state
        #: where the eyes look: None (ahead) or (yaw_rad, pitch_rad) (see Renderer.render)
        self.gaze = None

    def _relax(self, c) -> None:
        t0 = time.perf_counter()
        c = self.model.validate(c)
        # a frame that holds the previous frame's contractions (a held or neutral stretch of a
        # performance) is already at its equilibrium: no physics
        if not (self.state is self._settled and np.array_equal(c, self.state.contractions)):
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", RelaxWarning)
                res = self.model.relax(c, self.state, tol_mm=SYNTH_TOL_MM)
            self.state = res.state
            if res.converged and not any(issubclass(w.category, RelaxWarning) for w in caught):
                self._settled = self.state
            else:
                self.stats.unconverged += 1
        self.stats.relax_ms.append((time.perf_counter() - t0) * 1e3)

    def frame(self) -> np.ndarray:
        """Render the model's current skin (uint8 RGB)."""
        t0 = time.perf_counter()
        img = self.renderer.render(
            self.model.skin_vertices(self.state),
            jaw=self.model.jaw_pose(self.state),
            gaze=self.gaze,
        )
        if self.overlay == "muscles":
            ins, org = muscle_segments(self.model)
            img = overlay_segments(img, self.renderer.camera, ins, org)
        self.stats.render_ms.append((time.perf_counter() - t0) * 1e3)
        return img

    def image(self, contractions) -> np.ndarray:
        """Relax to ``contractions`` and render."""
        self._relax(contractions)
        return self.frame()

    def frames(self, table: np.ndarray, times: Sequence[float], gaze=None):
        """Yield one image per row of ``table`` (T, M) at ``times`` (s); ``gaze`` (T, 2) rad,
        optional: where the eyes look in each frame (:attr:`gaze`)."""
        times = np.asarray(times, dtype=np.float64)
        if self.dynamics == "quasistatic":
            for k, c in enumerate(table):
                if gaze is not None:
                    self.gaze = tuple(gaze[k])
                yield self.image(c)
            return
        prev = times[0]
        for k, c in enumerate(table):
            if gaze is not None:
                self.gaze = tuple(gaze[k])
            if k == 0:
                self._relax(c)
            else:
                dt = times[k] - prev
                n = max(1, int(np.ceil(dt / self.model.stable_dt)))
                self.state = self.model.step(self.state, c, dt=dt / n, n_steps=n)
            prev = times[k]
            yield self.frame()

    def write_video(
        self,
        table: np.ndarray,
        times: Sequence[float],
        path: str | os.PathLike,
        fps: float,
        *,
        compose: Callable[[int, np.ndarray], np.ndarray] | None = None,
        show_progress: bool = True,
        desc: str = "rendering",
        gaze=None,
    ) -> Path:
        """Write one video frame per row of ``table`` (T, M) at ``times`` (s) (see
        :meth:`frames`, continuing from :attr:`state`) to ``path`` at ``fps``; returns the path.

        Each frame is encoded in a background thread while the next one is simulated and
        rendered (:class:`~myoface.render.VideoWriter` with ``background=True``).
        ``compose(k, image)``, if given, returns the picture to write for frame ``k`` (e.g. the
        image beside an input video's frame). The encoding times land in
        ``stats.encode_ms``. ``gaze`` (T, 2) rad: see :meth:`frames`.
        """
        table = np.asarray(table, dtype=np.float64)
        frames = progress(
            self.frames(table, times, gaze), total=len(table), desc=desc, enabled=show_progress
        )
        with VideoWriter(path, fps, background=True) as vw:
            for k, img in enumerate(frames):
                vw.write(img if compose is None else compose(k, img))
        self.stats.encode_ms.extend(vw.encode_ms)  # complete once the encoder has finished
        return Path(path)

    def video(
        self,
        timeline: Timeline,
        path: str | os.PathLike,
        fps: float = 30.0,
        show_progress: bool = True,
    ) -> Path:
        """Render ``timeline`` to a video file at ``fps``, from the rest state (its gaze events
        turn the eyes); returns the path."""
        n = max(1, int(round(timeline.duration * fps)) + 1)
        times = np.arange(n) / fps
        table = timeline.contractions(times, self.model.ids)
        gaze = timeline.gaze(times) if getattr(timeline, "has_gaze", False) else None
        self.state = self.model.rest_state()
        return self.write_video(table, times, path, fps, show_progress=show_progress, gaze=gaze)
