"""``myoface analyze``: face video in, muscle contractions out (T&W 1993, Section V)."""

from __future__ import annotations

from pathlib import Path

from myoface.commands._common import MAX_REFINE, add_face_argument, integer, load_model, number
from myoface.errors import MyofaceValueError

NAME = "analyze"
HELP = "track facial features in a video and estimate muscle contractions per frame"
DESCRIPTION = """Track the face's features through a video and estimate the contractions of the
paper's 12 muscles and the jaw rotation, frame by frame. The first frame is the neutral
calibration frame.

Trackers (--tracker):
  snakes     the paper's: deformable contours on the feature edges. They start from a JSON
             file you edit (--init; format in myoface.analysis.pipeline; --check-init draws
             them on the first frame), or, without --init, from MediaPipe's face mesh on the
             first frame with a face (needs: pip install "myoface[mediapipe]").
  landmarks  MediaPipe's face mesh on every frame (same extra): its 468 points share the
             default face's topology, so fiducials are read at the model's own vertices.
             Robust on real video where faces are small; needs the default face.

Writes into the output folder:

  contractions.csv   frame, time_s, quality, one column per muscle, jaw_angle_rad, head frame
  analysis.json      settings, calibration and per-frame diagnostics
  contractions.png   the contractions over time (the paper's Fig. 8)
  overlay.mp4        the contours on the frames (the paper's Fig. 7a)
  potential.mp4      (snakes) the contours on the image potential (the paper's Fig. 7b)"""


def add_arguments(p):
    import argparse

    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.add_argument("video", help="a video file (mp4, mov, avi, ...) or a folder of images")
    p.add_argument("-o", "--output", help="output folder (required unless --check-init)")
    p.add_argument(
        "--tracker",
        choices=("snakes", "landmarks"),
        default="snakes",
        help="feature tracker (default: snakes, the paper's)",
    )
    p.add_argument(
        "--init",
        help="initial contours (JSON) on the first frame, for the snakes (default: found "
        "automatically with MediaPipe's face mesh)",
    )
    p.add_argument(
        "--check-init", metavar="PNG", help="draw the initial contours on the first frame and stop"
    )
    p.add_argument(
        "--calibration-frame",
        type=integer(0),
        default=0,
        metavar="N",
        help="the neutral frame to calibrate on; analysis starts there (default 0); with "
        "--init, the contours are on this frame",
    )
    p.add_argument("--max-frames", type=integer(1), help="analyse at most this many frames")
    p.add_argument(
        "--sigma",
        type=number(0.0, 100.0, lo_open=True, unit=" px"),
        default=None,
        help="potential smoothing, px (default: 1.2 mm on the face, from its size in the frame)",
    )
    p.add_argument(
        "--estimator",
        choices=("curves", "fiducials"),
        default="curves",
        help="(snakes) how contractions are read off the contours: the model's skin curves "
        "fitted to the whole contours (default), or the paper's fiducial points",
    )
    p.add_argument(
        "--refine",
        type=integer(0, MAX_REFINE),
        help="Gauss-Newton corrections per frame through the model, 0-10 "
        "(default 1 for snakes, 0 for landmarks)",
    )
    p.add_argument("--quiet", action="store_true")
    add_face_argument(p)


def draw_contours(frame, contours: dict, color=(255, 215, 0)):
    import numpy as np

    img = frame.copy()
    h, w = img.shape[:2]
    for pts in contours.values():
        p = np.asarray(pts, float)
        n = max(2, int(np.linalg.norm(np.diff(p, axis=0), axis=1).sum() * 2))
        t = np.linspace(0, len(p) - 1, n)
        x = np.interp(t, np.arange(len(p)), p[:, 0])
        y = np.interp(t, np.arange(len(p)), p[:, 1])
        xi = np.clip(np.round(x).astype(int), 0, w - 1)
        yi = np.clip(np.round(y).astype(int), 0, h - 1)
        img[yi, xi] = color
    return img


def potential_image(pot):
    """The potential as a grey RGB image, edges (its ravines) dark, as in the paper's Fig. 7b."""
    import numpy as np

    lo, hi = np.percentile(pot, [1, 99.5])
    g = np.clip((pot - lo) / max(hi - lo, 1e-12), 0, 1)
    return np.repeat((g * 255).astype(np.uint8)[:, :, None], 3, axis=2)


def plot_contractions(path, ids, times, table, quality):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from myoface._io import atomic_output

    groups = {}
    for j, k in enumerate(ids):
        base = k[:-2] if k.endswith(("_l", "_r")) else k
        groups.setdefault(base, []).append(j)
    fig, axes = plt.subplots(len(groups), 1, figsize=(8, 1.3 * len(groups) + 0.6), sharex=True)
    for ax, (base, cols) in zip(axes, groups.items(), strict=True):
        for j in cols:
            ax.plot(times, table[:, j], label=ids[j][-1] if ids[j][-2] == "_" else "")
        ax.set_ylim(-0.02, 1.02)
        ax.set_ylabel(base.replace("_", " "), rotation=0, ha="right", fontsize=8)
        ax.tick_params(labelsize=7)
        bad = [t for t, q in zip(times, quality, strict=True) if q != "ok"]
        for t in bad:
            ax.axvline(t, color="0.85", lw=2, zorder=0)
    axes[0].legend(loc="upper right", fontsize=7, ncol=2)
    axes[-1].set_xlabel("time (s)")
    fig.suptitle("estimated contractions (grey: frames that could not be measured)", fontsize=9)
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)


def run(args) -> int:

    from myoface._io import atomic_output, check_output_dir, check_output_path, output_dir
    from myoface.analysis.pipeline import load_init, make_analyzer
    from myoface.analysis.video import open_video
    from myoface.render import VideoWriter, progress, write_image

    if args.check_init:
        check_output_path(args.check_init, "--check-init")
    elif args.output:
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
    if args.init and args.tracker == "landmarks":
        raise MyofaceValueError("--init is for the snakes; the landmark tracker needs none")
    init = load_init(args.init) if args.init else None  # a bad file fails before the model
    fm = load_model(args)
    an, how, start = make_analyzer(
        fm,
        video,
        args.tracker,
        init,
        args.calibration_frame,
        args.refine,
        args.sigma,
        estimator=args.estimator,
    )
    if args.init:
        how = str(Path(args.init).resolve())
    with output_dir(args.output, "-o") as out:  # a failure removes the folders it made
        try:
            frames = _analyze(args, video, an, out, start, progress, VideoWriter)
        finally:
            an.close()
        _write_results(args, video, fm, an, out, frames, how, start, atomic_output)
    ok = sum(f.quality == "ok" for f in frames)
    print(f"analysed {len(frames)} frames ({ok} measured); output folder: {out.resolve()}")
    return 0


def _write_results(args, video, fm, an, out, frames, how, start, atomic_output) -> None:
    """contractions.csv, contractions.png and analysis.json."""
    import json

    import numpy as np
    from myoface.analysis.pipeline import write_contractions_csv

    jaw_max = fm.muscles.jaw.max_angle_rad if fm.muscles.jaw is not None else 0.0
    write_contractions_csv(out / "contractions.csv", an.ids, frames, jaw_max)
    table = np.array([f.contractions for f in frames])
    times = np.array([f.time_s for f in frames])
    plot_contractions(out / "contractions.png", an.ids, times, table, [f.quality for f in frames])
    side = {
        "video": str(Path(args.video).resolve()),
        "fps": video.fps,
        "size": list(video.size),
        "tracker": args.tracker,
        "init": how,
        "calibration_frame": start,
        "face": args.face or "default",
        "muscles": list(an.ids),
        "mm_per_px": an.mm_per_px,
        "refine": an.refine,
        "frames": [
            {"frame": f.index, "quality": f.quality, "iterations": f.iterations} for f in frames
        ],
    }
    if args.tracker == "snakes":
        side["sigma_px"] = an.sigma
        side["estimator"] = an.method
        side["snake_params"] = {
            k: float(np.mean(v)) if not isinstance(v, int) else v
            for k, v in vars(an.params).items()
        }
    with atomic_output(out / "analysis.json") as tmp:
        tmp.write_text(json.dumps(side, indent=1))


def _analyze(args, video, an, out, start, progress, VideoWriter):
    """Measure every frame from ``start`` on, writing the overlay videos; a clear error when
    nothing could be measured."""
    import contextlib

    from myoface.analysis.pipeline import measure_frames

    frames = []
    n = video.n_frames
    if n is not None:
        n -= start
    if args.max_frames is not None:
        n = args.max_frames if n is None else min(n, args.max_frames)
    with contextlib.ExitStack() as stack:
        vw = stack.enter_context(VideoWriter(out / "overlay.mp4", fps=video.fps))
        pw = None
        if args.tracker == "snakes":
            pw = stack.enter_context(VideoWriter(out / "potential.mp4", fps=video.fps))
        measured = measure_frames(video, an, start, args.max_frames)
        for frame, m in progress(measured, total=n, desc="analyzing", enabled=not args.quiet):
            frames.append(m)
            color = (255, 215, 0) if m.quality == "ok" else (230, 40, 40)
            vw.write(draw_contours(frame, m.contours, color))
            if pw is not None:
                pw.write(draw_contours(potential_image(an.last_potential), m.contours, color))
        if not frames:
            raise MyofaceValueError(f"{args.video}: the video has no frames")
        if not any(f.quality == "ok" for f in frames):
            raise MyofaceValueError(f"{args.video}: no frame could be measured (no face found?)")
    return frames
