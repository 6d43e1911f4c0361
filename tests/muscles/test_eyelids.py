"""Eyelids: AU45/AU43 close the eye, the lids never pass through the eyeball or each other,
AU5 opens the eye, a blink in a timeline closes and reopens it."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import myoface as mf
from myoface.control.timeline import BLINK_DURATION_S, Timeline
from myoface.errors import MyofaceFormatError, MyofaceValueError
from myoface.face import load_default_face
from myoface.face.eyes import EYE_RADIUS_MM, eyeball_center
from myoface.muscles import load_default_muscles, muscles_from_dict
from myoface.render import Camera, Renderer, dressing

EYES = ("eye_l", "eye_r")


@pytest.fixture(scope="module")
def fm():
    return mf.build_face_model()


def opening_area_mm2(skin: np.ndarray, eye) -> float:
    """Area (mm^2) of the eye opening projected on the front view plane (x, y)."""
    loop = np.r_[eye.upper, eye.lower[::-1][1:-1]]
    x, y = skin[loop, 0], skin[loop, 1]
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def clearance_mm(skin: np.ndarray, eye) -> float:
    """The lid vertices' least distance (mm) from the eyeball's surface (< 0: inside it)."""
    return float((np.linalg.norm(skin[eye.vertices] - eye.center, axis=1) - EYE_RADIUS_MM).min())


def lid_gap_rad(skin: np.ndarray, eye) -> np.ndarray:
    """Elevation of the upper margin minus the lower margin's at the same rest x (rad), at
    each upper margin vertex; about the eyeball's horizontal axis."""

    def elev(idx):
        q = skin[idx] - eye.center
        return np.arctan2(q[:, 1], q[:, 2])

    s_up, s_lo = eye.s_upper, eye.s_lower
    return elev(eye.upper)[1:-1] - np.interp(s_up[1:-1], s_lo, elev(eye.lower))


def skin_for(fm, aus, state=None):
    return fm.skin_vertices(fm.relax(mf.au_contractions(aus, fm.ids), state).state)


def test_default_model_has_both_eyes(fm):
    assert fm.eyelids is not None
    assert set(fm.eyelids.eyes) == set(EYES)
    for lid in ("levator_palpebrae_superioris", "orbicularis_oculi_palpebralis"):
        assert {f"{lid}_l", f"{lid}_r"} <= set(fm.ids)
    assert fm.ids[-1] == "jaw"


def test_rest_lids_outside_the_eyeball_and_unchanged(fm):
    rest = fm.face.vertices
    skin = fm.skin_vertices(fm.relax({}).state)
    np.testing.assert_allclose(skin, rest, atol=1e-9)
    for eye in fm.eyelids.eyes.values():
        assert clearance_mm(rest, eye) >= 0.25


def test_lid_muscles_leave_the_tissue_alone(fm):
    c = mf.au_contractions({45: 1.0, 5: 1.0}, fm.ids)
    state = fm.relax(c).state
    np.testing.assert_allclose(state.x, fm.rest_state().x, atol=1e-12)


@pytest.mark.parametrize("au", [45, 43])
def test_full_closure_meets_the_lids(fm, au):
    skin = skin_for(fm, {au: 1.0})
    rest = fm.face.vertices
    for eye in fm.eyelids.eyes.values():
        a0 = opening_area_mm2(rest, eye)
        assert a0 > 50.0  # the open eye, mm^2
        assert opening_area_mm2(skin, eye) < 1e-3 * a0
        # the margins meet in 3-D: each upper vertex on its lower partner (same rest x)
        gap = np.linalg.norm(skin[eye.upper] - skin[eye.lower], axis=1)
        assert gap.max() < 0.05  # mm
        assert clearance_mm(skin, eye) >= 0.0


def test_blink_closes_on_top_of_other_action_units(fm):
    # the cheek raiser and the brows move the lid skin through the tissue; a blink still closes
    skin = skin_for(fm, {45: 1.0, 6: 1.0, 1: 1.0, 2: 1.0})
    for eye in fm.eyelids.eyes.values():
        assert opening_area_mm2(skin, eye) < 0.1
        assert clearance_mm(skin, eye) >= 0.0


def _whitish(img: np.ndarray) -> np.ndarray:
    """Pixels of the sclera: bright and nearly grey (the skin is bright but reddish)."""
    f = img.astype(np.float64)
    return (f.min(axis=2) > 150) & (f.max(axis=2) - f.min(axis=2) < 40)


def test_blink_hides_the_eyeball_in_the_render(fm):
    face = fm.face
    cam = Camera.front(face.vertices, width=256, height=256)
    r = Renderer(face, cam, ssaa=1)
    box = cam.project(face.vertices[np.r_[face.landmarks["eye_l"], face.landmarks["eye_r"]]])
    x0, y0 = np.floor(box[:, :2].min(axis=0)).astype(int) - 3
    x1, y1 = np.ceil(box[:, :2].max(axis=0)).astype(int) + 3
    open_img = r.render(face.vertices)[y0:y1, x0:x1]
    shut_img = r.render(skin_for(fm, {45: 1.0}))[y0:y1, x0:x1]
    assert _whitish(open_img).sum() > 20  # the sclera shows in the open eyes
    assert _whitish(shut_img).sum() == 0


def test_au5_opens_wider_than_neutral(fm):
    rest = fm.face.vertices
    skin = skin_for(fm, {5: 1.0})
    for eye in fm.eyelids.eyes.values():
        assert opening_area_mm2(skin, eye) > 1.2 * opening_area_mm2(rest, eye)
        mid = eye.upper[len(eye.upper) // 2]
        assert skin[mid, 1] - rest[mid, 1] > 1.5  # the upper margin rises, mm
        assert clearance_mm(skin, eye) >= 0.0


def test_au7_narrows_and_half_closure_is_between(fm):
    rest = fm.face.vertices
    a7 = skin_for(fm, {7: 1.0})
    half = skin_for(fm, {43: 0.5})
    for eye in fm.eyelids.eyes.values():
        a0 = opening_area_mm2(rest, eye)
        assert opening_area_mm2(a7, eye) < 0.7 * a0
        assert 0.2 * a0 < opening_area_mm2(half, eye) < 0.8 * a0


@pytest.fixture(scope="module")
def tissue_states(fm):
    """Relaxed tissue for a few action units that move the skin around the eyes."""
    out = [fm.rest_state()]
    for aus in ({6: 1.0}, {1: 1.0, 2: 1.0}, {4: 1.0, 7: 1.0}, {6: 0.5, 12: 1.0}):
        out.append(fm.relax(mf.au_contractions(aus, fm.ids)).state)
    return out


unit = st.floats(0.0, 1.0, allow_nan=False)


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    which=st.integers(0, 4),
    lids=st.tuples(unit, unit, unit, unit),
)
def test_lids_never_pass_through_the_eyeball_or_each_other(fm, tissue_states, which, lids):
    base = tissue_states[which]
    c = np.array(base.contractions)
    for k, lid in enumerate(
        (
            "levator_palpebrae_superioris_l",
            "levator_palpebrae_superioris_r",
            "orbicularis_oculi_palpebralis_l",
            "orbicularis_oculi_palpebralis_r",
        )
    ):
        c[fm.ids.index(lid)] = lids[k]
    res = fm.relax(c, base)  # the lid muscles leave the tissue where it was
    skin = fm.skin_vertices(res.state)
    for eye in fm.eyelids.eyes.values():
        assert clearance_mm(skin, eye) >= 0.0
        assert lid_gap_rad(skin, eye).min() >= -1e-9  # the upper lid never below the lower


def test_blink_in_a_timeline_closes_then_reopens(fm):
    tl = Timeline.from_dict({"event": [{"kind": "blink", "start": 0.1}]})
    ev = tl.events[0]
    assert ev.duration == BLINK_DURATION_S
    a0, a1 = ev.apex_interval()
    assert a0 - ev.start < ev.end - a1  # closes faster than it reopens
    times = np.array([0.0, 0.5 * (a0 + a1), ev.end + 0.01])
    cs = tl.contractions(times, fm.ids)
    rest = fm.face.vertices
    state = None
    areas = []
    for c in cs:
        state = fm.relax(c, state).state
        skin = fm.skin_vertices(state)
        areas.append([opening_area_mm2(skin, e) for e in fm.eyelids.eyes.values()])
    before, shut, after = np.array(areas)
    full = [opening_area_mm2(rest, e) for e in fm.eyelids.eyes.values()]
    np.testing.assert_allclose(before, full, rtol=1e-9)
    assert shut.max() < 1e-3 * min(full)
    np.testing.assert_allclose(after, full, rtol=1e-6)


def test_one_sided_blink_closes_one_eye(fm):
    tl = Timeline.from_dict({"event": [{"kind": "blink", "name": "L", "start": 0.0}]})
    a0, a1 = tl.events[0].apex_interval()
    c = tl.contractions([0.5 * (a0 + a1)], fm.ids)[0]
    skin = fm.skin_vertices(fm.relax(c).state)
    el = fm.eyelids.eyes
    assert opening_area_mm2(skin, el["eye_l"]) < 0.01
    assert opening_area_mm2(skin, el["eye_r"]) == pytest.approx(
        opening_area_mm2(fm.face.vertices, el["eye_r"])
    )


@pytest.mark.parametrize(
    "event, message",
    [
        ({"kind": "blink", "start": 0.0, "name": "up"}, "both, L, R"),
        ({"kind": "blink", "start": 0.0, "duration": 0.0}, "duration"),
    ],
)
def test_bad_blink_events(event, message):
    with pytest.raises(MyofaceFormatError, match=message):
        Timeline.from_dict({"event": [event]})


def test_renderer_draws_the_eyeball_the_lids_slide_on(fm):
    face = fm.face
    r = Renderer(face, Camera.front(face.vertices, width=64, height=64), ssaa=1)
    balls = r.positions(face.vertices)[r.scene.n_dynamic :]
    centers = np.array([e.center for e in fm.eyelids.eyes.values()])
    d = np.linalg.norm(balls[:, None, :] - centers[None], axis=2)
    n_ball = len(dressing.eyeball(np.zeros(3), np.array([0, 0, 1.0]), EYE_RADIUS_MM)[0])
    on_sphere = np.abs(d - EYE_RADIUS_MM) < 1e-9  # (static vertices, eyes)
    assert (on_sphere.sum(axis=0) >= n_ball).all()


def test_eyeball_center_clears_the_margin_or_keeps_the_old_depth():
    # a flat ring of radius 10 mm: 12 mm sphere 3.5 mm in front would swallow it
    t = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    ring = np.column_stack([10 * np.cos(t), 5 * np.sin(t), np.zeros_like(t)])
    c = eyeball_center(ring, np.arange(16))
    d = np.linalg.norm(ring - c, axis=1)
    assert d.min() == pytest.approx(EYE_RADIUS_MM + 0.5)
    # a ring wider than the eyeball keeps the front pole 3.5 mm in front of its centroid
    wide = ring * 3
    c = eyeball_center(wide, np.arange(16))
    assert c[2] == pytest.approx(-(EYE_RADIUS_MM - 3.5))


def test_lid_muscle_file_checks():
    face = load_default_face()
    base = {
        "id": "lps",
        "sides": "lr",
        "type": "lid",
        "eye": "eye_l",
        "action": "raise",
        "origin": {"vertex": 386, "offset_mm": [0, 0, -30]},
        "insertion": {"vertex": 386},
    }
    ms = muscles_from_dict({"muscle": [base]}, face)
    assert ms["lps_r"].eye == "eye_r"
    with pytest.raises(MyofaceFormatError, match="landmark group"):
        muscles_from_dict({"muscle": [{**base, "eye": "nose"}]}, face)
    with pytest.raises(MyofaceFormatError, match="action"):
        muscles_from_dict({"muscle": [{**base, "action": "wink"}]}, face)
    assert load_default_muscles(face)["levator_palpebrae_superioris_l"].kind == "lid"


def test_a_face_saved_before_the_eyelids_gets_them(tmp_path):
    from importlib import resources

    from myoface.face.facefile import save_face

    text = (resources.files("myoface") / "data" / "default_muscles.toml").read_text()
    old = text[: text.index('[[muscle]]\nid = "levator_palpebrae_superioris"')]
    assert 'type = "lid"' not in old
    path = save_face(tmp_path / "old.myoface", load_default_face(), muscles_toml=old)
    fm = mf.load_face_model(path)
    assert "orbicularis_oculi_palpebralis_l" in fm.ids
    skin = fm.skin_vertices(fm.relax(mf.au_contractions({45: 1.0}, fm.ids)).state)
    for eye in fm.eyelids.eyes.values():
        assert opening_area_mm2(skin, eye) < 0.01


def test_gaze_turns_the_iris(fm):
    """The eyeballs turn about their centres: the dark iris and pupil move towards the
    subject's left (+x: the image's right in the front view) for a positive yaw, up for a
    positive pitch; bad angles are refused."""
    from myoface.render.renderer import gaze_rotation

    np.testing.assert_allclose(gaze_rotation((0.0, 0.0)), np.eye(3), atol=1e-15)
    g = gaze_rotation((0.3, 0.2))
    np.testing.assert_allclose(g @ g.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(
        g @ [0, 0, 1.0], [np.sin(0.3) * np.cos(0.2), np.sin(0.2), np.cos(0.3) * np.cos(0.2)]
    )
    face = fm.face
    cam = Camera.front(face.vertices[face.landmarks["eye_l"]], width=160, height=80)
    r = Renderer(face, cam, ssaa=1)
    skin = skin_for(fm, {5: 1.0})  # wide open: the iris has room to move

    def iris_centre(img):
        dark = img.astype(float).max(axis=2) < 70  # iris and pupil (the socket is hidden)
        rows, cols = np.nonzero(dark)
        return np.array([cols.mean(), rows.mean()])

    ahead = iris_centre(r.render(skin))
    left = iris_centre(r.render(skin, gaze=(0.35, 0.0)))
    up = iris_centre(r.render(skin, gaze=(0.0, 0.25)))
    assert left[0] - ahead[0] > 3  # px, towards the image's right
    assert ahead[1] - up[1] > 2  # px, up the image
    for bad in [(1.0, 0.0), (0.0, float("nan")), "up"]:
        with pytest.raises(MyofaceValueError, match="gaze"):
            r.render(skin, gaze=bad)


def test_each_eye_can_turn_its_own_way(fm):
    """A gaze per eye (``{"l": ..., "r": ...}``, eyes that converge on a near point): each
    eyeball is placed as a common gaze of its own angles places it, the other as its own;
    an eye not given looks ahead; unknown keys are refused."""
    face = fm.face
    r = Renderer(face, Camera.front(face.vertices, width=64, height=64), ssaa=1)
    skin = face.vertices
    eyes = {side: slice(a, b) for (a, b, _), side in zip(r._eyeballs, r._eye_sides, strict=True)}
    assert sorted(eyes) == ["l", "r"]
    left, right = (0.2, -0.1), (-0.15, 0.05)
    both = r.positions(skin, gaze={"l": left, "r": right})
    np.testing.assert_allclose(both[eyes["l"]], r.positions(skin, gaze=left)[eyes["l"]])
    np.testing.assert_allclose(both[eyes["r"]], r.positions(skin, gaze=right)[eyes["r"]])
    assert np.abs(both[eyes["l"]] - r.positions(skin, gaze=right)[eyes["l"]]).max() > 1.0
    only = r.positions(skin, gaze={"l": left})
    np.testing.assert_allclose(only[eyes["r"]], r.positions(skin)[eyes["r"]])
    with pytest.raises(MyofaceValueError, match="per eye"):
        r.render(skin, gaze={"left": left})


def test_gaze_events_in_a_timeline_turn_the_eyes(fm):
    from myoface.synth import Synthesizer

    ev = {"kind": "gaze", "start": 0.0, "duration": 1.0, "onset": 0.2, "offset": 0.2}
    tl = Timeline.from_dict({"event": [{**ev, "yaw_deg": 20.0}, {"kind": "blink", "start": 2.0}]})
    g = tl.gaze([0.0, 0.5, 1.5])
    np.testing.assert_allclose(g, [[0.0, 0.0], [np.deg2rad(20.0), 0.0], [0.0, 0.0]], atol=1e-12)
    assert not tl.contractions([0.5], fm.ids).any()  # a gaze moves no muscle
    assert Timeline.from_dict(tl.to_dict()).gaze([0.5])[0, 0] == pytest.approx(np.deg2rad(20.0))
    with pytest.raises(MyofaceFormatError, match="pitch_deg"):
        Timeline.from_dict({"event": [{**ev, "pitch_deg": 60.0}]})
    with pytest.raises(MyofaceFormatError, match="unknown keys"):
        Timeline.from_dict({"event": [{**ev, "kind": "au", "name": "12", "yaw_deg": 5.0}]})
    # the synthesizer turns the eyes frame by frame, and nothing else changes
    face = fm.face
    cam = Camera.front(face.vertices, width=96, height=96)
    syn = Synthesizer(fm, Renderer(face, cam, ssaa=1))
    table = np.zeros((2, fm.n_muscles))
    ahead, turned = syn.frames(table, [0.0, 0.5], gaze=np.array([[0.0, 0.0], [0.35, 0.0]]))
    changed = np.abs(ahead.astype(int) - turned.astype(int)).max(axis=2) > 0
    assert changed.sum() > 4
    eyes = cam.project(face.vertices[np.r_[face.landmarks["eye_l"], face.landmarks["eye_r"]]])
    rows, cols = np.nonzero(changed)
    assert cols.min() >= eyes[:, 0].min() - 2 and cols.max() <= eyes[:, 0].max() + 2
    assert rows.min() >= eyes[:, 1].min() - 2 and rows.max() <= eyes[:, 1].max() + 2


def test_a_face_saved_before_the_lips_marginal_part_takes_au24(tmp_path):
    """A personal face saved before orbicularis_oris_marginalis existed gets the default one:
    AU24 (which needs it) works and presses the lower lip up."""
    from importlib import resources

    from myoface.face.facefile import save_face

    text = (resources.files("myoface") / "data" / "default_muscles.toml").read_text()
    start = text.index('[[muscle]]\nid = "orbicularis_oris_marginalis"')
    end = text.index("\n\n", start) + 2  # the entry ends at the first blank line
    old = text[:start] + text[end:]
    assert "orbicularis_oris_marginalis" not in old and "[jaw]" in old
    path = save_face(tmp_path / "old.myoface", load_default_face(), muscles_toml=old)
    fm = mf.load_face_model(path)
    assert "orbicularis_oris_marginalis" in fm.ids
    lip = fm.face.landmark("lip_lower_outer")
    st = fm.relax(mf.au_contractions({24: 1.0}, fm.ids)).state
    assert (fm.skin_vertices(st)[lip, 1] - fm.skin_vertices()[lip, 1]).mean() > 0.3
