"""Render the person's face (the fidelity measure's ``person_model``) and the default face at a
few contractions with a given muscle file, side by side in one PNG, to look at.

    python tools/muscle_renders.py OUT.png [--muscles FILE] [--brows]

``--brows``: the brow lowerers instead (each at full contraction on both sides, AU4 and AU6),
the upper two thirds of the face.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import muscle_reach as mr  # noqa: E402

SHOWN = {
    "rest": {},
    "happiness 0.9": "happiness",
    "zyg. major 1.0 both": {"zygomaticus_major_l": 1.0, "zygomaticus_major_r": 1.0},
    "dep. labii inf. 1.0 both": {
        "depressor_labii_inferioris_l": 1.0,
        "depressor_labii_inferioris_r": 1.0,
    },
    "smile + DLI 0.8": {
        "zygomaticus_major_l": 1.0,
        "zygomaticus_major_r": 1.0,
        "orbicularis_oculi_l": 0.4,
        "orbicularis_oculi_r": 0.4,
        "depressor_labii_inferioris_l": 0.8,
        "depressor_labii_inferioris_r": 0.8,
    },  # fmt: skip
}

BOTH = {"_l": 1.0, "_r": 1.0}
SHOWN_BROWS = {
    "rest": {},
    "corrugator 1.0 both": {f"corrugator_supercilii{k}": v for k, v in BOTH.items()},
    "dep. supercilii 1.0 both": {f"depressor_supercilii{k}": v for k, v in BOTH.items()},
    "orb. oculi sup. 1.0 both": {f"orbicularis_oculi_superior{k}": v for k, v in BOTH.items()},
    "orb. oculi 1.0 both": {f"orbicularis_oculi{k}": v for k, v in BOTH.items()},
    "AU4 1.0": "au:4",
    "AU6 1.0": "au:6",
}


def main(argv=None):
    import cv2

    from myoface.analysis.resynthesis import resynthesis_frames
    from myoface.control import au_contractions, expression_contractions

    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--muscles", default=None)
    ap.add_argument("--size", type=int, default=320)
    ap.add_argument("--brows", action="store_true")
    a = ap.parse_args(argv)
    shown = SHOWN_BROWS if a.brows else SHOWN
    rows = []
    for name, fm in mr.models(a.muscles).items():
        table = []
        for c in shown.values():
            if isinstance(c, str) and c.startswith("au:"):
                table.append(fm.validate(au_contractions({int(c[3:]): 1.0}, fm.ids)))
            elif isinstance(c, str):
                table.append(expression_contractions(c, 0.9, fm.ids))
            else:
                table.append(fm.validate(c))
        frames = list(resynthesis_frames(fm, np.array(table), a.size))
        row = []
        for label, f in zip(shown, frames, strict=True):
            rows_px = slice(0, 2 * a.size // 3) if a.brows else slice(a.size // 3, None)
            f = np.ascontiguousarray(f[rows_px, :, ::-1])  # two thirds of the face, BGR
            cv2.putText(f, f"{name}: {label}", (4, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                        (255, 255, 255), 1)  # fmt: skip
            row.append(f)
        rows.append(np.hstack(row))
    cv2.imwrite(a.out, np.vstack(rows))


if __name__ == "__main__":
    main()
