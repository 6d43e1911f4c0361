"""Timelines: expressions, action units, visemes and muscle requests over time.

A timeline file (TOML or JSON) holds events::

    duration = 4.0            # optional: total length in s (default: the end of the last event)

    [[event]]
    kind = "expression"       # expression | au | muscle | viseme | blink | gaze
    name = "happiness"        # expression / viseme name, AU key ("12", "L12"), or muscle id
    start = 0.5               # s
    duration = 2.0            # s, onset + apex + offset
    intensity = 0.8           # [0, 1] (or a FACS letter A-E)
    onset = 0.3               # optional, s: rise time (default: the expression's, or duration/3)
    offset = 0.4              # optional, s: decay time

A blink is an event of its own: ``kind = "blink"`` with only ``start`` needed; ``name`` is
``"both"`` (default), ``"L"`` or ``"R"`` (the subject's side), ``duration`` defaults to
:data:`BLINK_DURATION_S` and the ramps to :data:`BLINK_ONSET_FRACTION` /
:data:`BLINK_OFFSET_FRACTION` of it (the lids close faster than they open); it drives AU45.
A gaze event turns the eyes: ``kind = "gaze"``, ``yaw_deg`` (towards the subject's left) and
``pitch_deg`` (up), each within :data:`MAX_GAZE_DEG`, with ``start`` / ``duration`` /
``onset`` / ``offset`` as for the others (the eyes go there and come back); overlapping gaze
events are averaged by their envelopes (:meth:`Timeline.gaze`). It moves no muscle.

JSON: ``{"duration": 4.0, "events": [{...}, ...]}``. Times are finite numbers of seconds, at
most :data:`MAX_TIME_S` (a day); files are UTF-8.

Each event contributes ``envelope(t) * intensity * (its apex contractions)``; the envelope rises
with a raised cosine over ``onset``, holds 1 over the apex, and falls with a raised cosine over
``offset`` (Terzopoulos & Waters 1993, Section II: onset time, duration and emphasis).
Overlapping events mix per muscle by the probabilistic OR (see :mod:`myoface.control.facs`).
Visemes may overlap only in their ramps (co-articulation), never at their apex: a mouth shows one
viseme at a time.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from myoface._io import atomic_output, parse_json, parse_toml, read_text
from myoface.control import facs
from myoface.errors import MyofaceFileNotFoundError, MyofaceFormatError, MyofaceValueError

KINDS = ("expression", "au", "muscle", "viseme", "blink", "gaze")
#: the largest gaze angle (degrees) of a gaze event (see myoface.render.renderer.MAX_GAZE_RAD)
MAX_GAZE_DEG = 45.0
#: a blink's default length (s) and its closing and reopening ramps (fractions of it): a
#: spontaneous blink lasts a few tenths of a second and the lid goes down faster than it comes
#: up (Evinger, Manning & Sibony, "Eyelid movements: mechanisms and normal data", Invest.
#: Ophthalmol. Vis. Sci. 32, 1991; VanderWerf et al., "Eyelid movements: behavioral studies of
#: blinking in humans under different stimulus conditions", J. Neurophysiol. 89, 2003); the
#: values are our choice within that, the rest of the duration is the pause shut
BLINK_DURATION_S = 0.25
BLINK_ONSET_FRACTION = 0.3
BLINK_OFFSET_FRACTION = 0.6
#: blink sides (``name`` of a blink event) -> the AU45 key
BLINK_SIDES = {"both": "45", "l": "L45", "r": "R45"}
_EVENT_KEYS = {"kind", "name", "start", "duration", "intensity", "onset", "offset"}
_GAZE_KEYS = {"yaw_deg", "pitch_deg"}
#: default rise/decay of AU, muscle and viseme events, as a fraction of their duration
DEFAULT_RAMP_FRACTION = 1.0 / 3.0
#: the largest time (s) a timeline may name: a start, a duration, an onset or an offset
MAX_TIME_S = 86400.0


def envelope(t, start: float, onset: float, apex: float, offset: float) -> np.ndarray:
    """Raised-cosine envelope in [0, 1] at times ``t`` (s)."""
    t = np.asarray(t, dtype=np.float64)
    u = t - start
    out = np.zeros_like(u)
    if onset > 0:
        m = (u >= 0) & (u < onset)
        out[m] = 0.5 - 0.5 * np.cos(np.pi * u[m] / onset)
    m = (u >= onset) & (u <= onset + apex)
    out[m] = 1.0
    if offset > 0:
        v = u - onset - apex
        m = (v > 0) & (v < offset)
        out[m] = 0.5 + 0.5 * np.cos(np.pi * v[m] / offset)
    return out


@dataclass(frozen=True)
class Event:
    """One timeline event (times in s)."""

    kind: str
    name: str
    start: float
    duration: float
    intensity: float = 1.0
    onset: float | None = None
    offset: float | None = None
    yaw_deg: float | None = None
    pitch_deg: float | None = None

    @property
    def ramps(self) -> tuple[float, float]:
        if self.onset is not None and self.offset is not None:
            return self.onset, self.offset
        if self.kind == "expression":
            a, o = facs.expression_envelope(self.name)
            scale = min(1.0, self.duration / (a + o)) if a + o > 0 else 1.0
            a, o = a * scale, o * scale
        elif self.kind == "blink":
            a = self.duration * BLINK_ONSET_FRACTION
            o = self.duration * BLINK_OFFSET_FRACTION
        else:
            a = o = self.duration * DEFAULT_RAMP_FRACTION
        return (self.onset if self.onset is not None else a), (
            self.offset if self.offset is not None else o
        )

    @property
    def end(self) -> float:
        return self.start + self.duration

    def apex_interval(self) -> tuple[float, float]:
        a, o = self.ramps
        return self.start + a, self.end - o

    def weight(self, t) -> np.ndarray:
        a, o = self.ramps
        return envelope(t, self.start, a, self.duration - a - o, o)

    def contractions(self, muscle_ids: Sequence[str], strict: bool = True) -> np.ndarray:
        """Apex contractions (M,) of this event at its intensity."""
        if self.kind == "expression":
            return facs.expression_contractions(
                self.name, self.intensity, muscle_ids, strict=strict
            )
        if self.kind == "au":
            return facs.au_contractions({self.name: self.intensity}, muscle_ids, strict=strict)
        if self.kind == "viseme":
            return facs.viseme_contractions(self.name, self.intensity, muscle_ids, strict=strict)
        if self.kind == "gaze":
            return np.zeros(len(muscle_ids))
        if self.kind == "blink":
            au = BLINK_SIDES[self.name.lower()]
            return facs.au_contractions({au: self.intensity}, muscle_ids, strict=strict)
        return facs.muscle_contractions({self.name: self.intensity}, muscle_ids)


def _brief(v) -> str:
    """``repr(v)``, at most 40 characters (an int too long to print says so)."""
    try:
        r = repr(v)
    except ValueError:
        return "an integer of thousands of digits"
    return r if len(r) <= 40 else r[:37] + "..."


def _number(ev: dict, key: str, where: str, default=None) -> float | None:
    if key not in ev:
        if default is None and key in ("start", "duration"):
            raise MyofaceFormatError(f"{where}: missing {key!r}")
        return default
    v = ev[key]
    try:
        f = float(v) if isinstance(v, int | float) and not isinstance(v, bool) else np.nan
    except OverflowError:  # an int beyond float
        f = np.inf
    if not np.isfinite(f):
        raise MyofaceFormatError(f"{where}: {key} must be a finite number (s); got {_brief(v)}")
    if abs(f) > MAX_TIME_S:
        raise MyofaceFormatError(
            f"{where}: {key} must be at most {MAX_TIME_S:g} s (a day); got {_brief(v)}"
        )
    return f


def _event(ev, where: str) -> Event:
    if not isinstance(ev, dict):
        raise MyofaceFormatError(f"{where}: an event must be a table; got {_brief(ev)}")
    unknown = set(ev) - _EVENT_KEYS - (_GAZE_KEYS if ev.get("kind") == "gaze" else set())
    if unknown:
        raise MyofaceFormatError(
            f"{where}: unknown keys {sorted(unknown)} (allowed: {sorted(_EVENT_KEYS)})"
        )
    kind = ev.get("kind")
    if kind not in KINDS:
        raise MyofaceFormatError(f"{where}: kind must be one of {KINDS}; got {_brief(kind)}")
    raw = ev.get("name", {"blink": "both", "gaze": "gaze"}.get(kind))
    if isinstance(raw, bool) or not isinstance(raw, str | int):
        raise MyofaceFormatError(f"{where}: missing name (a string, or an AU number)")
    if isinstance(raw, int) and not 0 <= raw < 1000:
        raise MyofaceFormatError(f"{where}: a numeric name must be an AU number in [0, 999]")
    name = str(raw)
    if kind == "blink" and name.lower() not in BLINK_SIDES:
        raise MyofaceFormatError(
            f"{where}: a blink's name must be one of both, L, R; got {_brief(raw)}"
        )
    start = _number(ev, "start", where)
    if kind == "blink" and "duration" not in ev:
        ev = {**ev, "duration": BLINK_DURATION_S}
    duration = _number(ev, "duration", where)
    if start < 0:
        raise MyofaceFormatError(f"{where}: start must be >= 0 s; got {start}")
    if duration <= 0:
        raise MyofaceFormatError(f"{where}: duration must be > 0 s; got {duration}")
    try:
        inten = facs.parse_intensity(ev.get("intensity", 1.0), f"{kind} {name}")
    except MyofaceValueError as exc:
        raise MyofaceFormatError(f"{where}: {exc}") from None
    onset = _number(ev, "onset", where, None)
    offset = _number(ev, "offset", where, None)
    for k, v in (("onset", onset), ("offset", offset)):
        if v is not None and v < 0:
            raise MyofaceFormatError(f"{where}: {k} must be >= 0 s; got {v}")
    # names are checked here, against the default vocabulary (muscles: when mixed)
    try:
        if kind == "expression":
            facs.expression_aus(name)
        elif kind == "au":
            facs.parse_au(name)
        elif kind == "viseme":
            facs.viseme_contractions(name, 1.0, [], strict=False)
    except MyofaceValueError as exc:
        raise MyofaceFormatError(f"{where}: {exc}") from None
    angles = {}
    if kind == "gaze":
        for key in sorted(_GAZE_KEYS):
            a = _number(ev, key, where, 0.0)
            if abs(a) > MAX_GAZE_DEG:
                raise MyofaceFormatError(
                    f"{where}: {key} must be within +-{MAX_GAZE_DEG:g} degrees; got {a:g}"
                )
            angles[key] = a
    e = Event(kind, name, start, duration, inten, onset, offset, **angles)
    a, o = e.ramps
    if a + o > duration + 1e-12:
        raise MyofaceFormatError(
            f"{where}: onset + offset ({a:g} + {o:g} s) exceed the duration ({duration:g} s)"
        )
    return e


class Timeline:
    """A list of events; :meth:`contractions` mixes them into a contraction vector per time."""

    def __init__(self, events: Sequence[Event], duration: float | None = None, source: str = ""):
        self.events = list(events)
        self.source = source or "timeline"
        end = max((e.end for e in self.events), default=0.0)
        self.duration = float(duration) if duration is not None else end
        if not self.duration > 0:
            raise MyofaceFormatError(f"{self.source}: the timeline is empty (duration 0)")
        self._check_visemes()

    def _check_visemes(self) -> None:
        vis = sorted(
            ((k, e) for k, e in enumerate(self.events) if e.kind == "viseme"),
            key=lambda ke: ke[1].start,
        )
        for (i, a), (j, b) in zip(vis, vis[1:], strict=False):
            a0, a1 = a.apex_interval()
            b0, b1 = b.apex_interval()
            if min(a1, b1) > max(a0, b0) + 1e-9:
                raise MyofaceFormatError(
                    f"{self.source}: viseme events #{i + 1} ({a.name}) and #{j + 1} ({b.name}) "
                    f"overlap at their apex ({max(a0, b0):.3f}-{min(a1, b1):.3f} s); visemes may "
                    "overlap only in their onset/offset ramps"
                )

    @classmethod
    def from_dict(cls, doc: dict, source: str = "timeline") -> Timeline:
        if not isinstance(doc, dict):
            raise MyofaceFormatError(f"{source}: a timeline must be a table/object")
        unknown = set(doc) - {"event", "events", "duration", "fps", "title"}
        if unknown:
            raise MyofaceFormatError(f"{source}: unknown top-level keys {sorted(unknown)}")
        events = doc.get("event", doc.get("events", []))
        if not isinstance(events, list) or not events:
            raise MyofaceFormatError(f'{source}: no events ([[event]] tables / "events" list)')
        evs = [_event(e, f"{source}: event #{k + 1}") for k, e in enumerate(events)]
        dur = _number(doc, "duration", source, None) if "duration" in doc else None
        if dur is not None and dur <= 0:
            raise MyofaceFormatError(f"{source}: duration must be > 0 s; got {dur}")
        return cls(evs, dur, source)

    def to_dict(self) -> dict:
        evs = []
        for e in self.events:
            d = {k: v for k, v in asdict(e).items() if v is not None}
            evs.append(d)
        return {"duration": self.duration, "events": evs}

    def save(self, path: str | os.PathLike) -> None:
        """Write as JSON (``.json``) or TOML (anything else)."""
        p = Path(path)
        doc = self.to_dict()
        if p.suffix.lower() == ".json":
            text = json.dumps(doc, indent=2)
        else:
            lines = [f"duration = {doc['duration']!r}", ""]
            for e in doc["events"]:
                lines.append("[[event]]")
                for k, v in e.items():
                    lines.append(f"{k} = {json.dumps(v)}")
                lines.append("")
            text = "\n".join(lines)
        with atomic_output(p) as tmp:
            tmp.write_text(text)

    @property
    def has_gaze(self) -> bool:
        return any(e.kind == "gaze" for e in self.events)

    def gaze(self, times) -> np.ndarray:
        """The eyes' gaze (T, 2) rad, (yaw, pitch), at ``times`` (T,) s: the gaze events'
        angles averaged with their envelopes as weights (straight ahead where none is on; a
        single event at weight w gives w times its angles)."""
        t = np.atleast_1d(np.asarray(times, dtype=np.float64))
        if t.ndim != 1 or not np.isfinite(t).all():
            raise MyofaceValueError("times must be a finite 1-D array (s)")
        total = np.zeros((len(t), 2))
        weight = np.zeros(len(t))
        for e in self.events:
            if e.kind != "gaze":
                continue
            w = e.weight(t)
            total += w[:, None] * np.deg2rad([e.yaw_deg or 0.0, e.pitch_deg or 0.0])[None, :]
            weight += w
        return total / np.maximum(weight, 1.0)[:, None]

    def contractions(self, times, muscle_ids: Sequence[str], *, strict: bool = True) -> np.ndarray:
        """Contraction vectors (T, M) at ``times`` (T,) s, in ``muscle_ids`` order."""
        t = np.atleast_1d(np.asarray(times, dtype=np.float64))
        if t.ndim != 1 or not np.isfinite(t).all():
            raise MyofaceValueError("times must be a finite 1-D array (s)")
        keep = np.ones((len(t), len(muscle_ids)))
        for k, e in enumerate(self.events):
            try:
                c = e.contractions(muscle_ids, strict=strict)
            except MyofaceValueError as exc:
                raise MyofaceValueError(f"{self.source}: event #{k + 1}: {exc}") from None
            keep *= 1.0 - e.weight(t)[:, None] * c[None, :]
        return 1.0 - keep


def load_timeline(path: str | os.PathLike) -> Timeline:
    """Read a timeline file (``.toml`` or ``.json``; see the module doc)."""
    p = Path(path)
    if not p.is_file():
        raise MyofaceFileNotFoundError(f"no such timeline file: {p}")
    text = read_text(p, "timeline file")
    doc = parse_json(text, str(p)) if p.suffix.lower() == ".json" else parse_toml(text, str(p))
    return Timeline.from_dict(doc, str(p))


def single_event_timeline(
    kind: str, name: str, intensity: float, duration: float, start: float = 0.0, tail: float = 0.0
) -> Timeline:
    """A timeline of one event (e.g. ``synth --expression surprise --duration 1.5``)."""
    ev = _event(
        {"kind": kind, "name": name, "start": start, "duration": duration, "intensity": intensity},
        f"{kind} {name}",
    )
    return Timeline([ev], start + duration + tail, f"{kind} {name}")
