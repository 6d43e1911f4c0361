"""The face's feature sections: the contours the snakes track and the model's skin curves
they are compared with, and the fiducial features read off them (T&W 1993, Section V).

Contours (the paper's nine sections, with the two lip contours joined into one closed
contour around the lips and the brows traced around their outline):

============  ==================================  =======================================
section       landmark groups (default face)      fiducial features read off the contour
============  ==================================  =======================================
hairline      forehead_top                        centroid
eyebrow_r/l   eyebrow + eyebrow_lower (closed)    inner end, centroid, outer end
nasolabial    nasolabial_r / nasolabial_l         top
nose          nose_base                           centroid
lips          lip_upper + lip_lower outer (closed) corners, top, bottom, lower-lip sides
chin          chin_outline                        bottom
============  ==================================  =======================================

Features are geometric (extremes, centroids) rather than node identities, because snake nodes
slide along the edges they sit on. The same rules applied to the model's landmark contours (front
view, rest) pick the model vertices the features stand for.
``_l`` / ``_r`` are the subject's left / right (the subject's left is on the image's right).
"""

from __future__ import annotations

import numpy as np

from myoface.analysis.estimate import PAPER_ASSIGNMENT, Fiducial

#: section -> (landmark groups whose concatenation is the contour, closed)
SECTIONS = {
    "hairline": (("forehead_top",), False),
    "eyebrow_r": (("eyebrow_r", "eyebrow_r_lower*"), True),
    "eyebrow_l": (("eyebrow_l", "eyebrow_l_lower*"), True),
    "nasolabial_r": (("nasolabial_r",), False),
    "nasolabial_l": (("nasolabial_l",), False),
    "nose": (("nose_base",), False),
    "lips": (("lip_upper_outer", "lip_lower_outer*"), True),
    "chin": (("chin_outline",), False),
}
#: the fiducial features read off each section's contour (see :func:`section_features`)
FEATURES = {
    # the hairline and the nose are tracked (head reference, midline) but give no fiducial: an
    # open contour's centroid moves as its ends slide, by more than these features move
    "hairline": (),
    "eyebrow_r": ("inner", "centroid", "outer"),
    "eyebrow_l": ("inner", "centroid", "outer"),
    "nasolabial_r": ("top",),
    "nasolabial_l": ("top",),
    "nose": (),
    "lips": ("corner_r", "corner_l", "top", "bottom", "bottom_r", "bottom_l"),
    "chin": ("bottom",),
}


def section_vertices(face, section: str) -> np.ndarray:
    """Vertex indices of a section's contour on the face model (``*``: reversed group, the
    first vertex dropped when it repeats the previous group's last)."""
    groups, _ = SECTIONS[section]
    out: list[int] = []
    for g in groups:
        rev = g.endswith("*")
        idx = list(face.landmark(g.rstrip("*")))
        if rev:
            idx = idx[::-1]
        if out and idx and idx[0] == out[-1]:
            idx = idx[1:]
        out += [int(i) for i in idx]
    if SECTIONS[section][1] and len(out) > 1 and out[-1] == out[0]:
        out = out[:-1]
    return np.array(out)


def curve_centroid(pts: np.ndarray, closed: bool) -> np.ndarray:
    """The centroid of a polyline as a curve (segment midpoints weighted by length), so that
    it does not move when nodes slide along the curve."""
    q = np.vstack([pts, pts[:1]]) if closed else pts
    seg = np.linalg.norm(np.diff(q, axis=0), axis=1)
    if seg.sum() <= 0:
        return pts.mean(axis=0)
    mid = 0.5 * (q[1:] + q[:-1])
    return (mid * seg[:, None]).sum(axis=0) / seg.sum()


def section_features(section: str, pts: np.ndarray, midline_x: float) -> np.ndarray:
    """The feature points (F, 2) of a contour ``pts`` (K, 2), image (x, y) pixels:
    ``inner``/``outer`` the points nearest to / farthest from the face's midline, ``top`` /
    ``bottom`` the highest / lowest, ``corner_r`` / ``corner_l`` the leftmost / rightmost in the
    image (the subject's right / left), ``bottom_r`` / ``bottom_l`` the lowest point of the
    middle third of the image-left / image-right half, ``centroid`` the mean."""
    out = []
    for f in FEATURES[section]:
        if f == "centroid":
            out.append(curve_centroid(pts, SECTIONS[section][1]))
        elif f == "inner":
            out.append(pts[np.argmin(np.abs(pts[:, 0] - midline_x))])
        elif f == "outer":
            out.append(pts[np.argmax(np.abs(pts[:, 0] - midline_x))])
        elif f == "top":
            out.append(pts[np.argmin(pts[:, 1])])
        elif f == "bottom":
            out.append(pts[np.argmax(pts[:, 1])])
        elif f == "corner_r":
            out.append(pts[np.argmin(pts[:, 0])])
        elif f == "corner_l":
            out.append(pts[np.argmax(pts[:, 0])])
        elif f in ("bottom_r", "bottom_l"):
            # the lowest point of the middle third of the contour's left / right half
            x0, x1 = pts[:, 0].min(), pts[:, 0].max()
            c = 0.5 * (x0 + x1)
            lo, hi = (
                (x0 + (c - x0) / 3, c - (c - x0) / 3)
                if f == "bottom_r"
                else (c + (x1 - c) / 3, x1 - (x1 - c) / 3)
            )
            m = (pts[:, 0] >= lo) & (pts[:, 0] <= hi)
            q = pts[m] if m.any() else pts
            out.append(q[np.argmax(q[:, 1])])
    return np.array(out).reshape(-1, 2)


#: sections tracked as thin dark lines (the "line" potential) rather than as edges
LINE_SECTIONS = ("nasolabial_r", "nasolabial_l")
#: sections tracked but not fitted by the curve estimator: the nose is the head reference, and
#: its lower contour is a shading boundary (the alae's shadow), not a mark on the skin, so its
#: snake does not stay on the same skin as the face moves
CURVE_EXCLUDED = ("nose",)
#: the muscles the paper estimates, plus the jaw
PAPER_MUSCLES = tuple(PAPER_ASSIGNMENT)


def project_sections(model, camera, state=None) -> dict[str, np.ndarray]:
    """The model's section contours in ``state`` (default: rest) projected by ``camera`` (for
    synthetic video whose camera is known, e.g. the closed-loop test: an exact automatic
    initialisation)."""
    v = camera.project(model.skin_vertices(state))[:, :2]
    return {name: v[section_vertices(model.face, name)] for name in SECTIONS}


def model_fiducials(face) -> list[Fiducial]:
    """The fiducials of every section's features on the face model, found with the same rules
    as on the image (:func:`section_features`) on the front view of the rest face."""
    out = []
    img_like = face.vertices[:, :2] * np.array([1.0, -1.0])  # image y points down
    for sec in SECTIONS:
        verts = section_vertices(face, sec)
        pts = img_like[verts]
        feats = section_features(sec, pts, 0.0)
        for name, q in zip(FEATURES[sec], feats, strict=True):
            if name == "centroid":
                out.append(Fiducial(f"{sec}:{name}", tuple(int(v) for v in verts)))
            else:
                k = int(np.argmin(np.linalg.norm(pts - q, axis=1)))
                out.append(Fiducial(f"{sec}:{name}", int(verts[k])))
    return out
