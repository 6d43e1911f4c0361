"""The viewer's control logic, independent of any GUI: the model, what the user asked for
(muscles, action units, an expression, the jaw), left/right linking, playback, and a physics
worker that always relaxes towards the latest request."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np

from myoface.analysis.contractions_csv import (
    display_gaze,
    hold_last_measured,
    read_contractions_csv,
    read_gaze,
)
from myoface.control import (
    au_contractions,
    expression_contractions,
    list_expressions,
    list_visemes,
    load_timeline,
    muscle_contractions,
    viseme_contractions,
)
from myoface.control.facs import parse_intensity
from myoface.errors import MyofaceError, MyofaceValueError
from myoface.synth import SYNTH_TOL_MM

REGIONS = {
    "brows and eyes": (
        "frontalis",
        "corrugator",
        "depressor_supercilii",
        "orbicularis_oculi",
        "levator_palpebrae",
    ),
    "nose and upper lip": ("levator", "zygomaticus_minor"),
    "mouth corners": ("zygomaticus_major", "risorius", "buccinator", "depressor_anguli"),
    "lower lip and chin": ("depressor_labii", "mentalis", "orbicularis_oris", "lateral_pterygoid"),
}


def region_of(muscle_id: str) -> str:
    for region, prefixes in REGIONS.items():
        if muscle_id.startswith(prefixes):
            return region
    return "other"


class ViewerState:
    """What the viewer shows: requests from the controls mixed into one contraction vector.

    Every setter validates its input and raises :class:`MyofaceValueError` with a message the
    GUI can show; the state is unchanged on error.
    """

    def __init__(self, model):
        self.model = model
        self.ids = model.ids
        self.muscles = np.zeros(len(self.ids))
        self.aus: dict[str, float] = {}
        self.expression: tuple[str, float] | None = None
        self.linked = True
        self.playback: tuple[np.ndarray, np.ndarray] | None = None  # times, table
        #: the file the playback was loaded from (for the glTF export), or None
        self.playback_path: Path | None = None
        #: the playback's gaze (T, 2) rad, (yaw, pitch) per row, or None (no gaze in it)
        self.playback_gaze: np.ndarray | None = None
        self.version = 0
        self._lock = threading.Lock()
        self.presets: dict[str, np.ndarray] = self.builtin_presets()

    # ------------------------------------------------------------------ requests
    def _bump(self):
        self.version += 1

    def set_muscle(self, muscle_id: str, value) -> None:
        if muscle_id not in self.ids:
            raise MyofaceValueError(f"unknown muscle {muscle_id!r}")
        v = parse_intensity(value, muscle_id)
        with self._lock:
            self.muscles[self.ids.index(muscle_id)] = v
            if self.linked and muscle_id.endswith(("_l", "_r")):
                twin = muscle_id[:-1] + ("r" if muscle_id.endswith("l") else "l")
                if twin in self.ids:
                    self.muscles[self.ids.index(twin)] = v
            self._bump()

    def set_au(self, au, value) -> None:
        v = parse_intensity(value, f"AU{au}")
        au_contractions({au: v}, self.ids, strict=False)  # validates the key
        with self._lock:
            self.aus[str(au)] = v
            self._bump()

    def set_expression(self, name: str | None, intensity=1.0) -> None:
        if name is None or name == "none":
            with self._lock:
                self.expression = None
                self._bump()
            return
        v = parse_intensity(intensity, f"expression {name}")
        expression_contractions(name, v, self.ids, strict=False)  # validates the name
        with self._lock:
            self.expression = (name, v)
            self._bump()

    def set_muscles(self, values) -> None:
        """Set every muscle at once from ``{muscle id or paired base name: value}`` or an (M,)
        vector; the action units and the expression are cleared (a preset replaces the face)."""
        if isinstance(values, dict):
            v = muscle_contractions(values, self.ids)
        else:
            v = np.asarray(values, dtype=np.float64)
            if v.shape != (len(self.ids),) or not np.isfinite(v).all():
                raise MyofaceValueError(
                    f"a contraction vector needs {len(self.ids)} finite values; got {v.shape}"
                )
            if v.min() < 0 or v.max() > 1:
                raise MyofaceValueError("contractions must lie in [0, 1]")
        with self._lock:
            self.muscles[:] = v
            self.aus.clear()
            self.expression = None
            self._bump()

    # ------------------------------------------------------------------ presets
    def builtin_presets(self) -> dict[str, np.ndarray]:
        """neutral, the six expressions at full intensity and the visemes."""
        out = {"neutral": np.zeros(len(self.ids))}
        for name in list_expressions():
            out[name] = expression_contractions(name, 1.0, self.ids, strict=False)
        for name in list_visemes():
            out[f"viseme {name}"] = viseme_contractions(name, 1.0, self.ids, strict=False)
        return out

    def save_preset(self, name: str) -> None:
        name = (name or "").strip()
        if not name:
            raise MyofaceValueError("give the preset a name")
        self.presets[name] = self.contractions()

    def apply_preset(self, name: str) -> None:
        if name not in self.presets:
            raise MyofaceValueError(f"unknown preset {name!r}")
        self.set_muscles(self.presets[name])

    def load_preset_file(self, path) -> str:
        """Load a JSON object ``{muscle: value}`` (what the viewer's export writes) as a preset
        named after the file, and apply it; returns the name."""
        import json

        p = Path(str(path).strip())
        if not p.is_file():
            raise MyofaceValueError(f"no such file: {p}")
        try:
            data = json.loads(p.read_text())
        except (ValueError, UnicodeDecodeError) as exc:
            raise MyofaceValueError(f"{p.name} is not JSON: {exc}") from None
        if not isinstance(data, dict) or not data:
            raise MyofaceValueError(f"{p.name} must hold an object {{muscle: value}}")
        vec = muscle_contractions(data, self.ids)
        self.presets[p.stem] = vec
        self.set_muscles(vec)
        return p.stem

    def reset(self) -> None:
        with self._lock:
            self.muscles[:] = 0
            self.aus.clear()
            self.expression = None
            self._bump()

    def contractions(self, t: float | None = None) -> np.ndarray:
        """The mixed contraction vector (probabilistic OR of the requests), or the playback
        frame at time ``t`` (s) when a playback is loaded and ``t`` is given."""
        if t is not None and self.playback is not None:
            return self.frame_at(t)
        with self._lock:
            parts = [self.muscles.copy()]
            if self.aus:
                parts.append(au_contractions(self.aus, self.ids, strict=False))
            if self.expression is not None:
                parts.append(expression_contractions(*self.expression, self.ids, strict=False))
        keep = np.ones(len(self.ids))
        for c in parts:
            keep *= 1.0 - np.clip(c, 0, 1)
        return 1.0 - keep

    # ------------------------------------------------------------------ playback
    def load_playback(self, path) -> float:
        """Load a ``contractions.csv`` or a timeline file; returns its duration (s). The eyes'
        gaze comes with it where it has one (an analysis' gaze columns, the eyes read
        averaged and held through blinks; a timeline's gaze events): :meth:`gaze_at`."""
        p = Path(path)
        gaze = None
        if p.suffix.lower() == ".csv":
            times, table, _ = read_contractions_csv(p, list(self.ids))
            table = hold_last_measured(table)
            read = read_gaze(p)
            gaze = None if read is None else display_gaze(read[0])
        else:
            tl = load_timeline(p)
            times = np.linspace(0, tl.duration, max(2, int(tl.duration * 30) + 1))
            table = tl.contractions(times, self.ids, strict=False)
            gaze = tl.gaze(times) if tl.has_gaze else None
        self.playback = (times, table)
        self.playback_gaze = gaze
        self.playback_path = p
        self._bump()
        return float(times[-1] - times[0])

    def _row_at(self, t: float) -> int:
        if self.playback is None:
            raise MyofaceValueError("no playback loaded")
        times = self.playback[0]
        return int(np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 1))

    def frame_at(self, t: float) -> np.ndarray:
        return self.playback[1][self._row_at(t)].copy()

    def gaze_at(self, t: float) -> tuple[float, float] | None:
        """The playback's gaze ``(yaw, pitch)`` rad at time ``t`` (s), or None when it has
        none."""
        k = self._row_at(t)
        if self.playback_gaze is None:
            return None
        return tuple(float(g) for g in self.playback_gaze[k])


class PhysicsWorker(threading.Thread):
    """Relaxes the model towards the latest requested contractions and calls ``publish``
    with the new tissue node positions (N, 3) mm (the skin's vertices first); coalesces
    requests that arrive while it works.

    The worker owns the live face's state (:attr:`current`, a :class:`~myoface.model.FaceState`
    value replaced after each relax); the model itself is immutable, so an export or any other
    reader may use it at the same time with a state of its own.
    """

    def __init__(self, model, publish, on_error=None):
        super().__init__(daemon=True)
        self.model = model
        self.publish = publish
        self.on_error = on_error
        self._target = None
        self._cond = threading.Condition()
        self._stop = False
        self.last_ms = float("nan")
        self.settled = threading.Event()
        #: the live face's state (replaced, never changed in place)
        self.current = model.rest_state()

    def request(self, contractions: np.ndarray) -> None:
        with self._cond:
            self._target = np.array(contractions, dtype=np.float64)
            self.settled.clear()
            self._cond.notify()

    def stop(self) -> None:
        with self._cond:
            self._stop = True
            self._cond.notify()

    def run(self) -> None:
        import warnings

        while True:
            with self._cond:
                while self._target is None and not self._stop:
                    self._cond.wait()
                if self._stop:
                    return
                c, self._target = self._target, None
            t0 = time.perf_counter()
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    state = self.model.relax(c, self.current, tol_mm=SYNTH_TOL_MM).state
                self.current = state
                x = np.array(state.x)  # the skin as drawn: with the eyelids and the lip contact
                x[: self.model.face.n_vertices] = self.model.skin_vertices(state)
                self.publish(x)
            except MyofaceError as exc:  # reported, the worker keeps running
                if self.on_error:
                    self.on_error(str(exc))
            self.last_ms = (time.perf_counter() - t0) * 1e3
            with self._cond:
                if self._target is None:
                    self.settled.set()
