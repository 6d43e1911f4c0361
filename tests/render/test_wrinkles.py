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
    # a uniform squeeze makes furrows wherever the skin folds into lines (forehead, glabella,
    # crow's feet, the nose), beyond the dead zone; nowhere else (the cheeks, around the mouth)
    from myoface.render.wrinkles import furrow_regions

    squeezed = wf.vertex_fields(0.9 * fm.face.vertices)[:, 3:5].max(axis=1)
    regions = furrow_regions(fm.face)
    assert 0.2 < np.mean(regions > 0) < 0.7
    assert np.mean(squeezed[regions > 0.5] > 0.0) > 0.95
    assert np.all(squeezed[regions == 0] == 0.0)


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


def test_furrow_regions_follow_the_face(fm):
    """Forehead and crow's feet fold into lines; the cheeks and the chin do not."""
    from myoface.render.wrinkles import furrow_regions

    w = furrow_regions(fm.face)
    lm = fm.face.landmarks
    assert w[lm["forehead"]].min() == 1.0
    assert w[lm["cheek_l"]].max() == 0.0 and w[lm["cheek_r"]].max() == 0.0
    assert w[lm["chin_boss"]].max() == 0.0
    # the same regions on a face twice the size (margins scale with the eyes' distance)
    from myoface.face import FaceMesh

    big = FaceMesh(2 * fm.face.vertices, fm.face.triangles, landmarks=fm.face.landmarks)
    np.testing.assert_allclose(furrow_regions(big), w, atol=1e-9)
    # without eye landmarks (Waters' face): the forehead only, the top of the face
    bare = furrow_regions(FaceMesh(fm.face.vertices, fm.face.triangles))
    y = fm.face.vertices[:, 1]
    assert bare[y > y.max() - 0.2 * np.ptp(y)].min() == 1.0
    assert bare[y < y.max() - 0.4 * np.ptp(y)].max() == 0.0


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


@pytest.fixture(scope="module")
def normal_map(fm):
    from myoface.render.wrinkles import WrinkleNormalMap

    return WrinkleNormalMap(WrinkleField(fm.face), fm.face.uv, size=256)


def test_normal_map_is_flat_at_rest_and_tilts_only_where_the_skin_compresses(fm, normal_map):
    assert normal_map.image(fm.face.vertices) is None
    st = fm.relax(mf.au_contractions({6: 1.0, 12: 1.0}, fm.ids)).state
    img = normal_map.image(fm.skin_vertices(st))
    assert img.shape == (256, 256, 3) and img.dtype == np.uint8
    tilted = np.abs(img.reshape(-1, 3).astype(int) - (128, 128, 255)).max(axis=1) > 2
    assert tilted.sum() > 1000  # the smile's cheeks and crow's feet fold
    fields, _ = normal_map.field.fields_fast(fm.skin_vertices(st))
    amp = normal_map._interp @ fields[:, 3:]
    compressed = np.zeros(256 * 256, bool)
    compressed[normal_map.texels[amp.max(axis=1) > 0]] = True
    assert not (tilted & ~compressed).any()


def test_normal_map_tilt_is_the_height_fields_slope(fm, normal_map):
    """The map's tilt at a texel against a finite difference of the height field along the
    surface (rest geometry, amplitudes held at the texel's): the slope along +u and +v."""
    from myoface.render.wrinkles import wrinkle_height

    st = fm.relax(mf.au_contractions({6: 1.0, 12: 1.0}, fm.ids)).state
    skin = fm.skin_vertices(st)
    img = normal_map.image(skin).reshape(-1, 3).astype(np.float64)
    fields, _ = normal_map.field.fields_fast(skin)
    fields = fields.copy()
    nm, face = normal_map, fm.face
    amp = nm._interp @ fields[:, 3:]
    rng = np.random.default_rng(0)
    strong = np.flatnonzero(np.abs(img[nm.texels, :2] - 128).max(axis=1) > 30)
    checked = 0
    for i in rng.choice(strong, size=min(40, len(strong)), replace=False):
        row = nm._interp.getrow(i)
        tri_v = row.indices
        f = int(np.flatnonzero((np.sort(face.triangles, 1) == np.sort(tri_v)).all(1))[0])
        a, b, c = face.triangles[f]
        uv = face.uv[[a, b, c]]
        w = dict(zip(row.indices, row.data, strict=True))
        bary = np.array([w.get(a, 0.0), w.get(b, 0.0), w.get(c, 0.0)])
        if bary.min() < 0.05:
            continue  # near an edge the step would leave the triangle
        uv0 = bary @ uv
        m = np.column_stack([uv[1] - uv[0], uv[2] - uv[0]])

        def at(q, a=a, b=b, c=c, uv=uv, m=m, i=i):
            l12 = np.linalg.solve(m, q - uv[0])
            bb = np.array([1 - l12.sum(), *l12])
            f6 = bb @ fields[[a, b, c]]
            f6[3:] = amp[i]  # the amplitudes held
            return wrinkle_height(f6[None], nm.field.k)[0], bb @ face.vertices[[a, b, c]]

        eps = 2e-4
        slopes = []
        for d in (np.array([eps, 0.0]), np.array([0.0, eps])):
            (h1, p1), (h0, p0) = at(uv0 + d), at(uv0 - d)
            slopes.append((h1 - h0) / np.linalg.norm(p1 - p0))
        # the tangent frame: T along +u, B the part of +v across T (rest geometry)
        jac = np.column_stack([face.vertices[b] - face.vertices[a],
                               face.vertices[c] - face.vertices[a]]) @ np.linalg.inv(m)  # fmt: skip
        t = jac[:, 0] / np.linalg.norm(jac[:, 0])
        dv = jac[:, 1] / np.linalg.norm(jac[:, 1])
        bv = dv - (dv @ t) * t
        slope_b = (slopes[1] - (dv @ t) * slopes[0]) / np.linalg.norm(bv)
        # the tangent-space normal is (-h_T, -h_B, 1) normalised (8-bit)
        n = img[nm.texels[i]] / 127.5 - 1.0
        np.testing.assert_allclose(-n[0] / n[2], slopes[0], atol=0.03 + 0.05 * abs(slopes[0]))
        np.testing.assert_allclose(-n[1] / n[2], slope_b, atol=0.03 + 0.05 * abs(slope_b))
        checked += 1
    assert checked >= 10
