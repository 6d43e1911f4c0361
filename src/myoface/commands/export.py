"""``myoface export``: a myoface animation as one binary glTF 2.0 file (``.glb``)."""

from __future__ import annotations

from myoface.commands._common import (
    MAX_VIDEO_S,
    add_face_argument,
    fps_type,
    load_model,
    number,
)
from myoface.errors import MyofaceUsageError, MyofaceValueError

NAME = "export"
HELP = "export an animation (contractions.csv, a timeline, expressions) as glTF (.glb)"
DESCRIPTION = """Export a myoface animation as one binary glTF 2.0 file for Blender, three.js,
Unity, Unreal: the skin (UVs, texture) with its motion as morph targets (one per muscle plus
correctives, every frame within --tol-mm RMS of the simulated skin), the eyes turned by the
gaze, the teeth, the tongue and the lower teeth turned by the jaw, the head pose of a video's
CSV on the root. Units metres, +Y up (docs/export.md).

Examples:
  myoface export out/contractions.csv -o anim.glb
  myoface export --timeline examples/talk.toml -o talk.glb
  myoface export --expression happiness --expression surprise=0.6 -o two.glb"""


def add_arguments(p):
    import argparse

    p.formatter_class = argparse.RawDescriptionHelpFormatter
    src = p.add_argument_group("what to export (one of)")
    src.add_argument("csv", nargs="?", help="a contractions.csv written by myoface analyze")
    src.add_argument("--timeline", metavar="FILE", help="a timeline file (TOML/JSON) of events")
    src.add_argument(
        "--expression",
        action="append",
        metavar="NAME[=INTENSITY]",
        help="an expression (anger, disgust, fear, happiness, sadness, surprise), intensity in "
        "[0, 1] or A-E (default 1); repeatable: played one after another",
    )
    p.add_argument("-o", "--output", required=True, help="output file (.glb)")
    p.add_argument(
        "--fps",
        type=fps_type,
        default=None,
        help="frames per second of a timeline or expressions (default: the timeline's "
        "'fps', else 30); a CSV keeps its own",
    )
    p.add_argument(
        "--duration",
        type=number(0.0, MAX_VIDEO_S, lo_open=True, unit=" s"),
        default=None,
        help="each --expression's length in s (default 1.5)",
    )
    p.add_argument(
        "--tol-mm",
        type=number(0.0, 10.0, lo_open=True, unit=" mm"),
        default=None,
        help="the largest RMS (mm) any frame's skin may be from the simulation (default 0.1)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_face_argument(p)


def _timeline_fps(path) -> float | None:
    """The ``fps`` a timeline file declares (its top-level key), or None."""
    from pathlib import Path

    from myoface._io import parse_json, parse_toml, read_text

    p = Path(path)
    text = read_text(p, "timeline file")
    doc = parse_json(text, str(p)) if p.suffix.lower() == ".json" else parse_toml(text, str(p))
    fps = doc.get("fps") if isinstance(doc, dict) else None
    if fps is None:
        return None
    if isinstance(fps, bool) or not isinstance(fps, int | float) or not 0 < fps <= 240:
        raise MyofaceValueError(f"{p}: fps must be a number in (0, 240]; got {fps!r}")
    return float(fps)


def run(args) -> int:
    from myoface._io import OutputConflictError, check_not_input, check_output_path
    from myoface.commands.analyze import refuse
    from myoface.export import (
        DEFAULT_TOL_MM,
        clip_from_csv,
        clip_from_expressions,
        clip_from_timeline,
        export_glb,
        parse_expression,
    )
    from myoface.export.clip import DEFAULT_FPS, EXPRESSION_S

    given = [x for x in (args.csv, args.timeline, args.expression) if x]
    if len(given) != 1:
        raise MyofaceUsageError(
            "give one of: a contractions.csv, --timeline FILE, or --expression NAME[=I] ..."
        )
    if args.csv and args.fps is not None:
        raise MyofaceUsageError("--fps is for a timeline or expressions; a CSV keeps its own")
    if args.duration is not None and not args.expression:
        raise MyofaceUsageError("--duration is the length of each --expression")
    try:
        check_not_input(
            args.output,
            {"the contractions CSV": args.csv, "--timeline": args.timeline, "--face": args.face},
            "-o",
        )
    except OutputConflictError as exc:
        return refuse(args, exc)
    if not args.output.lower().endswith(".glb"):
        raise MyofaceValueError(f"-o must be a binary glTF file (.glb); got {args.output}")
    out = check_output_path(args.output, "-o")
    expressions = [parse_expression(e) for e in args.expression or []]
    timeline = None
    fps = args.fps
    if args.timeline:
        from myoface.control import load_timeline

        timeline = load_timeline(args.timeline)
        if fps is None:
            fps = _timeline_fps(args.timeline)
        if timeline.duration > MAX_VIDEO_S:
            raise MyofaceValueError(
                f"--timeline {args.timeline} lasts {timeline.duration:g} s; an export is at "
                f"most {MAX_VIDEO_S:g} s"
            )
    fps = DEFAULT_FPS if fps is None else fps
    model = load_model(args)
    if args.csv:
        clip = clip_from_csv(args.csv, model)
    elif timeline is not None:
        clip = clip_from_timeline(timeline, model, fps)
    else:
        duration = EXPRESSION_S if args.duration is None else args.duration
        if len(expressions) * duration > MAX_VIDEO_S:
            raise MyofaceValueError(f"the expressions last more than {MAX_VIDEO_S:g} s")
        clip = clip_from_expressions(expressions, model, fps, duration)
    tol = DEFAULT_TOL_MM if args.tol_mm is None else args.tol_mm
    report = export_glb(model, clip, out, tol_mm=tol, show_progress=not args.quiet)
    print(f"wrote {out}: {report.summary()}")
    return 0
