"""``myoface analyze``: face video in, muscle contractions out (T&W 1993, Section V)."""

from __future__ import annotations

from pathlib import Path

from myoface.commands._common import add_face_argument, load_model
from myoface.errors import MyofaceValueError

NAME = "analyze"
HELP = "track facial features in a video and estimate muscle contractions per frame"
DESCRIPTION = """Track the face's feature contours (snakes) through a video and estimate the
contractions of the paper's 12 muscles and the jaw rotation, frame by frame.

The contours are initialised from a JSON file you edit (--init; format in
myoface.analysis.pipeline), drawn on the calibration frame with --check-init so you can see
them. Writes into the output folder:

  contractions.csv   frame, time_s, quality, one column per muscle, jaw_angle_rad, head shift
  analysis.json      settings, calibration and per-frame diagnostics
  contractions.png   the contractions over time (the paper's Fig. 8)
  overlay.mp4        the contours on the frames (the paper's Fig. 7a)"""


def add_arguments(p):
    import argparse

    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.add_argument("video", help="a video file (mp4, mov, avi, ...) or a folder of images")
    p.add_argument("-o", "--output", help="output folder (required unless --check-init)")
    p.add_argument("--init", required=True, help="initial contours (JSON) on the first frame")
    p.add_argument(
        "--check-init", metavar="PNG", help="draw the initial contours on the first frame and stop"
    )
    p.add_argument("--max-frames", type=int, help="analyse at most this many frames")
    p.add_argument("--sigma", type=float, default=1.5, help="potential smoothing, px (default 1.5)")
    p.add_argument(
        "--refine", type=int, default=1, help="Gauss-Newton corrections per frame (default 1)"
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
    import json

    import numpy as np

    from myoface._io import atomic_output, ensure_output_dir
    from myoface.analysis.pipeline import Analyzer, load_init, write_contractions_csv
    from myoface.analysis.video import open_video
    from myoface.render import VideoWriter, progress, write_image

    video = open_video(args.video)
    init = load_init(args.init)
    if args.check_init:
        first = next(iter(video), None)
        if first is None:
            raise MyofaceValueError(f"{args.video}: the video has no frames")
        write_image(args.check_init, draw_contours(first, init))
        print(f"wrote {args.check_init}")
        return 0
    if not args.output:
        raise MyofaceValueError("give an output folder with -o")
    h_w = (video.size[1], video.size[0])
    for name, pts in init.items():
        if (pts < 0).any() or (pts[:, 0] > h_w[1] - 1).any() or (pts[:, 1] > h_w[0] - 1).any():
            raise MyofaceValueError(f"contour {name!r} of {args.init} lies outside the frame")
    out = ensure_output_dir(args.output)
    fm = load_model(args)
    an = Analyzer(fm, init, refine=args.refine, sigma=args.sigma)
    frames = []
    n = video.n_frames if args.max_frames is None else min(args.max_frames, video.n_frames or 10**9)
    with VideoWriter(out / "overlay.mp4", fps=video.fps) as vw:
        for k, frame in enumerate(
            progress(video, total=n, desc="analyzing", enabled=not args.quiet)
        ):
            if args.max_frames is not None and k >= args.max_frames:
                break
            m = an.measure(frame, k, k / video.fps)
            frames.append(m)
            vw.write(
                draw_contours(
                    frame, m.contours, (255, 215, 0) if m.quality == "ok" else (230, 40, 40)
                )
            )
    if not frames:
        raise MyofaceValueError(f"{args.video}: the video has no frames")
    jaw_max = fm.muscles.jaw.max_angle_rad if fm.muscles.jaw is not None else 0.0
    write_contractions_csv(out / "contractions.csv", an.ids, frames, jaw_max)
    table = np.array([f.contractions for f in frames])
    times = np.array([f.time_s for f in frames])
    plot_contractions(out / "contractions.png", an.ids, times, table, [f.quality for f in frames])
    side = {
        "video": str(Path(args.video).resolve()),
        "fps": video.fps,
        "size": list(video.size),
        "init": str(Path(args.init).resolve()),
        "face": args.face or "default",
        "muscles": list(an.ids),
        "mm_per_px": an.mm_per_px,
        "sigma_px": args.sigma,
        "refine": args.refine,
        "snake_params": {
            k: float(np.mean(v)) if not isinstance(v, int) else v
            for k, v in vars(an.params).items()
        },
        "frames": [
            {"frame": f.index, "quality": f.quality, "iterations": f.iterations} for f in frames
        ],
    }
    with atomic_output(out / "analysis.json") as tmp:
        tmp.write_text(json.dumps(side, indent=1))
    ok = sum(f.quality == "ok" for f in frames)
    print(f"analysed {len(frames)} frames ({ok} measured); output folder: {out.resolve()}")
    return 0
