"""``myoface info``: describe a face model (mesh, lips at rest, lattice, muscles) and this
installation."""

from __future__ import annotations

import platform

from myoface.commands._common import add_face_argument, load_model

NAME = "info"
HELP = (
    "describe a face model: mesh, the lips' gap at rest, tissue lattice (element and spring "
    "counts), muscles"
)


def add_arguments(p):
    add_face_argument(p)
    p.add_argument("--muscles-list", action="store_true", help="list every muscle with its type")


def run(args) -> int:
    import numba
    import numpy as np

    import myoface
    from myoface.face.lips import rest_lip_gap

    fm = load_model(args)
    t = fm.tissue
    print(
        f"myoface {myoface.__version__} (Python {platform.python_version()}, "
        f"numpy {np.__version__}, numba {numba.__version__})"
    )
    print(
        f"face       {fm.face.name}: {fm.face.n_vertices} vertices, "
        f"{fm.face.n_triangles} triangles, {len(fm.face.boundary_loops)} boundary loops "
        f"{[len(b) for b in fm.face.boundary_loops]}"
    )
    gap = rest_lip_gap(fm.face)
    lips = "no mouth opening found" if gap is None else f"inner lips at rest {gap.text()}"
    print(f"lips       {lips}")
    print(
        f"lattice    {t.n_nodes} nodes ({int(t.kinematic.sum())} kinematic: bone + "
        f"{len(fm.driven_nodes)} muscle-driven fascia nodes)"
    )
    print(f"           {t.n_elements} elements, {t.n_springs} springs")
    print(f"           {t.summary().split('springs ')[-1]}")
    jaw = " + jaw" if fm.muscles.jaw is not None else ""
    print(f"muscles    {len(fm.muscles.muscles)} muscles{jaw} ({fm.muscles.name})")
    if args.muscles_list:
        for m in fm.muscles.muscles:
            print(f"  {m.id:45s} {m.kind}")
        if fm.muscles.jaw is not None:
            print(f"  {'jaw':45s} rotation up to {fm.muscles.jaw.max_angle_rad:.2f} rad")
    if fm.expressions:
        print(f"expressions {', '.join(sorted(fm.expressions))} (from the model's files)")
    return 0
