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

    if not args.output.lower().endswith((".mp4", ".mov", ".mkv", ".avi")):
        raise MyofaceValueError(f"-o must be a video file (.mp4); got {args.output}")
    fm = load_model(args)
    times, table, quality = read_contractions_csv(args.csv, list(fm.ids))
    table = hold_last_measured(table)  # unmeasured frames hold the last measured contractions
    fps = 1.0 / np.median(np.diff(times)) if len(times) > 1 else 30.0
    resynthesize(
        fm,
        times,
        table,
        args.output,
        fps,
        size=int(args.size),
        side_by_side=args.side_by_side,
        show_progress=not args.quiet,
    )
    print(f"wrote {args.output} ({len(table)} frames at {fps:.1f} fps)")
    return 0


def resynthesize(
    model,
    times,
    table,
    output,
    fps: float,
    *,
    size: int = 360,
    side_by_side=None,
    show_progress: bool = True,
):
    """Render ``model`` driven by the contractions ``table`` (T, M) at ``times`` (T,) s to the
    video ``output`` at ``fps``: one ``size`` x ``size`` frame per row (front view), each the
    equilibrium of its row warm-started from the previous one, encoded while the next is made;
    with the frames of the video ``side_by_side`` (scaled to ``size`` rows) on the left.

    Returns the :class:`~myoface.synth.Synthesizer`, whose ``stats`` hold the per-frame times
    of the physics, the rendering and the encoding.
    """
    import numpy as np

    from myoface.render import Renderer
    from myoface.render.renderer import resize_nearest
    from myoface.synth import Synthesizer, make_camera

    h = int(size)
    syn = Synthesizer(model, Renderer(model.face, make_camera(model.face.vertices, "front", h, h)))
    compose = None
    if side_by_side:
        from myoface.analysis.video import open_video

        src = iter(open_video(side_by_side))

        def compose(k, img):
            frame = next(src, None)
            if frame is None:
                raise MyofaceValueError("the side-by-side video is shorter than the CSV")
            return np.concatenate([resize_nearest(frame, h), img], axis=1)

    syn.write_video(
        table,
        times,
        output,
        fps,
        compose=compose,
        show_progress=show_progress,
        desc="resynthesizing",
    )
    return syn
