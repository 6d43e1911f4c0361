"""``myoface resynth``: drive the face model with measured contractions and render it."""

from __future__ import annotations

from pathlib import Path

from myoface.commands._common import MAX_FPS, add_face_argument, load_model, side_type
from myoface.errors import MyofaceFileNotFoundError, MyofaceValueError

NAME = "resynth"
HELP = "render the face model driven by a contractions.csv (from myoface analyze)"


def add_arguments(p):
    p.add_argument("csv", help="contractions.csv written by myoface analyze")
    p.add_argument("-o", "--output", required=True, help="output video (.mp4)")
    p.add_argument("--side-by-side", metavar="VIDEO", help="put the input video on the left")
    p.add_argument(
        "--size", type=side_type, default=360, help="rendered height in pixels (16-4096)"
    )
    p.add_argument(
        "--pose",
        action="store_true",
        help="reproduce the head pose of the CSV (its head_yaw_deg ... head_tz_mm columns, "
        "written by the landmarks' 3-D fit): the face turns and moves as in the video",
    )
    p.add_argument("--quiet", action="store_true")
    add_face_argument(p)


def run(args) -> int:
    import numpy as np

    from myoface._io import check_output_path
    from myoface.analysis.contractions_csv import hold_last_measured, read_contractions_csv

    if not args.output.lower().endswith((".mp4", ".mov", ".mkv", ".avi")):
        raise MyofaceValueError(f"-o must be a video file (.mp4); got {args.output}")
    check_output_path(args.output, "-o")
    if args.side_by_side and not Path(args.side_by_side).exists():
        raise MyofaceFileNotFoundError(f"--side-by-side: no such video: {args.side_by_side}")
    fm = load_model(args)
    times, table, quality = read_contractions_csv(args.csv, list(fm.ids))
    poses = None
    if args.pose:
        from myoface.analysis.fit import display_poses, read_head_poses

        poses = display_poses(read_head_poses(args.csv))
    table = hold_last_measured(table)  # unmeasured frames hold the last measured contractions
    dt = float(np.median(np.diff(times))) if len(times) > 1 else 1.0 / 30
    if not 1.0 / MAX_FPS <= dt <= 60.0:
        raise MyofaceValueError(
            f"{args.csv}: its rows are {dt:.3g} s apart (median); a video's frames are "
            f"{1 / MAX_FPS:.3g} to 60 s apart"
        )
    fps = 1.0 / dt
    resynthesize(
        fm,
        times,
        table,
        args.output,
        fps,
        size=int(args.size),
        side_by_side=args.side_by_side,
        show_progress=not args.quiet,
        poses=poses,
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
    poses=None,
):
    """Render ``model`` driven by the contractions ``table`` (T, M) at ``times`` (T,) s to the
    video ``output`` at ``fps``: one ``size`` x ``size`` frame per row (front view), each the
    equilibrium of its row warm-started from the previous one, encoded while the next is made;
    with the frames of the video ``side_by_side`` (scaled to ``size`` rows) on the left.
    ``poses``: per row ``(rotation, translation mm)`` of the head
    (:func:`~myoface.analysis.fit.display_poses`), or None for the still front view.

    Returns the :class:`~myoface.synth.Synthesizer`, whose ``stats`` hold the per-frame times
    of the physics, the rendering and the encoding.
    """
    import numpy as np

    from myoface.render import Renderer
    from myoface.render.renderer import resize_nearest
    from myoface.synth import Synthesizer, make_camera

    h = int(size)
    renderer = Renderer(model.face, make_camera(model.face.vertices, "front", h, h))
    if poses is not None:
        renderer = _PosedRenderer(renderer, poses)
    syn = Synthesizer(model, renderer)
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


class _PosedRenderer:
    """A renderer whose successive renders take the successive head ``poses``."""

    def __init__(self, renderer, poses):
        self._renderer = renderer
        self._poses = iter(poses)
        self.camera = renderer.camera

    def render(self, vertices=None, **kw):  # kw: the renderer's others, e.g. jaw=
        return self._renderer.render(vertices, pose=next(self._poses), **kw)
