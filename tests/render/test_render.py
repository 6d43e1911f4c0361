"""The renderer: coverage and depth, projection, Lambert shading, textures, symmetry, goldens."""

from pathlib import Path

import numpy as np
import pytest

from myoface.errors import MyofaceError, MyofaceFileNotFoundError, MyofaceValueError
from myoface.face import load_default_face
from myoface.render import (
    Camera,
    Light,
    Renderer,
    SkinMaterial,
    VideoWriter,
    render_mesh,
    write_image,
)
from myoface.render.raster import rasterize_coverage_numpy

GOLDEN = Path(__file__).parent / "golden"
FLAT = SkinMaterial(albedo=(1, 1, 1), ambient=(1, 1, 1), specular=0.0)  # unlit: colour = albedo


def ortho(width=64, height=64, span=64.0):
    return Camera((0, 0, 100.0), (0, 0, 0), (0, 1, 0), width, height, None, span)


def test_projection_perspective_and_orthographic():
    cam = Camera((0, 0, 100.0), (0, 0, 0), (0, 1, 0), 100, 80, fov_deg=90.0)
    p = cam.project(np.array([[0, 0, 0], [50, 0, 0], [0, 25, 50.0]]))
    f = 40.0  # half height / tan(45 deg)
    np.testing.assert_allclose(p[0], [50, 40, 100])
    np.testing.assert_allclose(p[1], [50 + f * 0.5, 40, 100])
    np.testing.assert_allclose(p[2], [50, 40 - f * 0.5, 50])  # closer: bigger offset
    o = ortho(100, 80, span=80.0).project(np.array([[10, 20, -30.0]]))
    np.testing.assert_allclose(o[0], [60, 20, 130])


def test_triangle_coverage_and_depth_order_match_the_reference():
    cam = ortho(48, 40, span=40.0)
    v = np.array(
        [[-15, -12, 0], [15, -12, 0], [0, 14, 0], [-5, -18, 5], [18, 0, 5], [-10, 10, 5.0]]
    )
    tris = np.array([[0, 1, 2], [3, 4, 5]])
    r = Renderer(
        __import__("myoface.face", fromlist=["FaceMesh"]).FaceMesh(v, tris),
        cam,
        [],
        FLAT,
        ssaa=1,
        dress=False,
    )
    r.render()
    tid = r.triangle_ids()
    ref_tid, _ = rasterize_coverage_numpy(cam.project(v), tris, 40, 48)
    assert (tid == ref_tid).mean() > 0.995  # edge pixels may differ by rounding only
    assert (tid == 1).sum() > 50 and (tid == 0).sum() > 50  # the nearer triangle occludes


def test_lambert_sphere_matches_the_analytic_value():
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=5, radius=30.0)
    cam = ortho(96, 96, span=80.0)
    light = Light((0.3, 0.4, 0.866), (1, 1, 1), 1.0)
    mat = SkinMaterial(albedo=(0.8, 0.8, 0.8), ambient=(0, 0, 0), specular=0.0)
    img = render_mesh(s.vertices, s.faces, cam, lights=[light], material=mat, linear=True)
    ys, xs = np.mgrid[0:96, 0:96]
    x = (xs + 0.5 - 48) * 80 / 96
    y = -(ys + 0.5 - 48) * 80 / 96
    inside = x**2 + y**2 < (0.9 * 30) ** 2
    z = np.sqrt(np.clip(900 - x**2 - y**2, 0, None))
    n = np.stack([x, y, z], -1) / 30
    ldir = np.array(light.direction) / np.linalg.norm(light.direction)
    expected = 0.8 * np.clip(n @ ldir, 0, None)
    err = np.abs(img[..., 0] - expected)[inside]
    assert err.max() < 0.02 and err.mean() < 0.004


def test_checkerboard_texture_lookup():
    tex = np.zeros((8, 8, 3), np.uint8)
    tex[(np.add.outer(np.arange(8), np.arange(8)) % 2) == 0] = 255
    v = np.array([[-36, -36, 0], [36, -36, 0], [36, 36, 0], [-36, 36, 0.0]])
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1.0]])
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    img = render_mesh(v, tris, ortho(72, 72, 72.0), uv=uv, texture=tex, material=FLAT, lights=[])
    # texel (row r, col c) covers pixels 9r..9r+8, its centre is the centre of pixel 9r+4
    # (v is flipped: texel row 0 is the top of the image); bilinear filtering is exact there
    centers = img[4::9, 4::9, 0]
    expected = np.where((np.add.outer(np.arange(8), np.arange(8)) % 2) == 0, 255, 0)
    np.testing.assert_array_equal(centers, expected)


def test_symmetric_face_renders_symmetric():
    face = load_default_face()
    cam = Camera.front(face.vertices, width=96, height=96, fov_deg=None)
    light = [Light((0, 0.3, 1.0))]
    r = Renderer(face, cam, light, ssaa=1)
    img = r.render().astype(int)
    # the camera centre is on the mid-sagittal plane: the image mirrors about its middle column
    diff = np.abs(img - img[:, ::-1])
    assert np.mean(diff > 24) < 0.01, np.mean(diff > 24)


def test_rendered_face_has_eyes_and_dark_mouth():
    """The default face rests with its lips together (issue 34): at rest the mouth's centre
    shows the lips; with the lower lip lowered 6 mm (about as the canonical mesh's rested)
    the mouth's inside shows there, dark."""
    face = load_default_face()
    cam = Camera.front(face.vertices, width=128, height=128)
    r = Renderer(face, cam)
    img = r.render()
    p = cam.project(face.vertices)
    mouth = (
        p[face.landmark("lip_upper_inner")].mean(axis=0) * 0.5
        + p[face.landmark("lip_lower_inner")].mean(axis=0) * 0.5
    )
    eye = p[face.landmark("eye_l")].mean(axis=0)
    skin = p[face.landmark("cheek_l")].mean(axis=0)
    px = lambda q: img[int(q[1]), int(q[0])].astype(int)  # noqa: E731
    assert px(mouth).sum() > px(skin).sum() * 0.6  # closed: the lips, not the mouth's inside
    lm = face.landmarks
    v = face.vertices.copy()
    v[np.r_[lm["lip_lower_inner"][1:-1], lm["lip_lower_outer"][1:-1]], 1] -= 6.0
    opened = r.render(v)
    q = cam.project(v)
    mouth = 0.5 * (q[lm["lip_upper_inner"]].mean(axis=0) + q[lm["lip_lower_inner"]].mean(axis=0))
    assert opened[int(mouth[1]), int(mouth[0])].astype(int).sum() < px(skin).sum() * 0.5
    # no background shows through the eye opening: the eye region is sclera/iris, not background
    ey, ex = int(eye[1]), int(eye[0])
    region = img[ey - 2 : ey + 3, ex - 6 : ex + 7].astype(int).sum(axis=2)
    assert region.min() < 200 and region.max() > 350  # dark iris and bright sclera


def test_golden_default_face(regen_golden):
    """128x128 renders of the default face; tolerance: mean |diff| < 1.5 levels and < 1% of
    pixels off by more than 24 levels (numba fastmath / CPU differences move edge pixels)."""
    import imageio.v3 as iio

    face = load_default_face()
    for view in ("front", "three_quarter"):
        cam = getattr(Camera, view)(face.vertices, width=128, height=128)
        img = Renderer(face, cam).render()
        path = GOLDEN / f"default_face_{view}.png"
        if regen_golden or not path.exists():
            write_image(path, img)
            if not regen_golden:
                pytest.fail(f"golden image {path.name} was missing and has been written; rerun")
            continue
        ref = iio.imread(path).astype(int)
        d = np.abs(img.astype(int) - ref)
        assert d.mean() < 1.5 and (d.max(axis=2) > 24).mean() < 0.01, (view, d.mean())


def test_bad_inputs(tmp_path):
    face = load_default_face()
    cam = Camera.front(face.vertices, width=32, height=32)
    r = Renderer(face, cam, ssaa=1)
    with pytest.raises(MyofaceValueError, match="shape"):
        r.render(np.zeros((3, 3)))
    bad = face.vertices.copy()
    bad[0, 0] = np.nan
    with pytest.raises(MyofaceValueError, match="NaN"):
        r.render(bad)
    with pytest.raises(MyofaceFileNotFoundError, match="no such texture"):
        Renderer(face, cam, texture=tmp_path / "missing.png")
    with pytest.raises(MyofaceValueError, match="ssaa"):
        Renderer(face, cam, ssaa=9)
    with pytest.raises(MyofaceValueError, match="image size"):
        Camera((0, 0, 1.0), (0, 0, 0), width=0, height=10)
    with pytest.raises(MyofaceValueError, match="parallel"):
        Camera((0, 0, 1.0), (0, 0, 0), up=(0, 0, 1))
    with pytest.raises(MyofaceError, match="does not exist"):
        write_image(tmp_path / "no" / "x.png", np.zeros((4, 4, 3), np.uint8))
    with pytest.raises(MyofaceValueError, match="uint8"):
        write_image(tmp_path / "x.png", np.zeros((4, 4, 3)))


def test_video_writer_roundtrip_and_atomicity(tmp_path):
    import imageio.v3 as iio

    path = tmp_path / "v.mp4"
    frames = [np.full((32, 48, 3), 40 * k, np.uint8) for k in range(5)]
    with VideoWriter(path, fps=10) as vw:
        for f in frames:
            vw.write(f)
    back = iio.imread(path, plugin="pyav")
    assert back.shape == (5, 32, 48, 3)
    assert abs(int(back[4].mean()) - 160) < 6
    broken = tmp_path / "broken.mp4"
    with pytest.raises(RuntimeError), VideoWriter(broken, fps=10) as vw:
        vw.write(frames[0])
        raise RuntimeError("crash mid-video")
    assert not broken.exists() and not list(tmp_path.glob(".broken*"))
    with pytest.raises(MyofaceValueError, match="same size"), VideoWriter(tmp_path / "s.mp4") as vw:
        vw.write(frames[0])
        vw.write(np.zeros((10, 10, 3), np.uint8))
    assert not (tmp_path / "s.mp4").exists()


def test_antialiased_edge_pixel_is_the_coverage_weighted_mean():
    """With 2x2 samples, a pixel that a white unlit square covers with exactly one column of
    samples is the mean of white and the background of its row; pixels inside are white."""
    from myoface.face import FaceMesh

    cam = ortho(64, 64, span=64.0)  # 1 mm per pixel, x = 0 at pixel 32
    edge = 10.5 - 32.0  # output pixel 10 spans samples at x = 10.25 and 10.75: one is inside
    v = np.array([[-40, -40, 0], [edge, -40, 0], [edge, 40, 0], [-40, 40, 0.0]])
    r = Renderer(FaceMesh(v, np.array([[0, 1, 2], [0, 2, 3]])), cam, [], FLAT, dress=False)
    img = r.render_linear()
    np.testing.assert_allclose(img[:, :10], 1.0, atol=1e-6)
    background = img[:, 40]  # same row, no geometry
    np.testing.assert_allclose(img[:, 10], 0.5 * (1.0 + background), atol=1e-6)
    assert (background < 0.1).all()


def _holed_grid(holes, half=40.0, n=41):
    """A flat z = 0 grid face (x, y in [-half, half] mm) without landmarks, with the triangles
    whose centroids fall in each (cx, cy, rx, ry) ellipse removed."""
    from myoface.face.mesh import FaceMesh

    g = np.linspace(-half, half, n)
    xx, yy = np.meshgrid(g, g)
    v = np.column_stack([xx.ravel(), yy.ravel(), np.zeros(n * n)])
    i = np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]
    a, b, c, d = i.ravel(), i.ravel() + 1, i.ravel() + n, i.ravel() + n + 1
    tris = np.concatenate([np.column_stack([a, b, d]), np.column_stack([a, d, c])])
    cen = v[tris].mean(axis=1)
    keep = np.ones(len(tris), bool)
    for cx, cy, rx, ry in holes:
        keep &= ((cen[:, 0] - cx) / rx) ** 2 + ((cen[:, 1] - cy) / ry) ** 2 > 1
    return FaceMesh(v, tris[keep], name="grid")


def test_openings_found_by_shape_without_landmarks():
    """A face without landmark groups (Waters' face) gets its eyes and mouth from its holes: the
    highest mirrored pair are the eyes (the subject's left on +x), the midline hole below
    them the mouth; an off-midline hole is neither."""
    from myoface.render.dressing import find_openings

    eyes_mouth = [(15, 12, 7, 4), (-15, 12, 7, 4), (0, -18, 12, 4)]
    face = _holed_grid([*eyes_mouth, (28, -25, 4, 4)])
    ops = {op.name: face.vertices[op.loop].mean(axis=0) for op in find_openings(face)}
    assert sorted(ops) == ["eye_l", "eye_r", "mouth"]
    np.testing.assert_allclose(ops["eye_l"][:2], [15, 12], atol=1.0)
    np.testing.assert_allclose(ops["eye_r"][:2], [-15, 12], atol=1.0)
    np.testing.assert_allclose(ops["mouth"][:2], [0, -18], atol=1.0)
    # holes that are not a mirrored pair are not eyes
    assert find_openings(_holed_grid([(15, 12, 7, 4), (-15, -20, 7, 4)])) == []


def test_waters_face_gets_eyes():
    """Waters' face (no landmarks) rendered with eyeballs behind its eye holes: a dark iris
    and bright sclera where the background showed through before."""
    from myoface.face.io import read_waters_geoface
    from tests.conftest import shared_path

    face = read_waters_geoface(shared_path("waters-geoface"))
    cam = Camera.front(face.vertices, width=128, height=128)
    img = Renderer(face, cam).render()
    eyes = [lp for lp in face.boundary_loops if len(lp) == 13]  # 13 vertices each
    assert len(eyes) == 2
    for lp in eyes:
        x, y = cam.project(face.vertices[lp])[:, :2].mean(axis=0)
        region = img[int(y) - 2 : int(y) + 3, int(x) - 5 : int(x) + 6].astype(int).sum(axis=2)
        assert region.min() < 200 and region.max() > 350, region
