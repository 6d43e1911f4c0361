"""``synth.au_range_within``: the model's action units against the human range of motion."""

from __future__ import annotations

from myoface.bench import Measurement, benchmark


@benchmark("synth.au_range_within", "-", higher_is_better=True)
def bench_au_range_within(quick: bool) -> Measurement:
    """Fraction of the action units with a published human range (``data/au_range.toml``) whose
    displacement at intensity 1 on the default face lies inside it: each AU relaxed alone, its
    points measured in the head frame. Deterministic, so one run (``n`` = 1); the detail lists
    every AU's measured value, direction, reference range and whether it is within (the table
    of ``tools/au_range_table.py``)."""
    from myoface.control.au_range import au_range_within, measure_au_ranges
    from myoface.model import build_face_model

    rows = measure_au_ranges(build_face_model())
    detail = {
        f"AU{r.ref.au}": {
            "mm": round(r.value_mm, 2),
            "direction": r.direction_text(),
            "direction_ok": r.direction_ok,
            "range_mm": None if r.ref.range_mm is None else list(r.ref.range_mm),
            "within": r.within,
        }
        for r in rows
    }
    return Measurement(au_range_within(rows), 1, detail=detail)
