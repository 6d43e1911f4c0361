"""Where the paper's snakes put the lips' outline on a video, against MediaPipe's.

    python tools/snake_lips.py [--video MP4] [--draw 20,45,60] [--out DIR] [--mouth] [--colour]

Runs :class:`~myoface.analysis.trackers.snakes.Analyzer` (the default options, or with the
mouth layer, ``--mouth``, or its colour layer, ``--colour``) on the video and, on every frame, MediaPipe's face mesh as an
independent reference for the lips' outer outline (its points 0-17 and 61-291 lie on the
vermilion border; on the sample video's smile it follows the upper lip above the teeth and the
lower lip's lower edge, which we checked by eye on the drawn frames). Prints per frame the
snakes' outline minus MediaPipe's (px, image y down): ``top`` (highest point), ``bottom``
(lowest), ``corner_r`` / ``corner_l`` (leftmost / rightmost in the image, x), with the zygomatic
majors' and depressor labii inferioris' estimates; then the means over the smile (frames
25-64). ``--draw``: those frames' mouths, 5x, with the snakes' outline (green), MediaPipe's
(blue) and the model's prediction at the estimate (red), to DIR (default: the working
directory).

Measured 2026-12-02 on single_face.mp4 (bundled muscles at 2da1fc6, default options): at rest
(frames 0-16) the outlines agree within 2.9 px; over the smile the snakes' top lies 5.7 px
below the upper lip's border (on the upper teeth), their bottom 12.6 px above the lower lip's
(on the lower teeth's edge), the subject's left corner 9.1 px inside (means), while the
zygomatic majors read 1.00: the snakes' outline is the teeth's, not the lips'.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

VIDEO = Path.home() / ".cache/myoface/single_face.mp4"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--video", default=str(VIDEO))
    ap.add_argument("--draw", default="")
    ap.add_argument("--out", default=".")
    ap.add_argument("--mouth", action="store_true", help="the mouth layer for the lips")
    ap.add_argument("--colour", action="store_true", help="the mouth layer from the lips' colour")
    args = ap.parse_args()

    import cv2
    import imageio.v3 as iio

    from myoface.analysis.landmarks import auto_init, contours_from_landmarks
    from myoface.analysis.trackers.snakes import MOUTH_SECTIONS, Analyzer
    from myoface.facemesh import FaceMeshDetector
    from myoface.model import build_face_model

    video = iio.imread(args.video, plugin="pyav")
    draw = {int(k) for k in args.draw.split(",") if k}
    fm = build_face_model()
    k0, _, init, _ = auto_init(iter(video), fm.face)
    mouth = args.mouth or args.colour
    an = Analyzer(
        fm, init, mouth_sections=MOUTH_SECTIONS if mouth else (), mouth_colour=args.colour
    )
    ids = list(an.ids)
    cols = [
        ids.index(m)
        for m in (
            "zygomaticus_major_r",
            "zygomaticus_major_l",
            "depressor_labii_inferioris_r",
            "depressor_labii_inferioris_l",
        )
    ]
    rows = []
    print("frame quality  top bottom corner_r corner_l (snakes - MediaPipe, px)  zyg r/l  dli r/l")
    with FaceMeshDetector(video=False) as det:
        for k, f in enumerate(video[k0:], start=k0):
            m = an.measure(f, k, k / 30)
            pts = det.detect(f)
            if pts is None:
                continue
            ref = contours_from_landmarks(fm.face, pts)["lips"]
            q = m.contours["lips"]
            d = np.array(
                [
                    q[:, 1].min() - ref[:, 1].min(),
                    q[:, 1].max() - ref[:, 1].max(),
                    q[:, 0].min() - ref[:, 0].min(),
                    q[:, 0].max() - ref[:, 0].max(),
                ]
            )
            c = np.asarray(m.contractions)[cols]
            rows.append((k, *d, *c))
            print(
                f"{k:5d} {m.quality[:10]:10s} "
                + " ".join(f"{v:+6.1f}" for v in d)
                + "   "
                + " ".join(f"{v:4.2f}" for v in c)
            )
            if k in draw:
                s = 5
                img = cv2.cvtColor(f, cv2.COLOR_RGB2BGR)
                x0, y0 = ref.mean(axis=0).astype(int) - (60, 45)
                big = cv2.resize(
                    img[y0 : y0 + 90, x0 : x0 + 120], None, fx=s, fy=s,
                    interpolation=cv2.INTER_CUBIC,
                )  # fmt: skip
                pred = an._predicted_sections(m.contractions, np.zeros(2))["lips"]
                for poly, col in ((ref, (255, 0, 0)), (q, (0, 255, 0)), (pred, (0, 0, 255))):
                    p = np.round((np.asarray(poly) - (x0 - 0.5, y0 - 0.5)) * s).astype(np.int32)
                    cv2.polylines(big, [p], True, col, 1, cv2.LINE_AA)
                cv2.imwrite(str(Path(args.out) / f"snake_lips_{k}.png"), big)
    an.close()
    r = np.array(rows, dtype=float)
    smile = r[(r[:, 0] >= 25) & (r[:, 0] < 65)]
    names = ("top", "bottom", "corner_r", "corner_l", "zyg_r", "zyg_l", "dli_r", "dli_l")
    means = np.nanmean(smile[:, 1:], axis=0)
    print(
        "smile (frames 25-64) means: "
        + ", ".join(f"{n} {v:+.2f}" for n, v in zip(names, means, strict=True))
    )


if __name__ == "__main__":
    main()
