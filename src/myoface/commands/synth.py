"""``myoface synth``: render expressions, action units, muscles or a timeline to PNG or MP4."""

from __future__ import annotations

import sys
from pathlib import Path

from myoface.commands._common import (
    MAX_VIDEO_S,
    _shown,
    add_face_argument,
    check_video_size,
    fps_type,
    load_model,
    number,
    side_type,
)
from myoface.errors import MyofaceFileNotFoundError, MyofaceUsageError, MyofaceValueError

NAME = "synth"
HELP = "render an expression / action units / muscles / a timeline to an image or a video"
DESCRIPTION = """Synthesize facial expressions with the physics-based face model.

Examples:
  myoface synth --expression surprise --intensity 0.8 --duration 1.5 -o surprise.mp4
  myoface synth --au 12=0.7 --au 6=0.4 -o smile.png
  myoface synth --muscle zygomaticus_major_l=0.6 -o half-smile.png
  myoface synth --timeline examples/talk.toml -o talk.mp4
  myoface synth --in-photo me.jpg --expression happiness -o me-smiling.png
  myoface synth --in-photo me.jpg --face me.myoface --timeline examples/talk.toml -o me.mp4

The output type follows the suffix: .png/.jpg for one image at the apex, .mp4 for a video."""


def _pairs(items, what):
    """``{name: value text}`` of the ``--au`` / ``--muscle`` requests ``items``; a name given
    twice is a usage error."""
    out = {}
    for it in items or []:
        if "=" not in it:
            raise MyofaceUsageError(f"--{what} takes NAME=VALUE (e.g. 12=0.7); got {_shown(it)}")
        k, v = it.split("=", 1)
        if k.strip() in out:
            raise MyofaceUsageError(f"--{what} {k.strip()[:40]} is given twice")
        out[k.strip()] = v.strip()
    return out


def _request(what: str):
    """An argparse ``type`` for ``--au N=I`` (``what`` "au") and ``--muscle ID=C``
    ("muscle"): the text as given, once its syntax and its intensity (in [0, 1], or a letter
    A-E) are checked, so that a value outside its limits is a usage error (exit status 2).
    The action unit and the muscle are checked after (:func:`_check_requests`; a muscle's
    name needs the model)."""

    def parse(text: str) -> str:
        import argparse

        from myoface.control.facs import parse_intensity
        from myoface.errors import MyofaceError

        if "=" not in text:
            raise argparse.ArgumentTypeError(
                f"expected NAME=VALUE (e.g. 12=0.7); got {_shown(text)}"
            )
        k, v = (x.strip() for x in text.split("=", 1))
        name = k if k.isprintable() and len(k) <= 40 else _shown(k)  # (a newline: repr)
        try:
            parse_intensity(v, f"AU{name}" if what == "au" else f"muscle {name}")
        except MyofaceError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        return text

    parse.__name__ = f"{what} request"
    return parse


def _check_requests(args) -> None:
    """The --au / --muscle requests: no name twice (a usage error) and known action units,
    before the model is built (the muscle names need the model)."""
    from myoface.control.facs import parse_au

    for k in _pairs(args.au, "au"):
        parse_au(k)
    _pairs(args.muscle, "muscle")


def add_arguments(p):
    import argparse

    p.formatter_class = argparse.RawDescriptionHelpFormatter
    src = p.add_argument_group("what to show (combine freely, except --timeline)")
    src.add_argument(
        "--expression", metavar="NAME", help="anger, disgust, fear, happiness, sadness, surprise"
    )
    src.add_argument(
        "--intensity",
        type=number(0.0, 1.0),
        default=None,
        help="emphasis of --expression / --viseme in [0, 1] (default 1)",
    )
    src.add_argument(
        "--au",
        action="append",
        type=_request("au"),
        metavar="N=I",
        help="action unit N at intensity I in [0, 1] or A-E (repeatable; L12/R12 for one side)",
    )
    src.add_argument(
        "--muscle",
        action="append",
        type=_request("muscle"),
        metavar="ID=C",
        help="muscle contraction C in [0, 1] (repeatable); see `myoface info --muscles-list`",
    )
    src.add_argument("--viseme", metavar="NAME", help="a speech viseme (e.g. A, O, U, PBM, FV)")
    src.add_argument("--timeline", metavar="FILE", help="a timeline file (TOML/JSON) of events")
    out = p.add_argument_group("output")
    out.add_argument(
        "-o", "--output", required=True, help="output .png/.jpg (apex) or .mp4 (video)"
    )
    out.add_argument(
        "--duration",
        type=number(0.0, MAX_VIDEO_S, lo_open=True, unit=" s"),
        default=1.5,
        help="event duration in s for videos (default 1.5; at most 3600)",
    )
    out.add_argument("--fps", type=fps_type, default=30.0, help="frames per second, up to 240")
    out.add_argument("--width", type=side_type, default=512, help="pixels, 16-4096")
    out.add_argument("--height", type=side_type, default=512, help="pixels, 16-4096")
    out.add_argument(
        "--view", default="front", choices=("front", "three_quarter", "profile"), help="camera"
    )
    out.add_argument(
        "--ssaa",
        type=int,
        choices=(1, 2, 3, 4),
        default=2,
        help="anti-aliasing supersampling 1-4 (default 2)",
    )
    out.add_argument("--texture", metavar="IMAGE", help="a texture image for the face's UVs")
    out.add_argument("--overlay", choices=["muscles"], help="draw the muscle vectors")
    out.add_argument(
        "--dynamics",
        default="quasistatic",
        choices=("quasistatic", "rk2"),
        help="quasistatic (default) or rk2",
    )
    out.add_argument("--quiet", action="store_true", help="no progress bar")
    add_face_argument(p)
    ph = p.add_argument_group("a photo, animated (needs the mediapipe extra)")
    ph.add_argument(
        "--in-photo",
        metavar="IMAGE",
        help="animate this photo of a face instead of rendering the model: the photo smiles, "
        "frowns, talks, blinks, looks around (the output has the photo's size, at most 1920 px "
        "a side; --width/--height/--view/--ssaa do not apply). --face: the person's model "
        "(default: one made from the photo, as `myoface face from-photo` makes it)",
    )


def _apex(args, fm):
    import numpy as np

    from myoface.control import (
        au_contractions,
        expression_contractions,
        muscle_contractions,
        viseme_contractions,
    )

    parts = []
    ids = fm.ids
    intensity = 1.0 if args.intensity is None else args.intensity
    if args.expression:
        if args.expression in fm.expressions:  # the model's own (e.g. Waters' macros)
            from myoface.control.facs import parse_intensity

            parts.append(
                fm.expressions[args.expression] * parse_intensity(intensity, "--intensity")
            )
        else:
            parts.append(expression_contractions(args.expression, intensity, ids))
    if args.au:
        parts.append(au_contractions(_pairs(args.au, "au"), ids))
    if args.muscle:
        parts.append(muscle_contractions(_pairs(args.muscle, "muscle"), ids))
    if args.viseme:
        parts.append(viseme_contractions(args.viseme, intensity, ids))
    if not parts:  # no control: the neutral face
        return np.zeros(len(ids))
    keep = np.ones(len(ids))
    for c in parts:
        keep *= 1 - c
    return 1 - keep


def run(args) -> int:
    import numpy as np

    from myoface._io import check_output_path
    from myoface.control import load_timeline
    from myoface.render import Renderer, write_image
    from myoface.synth import Synthesizer, make_camera

    out = check_output_path(args.output, "-o")
    suffix = out.suffix.lower()
    video = suffix in (".mp4", ".mov", ".mkv", ".avi")
    if not video and suffix not in (".png", ".jpg", ".jpeg"):
        raise MyofaceValueError(f"-o must end in .png, .jpg or .mp4; got {out.name}")
    if args.timeline and any((args.expression, args.au, args.muscle, args.viseme)):
        raise MyofaceUsageError("--timeline cannot be combined with other event options")
    if args.intensity is not None and not (args.expression or args.viseme):
        raise MyofaceUsageError(
            "--intensity is the emphasis of --expression or --viseme; give one of them (an "
            "action unit's or a muscle's value is in its --au N=I or --muscle ID=C)"
        )
    if args.texture and not Path(args.texture).is_file():
        raise MyofaceFileNotFoundError(f"--texture: no such texture image: {args.texture}")
    _check_requests(args)
    timeline = load_timeline(args.timeline) if args.timeline else None
    if video and timeline is not None and timeline.duration > MAX_VIDEO_S:
        raise MyofaceValueError(
            f"--timeline {args.timeline} lasts {timeline.duration:g} s; a video is at most "
            f"{MAX_VIDEO_S:g} s"
        )
    if args.in_photo:
        return _run_photo(args, out, video, timeline)
    if video:
        check_video_size(out, args.width, args.height)
    fm = load_model(args)
    apex = None if timeline else _apex(args, fm)
    cam = make_camera(fm.face.vertices, args.view, args.width, args.height)
    renderer = Renderer(fm.face, cam, texture=args.texture, ssaa=args.ssaa)
    syn = Synthesizer(fm, renderer, overlay=args.overlay, dynamics=args.dynamics)
    if not video:
        if timeline is not None:
            t_apex = max(timeline.events, key=lambda e: e.intensity)
            a0, a1 = t_apex.apex_interval()
            apex = timeline.contractions([0.5 * (a0 + a1)], fm.ids)[0]
        img = syn.image(apex)
        write_image(out, img)
    else:
        if timeline is None:
            # one event: ramp up, hold, ramp down, with a short rest before and after
            timeline = _ApexTimeline(apex, args.duration, fm.ids)
        syn.video(timeline, out, fps=args.fps, show_progress=not args.quiet)
    st = syn.stats
    msg = f"wrote {out}"
    if st.relax_ms:
        msg += (
            f" ({len(st.render_ms)} frame(s); median relax {np.median(st.relax_ms):.0f} ms, "
            f"render {np.median(st.render_ms):.0f} ms per frame)"
        )
    print(msg)
    if st.unconverged:
        print(
            f"note: the tissue did not fully converge on {st.unconverged} frame(s)", file=sys.stderr
        )
    return 0


def _run_photo(args, out, video: bool, timeline) -> int:
    """``--in-photo``: the photo moved by the model (:mod:`myoface.codec.photo`)."""
    import numpy as np

    from myoface.codec.photo import PhotoAnimation, read_photo
    from myoface.render import VideoWriter, progress, write_image

    for given, what in ((args.texture, "--texture"), (args.overlay, "--overlay")):
        if given:
            raise MyofaceUsageError(
                f"{what} does not apply to --in-photo (the photo is the picture)"
            )
    if args.view != "front" or args.dynamics != "quasistatic":
        raise MyofaceUsageError("--view and --dynamics do not apply to --in-photo")
    photo = read_photo(args.in_photo)
    fm = load_model(args) if args.face else None
    anim = PhotoAnimation.from_image(photo, fm)
    h, w = photo.shape[:2]
    how = "a face made from the photo" if anim.made_face else f"--face {args.face}"
    from myoface.face.image import image_size

    w0, h0 = image_size(args.in_photo, "photo")
    size = f"{w}x{h} px" if (w0, h0) == (w, h) else f"{w0}x{h0} px, animated at {w}x{h}"
    print(f"photo      {size}, the model ({how}) aligned to its face")
    ids = anim.model.ids
    if not video:
        if timeline is not None:
            t_apex = max(timeline.events, key=lambda e: e.intensity)
            a0, a1 = t_apex.apex_interval()
            t = 0.5 * (a0 + a1)
            apex = timeline.contractions([t], ids)[0]
            gaze = timeline.gaze([t])[0] if timeline.has_gaze else None
        else:
            apex, gaze = _apex(args, anim.model), None
        write_image(out, anim.image(apex, gaze))
        print(f"wrote {out}")
        return 0
    check_video_size(out, w, h)
    if timeline is None:
        timeline = _ApexTimeline(_apex(args, anim.model), args.duration, ids)
    n = max(1, int(round(timeline.duration * args.fps)) + 1)
    times = np.arange(n) / args.fps
    table = timeline.contractions(times, ids)
    gaze = timeline.gaze(times) if getattr(timeline, "has_gaze", False) else None
    frames = progress(anim.frames(table, gaze), total=n, desc="animating", enabled=not args.quiet)
    with VideoWriter(out, args.fps, background=True) as vw:
        for img in frames:
            vw.write(img)
    st = anim.picture.stats
    print(f"wrote {out} ({n} frame(s); median {np.median(st.total_ms):.0f} ms per frame)")
    return 0


class _ApexTimeline:
    """A fixed contraction vector under a raised-cosine envelope, with 0.25 s rest around it."""

    REST_S = 0.25

    def __init__(self, apex, duration, ids):
        from myoface.control import envelope

        self._apex = apex
        self._ids = tuple(ids)
        self._env = envelope
        self._d = float(duration)
        self.duration = self._d + 2 * self.REST_S

    def contractions(self, times, muscle_ids):
        import numpy as np

        if tuple(muscle_ids) != self._ids:
            raise MyofaceValueError("internal: muscle ids changed")
        ramp = min(0.35, self._d / 3)
        w = self._env(np.asarray(times), self.REST_S, ramp, self._d - 2 * ramp, ramp)
        return w[:, None] * self._apex[None, :]
