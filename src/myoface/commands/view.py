"""``myoface view``: the face in a web page, responding live to muscle / AU / expression controls."""

from __future__ import annotations

from myoface.commands._common import add_face_argument, load_model

NAME = "view"
HELP = "an interactive web viewer: sliders for muscles, AUs, expressions, jaw; live physics"


def add_arguments(p):
    p.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to serve on (default 127.0.0.1: this machine only)",
    )
    p.add_argument("--port", type=int, default=8080)
    p.add_argument("--open", action="store_true", help="open the page in a web browser")
    p.add_argument(
        "--texture",
        metavar="IMAGE",
        help="a texture image for the face's UVs (default: the face's own, or a neutral skin)",
    )
    add_face_argument(p)


def run(args) -> int:
    from myoface.viewer.app import FaceViewer, _viser

    _viser()  # fail early, with the pip command, when viser is missing
    fm = load_model(args)
    v = FaceViewer(fm, host=args.host, port=args.port, texture=args.texture)
    where = "this machine only" if args.host == "127.0.0.1" else f"all who can reach {args.host}"
    print(f"myoface viewer at {v.url} (serving {where}; Ctrl-C to stop)", flush=True)
    if args.open:
        import webbrowser

        webbrowser.open(v.url)
    try:
        v.serve_forever()
    except KeyboardInterrupt:
        pass
    return 0
