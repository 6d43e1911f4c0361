"""What each muscle can do at the fidelity measure's points, and the model's reach on a video.

    python tools/muscle_reach.py table [--muscles FILE]       # per-muscle full-contraction table
    python tools/muscle_reach.py reach --csv CONTRACTIONS.csv [--muscles FILE] [--cache NPZ]

``table``: each muscle's skin displacement at contraction 1 (the tissue relaxed, one muscle at a
time) at the points of the fidelity measure's regions (mouth corner, lower lip's outer edge,
brows inner/mid/outer, chin), on the default face and on the person's face made from the
sample video's calibration frame (``fidelity.person_model``), in mm and in the face's
inter-ocular distance (outer eye corners, 33-263), x (subject's left) and y (up).

``reach``: the input's displacements read as ``analysis.fidelity`` reads them (DIS flow from
frame 0, the 3-D alignment; from a contractions CSV of an earlier analysis, for the frames it
measured; cached in NPZ), then ``fidelity.model_reach`` with the person's face and the given
muscle file (default: the bundled one). The reach depends on the muscles only, not on the
analysis' contractions.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

VIDEO = Path.home() / ".cache/myoface/single_face.mp4"

#: points per row of the table (MediaPipe indices; left side of the subject = the higher index
#: of each pair in the default topology, x > 0)
POINTS = {
    "corner_l": 291,
    "lower_lip_c": 17,
    "lower_lip_l": 314,
    "brow_inner_l": 336,
    "brow_mid_l": 334,
    "brow_outer_l": 300,
    "lid_upper_l": 386,
    "chin_boss": 200,
    "menton": 152,
}
MUSCLES = (
    "zygomaticus_major_l",
    "zygomaticus_minor_l",
    "risorius_l",
    "levator_labii_superioris_l",
    "depressor_anguli_oris_l",
    "depressor_labii_inferioris_l",
    "mentalis_l",
    "orbicularis_oculi_l",
    "corrugator_supercilii_l",
    "depressor_supercilii_l",
    "orbicularis_oculi_superior_l",
    "frontalis_outer_l",
    "jaw",
)


def load_set(face, path=None):
    """The muscle set of ``path`` (default: the bundled file) placed on ``face`` as the
    default set is (mirrored onto the face's own right-side vertices)."""
    import tomllib

    from myoface.face import default_mirror_map
    from myoface.muscles import load_default_muscles
    from myoface.muscles.io import muscles_from_dict

    if path is None:
        return load_default_muscles(face)
    doc = tomllib.loads(Path(path).read_text())
    return muscles_from_dict(doc, face, where=str(path), mirror=default_mirror_map())


def models(path=None, which=("default", "person")):
    from myoface.analysis.fidelity import person_model
    from myoface.face import load_default_face
    from myoface.model import build_face_model

    out = {}
    if "default" in which:
        f = load_default_face()
        out["default"] = build_face_model(f, load_set(f, path))
    if "person" in which:
        f = person_model(VIDEO, 0)[0].face
        out["person"] = build_face_model(f, load_set(f, path))
    return out


def table(path=None) -> dict:
    from myoface.tissue import RelaxWarning

    rows = {}
    for name, fm in models(path).items():
        rest = fm.skin_vertices(fm.rest_state())
        iod = float(np.linalg.norm(rest[33, :2] - rest[263, :2]))
        rows[name] = {"iod_mm": round(iod, 2), "muscles": {}}
        for mid in MUSCLES:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RelaxWarning)
                res = fm.relax({mid: 1.0})
            d = fm.skin_vertices(res.state) - rest
            rows[name]["muscles"][mid] = {
                k: [round(float(d[v, 0]), 2), round(float(d[v, 1]), 2),
                    round(float(d[v, 1]) / iod, 4), round(float(np.linalg.norm(d[v])), 2)]
                for k, v in POINTS.items()
            }  # fmt: skip
    return rows


def print_table(rows):
    for name, r in rows.items():
        print(f"\n== {name} face (IOD {r['iod_mm']} mm): dx, dy mm (dy / IOD) |d| 3-D mm at c = 1")
        print("muscle".ljust(30) + "".join(k.rjust(25) for k in POINTS))
        for mid, pts in r["muscles"].items():
            cells = "".join(
                f"{a:+5.1f},{b:+5.1f}({c:+.3f}){n:5.1f}".rjust(25) for a, b, c, n in pts.values()
            )
            print(mid.ljust(30) + cells)


def input_d(csv, cache):
    from myoface.analysis.fidelity import fidelity_of_analysis

    cache = Path(cache)
    if cache.is_file():
        z = np.load(cache)
        return {k[2:]: z[k] for k in z.files if k.startswith("d_")}
    res, _ = fidelity_of_analysis(VIDEO, csv, calibration_frame=0, mediapipe_on_both=False)
    np.savez(cache, **{f"d_{k}": v for k, v in res.d_in.items()})
    print("fidelity of the CSV with the bundled muscles:", round(float(res.overall.explained), 4))
    return res.d_in


def reach(csv, cache, path=None, out=None):
    from myoface.analysis.fidelity import model_reach

    d_in = input_d(csv, cache)
    fm = models(path, ("person",))["person"]
    t0 = time.perf_counter()
    res, tab = model_reach(fm, d_in)
    doc = {
        "muscles": str(path or "bundled"),
        "overall": round(float(res.overall.explained), 4),
        "gain": round(float(res.overall.gain), 4),
        "regions": {
            k: {"explained": round(float(v.explained), 4), "gain": round(float(v.gain), 4)}
            for k, v in res.regions.items()
        },
        "held_smile_40_71_mean_contractions": {
            k: round(float(np.nanmean(tab[40:72, i])), 3)
            for i, k in enumerate(fm.ids)
            if np.nanmean(tab[40:72, i]) > 0.05
        },
        "seconds": round(time.perf_counter() - t0, 1),
    }
    print(json.dumps(doc, indent=1))
    if out:
        Path(out).write_text(json.dumps(doc, indent=1))
    return doc


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=("table", "reach"))
    ap.add_argument("--muscles", default=None)
    ap.add_argument("--csv", default=None)
    ap.add_argument("--cache", default="/tmp/muscle_reach_d_in.npz")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    if a.what == "table":
        rows = table(a.muscles)
        print_table(rows)
        if a.out:
            Path(a.out).write_text(json.dumps(rows, indent=1))
    else:
        reach(a.csv, a.cache, a.muscles, a.out)


if __name__ == "__main__":
    sys.exit(main())
