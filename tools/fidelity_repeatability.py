"""How repeatable the fidelity judge is: one analysis judged against its video encoded again.

    python tools/fidelity_repeatability.py VIDEO OUT/contractions.csv [--crf 12,18,23,28]

``myoface analyze VIDEO -o OUT`` made the CSV. The tool judges it
(:func:`myoface.analysis.fidelity.fidelity_of_analysis`, as ``--report`` does) against
``VIDEO`` itself and against ``VIDEO`` re-encoded by H.264 at each quality given (the same
frames, 640 x 360 stays 640 x 360): the model's side is the same every time, so what moves is
the judge's reading of the input alone. Prints each one's overall and per-region explained
fraction and the mouth corners' gain. About 15 s per quality for the sample video. Measured
2026-12-06: README, "How much motion the resynthesis keeps".
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path


def reencoded(video, crf: int, path: Path) -> Path:
    """``video``'s frames encoded again by libx264 at ``crf`` into ``path``."""
    from myoface.analysis.video import open_video
    from myoface.render import VideoWriter

    v = open_video(video)
    with VideoWriter(path, fps=v.fps, quality_crf=crf, preset="medium") as vw:
        for f in v:
            vw.write(f)
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("video")
    ap.add_argument("csv", help="the analysis' contractions.csv")
    ap.add_argument("--crf", default="12,18,23,28", help="H.264 qualities (comma-separated)")
    a = ap.parse_args(argv)

    from myoface.analysis.fidelity import fidelity_of_analysis

    with tempfile.TemporaryDirectory() as tmp:
        videos = [("as given", a.video)]
        for crf in (int(x) for x in a.crf.split(",")):
            videos.append((f"crf {crf}", reencoded(a.video, crf, Path(tmp) / f"crf{crf}.mp4")))
        for name, video in videos:
            r, _ = fidelity_of_analysis(video, a.csv, mediapipe_on_both=False)
            regions = ", ".join(f"{k} {v.explained:.3f}" for k, v in r.regions.items())
            print(
                f"{name:9s} overall {r.overall.explained:.3f} ({regions}); "
                f"mouth corners' gain {r.regions['mouth_corners'].gain:.3f}"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
