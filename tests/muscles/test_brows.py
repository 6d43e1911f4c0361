"""The brow lowerers (issue 30): the depressor supercilii (AU4) draws the brow's head down and
towards the midline; the orbital orbicularis oculi's upper part (with AU6) draws the whole brow
down. Neither raises the lower lid, which the orbital sphincter (the cheek raise) does."""

import numpy as np
import pytest

import myoface as mf

#: MediaPipe face mesh, the subject's left: the brow's upper edge from its head to its tail
BROW_L = (336, 296, 334, 293, 300)
BROW_INNER_L, BROW_OUTER_L = 336, 300
LOWER_LID_L = 374  # the lower lid's centre
UPPER_LID_L = 386

pytestmark = pytest.mark.slow  # relaxes from rest at full contraction


@pytest.fixture(scope="module")
def moved():
    """{muscle id: the skin's displacement (V, 3) mm at its full contraction alone}."""
    fm = mf.build_face_model()
    rest = fm.skin_vertices()
    out = {}
    for m in ("depressor_supercilii_l", "orbicularis_oculi_superior_l", "orbicularis_oculi_l"):
        res = fm.relax({m: 1.0})
        assert res.converged, m
        out[m] = fm.skin_vertices(res.state) - rest
    return out


def test_the_upper_orbital_part_brings_the_brow_straight_down(moved):
    """Every point of the brow goes down by at least 0.75 mm, more down than sideways, and
    the brow as a whole by at least 1.5 mm; the sphincter instead draws the brow's tail
    towards the eye's centre, more towards the midline than down (why the upper part is its
    own muscle)."""
    d = moved["orbicularis_oculi_superior_l"][list(BROW_L)]
    assert np.all(d[:, 1] < -0.75), d
    assert np.all(np.abs(d[:, 0]) < np.abs(d[:, 1])), d
    assert d[:, 1].mean() < -1.5, d
    tail = moved["orbicularis_oculi_l"][BROW_OUTER_L]
    assert tail[0] < 0 and abs(tail[0]) > abs(tail[1]), tail


def test_the_depressor_supercilii_lowers_the_brows_head_towards_the_midline(moved):
    """The brow's head goes down and in; its tail, 43 mm away, hardly moves."""
    d = moved["depressor_supercilii_l"]
    assert d[BROW_INNER_L, 1] < -0.5 and d[BROW_INNER_L, 0] < -0.3, d[BROW_INNER_L]
    assert np.linalg.norm(d[BROW_OUTER_L]) < 0.5, d[BROW_OUTER_L]


@pytest.mark.parametrize("muscle", ["depressor_supercilii_l", "orbicularis_oculi_superior_l"])
def test_the_brow_lowerers_leave_the_lower_lid(moved, muscle):
    """The lower lid stays within 0.3 mm (the sphincter raises it by more than 1 mm), and the
    upper lid's margin comes down, if at all, with the skin above it."""
    assert np.linalg.norm(moved[muscle][LOWER_LID_L]) < 0.3, moved[muscle][LOWER_LID_L]
    assert moved["orbicularis_oculi_l"][LOWER_LID_L, 1] > 1.0
    assert moved[muscle][UPPER_LID_L, 1] < 0.2, moved[muscle][UPPER_LID_L]


def test_a_face_saved_before_the_brow_lowerers_gets_them(tmp_path):
    """A personal face saved before the two muscles existed gets the default ones: AU4 (which
    needs the depressor supercilii) and AU6 (the upper part) work and lower the brow."""
    from importlib import resources

    from myoface.face import load_default_face
    from myoface.face.facefile import save_face

    text = (resources.files("myoface") / "data" / "default_muscles.toml").read_text()
    for mid in ("depressor_supercilii", "orbicularis_oculi_superior"):
        start = text.index(f'[[muscle]]\nid = "{mid}"')
        end = text.index("\n\n", start) + 2  # the entry ends at the first blank line
        text = text[:start] + text[end:]
        assert f'"{mid}"' not in text
    path = save_face(tmp_path / "old.myoface", load_default_face(), muscles_toml=text)
    fm = mf.load_face_model(path)
    assert {"depressor_supercilii_l", "orbicularis_oculi_superior_r"} <= set(fm.ids)
    for au in (4, 6):
        st = fm.relax(mf.au_contractions({au: 1.0}, fm.ids)).state
        dy = fm.skin_vertices(st)[list(BROW_L), 1] - fm.skin_vertices()[list(BROW_L), 1]
        assert dy.mean() < -1.0, (au, dy)
