"""Muscle level: linear, sheet and sphincter muscles, Waters' muscles, the jaw, the eyelids and
``MuscleSet``.

A contraction vector c (M,) in [0, 1] displaces the fascia nodes it reaches (Terzopoulos &
Waters 1993, eq. (5)); the jaw rotates the lower face about its hinge.
"""

from myoface.muscles.io import (
    load_default_muscles,
    load_muscles,
    muscles_from_dict,
    read_waters_expressions,
    read_waters_muscles,
)
from myoface.muscles.jaw import Jaw, harmonic_weights, rotate_about_axis
from myoface.muscles.lids import Eyelids, LidMuscle, build_eyelids
from myoface.muscles.muscleset import JAW_ID, MuscleSet
from myoface.muscles.types import (
    LinearMuscle,
    PterygoidMuscle,
    SheetMuscle,
    SphincterMuscle,
    WatersMuscle,
    cosine_falloff,
)

__all__ = [
    "JAW_ID",
    "Eyelids",
    "Jaw",
    "LidMuscle",
    "LinearMuscle",
    "MuscleSet",
    "PterygoidMuscle",
    "SheetMuscle",
    "SphincterMuscle",
    "WatersMuscle",
    "build_eyelids",
    "cosine_falloff",
    "harmonic_weights",
    "load_default_muscles",
    "load_muscles",
    "muscles_from_dict",
    "read_waters_expressions",
    "read_waters_muscles",
    "rotate_about_axis",
]
