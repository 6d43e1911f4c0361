"""``myoface view``: the face in a web page, responding live to muscle / AU / expression controls."""

from __future__ import annotations

from pathlib import Path

from myoface.commands._common import add_face_argument, integer, load_model, warn
from myoface.errors import MyofaceFileNotFoundError

NAME = "view"
HELP = "an interactive web viewer: sliders for muscles, AUs, expressions, jaw; live physics"


def add_arguments(p):
    p.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to serve on (default 127.0.0.1: this machine only)",
    )
    p.add_argument(
        "--port",
        type=integer(0, 65535),
        default=8080,
        help="port to serve on (default 8080; 0: any free port); a busy port is an error",
    )
    p.add_argument("--open", action="store_true", help="open the page in a web browser")
    p.add_argument(
        "--texture",
        metavar="IMAGE",
        help="a texture image for the face's UVs (default: the face's own, or a neutral skin)",
    )
    add_face_argument(p)


def run(args) -> int:
    import ipaddress

    from myoface.viewer.app import FaceViewer, _viser, check_address

    _viser()  # fail early, with the pip command, when viser is missing
    if args.texture and not Path(args.texture).is_file():
        raise MyofaceFileNotFoundError(f"--texture: no such texture image: {args.texture}")
    addr = check_address(args.host, args.port)  # before the model is built
    local = ipaddress.ip_address(addr.split("%")[0]).is_loopback
    if not local:
        warn(
            f"--host {args.host} serves the viewer, without a password, to every machine that "
            "can reach this one; --host 127.0.0.1 keeps it on this machine"
        )
    fm = load_model(args)
    v = FaceViewer(fm, host=args.host, port=args.port, texture=args.texture)
    where = "this machine only" if local else f"all who can reach {args.host}"
    print(f"myoface viewer at {v.url} (serving {where}; Ctrl-C to stop)", flush=True)
    if args.open:
        import webbrowser

        webbrowser.open(v.url)
    try:
        v.serve_forever()
    except KeyboardInterrupt:
        pass
    return 0
