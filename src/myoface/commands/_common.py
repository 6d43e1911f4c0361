"""Options and helpers shared by several subcommands."""

from __future__ import annotations

from pathlib import Path


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


def load_model(args):
    from myoface.model import load_face_model

    return load_face_model(args.face, muscles=getattr(args, "muscles", None))


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
