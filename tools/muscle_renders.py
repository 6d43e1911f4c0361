"""Render the person's face (the fidelity measure's ``person_model``) and the default face at a
few contractions with a given muscle file, side by side in one PNG, to look at.

    python tools/muscle_renders.py OUT.png [--muscles FILE]
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


def main(argv=None):
    import cv2

    from myoface.analysis.resynthesis import resynthesis_frames
    from myoface.control import expression_contractions

    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--muscles", default=None)
    ap.add_argument("--size", type=int, default=320)
    a = ap.parse_args(argv)
    rows = []
    for name, fm in mr.models(a.muscles).items():
        table = []
        for c in SHOWN.values():
            if isinstance(c, str):
                table.append(expression_contractions(c, 0.9, fm.ids))
            else:
                table.append(fm.validate(c))
        frames = list(resynthesis_frames(fm, np.array(table), a.size))
        row = []
        for label, f in zip(SHOWN, frames, strict=True):
            f = np.ascontiguousarray(f[a.size // 3 :, :, ::-1])  # the lower two thirds, BGR
            cv2.putText(f, f"{name}: {label}", (4, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                        (255, 255, 255), 1)  # fmt: skip
            row.append(f)
        rows.append(np.hstack(row))
    cv2.imwrite(a.out, np.vstack(rows))


if __name__ == "__main__":
    main()
