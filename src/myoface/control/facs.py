"""FACS action units, the six universal expressions and visemes, mapped to muscle contractions.

The control level of the paper's hierarchy (Terzopoulos & Waters 1993, Section II): an
expression is a set of action units (AUs) with intensities; each AU asks some muscles for a
contraction. Data: ``data/facs_action_units.toml``, ``data/expressions.toml``,
``data/visemes.toml`` (with their sources).

Mixing rule: when several requests (AUs, events) drive one muscle with values w_k in [0, 1], the
contraction is the probabilistic OR ``1 - prod(1 - w_k)``: in [0, 1], equal to w for a single
request, and monotonically increasing in every request.

AU keys: ``12``, ``"12"``, ``"AU12"``; unilateral: ``"L12"``, ``"R12"``, ``"12L"``, ``"AU12R"``
(the subject's left / right). Intensities: numbers in [0, 1] or FACS letters A-E.
"""

from __future__ import annotations

import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources

import numpy as np

from myoface.errors import MyofaceValueError

#: FACS intensity letters (trace .. maximum) as numbers
LETTERS = {"A": 0.2, "B": 0.4, "C": 0.6, "D": 0.8, "E": 1.0}
_AU_RE = re.compile(r"^\s*(?:(?P<pre>[LR])\s*)?(?:AU)?\s*(?P<num>\d+)\s*(?P<post>[LR])?\s*$", re.I)


def _load(name: str) -> dict:
    return tomllib.loads((resources.files("myoface") / "data" / name).read_text())


@dataclass(frozen=True)
class ActionUnit:
    number: int
    name: str
    muscles: dict[str, float]  # base muscle name (no side suffix) -> weight
    sides: bool
    note: str = ""
    #: the AU's side names where the jaw goes, its muscles acting from the other side (AD30:
    #: "L30", the jaw to the subject's left, is the right lateral pterygoid); such an AU is
    #: scored with a side only
    crossed: bool = False


@lru_cache(maxsize=1)
def au_table() -> dict[int, ActionUnit]:
    """The AU table, ``{number: ActionUnit}``."""
    doc = _load("facs_action_units.toml")["au"]
    return {
        int(k): ActionUnit(
            int(k),
            v["name"],
            dict(v["muscles"]),
            bool(v["sides"]),
            v.get("note", ""),
            bool(v.get("crossed", False)),
        )
        for k, v in doc.items()
    }


@lru_cache(maxsize=1)
def _expressions() -> dict:
    return _load("expressions.toml")["expression"]


@lru_cache(maxsize=1)
def _visemes() -> dict:
    return _load("visemes.toml")["viseme"]


def list_action_units() -> list[str]:
    """``["1: inner brow raiser", ...]`` for help texts."""
    return [f"{n}: {au.name}" for n, au in sorted(au_table().items())]


def list_expressions() -> list[str]:
    return list(_expressions())


def list_visemes() -> list[str]:
    return list(_visemes())


def _brief(value) -> str:
    """``repr(value)``, at most 40 characters."""
    try:
        r = repr(value)
    except ValueError:  # an int of more digits than Python prints
        return "an integer of thousands of digits"
    return r if len(r) <= 40 else r[:37] + "..."


def parse_intensity(value, what: str) -> float:
    """A number in [0, 1] or a FACS letter A-E."""
    if isinstance(value, str) and value.strip().upper() in LETTERS:
        return LETTERS[value.strip().upper()]
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        raise MyofaceValueError(
            f"intensity of {what} must be a number in [0, 1] or a letter A-E; got {_brief(value)}"
        ) from None
    if not np.isfinite(v) or not 0.0 <= v <= 1.0:
        raise MyofaceValueError(f"intensity of {what} must be in [0, 1]; got {_brief(value)}")
    return v


def parse_au(key) -> tuple[int, str]:
    """AU key -> (number, side) with side "" (both), "l" or "r"."""
    try:
        text = key if isinstance(key, str) else str(key)
    except ValueError:
        text = ""
    m = _AU_RE.match(text)
    if not m or (m.group("pre") and m.group("post")) or len(m.group("num").lstrip("0")) > 4:
        raise MyofaceValueError(
            f"not an action unit: {_brief(key)} (e.g. 12, 'AU12', 'L12', '12R')"
        )
    num = int(m.group("num"))
    table = au_table()
    if num not in table:
        known = ", ".join(str(n) for n in sorted(table))
        raise MyofaceValueError(f"unknown action unit AU{num}; supported: {known}")
    side = (m.group("pre") or m.group("post") or "").lower()
    if side and not table[num].sides:
        raise MyofaceValueError(f"AU{num} ({table[num].name}) has no left/right variant")
    if table[num].crossed and not side:
        raise MyofaceValueError(
            f"AU{num} ({table[num].name}) needs a side: L{num} (to the subject's left) or R{num}"
        )
    return num, side


def _expand(base: str, side: str, muscle_ids: Sequence[str]) -> list[str]:
    """Muscle ids for a base name: itself if it is an id, else its _l/_r (or one side)."""
    if base in muscle_ids and not side:
        return [base]
    sides = [side] if side else ["l", "r"]
    return [f"{base}_{s}" for s in sides]


class _Mixer:
    """Accumulates requests per muscle with the probabilistic OR; records missing muscles."""

    def __init__(self, muscle_ids: Sequence[str], strict: bool, what: str):
        self.ids = list(muscle_ids)
        self.index = {k: i for i, k in enumerate(self.ids)}
        self.keep = np.ones(len(self.ids))  # prod(1 - w)
        self.strict = strict
        self.what = what
        self.missing: set[str] = set()

    def add(self, muscle: str, w: float) -> None:
        i = self.index.get(muscle)
        if i is None:
            if self.strict:
                raise MyofaceValueError(
                    f"{self.what} needs muscle {muscle!r}, which this face model does not have"
                )
            self.missing.add(muscle)
            return
        self.keep[i] *= 1.0 - float(np.clip(w, 0.0, 1.0))

    def result(self) -> np.ndarray:
        return 1.0 - self.keep


def _au_requests(aus: Mapping) -> list[tuple[int, str, float]]:
    out = []
    for key, val in aus.items():
        num, side = parse_au(key)
        out.append((num, side, parse_intensity(val, f"AU{key}")))
    return out


def _apply_aus(mixer: _Mixer, aus: Mapping, scale: float = 1.0) -> None:
    table = au_table()
    for num, side, inten in _au_requests(aus):
        if table[num].crossed:  # (parse_au has made sure there is a side)
            side = {"l": "r", "r": "l"}[side]
        for base, w in table[num].muscles.items():
            for mid in _expand(base, side, mixer.ids):
                mixer.add(mid, w * inten * scale)


def au_contractions(aus: Mapping, muscle_ids: Sequence[str], *, strict: bool = True) -> np.ndarray:
    """Contractions (M,) in ``muscle_ids`` order for action units ``{key: intensity}``.

    With ``strict=False`` muscles the face model lacks are skipped (see
    :func:`missing_muscles`); with ``strict=True`` (default) they are an error.
    """
    mixer = _Mixer(muscle_ids, strict, "an action unit")
    _apply_aus(mixer, aus)
    return mixer.result()


def missing_muscles(aus: Mapping, muscle_ids: Sequence[str]) -> set[str]:
    """Muscles that ``aus`` need and ``muscle_ids`` lacks."""
    mixer = _Mixer(muscle_ids, False, "")
    _apply_aus(mixer, aus)
    return mixer.missing


def expression_aus(name: str, intensity: float = 1.0) -> dict[int, float]:
    """The AUs of expression ``name`` at apex, scaled by ``intensity`` in [0, 1]."""
    table = _expressions()
    if name not in table:
        raise MyofaceValueError(f"unknown expression {name!r}; choose from {', '.join(table)}")
    k = parse_intensity(intensity, f"expression {name}")
    return {int(a): float(v) * k for a, v in table[name]["aus"].items()}


def expression_envelope(name: str) -> tuple[float, float]:
    """Default (onset, offset) durations in s of expression ``name``."""
    expression_aus(name)
    e = _expressions()[name]
    return float(e["onset"]), float(e["offset"])


def expression_contractions(
    name: str, intensity: float, muscle_ids: Sequence[str], *, strict: bool = True
) -> np.ndarray:
    """Contractions (M,) at the apex of expression ``name`` with emphasis ``intensity``."""
    return au_contractions(expression_aus(name, intensity), muscle_ids, strict=strict)


def viseme_contractions(
    name: str, intensity: float, muscle_ids: Sequence[str], *, strict: bool = True
) -> np.ndarray:
    """Contractions (M,) of viseme ``name`` at ``intensity``."""
    table = _visemes()
    if name not in table:
        raise MyofaceValueError(f"unknown viseme {name!r}; choose from {', '.join(table)}")
    k = parse_intensity(intensity, f"viseme {name}")
    mixer = _Mixer(muscle_ids, strict, f"viseme {name}")
    for base, w in table[name]["muscles"].items():
        for mid in _expand(base, "", mixer.ids):
            mixer.add(mid, float(w) * k)
    return mixer.result()


def muscle_contractions(values: Mapping[str, float], muscle_ids: Sequence[str]) -> np.ndarray:
    """Contractions (M,) from ``{muscle id or paired base name: value}``."""
    mixer = _Mixer(muscle_ids, True, "a muscle request")
    for key, val in values.items():
        v = parse_intensity(val, f"muscle {key}")
        targets = _expand(key, "", mixer.ids)
        if not all(t in mixer.index for t in targets):
            import difflib

            close = difflib.get_close_matches(key, mixer.ids, n=3)
            hint = f"; did you mean {', '.join(close)}?" if close else ""
            raise MyofaceValueError(f"unknown muscle {key!r}{hint}")
        for mid in targets:
            mixer.add(mid, v)
    return mixer.result()
