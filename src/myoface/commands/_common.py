"""Options and helpers shared by several subcommands.

Limits on numbers the user gives (checked as the arguments are parsed, before any work; a
value outside them is a usage error, exit status 2):

- frame rates (``--fps``): in (0, :data:`MAX_FPS`] frames per second;
- video lengths (``synth --duration``, a timeline's end): in (0, :data:`MAX_VIDEO_S`] s;
- image sides (``--width``, ``--height``, ``--size``): :data:`IMAGE_SIDE` pixels;
- cylindrical map sides (``face maps --size``): :data:`MAP_SIDE` cells, at most
  :data:`MAX_MAP_CELLS` cells in all;
- Gauss-Newton corrections (``analyze --refine``, ``batch --refine``): 0 to :data:`MAX_REFINE`;
- ports (``view --port``): 0 (any free port) to 65535;
- intensities (``synth --au N=I``, ``--muscle ID=C``, ``--intensity``): in [0, 1] (or a FACS
  letter A-E for an action unit);
- faces of a photo (``face from-photo --face-index``): 0 to 9.

Options that do not go together (e.g. ``synth --intensity`` without ``--expression`` or
``--viseme``, an ``--estimator`` of the other tracker) are usage errors too
(:class:`~myoface.errors.MyofaceUsageError`). A value echoed in a message is cut to 40
characters (a number of 5000 digits is said by its length).
"""

from __future__ import annotations

import argparse
import math
import warnings
from pathlib import Path

#: the largest frame rate (frames per second) of a video the commands write
MAX_FPS = 240.0
#: the longest video (s) ``synth`` renders: one hour
MAX_VIDEO_S = 3600.0
#: smallest and largest side (pixels) of a rendered image or video frame
IMAGE_SIDE = (16, 4096)
#: smallest and largest side (cells) of a cylindrical map
MAP_SIDE = (16, 8192)
#: the most cells of a cylindrical map (8192 x 4096: about 2 GB of memory while it is made)
MAX_MAP_CELLS = 8192 * 4096
#: the most Gauss-Newton corrections per frame (``analyze --refine``, ``batch --refine``)
MAX_REFINE = 10
#: a face (its mesh's largest extent, mm) outside this range is probably not in millimetres
FACE_SIZE_MM = (50.0, 500.0)


def first_run_note() -> str | None:
    """The line a command prints on the first run on a new install, when numba has not yet
    compiled myoface's kernels (it caches them for later runs, beside the sources or in
    numba's cache folder): that run is several times longer, and its progress bars pause at
    each stage's first frame while it compiles. Measured 2026-12-08 on the 2-core machine:
    ``myoface demo`` 204 s on a new install, 159 s of it compiling (the tissue solver's
    Newton step 36 s, the renderer's shading 26 s, the gaze's kernels about 40 s), against
    about 40 s once compiled. None once the tissue solver's kernel is in numba's cache (or
    when that cannot be told)."""
    try:
        import os

        from myoface.tissue.solver import _newton

        if os.environ.get("NUMBA_DISABLE_JIT"):
            return None
        index = _newton._cache._cache_file._index_path  # (numba.core.caching's own path)
        if os.path.exists(index):
            return None
    except Exception:  # noqa: BLE001 - a note, never a failure
        return None
    return (
        "first run on this install: numba compiles myoface's kernels as they are first used "
        "(a few minutes, once; cached for later runs)"
    )


def number(lo: float, hi: float, *, lo_open: bool = False, unit: str = ""):
    """An argparse ``type``: a finite float in [lo, hi] (or (lo, hi] with ``lo_open``)."""
    interval = f"{'(' if lo_open else '['}{lo:g}, {hi:g}]"

    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            v = math.nan
        ok = math.isfinite(v) and (lo < v if lo_open else lo <= v) and v <= hi
        if not ok:
            raise argparse.ArgumentTypeError(
                f"expected a number in {interval}{unit}; got {_shown(text)}"
            )
        return v

    parse.__name__ = "number"
    return parse


def integer(lo: int, hi: int | None = None, *, unit: str = ""):
    """An argparse ``type``: an integer in [lo, hi] (no upper bound when ``hi`` is None)."""
    interval = f"[{lo}, {hi}]" if hi is not None else f">= {lo}"

    def parse(text: str) -> int:
        try:
            v = int(text.strip())
        except ValueError:
            v = None
        if v is None or v < lo or (hi is not None and v > hi):
            what = f"an integer in {interval}" if hi is not None else f"an integer {interval}"
            raise argparse.ArgumentTypeError(f"expected {what}{unit}; got {_shown(text)}")
        return v

    parse.__name__ = "integer"
    return parse


def _shown(text: str, n: int = 40) -> str:
    """``text`` quoted for a message, at most ``n`` characters of it (a number of 5000 digits
    is said by its length)."""
    if len(text) <= n:
        return repr(text)
    return f"{text[:n]!r}... ({len(text)} characters)"


fps_type = number(0.0, MAX_FPS, lo_open=True, unit=" frames per second")
side_type = integer(*IMAGE_SIDE, unit=" pixels")


def warn(message: str) -> None:
    """A :class:`~myoface.errors.MyofaceWarning` (one line on stderr from the command line)."""
    from myoface.errors import MyofaceWarning

    warnings.warn(message, MyofaceWarning, stacklevel=2)


def check_video_size(path, width: int, height: int) -> None:
    """Say (a warning) that an H.264 video of an odd ``width`` or ``height`` is padded by a
    copy of its last column or row (:class:`~myoface.render.VideoWriter`): its frames need
    even sides."""
    if width % 2 or height % 2:
        warn(
            f"H.264 needs even frame sizes: {Path(path).name} will be "
            f"{width + width % 2}x{height + height % 2} pixels, not {width}x{height} (the last "
            f"{'column' if width % 2 else 'row'}{' and row' if width % 2 and height % 2 else ''}"
            " repeated)"
        )


def check_face_scale(
    vertices, source: str, hint: str = "", size_mm: tuple[float, float] = FACE_SIZE_MM
) -> None:
    """Warn when a mesh's largest extent is outside ``size_mm`` (default :data:`FACE_SIZE_MM`):
    a mesh in metres, centimetres or micrometres rather than millimetres."""
    import numpy as np

    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or len(v) == 0 or not np.isfinite(v).all():
        return
    size = float((v.max(axis=0) - v.min(axis=0)).max())
    lo, hi = size_mm
    if not lo <= size <= hi:
        warn(
            f"{source} is {size:.4g} mm across, not the {lo:g}-{hi:g} mm of a face: is it in "
            f"millimetres?{' ' + hint if hint else ''}"
        )


def add_face_argument(p) -> None:
    p.add_argument(
        "--face",
        metavar="PATH",
        default=None,
        help="face model: a .myoface file (myoface face from-scan/from-photo), a Waters geoface "
        "folder, or a mesh (OBJ/PLY) with a muscle file <stem>.muscles.toml beside it "
        "(default: the bundled face and muscles)",
    )
    p.add_argument(
        "--muscles",
        metavar="TOML",
        default=None,
        help="muscle file for --face (default: <stem>.muscles.toml beside the mesh)",
    )


#: the trackers of ``--tracker`` (:func:`~myoface.analysis.pipeline.make_analyzer`)
TRACKERS = ("snakes", "landmarks")
#: the estimators of ``--estimator``: the snakes' (curves, fiducials) and the landmarks' (fit,
#: fit-synthesis, paper)
ESTIMATORS = ("curves", "fiducials", "fit", "fit-synthesis", "paper")


#: ``myoface analyze`` and ``myoface batch``'s tracker when none is named (and no --init):
#: the landmarks' 3-D fit. Measured 2026-12-01 against the paper's snakes: on the degraded
#: head-motion renders the snakes measured 30 of 90 frames with the head moving (the fit all
#: 90), with a worst RMSE of 0.71 against the fit's 0.31
DEFAULT_TRACKER = "landmarks"


def add_analysis_arguments(p) -> None:
    """The options of one video's analysis, the same for ``myoface analyze`` and ``myoface
    batch`` (which gives them to every video): ``--tracker``, ``--init``,
    ``--calibration-frame``, ``--max-frames``, ``--sigma``, ``--estimator``, ``--refine``,
    ``--flow`` and ``--photometric``. :func:`analysis_settings` reads them back."""
    p.add_argument(
        "--tracker",
        choices=TRACKERS,
        default=None,
        help="landmarks: MediaPipe's face mesh and the 3-D fit of the whole model (the "
        "default, the best measured: README, 'How well the analysis works'); snakes: the "
        "paper's deformable contours in a 2-D head frame (the default when --init is given)",
    )
    p.add_argument(
        "--init",
        help="initial contours (JSON) on the calibration frame, for the snakes (default: found "
        "automatically with MediaPipe's face mesh); myoface batch uses them for every video, "
        "e.g. videos from one fixed camera",
    )
    p.add_argument(
        "--calibration-frame",
        type=integer(0),
        default=None,
        metavar="N",
        help="the neutral frame to calibrate on (default: for the landmarks' 3-D fit the most "
        "neutral frame of the first 2 s, for the snakes frame 0). The 3-D fit analyses every "
        "frame, those before it too; the snakes start there (with --init, the contours are "
        "on this frame)",
    )
    p.add_argument(
        "--max-frames",
        type=integer(1),
        metavar="N",
        help="analyse at most N frames (of each video)",
    )
    p.add_argument(
        "--sigma",
        type=number(0.0, 100.0, lo_open=True, unit=" px"),
        default=None,
        help="potential smoothing, px (default: 1.2 mm on the face, from its size in the frame)",
    )
    p.add_argument(
        "--estimator",
        choices=ESTIMATORS,
        default=None,
        help="how contractions are estimated. snakes: the model's skin curves fitted to the "
        "whole contours (curves, default), or the paper's fiducial points (fiducials). "
        "landmarks: the 3-D fit of the whole model, head pose and every muscle (fit, "
        "default), the same with analysis by synthesis (fit-synthesis: the face rendered at "
        "each estimate and tracked too, which takes out MediaPipe's own error; slower), or "
        "the paper's 12 muscles in a 2-D head frame (paper)",
    )
    p.add_argument(
        "--refine",
        type=integer(0, MAX_REFINE),
        help=f"Gauss-Newton corrections per frame through the model, 0-{MAX_REFINE} "
        "(default 1 for snakes and the 3-D fit, 0 for landmarks --estimator paper)",
    )
    p.add_argument(
        "--flow",
        action="store_true",
        help="landmarks' 3-D fit: also read its points in the pixels, each against the "
        "calibration frame through the model (Lucas-Kanade on the template the fitted mesh "
        "warps; no drift), which reads skin motion MediaPipe reads short; best where the "
        "skin has texture and the face keeps its look; ~5 ms CPU a frame more, on a thread "
        "of its own beside the fit (see README)",
    )
    p.add_argument(
        "--photometric",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="landmarks' 3-D fit: also fit the frame's pixels against the calibration "
        "frame's appearance (the photometric term; the default with the 3-D fit, the best "
        "measured: it reads the skin's motion where MediaPipe reads it short); "
        "--no-photometric: MediaPipe's points alone (faster, about 1.6x)",
    )


def analysis_settings(args) -> dict:
    """The analysis settings of ``args`` (parsed with :func:`add_analysis_arguments`): the
    keyword arguments ``tracker``, ``init``, ``calibration_frame``, ``max_frames``,
    ``refine``, ``sigma``, ``estimator``, ``flow`` and ``photometric`` of
    :func:`~myoface.analysis.outputs.analyze_to_folder` and
    :func:`~myoface.analysis.batch.run_batch`.

    Raises
    ------
    MyofaceValueError
        For ``--init`` with the landmark tracker, which needs none, and ``--photometric``
        with the snakes or ``--estimator paper`` (it is a term of the landmarks' 3-D fit).
    MyofaceUsageError
        For an ``--estimator`` that is not the tracker's (:data:`TRACKER_ESTIMATORS`), e.g.
        ``fiducials`` (the snakes') with the landmark tracker: a usage error (exit status 2),
        where the library would take it for its counterpart (``paper``).
    """
    from myoface.errors import MyofaceValueError

    defaulted = args.tracker is None
    if defaulted:
        # the best measured analysis; initial contours are the snakes'
        args.tracker = "snakes" if args.init else DEFAULT_TRACKER
    if args.init and args.tracker == "landmarks":
        raise MyofaceValueError("--init is for the snakes; the landmark tracker needs none")
    # refused before the model is built, as make_analyzer would; None: on with the 3-D fit
    from myoface.analysis.pipeline import resolve_photometric

    photometric = resolve_photometric(args.photometric, args.tracker, args.estimator)
    _check_estimator(args.tracker, args.estimator, defaulted)
    return {
        "tracker": args.tracker,
        "init": args.init or None,
        "calibration_frame": args.calibration_frame,
        "max_frames": args.max_frames,
        "refine": args.refine,
        "sigma": args.sigma,
        "estimator": args.estimator,
        "flow": bool(args.flow),
        "photometric": photometric,
    }


#: each tracker's estimators (``--estimator``)
TRACKER_ESTIMATORS = {
    "snakes": ("curves", "fiducials"),
    "landmarks": ("fit", "fit-synthesis", "paper"),
}


def _check_estimator(tracker: str, estimator: str | None, defaulted: bool = False) -> None:
    """A usage error for an ``--estimator`` of the other tracker (the library takes the
    snakes' names for the landmarks' counterparts, "fiducials" for "paper": the command line
    says so rather than change the estimator silently)."""
    from myoface.errors import MyofaceUsageError

    own = TRACKER_ESTIMATORS.get(tracker, ())
    if estimator is None or estimator in own:
        return
    how = f"--tracker {tracker}"
    if defaulted:  # (the landmarks, or the snakes given --init)
        how = f"--tracker {tracker} (the default{' with --init' if tracker == 'snakes' else ''})"
    hint = {
        "fiducials": "; the paper's fiducial scheme on the landmarks is --estimator paper",
        "curves": "; the landmarks' fit of the whole model is --estimator fit",
        "paper": "; the paper's fiducials on the snakes are --estimator fiducials",
        "fit": "; give --tracker landmarks for the 3-D fit",
        "fit-synthesis": "; give --tracker landmarks for the 3-D fit",
    }.get(estimator, "")
    raise MyofaceUsageError(
        f"--estimator {estimator} is not an estimator of {how}, whose are {', '.join(own)}{hint}"
    )


def default_analysis_settings(**given) -> dict:
    """The analysis settings (:func:`analysis_settings`) of a command given none of the
    analysis options, but those in ``given`` (e.g. ``tracker="landmarks"``, ``init=path``):
    the defaults are the options' own."""
    parser = argparse.ArgumentParser(add_help=False)
    add_analysis_arguments(parser)
    args = parser.parse_args([])
    unknown = set(given) - set(vars(args))
    if unknown:
        raise TypeError(f"not an analysis option: {', '.join(sorted(unknown))}")
    vars(args).update(given)
    return analysis_settings(args)


def load_model(args):
    """The face model of ``--face`` and ``--muscles`` (:func:`load_face_model_option`)."""
    return load_face_model_option(args.face, getattr(args, "muscles", None))


def load_face_model_option(face=None, muscles=None):
    """The face model of the options ``--face face`` and ``--muscles muscles`` (None: not
    given, the bundled face and muscles); warns when the face is not about a face's size in
    millimetres."""
    from myoface.errors import MyofaceValueError
    from myoface.model import load_face_model

    if muscles and face is None:
        raise MyofaceValueError(
            f"--muscles {muscles} needs --face (the bundled face has its own muscles)"
        )
    fm = load_face_model(face, muscles=muscles)
    if face is not None:
        check_face_scale(fm.face.vertices, f"--face {face}")
    return fm


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
