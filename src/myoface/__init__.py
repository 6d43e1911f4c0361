"""myoface: physics-based, anatomically driven facial animation and face-video analysis.

An implementation of D. Terzopoulos and K. Waters, "Analysis and Synthesis of Facial Image
Sequences Using Physical and Anatomical Models", IEEE Trans. PAMI 15(6), 1993, taken further.

Levels (one subpackage each): ``face`` (geometry), ``tissue`` (physics), ``muscles``,
``control`` (FACS and expressions), ``render`` (images), ``analysis`` (video -> contractions).
"""

from myoface.errors import (
    MyofaceError,
    MyofaceFileNotFoundError,
    MyofaceFormatError,
    MyofaceSimulationError,
    MyofaceValueError,
)

__version__ = "0.1.0"

__all__ = [
    "MyofaceError",
    "MyofaceFileNotFoundError",
    "MyofaceFormatError",
    "MyofaceSimulationError",
    "MyofaceValueError",
    "__version__",
]
