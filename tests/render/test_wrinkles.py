"""Wrinkle shading appears only where the skin compresses."""

import numpy as np
import pytest

import myoface as mf
from myoface.render import Renderer
from myoface.render.wrinkles import WrinkleField
from myoface.synth import make_camera

SIZE = 256


@pytest.fixture(scope="module")
def fm():
    return mf.build_face_model()


@pytest.fixture(scope="module")
def pair(fm):
    cam = make_camera(fm.face.vertices, "front", SIZE, SIZE)
    return Renderer(fm.face, cam), Renderer(fm.face, cam, wrinkles=False)


def _diff(pair, fm, state):
    on, off = pair
    skin, jaw = fm.skin_vertices(state), fm.jaw_pose(state)
    a = on.render_linear(skin, jaw=jaw)
    b = off.render_linear(skin, jaw=jaw)
    return np.abs(a - b).max(axis=2), on


def _region_pixels(renderer, fm, state, vertices, grow_px=3):
    """Pixel mask around the projected vertices (their bounding box, grown)."""
    xy = renderer.camera.project(fm.skin_vertices(state)[vertices])[:, :2]
    x0, y0 = np.floor(xy.min(axis=0)).astype(int) - grow_px
    x1, y1 = np.ceil(xy.max(axis=0)).astype(int) + grow_px
    m = np.zeros((SIZE, SIZE), bool)
    m[max(y0, 0) : y1, max(x0, 0) : x1] = True
    return m


def test_neutral_face_renders_identically_with_and_without(fm, pair):
    d, _ = _diff(pair, fm, fm.rest_state())
    assert d.max() == 0.0


def test_no_compression_no_amplitude(fm):
    wf = WrinkleField(fm.face)
    f = wf.vertex_fields(fm.face.vertices)
    assert np.all(f[:, 3:] == 0.0)
    # a uniform stretch (no compression anywhere) makes no furrows either
    assert np.all(wf.vertex_fields(1.05 * fm.face.vertices)[:, 3:] == 0.0)
    # a uniform squeeze makes them everywhere it is beyond the dead zone
    squeezed = wf.vertex_fields(0.9 * fm.face.vertices)[:, 3:5].max(axis=1)
    assert np.mean(squeezed > 0.0) > 0.95


def test_shading_differs_only_where_the_skin_compresses(fm, pair):
    st = fm.relax(mf.au_contractions({1: 1.0, 2: 1.0}, fm.ids)).state
    d, r = _diff(pair, fm, st)
    wf = r.wrinkles
    amp = wf.vertex_fields(fm.skin_vertices(st))[:, 3:].max(axis=1)
    tris = fm.face.triangles
    wrinkled = np.flatnonzero(amp[tris].max(axis=1) > 0)
    r.render(fm.skin_vertices(st), jaw=fm.jaw_pose(st))
    tid = r.triangle_ids().reshape(SIZE, r.ssaa, SIZE, r.ssaa).transpose(0, 2, 1, 3)
    touched = np.isin(tid, wrinkled).any(axis=(2, 3))
    assert d[~touched].max() == 0.0  # nothing changes off the compressed triangles
    assert d[touched].max() > 0.01


def test_forehead_lines_in_a_brow_raise(fm, pair):
    st = fm.relax(mf.au_contractions({1: 1.0, 2: 1.0}, fm.ids)).state
    d, r = _diff(pair, fm, st)
    lm = fm.face.landmarks
    fore = np.r_[lm["forehead"], lm["eyebrow_l"], lm["eyebrow_r"]]
    m = _region_pixels(r, fm, st, fore)
    assert d[m].max() > 0.0  # faint: this tissue's forehead compresses by 4 % at most
    assert d[~m].max() > 0.01  # the brow tails and eyelids, where it compresses more
    # the chin, far from the brows, is unchanged
    chin = _region_pixels(r, fm, st, lm["chin_outline"], grow_px=0)
    assert d[chin].max() == 0.0


def test_nasolabial_fold_in_a_smile(fm, pair):
    st = fm.relax(mf.au_contractions({12: 1.0}, fm.ids)).state
    d, r = _diff(pair, fm, st)
    lm = fm.face.landmarks
    m = _region_pixels(r, fm, st, np.r_[lm["nasolabial_l"], lm["nasolabial_r"]])
    assert d[m].max() > 0.01  # linear RGB


def test_compiled_kernels_match_the_reference(fm):
    from myoface.render.raster import W_COLS
    from myoface.render.wrinkles import wrinkle_planes

    wf = WrinkleField(fm.face)
    st = fm.relax(mf.au_contractions({12: 1.0, 4: 1.0}, fm.ids)).state
    skin = fm.skin_vertices(st)
    ref = wf.vertex_fields(skin)
    fast, any_ = wf.fields_fast(skin)
    assert any_
    np.testing.assert_allclose(fast, ref, rtol=1e-10, atol=1e-12)
    # the gradients in the planes' last 9 columns against the numpy reference
    tris = fm.face.triangles
    wp = np.zeros((len(tris), W_COLS))
    flag = np.zeros(len(tris), bool)
    setup = np.random.default_rng(0).normal(size=(len(tris), 12))
    wrinkle_planes(fast, skin, tris.astype(np.int64), setup, np.ones(len(skin)), wp, flag)
    g = wf.gradients(skin)
    np.testing.assert_allclose(wp[flag, 18:], g[flag].reshape(-1, 9), rtol=1e-9, atol=1e-12)
    assert np.array_equal(flag, ref[tris, 3:].max(axis=(1, 2)) > 0)
