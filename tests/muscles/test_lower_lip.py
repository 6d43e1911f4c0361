"""The depressor labii inferioris (AU16) lowers the lower lip without the jaw: FACS (Ekman,
Friesen & Hager 2002) AU16 pulls the lower lip down and stretches it laterally, the lower teeth
may show; Gray's Anatomy (41st ed., ch. 30) has the muscle draw the lip down and a little
laterally, from the mandible's oblique line, lateral to the chin boss (the mentalis')."""

import numpy as np
import pytest

import myoface as mf

LOWER_LIP = (17, 84, 314)  # the lower lip's outer edge: centre, right, left (MediaPipe mesh)
UPPER_LIP = (0, 13)  # the upper lip's outer and inner edge at the midline
CHIN_BOSS = 200

pytestmark = pytest.mark.slow  # relaxes from rest at full contraction


@pytest.fixture(scope="module")
def fm():
    return mf.build_face_model()


def _d(fm, c):
    res = fm.relax(c)
    assert res.converged
    return fm.skin_vertices(res.state) - fm.skin_vertices()


def test_both_lower_the_lower_lip_and_not_the_chin_or_upper_lip(fm):
    """Both at full contraction: every point of the lower lip's edge goes down by 2 mm or more
    (a lowering one sees; until 2026-12-02 the lip's centre went down 0.5 mm, so a real lip's
    drop could only come from the jaw, which drops the chin too); the chin boss, between the
    two muscles, by less than half the lip's centre; the upper lip stays within 0.5 mm."""
    d = _d(fm, {"depressor_labii_inferioris_l": 1.0, "depressor_labii_inferioris_r": 1.0})
    lip = d[list(LOWER_LIP), 1]
    assert np.all(lip < -2.0), lip
    assert abs(d[CHIN_BOSS, 1]) < 0.5 * abs(d[LOWER_LIP[0], 1]), (d[CHIN_BOSS], lip)
    assert np.abs(d[list(UPPER_LIP)]).max() < 0.5, d[list(UPPER_LIP)]


def test_one_side_draws_its_half_of_the_lip_down_and_out(fm):
    """The left muscle alone: the lip's left part goes down more than its right part and moves
    to the subject's left (+x), lateral, as AU16 stretches the lip."""
    d = _d(fm, {"depressor_labii_inferioris_l": 1.0})
    left, right = d[314], d[84]
    assert left[1] < -2.0 and left[1] < right[1] - 1.0, (left, right)
    assert left[0] > 0.5, left
