"""``myoface encode``: a face video to a model-based stream (.myo), a few dozen bits a frame."""

from __future__ import annotations

import sys
from pathlib import Path

from myoface.errors import MyofaceFileNotFoundError, MyofaceValueError

NAME = "encode"
HELP = "code a face video as head pose, muscle contractions and gaze (a .myo stream)"
DESCRIPTION = """Analyse a face video with the landmark tracker's 3-D fit (head pose, every
muscle, the jaw, the lids, the eyes' gaze) and write it as a stream: a header sent once (the
person's face as offsets from the default face, the calibration frame's picture compressed
with WebP, AVIF or JPEG, whichever is smallest at the quality's PSNR, the camera), then one
packet per frame, quantised, predicted from the previous frame and range-coded with adaptive
models. The format: docs/codec-format.md. Decode with myoface decode.

Each packet is written (and flushed) as its frame is analysed. -o FILE is written under a
temporary name and renamed when complete; an interrupted encode (Ctrl-C, SIGTERM) ends the
stream properly and keeps it with the frames analysed so far. --live writes FILE in place
as it grows (myoface decode --follow FILE reads it meanwhile); -o - writes to standard
output (a pipe)."""


def add_arguments(p):
    import argparse

    from myoface.codec.entropy import DEFAULT_QUALITY, QUALITIES

    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.add_argument("video", help="a face video (mp4, mov, ...)")
    p.add_argument("-o", "--output", required=True, help="the stream (.myo), or - for stdout")
    p.add_argument(
        "--quality",
        choices=tuple(QUALITIES),
        default=DEFAULT_QUALITY,
        help=f"the quantiser's steps and the picture's PSNR target (default {DEFAULT_QUALITY})",
    )
    p.add_argument(
        "--image-codec",
        choices=("webp", "avif", "jpeg"),
        help="the calibration picture's codec (default: the smallest at the quality's PSNR)",
    )
    p.add_argument(
        "--calibration-frame",
        type=int,
        metavar="N",
        help="the neutral frame, where the stream starts (default: the most neutral of the "
        "first 2 s, the stream starting at frame 0)",
    )
    p.add_argument("--max-frames", type=int, metavar="N", help="encode at most N frames")
    p.add_argument(
        "--live",
        action="store_true",
        help="write the file in place as it grows (no rename; an encode that fails leaves a "
        "truncated stream, decodable up to there)",
    )
    p.add_argument("--quiet", action="store_true")


def run(args) -> int:
    from myoface._io import OutputConflictError, atomic_output, check_not_input, check_output_path
    from myoface._signals import interrupt_in
    from myoface.codec.encode import VideoParams, encode_params
    from myoface.commands.analyze import refuse

    if not Path(args.video).exists():
        raise MyofaceFileNotFoundError(f"no such video: {args.video}")
    if args.max_frames is not None and args.max_frames < 1:
        raise MyofaceValueError(f"--max-frames must be at least 1; got {args.max_frames}")
    to_stdout = args.output == "-"
    if not to_stdout:
        try:
            check_not_input(args.output, {"the video": args.video}, "-o")
        except OutputConflictError as exc:
            return refuse(args, exc)
        check_output_path(args.output, "-o")
    live = None
    if args.live and not to_stdout:  # (there at once: a reader may follow it from the start)
        live = open(args.output, "wb")  # noqa: SIM115 (closed below)
    try:
        vp = VideoParams(
            args.video,
            calibration_frame=args.calibration_frame,
            max_frames=args.max_frames,
            show_progress=not args.quiet,
        )
    except BaseException:
        if live is not None:
            live.close()
            Path(args.output).unlink(missing_ok=True)  # (nothing was written)
        raise

    def encode(fh):
        return encode_params(
            fh, vp, lambda: vp.setup, quality=args.quality, image_codec=args.image_codec
        )

    where = "<stdout>" if to_stdout else args.output
    try:
        if to_stdout:
            stats = encode(sys.stdout.buffer)
        elif live is not None:
            with live:
                stats = encode(live)
        else:
            with atomic_output(args.output) as tmp:
                try:
                    with open(tmp, "wb") as fh:
                        stats = encode(fh)
                except BaseException as err:
                    if interrupt_in(err) is None or tmp.stat().st_size == 0:
                        raise
                    # the stream was ended with the frames encoded: keep it (renamed below)
                    import os

                    os.replace(tmp, args.output)
                    raise
    except BaseException as err:
        # (an interrupt may come wrapped: a SystemError from a C callback it landed in)
        stop = interrupt_in(err)
        if stop is None:
            raise
        stop.add_note(f"the stream {where} is complete with the frames encoded before the stop")
        raise
    out = sys.stderr if to_stdout else sys.stdout
    print(
        f"wrote {where}: {stats.n_frames} frames, header {stats.header_bytes} bytes "
        f"(picture {stats.picture['codec'].upper()}), {stats.bits_per_frame:.1f} bits/frame "
        f"after it, {stats.total_bytes} bytes in all",
        file=out,
    )
    return 0
