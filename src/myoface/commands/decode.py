"""``myoface decode``: a .myo stream to a video."""

from __future__ import annotations

from pathlib import Path

from myoface.errors import MyofaceFileNotFoundError, MyofaceValueError

NAME = "decode"
HELP = "reconstruct a video from a .myo stream (myoface encode)"
DESCRIPTION = """Decode a stream written by myoface encode: the calibration picture moved by
the person's model, frame by frame (myoface.codec.picture), into a video.

STREAM is a file, or - for standard input (a pipe: frames are decoded as they arrive). With
--follow the file may still be growing (myoface encode --live): the decoder waits for its
packets until the stream's end marker, or until the file has not grown for --timeout seconds.

A stream that stops before its end marker keeps the frames decoded so far in the video and
says so (exit status 1); a corrupted stream or one of another format version ends in one
line (exit status 1) and writes no video."""


def add_arguments(p):
    import argparse

    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.add_argument("stream", help="a .myo stream, or - for standard input")
    p.add_argument("-o", "--output", required=True, help="output video (.mp4)")
    p.add_argument(
        "--follow", action="store_true", help="the file is still being written: wait for it"
    )
    p.add_argument(
        "--timeout",
        type=float,
        default=10.0,
        metavar="S",
        help="with --follow: give up when the file has not grown for S seconds (default 10)",
    )
    p.add_argument("--quiet", action="store_true")


def run(args) -> int:
    from myoface._io import OutputConflictError, check_not_input, check_output_path
    from myoface.codec.decode import decode_to_video
    from myoface.codec.stream import FileSource, PipeSource
    from myoface.commands.analyze import refuse

    if not (0 < args.timeout <= 3600):
        raise MyofaceValueError(f"--timeout must be in (0, 3600] s; got {args.timeout}")
    if not args.output.lower().endswith((".mp4", ".mov", ".mkv", ".avi")):
        raise MyofaceValueError(f"-o must be a video file (.mp4); got {args.output}")
    if args.stream != "-":
        if args.follow:  # (a live encode may not have made it yet)
            import time

            t0 = time.monotonic()
            while not Path(args.stream).exists() and time.monotonic() - t0 < args.timeout:
                time.sleep(0.05)
        if not Path(args.stream).is_file():
            raise MyofaceFileNotFoundError(f"no such stream: {args.stream}")
        try:
            check_not_input(args.output, {"the stream": args.stream}, "-o")
        except OutputConflictError as exc:
            return refuse(args, exc)
    check_output_path(args.output, "-o")
    if args.stream == "-":
        source = PipeSource()
    else:
        source = FileSource(args.stream, follow=args.follow, timeout_s=args.timeout)
    stats = decode_to_video(source, args.output, show_progress=not args.quiet)
    secs = stats.setup_seconds + stats.frame_seconds  # (a pipe's: waiting for the sender too)
    print(f"wrote {args.output} ({stats.n_frames} frames in {secs:.1f} s)")
    return 0
