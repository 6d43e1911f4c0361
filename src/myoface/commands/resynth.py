"""``myoface resynth``: drive the face model with measured contractions and render it."""

from __future__ import annotations

from myoface.commands._common import add_face_argument, load_model
from myoface.errors import MyofaceValueError

NAME = "resynth"
HELP = "render the face model driven by a contractions.csv (from myoface analyze)"


def add_arguments(p):
    p.add_argument("csv", help="contractions.csv written by myoface analyze")
    p.add_argument("-o", "--output", required=True, help="output video (.mp4)")
    p.add_argument("--side-by-side", metavar="VIDEO", help="put the input video on the left")
    p.add_argument("--size", type=int, default=360, help="rendered height in pixels")
    p.add_argument("--quiet", action="store_true")
    add_face_argument(p)


def run(args) -> int:
    import numpy as np

    from myoface.analysis.pipeline import hold_last_measured, read_contractions_csv
    from myoface.render import Renderer, VideoWriter, progress
    from myoface.synth import Synthesizer, make_camera

    if not args.output.lower().endswith((".mp4", ".mov", ".mkv", ".avi")):
        raise MyofaceValueError(f"-o must be a video file (.mp4); got {args.output}")
    fm = load_model(args)
    times, table, quality = read_contractions_csv(args.csv, list(fm.ids))
    table = hold_last_measured(table)  # unmeasured frames hold the last measured contractions
    fps = 1.0 / np.median(np.diff(times)) if len(times) > 1 else 30.0
    src = None
    if args.side_by_side:
        from myoface.analysis.video import open_video

        src = iter(open_video(args.side_by_side))
    h = int(args.size)
    syn = Synthesizer(fm, Renderer(fm.face, make_camera(fm.face.vertices, "front", h, h)))
    with VideoWriter(args.output, fps=fps) as vw:
        for c in progress(table, total=len(table), desc="resynthesizing", enabled=not args.quiet):
            img = syn.image(c)
            if src is not None:
                frame = next(src, None)
                if frame is None:
                    raise MyofaceValueError("the side-by-side video is shorter than the CSV")
                from myoface.render.renderer import resize_nearest

                img = np.concatenate([resize_nearest(frame, h), img], axis=1)
            vw.write(img)
    print(f"wrote {args.output} ({len(table)} frames at {fps:.1f} fps)")
    return 0
