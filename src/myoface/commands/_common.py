"""Options and helpers shared by several subcommands."""

from __future__ import annotations


def add_face_argument(p) -> None:
    p.add_argument(
        "--face",
        metavar="PATH",
        default=None,
        help="face model: a Waters geoface folder, or a mesh (OBJ/PLY) with a muscle file "
        "<stem>.muscles.toml beside it (default: the bundled face and muscles)",
    )
    p.add_argument(
        "--muscles",
        metavar="TOML",
        default=None,
        help="muscle file for --face (default: <stem>.muscles.toml beside the mesh)",
    )


def load_model(args):
    from myoface.model import load_face_model

    return load_face_model(args.face, muscles=getattr(args, "muscles", None))
