"""``myoface face``: personal face models from 3-D scans and photographs, and scan maps."""

from __future__ import annotations

from pathlib import Path

from myoface._io import OutputSet, check_output_dir, check_output_path, sha256_file
from myoface.commands._common import (
    MAP_SIDE,
    MAX_MAP_CELLS,
    check_face_scale,
    integer,
    number,
)
from myoface.errors import MyofaceFileNotFoundError, MyofaceValueError

NAME = "face"
HELP = "make personal face models (.myoface) from a 3-D head scan or a photograph"
DESCRIPTION = (
    "Personal face models. 'from-scan' conforms the generic face to a textured head mesh (or to "
    "its cylindrical range/colour maps) as in Terzopoulos & Waters 1993, Section IV; "
    "'from-photo' builds one from a frontal photograph (needs the mediapipe extra); 'maps' "
    "writes a mesh's cylindrical range and colour maps. Use the result with --face in every "
    "other command."
)
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")
#: the largest ``--face-index``: MediaPipe is asked for at most 10 faces in a photo
#: (:data:`myoface.face.personal.MAX_PHOTO_FACES`)
MAX_FACE_INDEX = 9
VIDEO_SUFFIXES = (".mp4", ".mov", ".avi", ".mkv", ".webm")


def add_arguments(p):
    sub = p.add_subparsers(dest="face_command", metavar="ACTION")
    s = sub.add_parser("from-scan", help="conform the generic face to a head scan or its maps")
    s.add_argument("scan", help="textured head mesh (OBJ/PLY, mm, +y up) or maps (.npz/folder)")
    s.add_argument("-o", "--output", required=True, help="the face file to write (.myoface)")
    s.add_argument(
        "--landmarks",
        metavar="FILE",
        help="68 iBUG landmarks of the scan in its coordinates (.ljson/.json/.npy/.txt); "
        "default: those stored in the maps, else found automatically in the colour map (needs "
        "the mediapipe extra)",
    )
    s.add_argument(
        "--texture",
        metavar="IMAGE",
        help="texture image of the mesh (default: <stem>.jpg/.png beside it, if any)",
    )
    s.add_argument("--scale-mm", type=_scale_type, default=1.0, help="mesh units in mm (10 for cm)")
    s.add_argument("--maps-out", metavar="PATH", help="also write the maps (.npz or a folder)")
    _common_outputs(s)

    ph = sub.add_parser("from-photo", help="build a face from one frontal photograph")
    ph.add_argument("photo", help="an image, or a video (its --frame) of one frontal face")
    ph.add_argument("-o", "--output", required=True, help="the face file to write (.myoface)")
    ph.add_argument(
        "--frame", type=integer(0), default=0, help="frame of a video to use (default 0)"
    )
    ph.add_argument(
        "--face-index",
        type=integer(0, MAX_FACE_INDEX),
        default=None,
        metavar="N",
        help="of a photo of several faces, numbered from 0 left to right, face N (default: "
        "the largest, said on stderr)",
    )
    ph.add_argument(
        "--depth-blend",
        type=number(0.0, 1.0),
        default=None,
        help="share of the generic face's depth mixed into the photo's (0..1, default 0.5)",
    )
    _common_outputs(ph)

    m = sub.add_parser("maps", help="cylindrical range and colour maps of a head mesh")
    m.add_argument("mesh", help="head mesh (OBJ/PLY), +y up")
    m.add_argument("-o", "--output", required=True, help=".npz file or a folder (PNG layout)")
    m.add_argument("--texture", metavar="IMAGE", help="texture image (default: beside the mesh)")
    m.add_argument("--landmarks", metavar="FILE", help="68 iBUG landmarks: orient the head")
    m.add_argument("--scale-mm", type=_scale_type, default=1.0, help="mesh units in mm")
    m.add_argument(
        "--size",
        type=_map_size,
        default=(512, 256),
        help="W x H cells, each side 16-8192, at most 8192x4096 cells (default the paper's "
        "512x256)",
    )


_scale_type = number(1e-6, 1e6, lo_open=True, unit=" mm per mesh unit")


def _map_size(text: str) -> tuple[int, int]:
    """``WxH`` -> (W, H) within :data:`MAP_SIDE` and :data:`MAX_MAP_CELLS`."""
    import argparse

    lo, hi = MAP_SIDE
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WxH, e.g. 512x256; got {text!r}") from None
    if not (lo <= w <= hi and lo <= h <= hi):
        raise argparse.ArgumentTypeError(f"expected each side in [{lo}, {hi}] cells; got {text!r}")
    if w * h > MAX_MAP_CELLS:
        raise argparse.ArgumentTypeError(
            f"expected at most {MAX_MAP_CELLS} cells (8192x4096); got {text!r} ({w * h})"
        )
    return w, h


def _common_outputs(p) -> None:
    p.add_argument("--name", help="name of the person (default: the input's stem)")
    p.add_argument(
        "--preview",
        metavar="PNG",
        help="also render the face neutral and with two expressions, front and three-quarter",
    )


def run(args) -> int:
    if args.face_command is None:
        raise MyofaceValueError("give an action: from-scan, from-photo or maps")
    return {"from-scan": _from_scan, "from-photo": _from_photo, "maps": _maps}[args.face_command](
        args
    )


# --------------------------------------------------------------------------- helpers


def _check_output(path: str, suffix: str, what: str = "-o") -> Path:
    out = Path(path)
    if out.suffix.lower() != suffix:
        raise MyofaceValueError(f"{what} must be a {suffix} file; got {out}")
    return check_output_path(out, what)


def _check_maps_output(path: str, what: str) -> Path:
    """A .npz file, or a folder (no suffix) for the PNG layout."""
    out = Path(path)
    if out.suffix.lower() == ".npz":
        return check_output_path(out, what)
    if out.suffix:
        raise MyofaceValueError(f"{what} must be a .npz file or a folder; got {out}")
    return check_output_dir(out, what)


def _load_scan(path: Path, texture: str | None, scale_mm: float):
    from myoface.face import load_mesh
    from myoface.render.renderer import load_texture, to_srgb8

    if not scale_mm > 0:
        raise MyofaceValueError(f"--scale-mm must be positive; got {scale_mm}")
    scan = load_mesh(path, scale_mm=scale_mm, split_uv_seams=True)
    check_face_scale(
        scan.vertices,
        f"the scan {path} (at --scale-mm {scale_mm:g})",
        "Give --scale-mm (10 for cm, 1000 for m).",
        size_mm=(50.0, 1000.0),
    )
    tex_path = Path(texture) if texture else None
    if tex_path is None:
        for sfx in (".jpg", ".jpeg", ".png"):
            if path.with_suffix(sfx).is_file():
                tex_path = path.with_suffix(sfx)
                break
    if tex_path is not None:
        if scan.uv is None:
            raise MyofaceValueError(f"{path} has no texture coordinates for {tex_path}")
        scan.texture = to_srgb8(load_texture(tex_path))
        print(f"texture    {tex_path}")
    else:
        print("texture    none (the colour map will be grey)")
    return scan, tex_path


def _write_preview(face, path: str) -> None:
    import numpy as np

    from myoface.commands._common import contact_sheet
    from myoface.control import expression_contractions
    from myoface.model import build_face_model
    from myoface.render import Renderer
    from myoface.synth import Synthesizer, make_camera

    out = _check_output(path, ".png", "--preview")
    fm = build_face_model(face)
    images = {}
    for view in ("front", "three_quarter"):
        syn = Synthesizer(fm, Renderer(fm.face, make_camera(fm.face.vertices, view, 384, 384)))
        for expr in ("neutral", "happiness", "surprise"):
            syn.state = fm.rest_state()
            c = np.zeros(fm.n_muscles) if expr == "neutral" else None
            if c is None:
                c = expression_contractions(expr, 1.0, fm.ids)
            images[f"{expr} ({view.replace('_', '-')})"] = syn.image(c)
    contact_sheet(images, out, f"{face.name}: personal face model, neutral and two expressions")
    print(f"wrote {out}")


def _save(face, out: Path, provenance: dict) -> None:
    from importlib import resources

    from myoface.face.facefile import save_face
    from myoface.muscles.io import DEFAULT_MUSCLES_FILE

    muscles = (resources.files("myoface") / "data" / DEFAULT_MUSCLES_FILE).read_text()
    save_face(out, face, muscles_toml=muscles, provenance=provenance)
    print(f"wrote {out}")
    from myoface.face.lips import rest_lip_gap

    gap = rest_lip_gap(face)
    if gap is not None:
        print(f"lips       inner lips at rest {gap.text()}")


# --------------------------------------------------------------------------- actions


def _from_scan(args) -> int:
    import numpy as np

    import myoface
    from myoface.face import load_default_face
    from myoface.face.cylindrical import load_maps
    from myoface.face.personal import (
        INNER_IBUG,
        conform_to_maps,
        face_from_scan,
        find_landmarks,
        find_landmarks_in_maps,
        read_landmarks,
        surface_errors,
    )

    out = _check_output(args.output, ".myoface")
    if args.preview:
        _check_output(args.preview, ".png", "--preview")
    if args.maps_out:
        _check_maps_output(args.maps_out, "--maps-out")
    src = Path(args.scan)
    if not src.exists():
        raise MyofaceFileNotFoundError(f"no such scan: {src}")
    name = args.name or src.stem
    lm = read_landmarks(args.landmarks) if args.landmarks else None
    how = f"given ({args.landmarks})" if lm is not None else "found (MediaPipe on the colour map)"
    provenance = {
        "made_by": f"myoface {myoface.__version__} face from-scan",
        "method": "Terzopoulos & Waters 1993, Section IV: cylindrical maps, generic mesh "
        "projected radially, conformed to the landmarks as a 2-D spring mesh, radius sampled",
        "source": {"path": src.name},
    }
    if src.is_dir() or src.suffix.lower() == ".npz":
        maps = load_maps(src)
        if lm is None and maps.landmarks_mm is not None:
            lm, how = maps.landmarks_mm, f"stored in {src.name}"
        elif lm is None:
            lm = find_landmarks_in_maps(maps)
        conf = conform_to_maps(maps, lm, load_default_face(), name=name)
        scan = None
    else:
        provenance["source"]["sha256"] = sha256_file(src)
        scan, tex = _load_scan(src, args.texture, args.scale_mm)
        if tex is not None:
            provenance["source"]["texture"] = tex.name
        print(f"scan       {scan.n_vertices} vertices, {scan.n_triangles} triangles")
        if lm is None:
            lm = find_landmarks(scan)
        conf = face_from_scan(scan, lm, name=name)
        scan = conf.scan
    provenance["landmarks"] = how
    err = conf.landmark_error_mm
    print(
        f"landmarks  {how}; fitted to the generic face within "
        f"{conf.info['alignment_residual_mm']:.1f} mm RMS (scale {conf.info['scale']:.3f})"
    )
    print(
        f"conformed  landmark error {np.nanmean(err[INNER_IBUG]):.2f} mm mean, "
        f"{np.nanmax(err[INNER_IBUG]):.2f} mm max (inner 51 points)"
    )
    provenance["fit"] = {
        k: v for k, v in conf.info.items() if k not in ("scan_rotation", "scan_translation_mm")
    }
    provenance["fit"]["landmark_error_mean_mm"] = float(np.nanmean(err[INNER_IBUG]))
    if scan is not None:
        se = surface_errors(conf.face, scan)
        provenance["fit"].update(se)
        print(
            f"surface    mesh to scan {se['mesh_to_scan_mean_mm']:.2f} mm mean, "
            f"{se['mesh_to_scan_max_mm']:.2f} mm max; scan to mesh "
            f"{se['scan_to_mesh_mean_mm']:.2f} mm mean"
        )
    with OutputSet() as outs:  # the face file last: a failure leaves none of them
        if args.maps_out:
            conf.maps.save(outs.add(args.maps_out))
            print(f"wrote {args.maps_out}")
        if args.preview:
            _write_preview(conf.face, outs.add(args.preview))
        _save(conf.face, out, provenance)
    return 0


def _read_photo(path: Path, frame: int):
    """The photo ``path`` (an image, or frame ``frame`` of a video) as (H, W, 3) uint8 RGB:
    any colour space (:func:`~myoface.face.image.read_image`), upright by its EXIF
    orientation, at most :data:`~myoface.face.personal.PHOTO_MAX_SIDE` pixels a side (a
    larger one scaled down as it is read, said on stdout)."""
    from myoface.face.image import image_size, read_image
    from myoface.face.personal import PHOTO_MAX_SIDE

    if path.is_dir():
        raise MyofaceValueError(f"the photo {path} is a folder; expected an image or a video")
    if not path.is_file():
        raise MyofaceFileNotFoundError(f"no such photo: {path}")
    if path.suffix.lower() in VIDEO_SUFFIXES:
        from myoface.analysis.video import open_video

        if frame < 0:
            raise MyofaceValueError(f"--frame must be >= 0; got {frame}")
        n = 0
        for k, img in enumerate(open_video(path)):  # one frame kept, not all up to it
            n = k + 1
            if k == frame:
                return img
        raise MyofaceValueError(f"{path} has {n} frames; no frame {frame}")
    w, h = image_size(path, "photo")
    img = read_image(path, "photo", max_side=PHOTO_MAX_SIDE, orient=True)
    if max(w, h) > PHOTO_MAX_SIDE:
        print(
            f"photo      {w}x{h} px, read at {img.shape[1]}x{img.shape[0]} (at most "
            f"{PHOTO_MAX_SIDE} px a side)"
        )
    return img


def _from_photo(args) -> int:
    photo_face_file(
        args.photo,
        args.output,
        frame=args.frame,
        name=args.name,
        depth_blend=args.depth_blend,
        preview=args.preview,
        face_index=args.face_index,
    )
    return 0


def photo_face_file(
    photo, output, *, frame: int = 0, name=None, depth_blend=None, preview=None, face_index=None
) -> None:
    """``myoface face from-photo``'s work (also the demo's): the face of the photograph
    ``photo`` (an image, or frame ``frame`` of a video) made by
    :func:`~myoface.face.personal.face_from_photo` (``depth_blend``: default
    :data:`~myoface.face.personal.PHOTO_DEPTH_BLEND`; ``face_index``: which face of several,
    numbered from 0 left to right, default the largest), saved with the default muscles and
    its provenance to the face file ``output`` (.myoface), and, with ``preview``, its contact
    sheet (PNG); the command's lines printed. A failure leaves neither file."""
    import myoface
    from myoface.face.personal import PHOTO_DEPTH_BLEND, face_from_photo

    out = _check_output(output, ".myoface")
    if preview:
        _check_output(preview, ".png", "--preview")
    src = Path(photo)
    img = _read_photo(src, frame)
    blend = PHOTO_DEPTH_BLEND if depth_blend is None else depth_blend
    face, info = face_from_photo(
        img, name=name or src.stem, depth_blend=blend, face_index=face_index
    )
    n_faces = info.get("n_faces", 1)
    which = f" (face {info['face_index']} of {n_faces}, left to right)" if n_faces > 1 else ""
    print(
        f"face found {info['face_width_px']:.0f} px wide{which}; yaw "
        f"{info['head_yaw_deg']:.1f} deg; {info['fit_rms_to_generic_mm']:.1f} mm RMS from the "
        "generic face's shape"
    )
    provenance = {
        "made_by": f"myoface {myoface.__version__} face from-photo",
        "method": "MediaPipe face mesh (468 points of the default topology) on one photo; "
        "similarity to the generic face; depth blended with the generic face's",
        "source": {"path": src.name, "sha256": sha256_file(src), "frame": frame},
        "fit": info,
        "note": "one photograph has no absolute scale: the face has the generic face's size",
    }
    with OutputSet() as outs:  # the face file last: a failure leaves neither
        if preview:
            _write_preview(face, outs.add(preview))
        _save(face, out, provenance)


def _maps(args) -> int:
    from myoface.face.cylindrical import maps_from_mesh
    from myoface.face.personal import head_maps, read_landmarks

    w, h = args.size
    out = _check_maps_output(args.output, "-o")
    src = Path(args.mesh)
    if not src.exists():
        raise MyofaceFileNotFoundError(f"no such mesh: {src}")
    scan, _ = _load_scan(src, args.texture, args.scale_mm)
    if args.landmarks:
        from myoface.face import load_default_face

        lm = read_landmarks(args.landmarks)
        _, maps, _ = head_maps(scan, lm, load_default_face(), (h, w))
        print("oriented   the head by its landmarks (head frame: +y up, +z out of the face)")
    else:
        maps = maps_from_mesh(scan, (h, w))
    with OutputSet() as outs:
        maps.save(outs.add(out))
    print(
        f"wrote {out}: {w}x{h} cells, axis at x={maps.axis_x_mm:.1f} z={maps.axis_z_mm:.1f} mm, "
        f"{maps.holes.mean():.0%} holes"
    )
    return 0
