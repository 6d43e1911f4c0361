"""The viewer's control logic, independent of any GUI: the model, what the user asked for
(muscles, action units, an expression, the jaw), left/right linking, playback, and a physics
worker that always relaxes towards the latest request."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np

from myoface.control import au_contractions, expression_contractions
from myoface.control.facs import parse_intensity
from myoface.errors import MyofaceError, MyofaceValueError

REGIONS = {
    "brows and eyes": ("frontalis", "corrugator", "orbicularis_oculi"),
    "nose and upper lip": ("levator", "zygomaticus_minor"),
    "mouth corners": ("zygomaticus_major", "risorius", "buccinator", "depressor_anguli"),
    "lower lip and chin": ("depressor_labii", "mentalis", "orbicularis_oris"),
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
        self.version = 0
        self._lock = threading.Lock()

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
        """Load a ``contractions.csv`` or a timeline file; returns its duration (s)."""
        from myoface.analysis.pipeline import read_contractions_csv
        from myoface.control import load_timeline

        p = Path(path)
        if p.suffix.lower() == ".csv":
            times, table, _ = read_contractions_csv(p, list(self.ids))
            last = np.zeros(len(self.ids))
            for k in range(len(table)):  # unmeasured frames hold the last measured one
                if np.isnan(table[k]).any():
                    table[k] = last
                else:
                    last = table[k]
        else:
            tl = load_timeline(p)
            times = np.linspace(0, tl.duration, max(2, int(tl.duration * 30) + 1))
            table = tl.contractions(times, self.ids, strict=False)
        self.playback = (times, table)
        self._bump()
        return float(times[-1] - times[0])

    def frame_at(self, t: float) -> np.ndarray:
        if self.playback is None:
            raise MyofaceValueError("no playback loaded")
        times, table = self.playback
        k = int(np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 1))
        return table[k].copy()


class PhysicsWorker(threading.Thread):
    """Relaxes the model towards the latest requested contractions and calls ``publish``
    with the new skin vertices; coalesces requests that arrive while it works."""

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
                    self.model.relax(c, start="current", tol_mm=5e-3)
                self.publish(self.model.skin_vertices())
            except MyofaceError as exc:  # reported, the worker keeps running
                if self.on_error:
                    self.on_error(str(exc))
            self.last_ms = (time.perf_counter() - t0) * 1e3
            with self._cond:
                if self._target is None:
                    self.settled.set()
