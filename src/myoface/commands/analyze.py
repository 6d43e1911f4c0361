"""``myoface analyze``: face video in, muscle contractions out (T&W 1993, Section V)."""

from __future__ import annotations

import os
from pathlib import Path

from myoface.commands._common import (
    add_analysis_arguments,
    add_face_argument,
    analysis_settings,
    load_model,
)
from myoface.errors import MyofaceValueError

NAME = "analyze"
HELP = "track facial features in a video and estimate muscle contractions per frame"
DESCRIPTION = """Track the face's features through a video and estimate the contractions of the
paper's 12 muscles and the jaw rotation, frame by frame, against a neutral calibration frame
(the snakes: the first frame; the 3-D fit: the most neutral of the first 2 s; either: the
frame --calibration-frame names).

Trackers (--tracker):
  snakes     the paper's: deformable contours on the feature edges. They start from a JSON
             file you edit (--init; format in myoface.analysis.pipeline; --check-init draws
             them on the first frame), or, without --init, from MediaPipe's face mesh on the
             first frame with a face (needs: pip install "myoface[mediapipe]").
  landmarks  MediaPipe's face mesh on every frame (same extra): its 468 points share the
             default face's topology. By default the whole face model is fitted to them in
             3-D (head pose, every muscle and the jaw), calibrated on the person's own
             neutral (the most neutral frame of the first 2 s); --estimator paper reads the
             paper's 12 muscles in a 2-D head frame instead. Needs the default topology.

Writes into the output folder:

  contractions.csv   frame, time_s, quality, one column per muscle, jaw_angle_rad, head frame
                     (the 3-D fit: head_yaw_deg, head_pitch_deg, head_roll_deg, head_tx_mm,
                     head_ty_mm, head_tz_mm and the fit's residual_mm)
  analysis.json      settings, calibration and per-frame diagnostics
  contractions.png   the contractions over time (the paper's Fig. 8)
  overlay.mp4        the contours on the frames (the paper's Fig. 7a)
  potential.mp4      (snakes) the contours on the image potential (the paper's Fig. 7b)
  openface.csv       (--format openface) the same as OpenFace 2.2's CSV: frame, face_id,
                     timestamp, confidence, success, pose_Tx..pose_Rz, AU01_r..AU45_r
  fidelity.json/png  (--report) how much of the input's expression motion the model
                     reproduces, per region: the model's own vertices against the video read
                     by DIS optical flow (validated on known warps); beside it, labelled,
                     the earlier measure (MediaPipe's face mesh on the video and the render)

The output folder is written as one transaction: the run writes into a temporary folder
beside it (.NAME.myoface-run-*) and its files replace the earlier run's only when it succeeds
(or is interrupted: then with what it completed, analysis.json saying "interrupted"); a
failed run leaves the earlier results as they were. Other files in the folder (yours) are
never touched. While a run writes the folder, its lock file (.myoface.lock) names it and a
second run into the folder is refused; the folder may not be the input or inside it.
Ctrl-C, SIGTERM or SIGHUP stop the run within a second or two and keep what was complete."""


def add_arguments(p):
    import argparse

    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.add_argument("video", help="a video file (mp4, mov, avi, ...) or a folder of images")
    p.add_argument("-o", "--output", help="output folder (required unless --check-init)")
    add_analysis_arguments(p)
    p.add_argument(
        "--check-init", metavar="PNG", help="draw the initial contours on the first frame and stop"
    )
    p.add_argument(
        "--format",
        choices=("myoface", "openface"),
        default="myoface",
        help="openface: also write openface.csv, OpenFace 2.2's columns (head pose in mm and "
        "radians, AU intensities 0-5 from the contractions through the AU table); "
        "contractions.csv is always written",
    )
    p.add_argument(
        "--report",
        action="store_true",
        help="also measure the fidelity: the video's motion read by DIS optical flow from the "
        "calibration frame against the model's vertices (the person's face made from the "
        "calibration frame, or --face), and MediaPipe's face mesh on the video and on the "
        "resynthesis as earlier reports did; fidelity.json and fidelity.png (needs the "
        "mediapipe extra)",
    )
    p.add_argument(
        "--two-pass",
        action="store_true",
        help="landmarks' 3-D fit with its photometric term: analyse the video twice, the "
        "second time with the appearance registered on the first pass's neutral frames spread "
        "over the video (not on the first seconds' view alone): fewer expressions read at rest "
        "where the head turns (see docs/expressions.md); twice the time",
    )
    p.add_argument("--quiet", action="store_true")
    add_face_argument(p)


def run(args) -> int:
    from myoface._io import OutputConflictError

    try:
        return _run(args)
    except OutputConflictError as exc:  # a usage error, said before any work
        return refuse(args, exc)


def refuse(args, exc) -> int:
    """Say ``exc`` (an :class:`~myoface._io.OutputConflictError`: an output that is an input,
    or a folder another run writes) in one line, as the command line's usage errors are,
    and return their exit status (2)."""
    import sys

    prog = getattr(args, "_prog", None) or f"myoface {getattr(args, 'command', NAME)}"
    print(f"{prog}: error: {' '.join(str(exc).split())}", file=sys.stderr)
    return int(getattr(exc, "exit_status", 2))


def _inputs(args) -> dict:
    """The command's input files, by what they are (for :func:`~myoface._io.check_not_input`)."""
    from pathlib import Path

    video = "the input folder" if Path(args.video).is_dir() else "the input video"
    return {video: args.video, "--init": args.init, "--face": args.face, "--muscles": args.muscles}


def _run(args) -> int:
    from myoface._io import check_not_input, check_output_dir, check_output_path
    from myoface.analysis.initfiles import load_init
    from myoface.analysis.outputs import ANALYSIS_FILES, analysis_transaction, draw_contours
    from myoface.analysis.video import open_video
    from myoface.render import write_image

    if args.check_init:
        check_not_input(args.check_init, _inputs(args), "--check-init")
        check_output_path(args.check_init, "--check-init")
    elif args.output:
        check_not_input(args.output, _inputs(args), "-o", names=ANALYSIS_FILES)
        check_output_dir(args.output, "-o")
    video = open_video(args.video)
    if args.check_init:
        if not args.init:
            raise MyofaceValueError("--check-init draws the contours of --init; give --init")
        init = load_init(args.init)
        first = next(iter(video), None)
        if first is None:
            raise MyofaceValueError(f"{args.video}: the video has no frames")
        write_image(args.check_init, draw_contours(first, init))
        print(f"wrote {args.check_init}")
        return 0
    if not args.output:
        raise MyofaceValueError("give an output folder with -o")
    settings = analysis_settings(args)
    if args.two_pass:
        if settings["tracker"] != "landmarks" or not settings["photometric"]:
            raise MyofaceValueError(
                "--two-pass is for the landmarks' 3-D fit with its photometric term"
            )
        settings["two_pass"] = True
    if settings["init"]:
        load_init(settings["init"])  # a bad file fails before the model is built
    if args.report:
        check_report_possible()  # before the analysis, not after it
    # the output folder's lock and checks before the model is built: a refusal comes at once
    with analysis_transaction(args.output, args.video, inputs=_inputs(args)) as tx:
        fm = load_model(args)
        analyze_video(
            video,
            tx,
            model=fm,
            settings=settings,
            face=args.face,
            fmt=args.format,
            report=args.report,
            quiet=args.quiet,
            video_path=args.video,
        )
    return 0


def check_report_possible() -> None:
    """The fidelity report (``--report``) runs MediaPipe's face mesh: a
    :class:`~myoface.errors.MyofaceDependencyError` when it is not installed."""
    from myoface.errors import MyofaceDependencyError
    from myoface.facemesh import PIP_HINT, mediapipe_available

    if not mediapipe_available():
        raise MyofaceDependencyError(
            f"--report runs MediaPipe's face mesh, which is not installed; {PIP_HINT}"
        )


def analyze_video(
    video,
    output,
    *,
    model,
    settings: dict,
    face=None,
    fmt: str = "myoface",
    report: bool = False,
    quiet: bool = False,
    video_path=None,
):
    """``myoface analyze``'s work once its arguments are checked (also the demo's): ``video``
    (a path or an opened :class:`~myoface.analysis.video.Video`, whose file is
    ``video_path``) analysed into the folder ``output`` by
    :func:`~myoface.analysis.outputs.analyze_to_folder` with ``settings``
    (:func:`~myoface.commands._common.analysis_settings`), the same library function
    ``myoface batch`` runs for each video; then openface.csv (``fmt="openface"``) and the
    fidelity report (``report``); the command's lines printed. Returns the
    :class:`~myoface.analysis.outputs.FolderResult`."""
    from myoface.analysis.outputs import analyze_to_folder, limit_note, own_neutral_note

    video_path = video if video_path is None else video_path
    lines: list[str] = []  # the report's, said once its files are in place
    res = analyze_to_folder(
        video,
        output,
        model=model,
        **settings,
        face=face,
        show_progress=not quiet,
        finish=lambda folder, res: _extra_outputs(
            folder, res, video_path, model, face=face, fmt=fmt, report=report, quiet=quiet,
            lines=lines,
        ),
    )  # fmt: skip
    for note in (limit_note(res.at_limit()), own_neutral_note(res.n_measured, len(res.frames))):
        if note is not None:
            lines.append(note)
    try:
        for line in lines:
            print(line)
        print(
            f"analysed {len(res.frames)} frame{'' if len(res.frames) == 1 else 's'} "
            f"({res.n_measured} measured, against frame "
            f"{res.calibration_frame} as the neutral); output folder: {res.folder.resolve()}"
        )
    except KeyboardInterrupt as exc:  # (the outputs are in place)
        exc.add_note(f"the analysis was complete: {res.folder}")
        raise
    return res


def _extra_outputs(folder, res, video_path, model, *, face, fmt, report, quiet, lines) -> None:
    """openface.csv (``--format openface``) and the fidelity report (``--report``), made from
    the analysis' finished files in ``folder`` (the transaction's; ``res.folder`` is where
    they go); after an interruption in the frames (``res.interrupted``), openface.csv only.
    The report's printed lines are added to ``lines``."""
    if fmt == "openface":
        from myoface.analysis.openface import write_openface_csv

        res.stage = "openface"
        try:
            write_openface_csv(folder / "contractions.csv", folder / "openface.csv")
        except KeyboardInterrupt as exc:
            exc.add_note("openface.csv (--format openface) was not made")
            raise
    if not report:
        return
    if res.interrupted is not None:
        res.notes.append("the fidelity report (--report) was not made")
        return
    from myoface.analysis.fidelity import write_fidelity_report

    res.stage = "report"
    try:
        # the person's own face from the calibration frame, unless a face was given
        fid = write_fidelity_report(
            folder,
            video_path,
            model=model if face else None,
            fallback_model=model,  # when no face is found on the calibration frame
            show_progress=not quiet,
        )
        _name_final_paths(folder / "fidelity.json", folder, res.folder)
    except KeyboardInterrupt as exc:
        from myoface.analysis.outputs import REPORT_FILES

        for name in REPORT_FILES:  # a report is both files or none
            (folder / name).unlink(missing_ok=True)
        exc.add_note("the fidelity report (--report) was not made")
        raise
    lines.extend(fidelity_lines(fid, res.folder / "fidelity.json"))


def _name_final_paths(path, folder, final) -> None:
    """The JSON file ``path`` with the paths into ``folder`` (the transaction's) written as
    into ``final``, where the files will be."""
    import json

    from myoface._io import atomic_output

    src = str(Path(folder).resolve())
    dst = str(Path(final).resolve())

    def fix(v):
        if isinstance(v, str) and (v == src or v.startswith(src + os.sep)):
            return dst + v[len(src) :]
        if isinstance(v, dict):
            return {k: fix(x) for k, x in v.items()}
        if isinstance(v, list):
            return [fix(x) for x in v]
        return v

    doc = json.loads(Path(path).read_text(encoding="utf-8"))
    with atomic_output(path) as tmp:
        tmp.write_text(json.dumps(fix(doc), indent=1), encoding="utf-8")


def fidelity_lines(res, path=None) -> list[str]:
    """The printed lines of a fidelity report (``--report``; the demo's): the measure (the
    model's vertices against the video read by the validated motion reader), then, labelled,
    MediaPipe's face mesh on both, the measure of earlier reports, when it was made; the first
    line ends with ``path`` (fidelity.json) when given."""

    def scores(r):
        o, mc = r.overall, r.regions["mouth_corners"]
        return (
            f"{o.explained:.2f} of the input's expression motion explained (gain {o.gain:.2f}, "
            f"correlation {o.corr:.2f}; mouth corners' gain {mc.gain:.2f})"
        )

    where = "" if path is None else f"; {path}"
    n, lost = res.n_frames, getattr(res, "frames_unjudged", 0)
    if lost and not res.valid:
        lines = [
            f"fidelity: not measurable on this video: the judge ({res.reader}) could not "
            f"read {lost} of the {n + lost} measured frames (their look too far from the "
            f"calibration frame's: eyes shut or opened, a laugh, a hand; most of their points' "
            f"readings fail its forward-backward check); on the {n} it read, {scores(res)}"
            f"{where}"
        ]
    else:
        judged = f" ({n} of the {n + lost} measured frames; the judge could not read the rest)"
        lines = [
            f"fidelity: {scores(res)}; the model's vertices against the video read by "
            f"{res.reader}{judged if lost else ''}{where}"
        ]
    if res.mediapipe_on_both is not None:
        lines.append(
            f"fidelity, MediaPipe's face mesh on both (earlier reports' measure, not a valid "
            f"judge): {scores(res.mediapipe_on_both)}"
        )
    return lines
