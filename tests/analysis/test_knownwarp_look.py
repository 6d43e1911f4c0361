"""The look an expression adds to a known-warp frame (:func:`myoface.analysis.knownwarp.
expression_look`): painted where the face is, only there, as strong as asked."""

import numpy as np
import pytest

from myoface.analysis.knownwarp import (
    INNER_LIP_LOWER,
    INNER_LIP_UPPER,
    MOUTH_DARK_RGB,
    TEETH_RGB,
    expression_look,
)

SKIN = (180, 140, 120)


@pytest.fixture(scope="module")
def face_points():
    """The default face's vertices (MediaPipe's topology) seen front on, 1.5 px per mm."""
    from myoface.model import build_face_model

    v = np.asarray(build_face_model().face.vertices)
    return np.column_stack([320 + 1.5 * v[:, 0], 175 - 1.5 * v[:, 1]])


def _frame():
    img = np.empty((360, 640, 3), np.uint8)
    img[:] = SKIN
    return img


def _closed(points):
    """The lips closed: the lower inner lip on the upper one."""
    p = points.copy()
    p[list(INNER_LIP_LOWER)] = p[list(INNER_LIP_UPPER)]
    return p


def _parted(points, px):
    """The lips parted by ``px`` at the centre (the lower inner lip dropped, less toward the
    corners)."""
    p = _closed(points)
    inner = list(INNER_LIP_LOWER)
    t = np.linspace(0, 1, len(inner))
    p[inner, 1] += px * np.sin(np.pi * t)
    return p


def test_no_expression_no_look(face_points):
    img = _frame()
    for expr in ("happiness", "surprise"):
        assert np.array_equal(expression_look(img, _parted(face_points, 8), expr, 0.0), img)


def test_parted_lips_show_teeth_and_the_dark_of_the_mouth(face_points):
    img = _frame()
    p = _parted(face_points, 10)
    out = expression_look(img, p, "surprise", 1.0)
    top, bottom = p[13], p[14]  # the inner lips' centres
    x = int(round(top[0]))
    upper = out[int(round(top[1] + 2)), x].astype(float)
    lower = out[int(round(bottom[1] - 2)), x].astype(float)
    assert np.abs(upper - TEETH_RGB).max() < 30, upper  # the upper teeth under the upper lip
    assert np.abs(lower - MOUTH_DARK_RGB).max() < 30, lower  # the dark above the lower lip
    # near the corners it is dark, not teeth
    corner = 0.85 * p[INNER_LIP_UPPER[0]] + 0.15 * 0.5 * (top + bottom)
    c = out[int(round(corner[1] + 1)), int(round(corner[0]))].astype(float)
    assert c.mean() < 120, c
    # closed lips: nothing shows
    shut = expression_look(img, _closed(face_points), "surprise", 1.0)
    assert np.array_equal(
        shut[int(top[1]) - 20 : int(top[1]) + 20], img[int(top[1]) - 20 : int(top[1]) + 20]
    )


def test_the_look_stays_on_the_face(face_points):
    img = _frame()
    out = expression_look(img, _parted(face_points, 8), "happiness", 1.0)
    changed = np.abs(out.astype(int) - img).max(-1) > 0
    ys, xs = np.nonzero(changed)
    assert changed.any()
    lo, hi = face_points.min(0), face_points.max(0)
    assert xs.min() >= lo[0] and xs.max() <= hi[0] and ys.min() >= lo[1] and ys.max() <= hi[1]


def test_each_expression_folds_its_own_skin(face_points):
    img = _frame()
    p = _closed(face_points)
    smile = expression_look(img, p, "happiness", 1.0).astype(float).mean(-1)
    surprise = expression_look(img, p, "surprise", 1.0).astype(float).mean(-1)
    base = img.astype(float).mean(-1)
    forehead = slice(int(p[10, 1]), int(p[9, 1]))
    cheeks = slice(int(p[129, 1]), int(p[61, 1]))
    # the smile darkens the nasolabial folds (beside the mouth, below the nose's wings) ...
    assert (base[cheeks] - smile[cheeks]).max() > 0.2 * base.max()
    assert np.array_equal(smile[forehead], base[forehead])
    # ... surprise the forehead, above the brows
    assert (base[forehead] - surprise[forehead]).max() > 0.1 * base.max()
    assert np.array_equal(surprise[cheeks], base[cheeks])
    # half as strong: about half the darkening
    half = expression_look(img, p, "happiness", 0.5).astype(float).mean(-1)
    ratio = (base[cheeks] - half[cheeks]).max() / (base[cheeks] - smile[cheeks]).max()
    assert 0.4 < ratio < 0.6, ratio
