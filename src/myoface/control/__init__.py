"""Control and expression levels: FACS action units, expressions, visemes, timelines.

Everything here produces contraction vectors for a given list of muscle ids (a face model's
``ids``); see :mod:`myoface.control.facs` for the mixing rule and :mod:`myoface.control.timeline`
for the timeline file format.
"""

from myoface.control.facs import (
    LETTERS,
    ActionUnit,
    au_contractions,
    au_table,
    expression_aus,
    expression_contractions,
    expression_envelope,
    list_action_units,
    list_expressions,
    list_visemes,
    missing_muscles,
    muscle_contractions,
    parse_au,
    parse_intensity,
    viseme_contractions,
)
from myoface.control.timeline import (
    Event,
    Timeline,
    envelope,
    load_timeline,
    single_event_timeline,
)

__all__ = [
    "LETTERS",
    "ActionUnit",
    "Event",
    "Timeline",
    "au_contractions",
    "au_table",
    "envelope",
    "expression_aus",
    "expression_contractions",
    "expression_envelope",
    "list_action_units",
    "list_expressions",
    "list_visemes",
    "load_timeline",
    "missing_muscles",
    "muscle_contractions",
    "parse_au",
    "parse_intensity",
    "single_event_timeline",
    "viseme_contractions",
]
