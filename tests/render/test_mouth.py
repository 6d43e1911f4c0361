"""Teeth in the mouth: hidden behind the closed lips at rest, visible in a broad smile and when the
lips part, the lower ones with the jaw; the lips never pass through the teeth or each other
(hypothesis, relaxed tissue)."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import myoface as mf
from myoface.face.teeth import contact_violations
from myoface.render import Renderer
from myoface.synth import make_camera

#: a pixel is tooth-bright when its mean sRGB level is above this (the lips and skin around
#: the mouth are pink-red with a low green channel; the cavity is below 40)
BRIGHT_GREEN = 150


@pytest.fixture(scope="module")
def fm():
    return mf.build_face_model()


@pytest.fixture(scope="module")
def renderer(fm):
    return Renderer(fm.face, make_camera(fm.face.vertices, "front", 256, 256))


def _teeth_pixels(renderer, fm, state) -> int:
    """Bright, nearly grey pixels inside the mouth's box (the teeth; skin and lips are
    reddish: their green channel is well below their red)."""
    img = renderer.render(fm.skin_vertices(state), jaw=fm.jaw_pose(state))
    lips = np.r_[fm.face.landmarks["lip_upper_outer"], fm.face.landmarks["lip_lower_outer"]]
    xy = renderer.camera.project(fm.skin_vertices(state)[lips])[:, :2]
    x0, y0 = np.floor(xy.min(axis=0)).astype(int)
    x1, y1 = np.ceil(xy.max(axis=0)).astype(int)
    box = img[y0:y1, x0:x1].astype(int)
    r, g = box[..., 0], box[..., 1]
    return int(((g > BRIGHT_GREEN) & (r - g < 30)).sum())


def test_closed_lips_hide_the_teeth_at_rest(fm, renderer):
    """The default face rests with its lips together (issue 34): no tooth shows. The upper
    incisal edge lies REST_DISPLAY_MM below the upper lip's margin (Vig & Brundo 1978), behind
    the lower lip; the lower one behind the lower lip, INCISAL_REST_GAP_MM below the upper."""
    from myoface.face.teeth import INCISAL_REST_GAP_MM, REST_DISPLAY_MM

    assert _teeth_pixels(renderer, fm, fm.rest_state()) == 0
    d = renderer.dentition
    lm = fm.face.landmarks
    v = fm.face.vertices
    mid_u = v[lm["lip_upper_inner"][len(lm["lip_upper_inner"]) // 2], 1]
    mid_l = v[lm["lip_lower_inner"][len(lm["lip_lower_inner"]) // 2], 1]
    assert mid_u - d.upper.edge_y == pytest.approx(REST_DISPLAY_MM * d.scale)
    assert d.upper.edge_y < mid_l  # below the lower lip's margin: the lower lip covers it
    assert d.upper.edge_y - d.lower.edge_y == pytest.approx(INCISAL_REST_GAP_MM * d.scale)


def test_upper_incisors_show_when_the_lips_part(fm, renderer):
    """Lips parted at rest (the default face's lower lip lowered by 5 mm, as the canonical
    mesh's was): the upper incisors show below the upper lip, the lower ones stay behind the
    lower lip."""
    from myoface.face.teeth import EDGE_HIDDEN_MM, REST_DISPLAY_MM, fit_dentition

    lm = fm.face.landmarks
    v = fm.face.vertices.copy()
    ui, li = lm["lip_upper_inner"], lm["lip_lower_inner"]
    lower = np.r_[li[1:-1], lm["lip_lower_outer"][1:-1]]
    v[lower, 1] -= 5.0
    d = fit_dentition(fm.face.with_vertices(v))
    mid_u, mid_l = v[ui[len(ui) // 2], 1], v[li[len(li) // 2], 1]
    assert mid_u - d.upper.edge_y == pytest.approx(REST_DISPLAY_MM * d.scale)
    assert d.upper.edge_y > mid_l  # between the lips
    assert d.lower.edge_y == pytest.approx(mid_l - EDGE_HIDDEN_MM)


def test_teeth_visible_in_a_broad_smile(fm, renderer):
    c = mf.au_contractions({12: 1.0, 6: 0.6, 25: 0.6}, fm.ids)
    assert _teeth_pixels(renderer, fm, fm.relax(c).state) >= 10


def test_no_teeth_without_dressing(fm):
    r = Renderer(fm.face, make_camera(fm.face.vertices, "front", 64, 64), teeth=False)
    assert r.dentition is None and r.scene.cavity is None


def test_lower_teeth_follow_the_jaw(fm, renderer):
    c = mf.au_contractions({26: 1.0}, fm.ids)
    st = fm.relax(c).state
    rot, shift = fm.jaw_pose(st)
    sc = renderer.scene
    rest = renderer.positions(fm.skin_vertices(st))
    moved = renderer.positions(fm.skin_vertices(st), jaw=(rot, shift))
    lower = slice(sc.n_jaw_first, None)
    upper = slice(sc.n_dynamic, sc.n_jaw_first)
    np.testing.assert_allclose(moved[lower], rest[lower] @ rot.T + shift, atol=1e-9)
    np.testing.assert_array_equal(moved[upper], rest[upper])  # the skull's teeth stay
    assert sc.n_jaw_first < len(moved)
    # the jaw opened: the lower incisors went down (mm)
    assert (rest[lower][:, 1] - moved[lower][:, 1]).max() > 3.0
    # and the jaw's rigid motion is the one that moved the tissue's bone nodes
    kin = fm.tissue.kinematic_index
    jaw_w = fm.muscles.jaw.weights[kin % fm.face.n_vertices]
    full = np.flatnonzero(jaw_w == 1.0)
    x0 = fm.tissue.rest_positions[kin[full]]
    j = fm.muscles.jaw_index
    np.testing.assert_allclose(
        fm.muscles.jaw.rotate(x0, np.ones(len(x0)), c[j]), x0 @ rot.T + shift, atol=1e-9
    )


def test_rest_skin_untouched_by_the_contact(fm):
    d = fm.dentition
    v = fm.face.vertices
    assert contact_violations(v, d) == {"in_upper": 0, "in_lower": 0, "lip_cross_mm": 0.0}
    from myoface.face.teeth import lip_contact

    np.testing.assert_array_equal(lip_contact(v, d), v)


@settings(
    max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    st.lists(st.floats(0.0, 1.0), min_size=48, max_size=48),
    st.lists(st.booleans(), min_size=48, max_size=48),
)
def test_lips_never_pass_through_the_teeth_or_each_other(fm, values, on):
    assert fm.n_muscles <= 48
    c = np.where(on[: fm.n_muscles], values[: fm.n_muscles], 0.0)
    st_ = fm.relax(c).state
    v = contact_violations(fm.skin_vertices(st_), fm.dentition, fm.jaw_pose(st_))
    assert v == {"in_upper": 0, "in_lower": 0, "lip_cross_mm": 0.0}


def _lower_teeth_through_skin(fm, skin, jaw_pose, res_mm: float = 0.25) -> float:
    """How far (mm) the vertices of the lower teeth, gums and tongue as the renderer and the
    glTF export draw them (render.mouth.mouth_meshes), carried by the jaw, lie in front of the
    skin seen straight on (an orthographic z-buffer of the skin's triangles, ``res_mm`` a
    pixel; the mouth's opening has no skin, so the teeth seen through it do not count): 0 when
    the skin covers them."""
    from myoface.analysis.photometric import _zbuffer
    from myoface.face.teeth import _rigid_apply
    from myoface.render.mouth import mouth_meshes

    teeth = _rigid_apply(jaw_pose, mouth_meshes(fm.dentition).lower[0])
    lo = skin[:, :2].min(axis=0) - 1.0
    uv = np.ascontiguousarray((skin[:, :2] - lo) / res_mm)
    w, hgt = (int(v) + 2 for v in uv.max(axis=0))
    tris = np.asarray(fm.face.triangles)
    zb = _zbuffer(uv, np.ascontiguousarray(-skin[:, 2]), tris, hgt, w)
    q = ((teeth[:, :2] - lo) / res_mm).astype(int)
    on = (q[:, 0] >= 0) & (q[:, 0] < w) & (q[:, 1] >= 0) & (q[:, 1] < hgt)
    skin_z = np.full(len(teeth), -np.inf)
    skin_z[on] = -zb[q[on, 1], q[on, 0]]
    over = teeth[:, 2] - skin_z
    over = over[np.isfinite(over)]
    return float(max(over.max(), 0.0)) if len(over) else 0.0


def test_the_lower_teeth_never_show_through_the_chin(fm):
    """The skin below the lower lip covers the lower teeth (face.teeth.CHIN_CLEARANCE_MM): on
    the sample video's analysed smile (the 3-D fit's contractions, the lower lip drawn down
    and back) the coarse mesh's triangles passed in front of the lower teeth and gums by up to
    1.85 mm without it, which a glTF client shows (myoface export)."""
    from myoface.analysis.resynthesis import read_performance

    csv = Path(__file__).parents[1] / "export" / "data" / "single_face_contractions.csv"
    from myoface.face.teeth import lip_contact

    perf = read_performance(csv, fm)
    lips_only = replace(fm.dentition, chin=np.zeros(0, np.int64), chin_clearance=np.zeros(0))
    state = fm.rest_state()
    for k in (30, 45, 60):
        state = fm.relax(perf.contractions[k], state).state
        pose = fm.jaw_pose(state)
        assert _lower_teeth_through_skin(fm, fm.skin_vertices(state), pose) == 0.0, k
        # (the chin's clearance is what does it: the lips' contact alone lets them through)
        raw = np.array(state.x[: fm.face.n_vertices])
        assert _lower_teeth_through_skin(fm, lip_contact(raw, lips_only, pose), pose) > 0.3, k
    for aus in ({12: 1.0, 25: 0.8, 26: 0.6}, {15: 1.0, 16: 1.0, 26: 0.5}, {17: 1.0, 24: 1.0}):
        st_ = fm.relax(mf.au_contractions(aus, fm.ids)).state
        assert _lower_teeth_through_skin(fm, fm.skin_vertices(st_), fm.jaw_pose(st_)) == 0.0, aus


def test_the_lower_teeth_never_show_through_a_persons_chin():
    """The same on the face made from the sample video's photo (its own teeth and chin: with
    the skin below the band left free, its chin's triangles passed over the gums by 0.6 mm)."""
    from myoface.analysis.resynthesis import read_performance
    from myoface.bench.headmotion import personal_face

    face = personal_face()
    if face is None:
        pytest.skip("MediaPipe or the sample video is not available")
    person = mf.build_face_model(face)
    csv = Path(__file__).parents[1] / "export" / "data" / "single_face_contractions.csv"
    perf = read_performance(csv, person)
    state = person.rest_state()
    for k in (30, 60):
        state = person.relax(perf.contractions[k], state).state
        skin, pose = person.skin_vertices(state), person.jaw_pose(state)
        assert _lower_teeth_through_skin(person, skin, pose) == 0.0, k


def test_contact_acts_where_the_tissue_alone_interpenetrates(fm):
    """The relaxed tissue alone lets the lips through in some of these (lip press, chin
    raise, broad smile): the contact is what keeps them apart."""
    clean = {"in_upper": 0, "in_lower": 0, "lip_cross_mm": 0.0}
    n_through = 0
    for aus in ({24: 1.0}, {17: 1.0}, {12: 1.0, 6: 0.6, 25: 0.6}):
        st_ = fm.relax(mf.au_contractions(aus, fm.ids)).state
        raw = np.array(st_.x[: fm.face.n_vertices])
        pose = fm.jaw_pose(st_)
        n_through += contact_violations(raw, fm.dentition, pose) != clean
        assert contact_violations(fm.skin_vertices(st_), fm.dentition, pose) == clean
    assert n_through >= 1


def test_mouth_drawn_only_through_the_lips_changes_nothing(fm, renderer, monkeypatch):
    """Limiting the mouth's inside to the box of the lips' inner margin is an optimization: the
    image is the same as when everything is rasterized."""
    st_ = fm.relax(mf.au_contractions({26: 1.0, 12: 0.6}, fm.ids)).state
    skin, jaw = fm.skin_vertices(st_), fm.jaw_pose(st_)
    clipped = renderer.render(skin, jaw=jaw)
    monkeypatch.setattr(Renderer, "_clip_to_mouth", lambda self, scr: None)
    np.testing.assert_array_equal(renderer.render(skin, jaw=jaw), clipped)


def test_teeth_placed_from_the_lips_of_any_face(fm):
    """A larger face moved elsewhere (as a personal face may be) gets larger teeth there."""
    from myoface.face.teeth import EDGE_HIDDEN_MM, LABIAL_GAP_MM, fit_dentition

    face = fm.face
    big = face.with_vertices(1.2 * face.vertices + np.array([3.0, -5.0, 2.0]))
    d0, d1 = fit_dentition(face), fit_dentition(big)
    assert d1.scale == pytest.approx(1.2 * d0.scale)
    assert d1.upper.xc == pytest.approx(1.2 * d0.upper.xc + 3.0)
    g = LABIAL_GAP_MM  # the teeth's front a fixed distance behind the lips, in any face
    assert d1.upper.z0 == pytest.approx(1.2 * (d0.upper.z0 + g) - g + 2.0)
    # the upper edge a display proportional to the mouth's size below the lip's margin
    assert d1.upper.edge_y == pytest.approx(1.2 * d0.upper.edge_y - 5.0)
    # with the lips closed, the lower edge a rest gap proportional to the mouth's size below
    # the upper edge (the lower lip's margin is above it)
    assert d1.lower.edge_y == pytest.approx(1.2 * d0.lower.edge_y - 5.0)
    # with the lips apart, a fixed distance below the lower lip's margin
    lm = face.landmarks
    v = face.vertices.copy()
    v[np.r_[lm["lip_lower_inner"][1:-1], lm["lip_lower_outer"][1:-1]], 1] -= 5.0
    d2 = fit_dentition(face.with_vertices(v))
    d3 = fit_dentition(face.with_vertices(1.2 * v + np.array([3.0, -5.0, 2.0])))
    e = EDGE_HIDDEN_MM
    assert d3.lower.edge_y == pytest.approx(1.2 * (d2.lower.edge_y + e) - e - 5.0)
    # no lip landmarks, no teeth
    from myoface.face import FaceMesh

    bare = FaceMesh(face.vertices, face.triangles, face.uv, None, {})
    assert fit_dentition(bare) is None
