"""``myoface demo``: what myoface does, in one command."""

from __future__ import annotations

from pathlib import Path

NAME = "demo"
HELP = "the six universal expressions on the default face: a contact sheet and a video"
DESCRIPTION = """Build the default face model (face mesh, layered tissue lattice, 29 muscles + jaw),
drive it through the six universal expressions (FACS action units -> muscles -> tissue physics),
render them, and write into the output folder:

  expressions.png   a contact sheet of the six expressions at apex (like the paper's Fig. 1)
  expressions.mp4   a video: each expression rises from neutral, holds and fades
  muscles.png       the muscle vectors on the neutral face (like the paper's Fig. 4)"""


def add_arguments(p):
    import argparse

    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.add_argument(
        "-o", "--output", default="myoface-demo", help="output folder (default ./myoface-demo)"
    )
    p.add_argument("--size", type=int, default=384, help="image size in pixels (default 384)")
    p.add_argument("--fps", type=float, default=25.0)
    p.add_argument("--no-video", action="store_true", help="skip the video (faster)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")


def contact_sheet(images: dict, path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from myoface._io import atomic_output

    names = list(images)
    cols = 3
    rows = (len(names) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 3.5 * rows), facecolor="#16181c")
    for ax in axes.ravel():
        ax.axis("off")
    for ax, name in zip(axes.ravel(), names, strict=False):
        ax.imshow(images[name])
        ax.set_title(name, color="#e8e8e8", fontsize=13)
    fig.suptitle(title, color="#e8e8e8", fontsize=11)
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp, dpi=110, facecolor=fig.get_facecolor())
    plt.close(fig)


def run(args) -> int:
    import time

    from myoface._io import ensure_output_dir
    from myoface.control import Timeline, expression_contractions, list_expressions
    from myoface.control.timeline import Event
    from myoface.model import build_face_model
    from myoface.render import Renderer, write_image
    from myoface.synth import Synthesizer, make_camera, muscle_segments

    out = ensure_output_dir(args.output)
    t0 = time.perf_counter()
    fm = build_face_model()
    print(f"face model: {fm.summary()}")
    cam = make_camera(fm.face.vertices, "front", args.size, args.size)
    syn = Synthesizer(fm, Renderer(fm.face, cam))
    apex = {}
    for name in list_expressions():
        fm.reset()
        apex[name] = syn.image(expression_contractions(name, 1.0, fm.ids))
    contact_sheet(
        apex,
        out / "expressions.png",
        "myoface: FACS action units -> 29 muscles + jaw -> layered tissue physics -> render",
    )
    print(f"wrote {out / 'expressions.png'}")
    fm.reset()
    from myoface.render import overlay_segments

    ins, org = muscle_segments(fm)
    tq = make_camera(fm.face.vertices, "three_quarter", args.size, args.size)
    img = Renderer(fm.face, tq).render()
    write_image(out / "muscles.png", overlay_segments(img, tq, ins, org))
    print(f"wrote {out / 'muscles.png'}")
    if not args.no_video:
        events = [Event("expression", name, 0.2 + 1.6 * k, 1.4, 1.0) for k, name in enumerate(apex)]
        tl = Timeline(events, 0.4 + 1.6 * len(events), "demo")
        syn.video(tl, out / "expressions.mp4", fps=args.fps, show_progress=not args.quiet)
        print(f"wrote {out / 'expressions.mp4'} ({tl.duration:.1f} s)")
    print(f"done in {time.perf_counter() - t0:.0f} s; output folder: {out.resolve()}")
    return 0
