"""myoface: physics-based, anatomically driven facial animation and face-video analysis.

An implementation of D. Terzopoulos and K. Waters, "Analysis and Synthesis of Facial Image
Sequences Using Physical and Anatomical Models", IEEE Trans. PAMI 15(6), 1993, taken further.

Levels (one subpackage each): ``face`` (geometry), ``tissue`` (physics), ``muscles``,
``control`` (FACS and expressions), ``render`` (images), ``analysis`` (video -> contractions).

The handful of things a user starts from are here (imported on first use, so
``import myoface`` stays cheap)::

    import myoface as mf

    fm = mf.build_face_model()                       # or mf.load_face_model(path)
    c = mf.au_contractions({12: 0.8, 6: 0.5}, fm.ids)
    res = mf.relax(fm, c)                            # tissue equilibrium -> res.state
    mf.write_image("smile.png", mf.render_face(fm, res.state))
    result = mf.analyze_video("face.mp4")            # contractions per frame
"""

from importlib import import_module

from myoface.errors import (
    MyofaceError,
    MyofaceFileNotFoundError,
    MyofaceFormatError,
    MyofaceSimulationError,
    MyofaceValueError,
)

__version__ = "0.1.0"

#: public name -> the module that defines it
_LAZY = {
    "FaceModel": "myoface.model",
    "FaceState": "myoface.model",
    "build_face_model": "myoface.model",
    "load_face_model": "myoface.model",
    "relax": "myoface.model",
    "step": "myoface.model",
    "simulate": "myoface.model",
    "au_contractions": "myoface.control",
    "expression_contractions": "myoface.control",
    "viseme_contractions": "myoface.control",
    "muscle_contractions": "myoface.control",
    "Timeline": "myoface.control",
    "render_face": "myoface.synth",
    "Synthesizer": "myoface.synth",
    "write_image": "myoface.render",
    "VideoWriter": "myoface.render",
    "analyze_video": "myoface.analysis.pipeline",
}

__all__ = [
    "MyofaceError",
    "MyofaceFileNotFoundError",
    "MyofaceFormatError",
    "MyofaceSimulationError",
    "MyofaceValueError",
    "__version__",
    *_LAZY,
]


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'myoface' has no attribute {name!r}")


def __dir__():
    return sorted(__all__)
