"""``myoface resynth``: drive the face model with measured contractions and render it."""

from __future__ import annotations

from pathlib import Path

from myoface.commands._common import add_face_argument, load_model, side_type
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
    from myoface._io import OutputConflictError, check_not_input, check_output_path
    from myoface.commands.analyze import refuse

    inputs = {
        "the contractions CSV": args.csv,
        "the --side-by-side video": args.side_by_side,
        "--face": args.face,
        "--muscles": args.muscles,
    }
    try:  # never over an input (or inside an input folder): a usage error, before any work
        check_not_input(args.output, inputs, "-o")
    except OutputConflictError as exc:
        return refuse(args, exc)
    if not args.output.lower().endswith((".mp4", ".mov", ".mkv", ".avi")):
        raise MyofaceValueError(f"-o must be a video file (.mp4); got {args.output}")
    check_output_path(args.output, "-o")
    if args.side_by_side and not Path(args.side_by_side).exists():
        raise MyofaceFileNotFoundError(f"--side-by-side: no such video: {args.side_by_side}")
    fm = load_model(args)
    resynth_video(
        fm,
        args.csv,
        args.output,
        size=args.size,
        side_by_side=args.side_by_side,
        pose=args.pose,
        quiet=args.quiet,
    )
    return 0


def resynth_video(
    model,
    csv,
    output,
    *,
    size: int = 360,
    side_by_side=None,
    pose: bool = False,
    quiet: bool = False,
) -> None:
    """``myoface resynth``'s work once its arguments are checked (also the demo's): the
    contractions of ``csv`` (:func:`~myoface.analysis.resynthesis.read_performance`) drive
    ``model`` into the video ``output``
    (:func:`~myoface.analysis.resynthesis.resynthesize`), and the command's line is printed."""
    from myoface.analysis.resynthesis import read_performance, resynthesize

    perf = read_performance(csv, model, pose=pose)
    resynthesize(
        model,
        perf.times,
        perf.contractions,
        output,
        perf.fps,
        size=int(size),
        side_by_side=side_by_side,
        show_progress=not quiet,
        poses=perf.poses,
        gaze=perf.gaze,
    )
    print(f"wrote {output} ({perf.n_frames} frames at {perf.fps:.1f} fps)")
