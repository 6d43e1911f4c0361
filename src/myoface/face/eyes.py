"""The eyeballs behind the eye openings: where they sit in the head (geometry level).

An eyeball is a sphere of radius :data:`EYE_RADIUS_MM`, fixed in the head, behind the eye
opening's boundary loop (the lid margins). Its centre lies on the line through the loop's
centroid along -z (the head frame: x lateral, y up, z out of the face), as far forward as the
renderer has always drawn it (its front pole 3.5 mm in front of the centroid) unless that puts
part of the lid margin inside the sphere: then just far enough back that every margin vertex is
:data:`EYE_CLEARANCE_MM` outside it. The renderer draws the eyeball there and the eyelids
(:mod:`myoface.muscles.lids`) slide over the same sphere.
"""

from __future__ import annotations

import numpy as np

#: eyeball radius (mm): the adult eye's axial length is about 24 mm (Bekerman, Gottlieb &
#: Vaiman, "Variations in eyeball diameters of the healthy adults", J. Ophthalmol. 2014)
EYE_RADIUS_MM = 12.0
#: how far the front pole of the eyeball may stand in front of the opening's centroid (mm):
#: the renderer's placement before the lids moved
EYE_PROTRUSION_MM = 3.5
#: the least distance (mm) of a lid margin vertex from the eyeball at rest: a mesh edge of
#: length L between two points on the sphere dips L^2 / (8 R) inside it (0.17 mm for L = 4 mm,
#: the margin's spacing on the default face), so the drawn lid clears the drawn eyeball
EYE_CLEARANCE_MM = 0.5


def eye_loop(face, group: str) -> np.ndarray | None:
    """The boundary loop (vertex indices, in order) of ``face`` that holds most of landmark
    group ``group`` (e.g. ``"eye_l"``), or None when the face has no such group or loop."""
    if group not in face.landmarks:
        return None
    loops = face.boundary_loops
    if len(loops) < 2:
        return None
    feat = set(int(v) for v in face.landmarks[group])
    best, score = None, 0
    for lp in loops[1:]:  # the longest loop is the outer rim
        s = len(feat & set(lp.tolist()))
        if s > score:
            best, score = lp, s
    return best


def eyeball_center(
    vertices: np.ndarray,
    loop: np.ndarray,
    radius_mm: float = EYE_RADIUS_MM,
    clearance_mm: float = EYE_CLEARANCE_MM,
) -> np.ndarray:
    """Centre (3,) mm of the eyeball behind the eye opening ``loop`` of the rest ``vertices``.

    Parameters
    ----------
    vertices : (V, 3) mm — the rest skin.
    loop : (K,) int — the opening's boundary loop.
    radius_mm, clearance_mm : float — the eyeball's radius; the least distance of every loop
        vertex from its surface.

    The centre is ``c - d z`` with ``c`` the loop's centroid and ``d`` the smallest depth that
    is at least ``radius_mm - EYE_PROTRUSION_MM`` and keeps every loop vertex at least
    ``radius_mm + clearance_mm`` from the centre.
    """
    pts = np.asarray(vertices, dtype=np.float64)[np.asarray(loop)]
    c = pts.mean(axis=0)
    w = pts - c
    reach = (radius_mm + clearance_mm) ** 2 - w[:, 0] ** 2 - w[:, 1] ** 2
    need = np.sqrt(np.maximum(reach, 0.0)) - w[:, 2]  # (w_z + d)^2 >= reach
    d = radius_mm - EYE_PROTRUSION_MM
    inside = reach > 0
    if inside.any():
        d = max(d, float(need[inside].max()))
    return c - np.array([0.0, 0.0, d])
