"""The eyes' gaze (``myoface.analysis.gaze``), its CSV columns and its resynthesis."""

import csv
import warnings

import numpy as np
import pytest

from myoface.analysis.camera import HeadPose, PinholeCamera
from myoface.analysis.gaze import (
    GAZE_COLUMNS,
    GAZE_STATE_COLUMNS,
    IRIS_DEPTH_MM,
    EyeGaze,
    Gaze,
    GazeEstimator,
    GazeSettings,
    GazeSmoother,
    _chain_distance,
    _inside_polygon,
    _opening_pixels,
    _rss_numba,
    _rss_numpy,
    gaze_angles,
    gaze_directions,
    iris_ellipses,
)
from myoface.errors import MyofaceFormatError, MyofaceValueError
from myoface.render.renderer import gaze_rotation
from tests.conftest import needs_mediapipe, shared_path

#: the renders' camera: 640 x 480, 40 deg vertical field of view (the benchmark's)
SIZE, FOV = (640, 480), 40.0


@pytest.fixture(scope="module")
def renderer(default_face):
    from myoface.bench.headmotion import camera_renderer

    return camera_renderer(default_face)


@pytest.fixture(scope="module")
def camera():
    return PinholeCamera.for_image(*SIZE, FOV)


def test_directions_are_the_renderers_rotation():
    """A gaze (yaw, pitch) turns the eyeball's axis (+z) as the renderer turns it, and the
    angles come back from the direction."""
    rng = np.random.default_rng(0)
    for yaw, pitch in rng.uniform(-40, 40, (20, 2)):
        d = gaze_directions(yaw, pitch)
        want = gaze_rotation((np.radians(yaw), np.radians(pitch))) @ np.array([0.0, 0, 1])
        np.testing.assert_allclose(d, want, atol=1e-12)
        np.testing.assert_allclose(gaze_angles(d), [yaw, pitch], atol=1e-9)


def test_iris_ellipse_geometry(camera):
    """The limbus' image: its centre is the projection of the circle's centre; looking into the
    camera it is a circle of the limbus' radius over its depth; turned 60 deg away, half as
    wide along the turn."""
    from myoface.analysis.gaze import IRIS_RADIUS_MM

    centre = np.array([10.0, -5.0, -400.0])
    to_cam = -(centre + IRIS_DEPTH_MM * np.array([0, 0, 1.0]))
    to_cam /= np.linalg.norm(to_cam)
    c2, tilt, major, minor, facing = iris_ellipses(camera, centre, to_cam[None])
    np.testing.assert_allclose(c2[0], camera.project((centre + IRIS_DEPTH_MM * to_cam)[None])[0])
    depth = -(centre + IRIS_DEPTH_MM * to_cam)[2]
    assert major[0] == pytest.approx(IRIS_RADIUS_MM * camera.focal_px / depth, rel=1e-5)
    assert minor[0] == pytest.approx(major[0], rel=1e-5) and facing[0]
    side = gaze_directions(60.0, 0.0)[None] * np.array([1, 1, 1.0])
    _, tilt, major, minor, facing = iris_ellipses(camera, np.array([0, 0, -400.0]), side)
    assert minor[0] / major[0] == pytest.approx(np.cos(np.radians(60)), abs=0.03)
    assert abs(tilt[0, 0]) > 0.99  # the minor axis along the image's x
    back = iris_ellipses(camera, np.zeros(3) + [0, 0, -400], np.array([[0, 0, -1.0]]))
    assert not back[4][0]  # an iris turned away from the camera does not face it


def test_the_compiled_kernel_is_the_numpy_one():
    rng = np.random.default_rng(1)
    n, m, k = 150, 5, 40
    px = rng.uniform(0, 20, (n, 2))
    bright = rng.uniform(0, 1, n)
    fixed = np.column_stack([np.ones(n), rng.normal(size=(n, m - 1))])
    proj = np.linalg.inv(fixed.T @ fixed)
    centres = rng.uniform(5, 15, (k, 2))
    tilt = rng.normal(size=(k, 2))
    tilt /= np.linalg.norm(tilt, axis=1, keepdims=True)
    major = rng.uniform(3, 8, k)
    minor = major * rng.uniform(0.3, 1, k)
    args = (px, bright, fixed, proj, centres, tilt, major, minor, 0.6)
    none = (np.zeros((0, 2)), np.zeros(0), np.zeros(0))
    for a, b in zip(_rss_numpy(*args), _rss_numba(*args, *none), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-12)
    # with a pupil: a darker disc in each iris (its coefficient <= 0, else the iris alone), on
    # brightness with a dark disc and a darker one inside it
    r = np.linalg.norm(px - 10.0, axis=1)
    dark = bright - 0.5 * (r < 5) - 0.3 * (r < 2)
    args = (px, dark, fixed, proj, centres, tilt, major, minor, 0.6)
    pupil = (centres + rng.normal(0, 0.5, (k, 2)), 0.36 * major, 0.36 * minor)
    with_pupil = _rss_numpy(*args, pupil)
    for a, b in zip(with_pupil, _rss_numba(*args, *pupil), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-8, atol=1e-10)
    alone = _rss_numpy(*args)[0]
    assert np.all(with_pupil[0] <= alone + 1e-9) and np.any(with_pupil[0] < alone - 1e-6)


def _plain_rss(samples, camera, rot, centre, yaw, pitch, edge_px, pupil):
    """The candidates' residuals the plain way (numpy): the reference of the one-pass kernel
    :func:`_gaze_rss` (what ``_Eye.rss`` computed before it)."""
    from myoface.analysis.gaze import PUPIL_DEPTH_MM, PUPIL_RADIUS_MM

    dirs = gaze_directions(yaw, pitch) @ rot.T
    c2, t, a, b, facing = iris_ellipses(camera, centre, dirs)
    lo, hi = samples.px.min(axis=0), samples.px.max(axis=0)
    use = facing & np.all((c2 > lo - a[:, None]) & (c2 < hi + a[:, None]), axis=1)
    pick = None
    if pupil:
        pc, _, pa, pb, _ = iris_ellipses(camera, centre, dirs, PUPIL_DEPTH_MM, PUPIL_RADIUS_MM)
        pick = (pc[use], pa[use], pb[use])
    rss, coef = np.full(len(c2), np.inf), np.zeros(len(c2))
    rss[use], coef[use] = _rss_numpy(samples.px, samples.bright, samples.fixed, samples.proj,
                                     c2[use], t[use], a[use], b[use], edge_px, pick)  # fmt: skip
    return np.where((coef < 0) & use, rss, np.inf), coef, use


def test_the_one_pass_kernel_is_the_plain_reference(camera):
    """An eye drawn by the model itself (a shaded sclera, the iris and a darker pupil of a
    known gaze, noise) seen through a turned head: the compiled one-pass kernel (ellipses, the
    box test, the sums over the pixels within the iris' reach, the polynomial logistic) gives
    the plain numpy path's residuals and coefficients, with and without the pupil, on the
    candidates of a coarse grid (some facing away or off the opening) and of a fine one; and
    its best candidate with the pupil is the truth (without it, within a step)."""
    from myoface.analysis.gaze import (
        PUPIL_DEPTH_MM,
        PUPIL_RADIUS_MM,
        _gaze_rss,
        _grid,
        eye_samples,
        iris_cover,
    )

    rng = np.random.default_rng(5)
    rot = HeadPose.from_euler(25.0, -10.0, 5.0).rotation
    centre = np.array([8.0, -5.0, -420.0])
    truth = (12.0, -6.0)
    g = gaze_directions(*truth) @ rot.T
    c, t, a, b, _ = iris_ellipses(camera, centre, g[None])
    pc, _, pa, pb, _ = iris_ellipses(camera, centre, g[None], PUPIL_DEPTH_MM, PUPIL_RADIUS_MM)
    mid = camera.project(centre[None])[0]
    s = np.linspace(-1.0, 1.0, 11)
    upper = np.column_stack([mid[0] + 26 * s, mid[1] - 11 * (1 - s**2) + 1])
    lower = np.column_stack([mid[0] + 26 * s, mid[1] + 8 * (1 - s**2) + 1])
    h, w = 480, 640
    y, x = np.mgrid[0:h, 0:w] + 0.5
    every = np.column_stack([x.ravel(), y.ravel()])
    near = np.abs(every - mid).max(axis=1) < 40
    luma = np.full(h * w, 0.8)
    iris = iris_cover(every[near], c, t, a, b, 0.6)[0]
    pupil = iris_cover(every[near], pc, t, pa, pb, 0.6)[0]
    luma[near] += 0.002 * (every[near, 0] - mid[0]) - 0.5 * iris - 0.2 * pupil
    frame = np.clip(luma.reshape(h, w, 1) + rng.normal(0, 0.01, (h, w, 1)), 0, 1).repeat(3, 2)
    samples = eye_samples(frame, upper, lower, float(a[0]), GazeSettings())
    assert samples.n > 300
    cam = (camera.focal_px, camera.cx, camera.cy)
    for yaw, pitch in (_grid((0.0, 0.0), 6.0, 45.0), _grid(truth, 0.5, 1.0)):
        for with_pupil in (False, True):
            want, wcoef, use = _plain_rss(samples, camera, rot, centre, yaw, pitch, 0.6,
                                          with_pupil)  # fmt: skip
            got, gcoef, base = _gaze_rss(*samples.by_x(), samples.proj, centre, rot, *cam,
                                         yaw, pitch, 0.6, with_pupil)  # fmt: skip
            assert base == pytest.approx(samples.base_rss(), rel=1e-12)
            np.testing.assert_array_equal(np.isfinite(got), np.isfinite(want))
            ok = np.isfinite(want)
            assert 0 < ok.sum() < len(yaw) or len(yaw) < 30
            np.testing.assert_allclose(got[ok], want[ok], rtol=0, atol=1e-10 * base)
            np.testing.assert_allclose(gcoef[use], wcoef[use], rtol=1e-9, atol=1e-12)
            assert np.argmin(got) == np.argmin(want)
            if len(yaw) < 30:  # (the truth with the pupil's term, the image's model)
                k = int(np.argmin(got))
                tol = 0.0 if with_pupil else 0.5
                assert abs(yaw[k] - truth[0]) <= tol and abs(pitch[k] - truth[1]) <= tol
                # (the iris' darkening; without the pupil's term it takes some of the pupil's)
                assert gcoef[k] == pytest.approx(-0.5, abs=0.02) if with_pupil else gcoef[k] < -0.5


def test_the_compiled_samples_are_the_numpy_ones():
    """The opening's samples compiled (pixels kept, brightness, the fixed columns, the
    inverse normal matrix; and their checkerboard), the lids' aperture and the contrasts'
    90th percentile against their plain-numpy references."""
    from myoface.analysis.gaze import (
        EyeSamples,
        _aperture_mm,
        _eye_samples_numpy,
        _percentile90,
        eye_samples,
    )

    rng = np.random.default_rng(7)
    t = np.linspace(0.0, np.pi, 9)
    upper = np.column_stack([40 + 22 * np.cos(t[::-1]), 30 - 9 * np.sin(t[::-1])])
    lower = np.column_stack([40 + 22 * np.cos(t[::-1]), 30 + 6 * np.sin(t[::-1])])
    for frame in (
        rng.integers(0, 256, (60, 90, 3), dtype=np.uint8),
        rng.uniform(0, 1, (60, 90, 4)),
    ):
        got = eye_samples(frame, upper, lower, 8.0, GazeSettings())
        want = _eye_samples_numpy(frame, upper, lower, 8.0, GazeSettings())
        assert got.n == want.n > 200
        np.testing.assert_array_equal(got.px, want.px)
        for a, b in ((got.bright, want.bright), (got.fixed, want.fixed), (got.proj, want.proj)):
            np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-12)
        keep = (np.floor(want.px).astype(np.int64).sum(axis=1) % 2) == 0
        ref = EyeSamples(want.px[keep], want.bright[keep], want.fixed[keep],
                         np.linalg.pinv(want.fixed[keep].T @ want.fixed[keep]))  # fmt: skip
        board = got.checkerboard()
        np.testing.assert_array_equal(board.px, ref.px)
        np.testing.assert_allclose(board.proj, ref.proj, rtol=1e-9, atol=1e-12)
    v = rng.normal(size=(30, 3))
    up, lo = np.arange(0, 8), np.arange(8, 15)
    xs = np.linspace(0.2, 0.8, 7)

    def along(chain):
        p = v[chain]
        s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]
        return np.column_stack([np.interp(xs, s / s[-1], p[:, k]) for k in range(3)])

    want = np.linalg.norm(along(up) - along(lo), axis=1).mean()
    assert _aperture_mm(v, up, lo) == pytest.approx(want, rel=1e-12)
    for n in (1, 2, 3, 7, 10, 59, 60):
        vals = list(rng.uniform(0, 1, n))
        assert _percentile90(vals) == pytest.approx(np.percentile(vals, 90), rel=1e-14)


def test_the_pupil_is_read_where_the_iris_is_dark_in_its_middle():
    """Brightness made by the model itself (a sclera, an iris, and a pupil darker still): the
    candidate at the truth explains it with the pupil's term; where the pupil is as bright as
    the iris, the term is not used (the same residual as without it)."""
    from myoface.analysis.gaze import iris_cover

    y, x = np.mgrid[0:14, 0:30] + 0.5
    px = np.column_stack([x.ravel(), y.ravel()])
    fixed = np.column_stack([np.ones(len(px)), px / 10.0])
    proj = np.linalg.inv(fixed.T @ fixed)
    c, t, a, b = np.array([[14.0, 7.5]]), np.array([[1.0, 0.0]]), np.array([7.0]), np.array([6.5])
    iris = iris_cover(px, c, t, a, b, 0.6)[0]
    pupil = iris_cover(px, c, t, 0.36 * a, 0.36 * b, 0.6)[0]
    for dark, used in ((0.2, True), (0.0, False)):
        bright = 0.9 - 0.6 * iris - dark * pupil
        shifted = (c + [[0.0, 1.0]], 0.36 * a, 0.36 * b)
        rss, coef = _rss_numba(px, bright, fixed, proj, c, t, a, b, 0.6, c, 0.36 * a, 0.36 * b)
        assert rss[0] == pytest.approx(0.0, abs=1e-9) and coef[0] == pytest.approx(-0.6)
        off = _rss_numba(px, bright, fixed, proj, c, t, a, b, 0.6, *shifted)[0][0]
        alone = _rss_numba(px, bright, fixed, proj, c, t, a, b, 0.6, *shifted[:0],
                           np.zeros((0, 2)), np.zeros(0), np.zeros(0))[0][0]  # fmt: skip
        assert (off > 1e-4) == used and off <= alone + 1e-12


def test_the_compiled_cover_is_the_logistic_of_the_ellipse():
    """The one compiled cover every kernel uses (``_cover``) against :func:`iris_cover` on
    pixels inside, on the edge and far outside ellipses of any tilt and eccentricity (and
    at the centre): the same to 1e-12, nought beyond 12 edge widths outside."""
    from myoface.analysis.gaze import _cover, iris_cover

    rng = np.random.default_rng(11)
    for _ in range(20):
        c = rng.uniform(-5, 5, (1, 2))
        t = rng.normal(size=(1, 2))
        t /= np.linalg.norm(t)
        a = rng.uniform(2, 9, 1)
        b = a * rng.uniform(0.2, 1.0, 1)
        px = np.vstack([c + rng.normal(0, 1.5 * a[0], (200, 2)), c])
        edge = rng.uniform(0.3, 1.2)
        want = iris_cover(px, c, t, a, b, edge)[0]
        got = np.array([_cover(x, y, c[0, 0], c[0, 1], t[0, 0], t[0, 1], 1 / a[0], 1 / b[0],
                               a[0], edge) for x, y in px])  # fmt: skip
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
        assert np.all(got[want == 0.0] == 0.0)
        assert (want == 0.0).any() and ((want > 0.01) & (want < 0.99)).any()


def test_the_openings_pixels_are_the_numpy_ones():
    """The compiled opening (pixels inside the lids' polygon and their distances to the two
    margins) against the plain-numpy references, on an eye-shaped polygon and a random one."""
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, np.pi, 9)
    upper = np.column_stack([20 + 12 * np.cos(t[::-1]), 15 - 6 * np.sin(t[::-1])])
    lower = np.column_stack([20 + 12 * np.cos(t[::-1]), 15 + 4 * np.sin(t[::-1])])
    shapes = [(upper, lower), (rng.uniform(0, 30, (6, 2)), rng.uniform(0, 30, (5, 2)))]
    for up, lo in shapes:
        poly = np.concatenate([up, lo[::-1][1:-1]])
        x0, y0, x1, y1 = 0, 0, 34, 31
        px, du, dl = _opening_pixels(x0, y0, x1, y1, poly, up, lo)
        cols, rows = np.meshgrid(np.arange(x0, x1 + 1), np.arange(y0, y1 + 1))
        every = np.column_stack([cols.ravel(), rows.ravel()]).astype(np.float64) + 0.5
        want = every[_inside_polygon(every, poly)]
        assert len(want) > 20
        np.testing.assert_array_equal(px, want)
        np.testing.assert_allclose(du, _chain_distance(want, up), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(dl, _chain_distance(want, lo), rtol=1e-12, atol=1e-12)


def _read(renderer, camera, face, head, gaze_deg, skin=None, est=None):
    pose = HeadPose.from_euler(*head, (0, 0, -400))
    img = renderer.render(skin, pose=(pose.rotation, pose.translation_mm),
                          gaze=tuple(np.radians(gaze_deg)))  # fmt: skip
    est = est or GazeEstimator(face)
    return est.read(img, camera, pose, face.vertices if skin is None else skin)


def test_reads_a_known_gaze_on_renders(renderer, camera, default_face):
    """The reader alone (the true pose, skin and camera) on renders of the default face at
    known gazes, the head frontal and turned: measured 2026-12-02 RMS 1.1 deg yaw and 2.3 deg
    pitch over 30 readings (pitch is the weaker: the iris is taller than the opening)."""
    errs = []
    for head in ((0, 0, 0), (25, 10, -5), (-20, -10, 8)):
        for g in ((15, -5), (-20, 10), (5, 12), (-25, -10), (8, 4)):
            r = _read(renderer, camera, default_face, head, g)
            for e in (r.left, r.right):
                assert e.state == "ok" and e.explained > 0.3 and e.contrast < 0
                errs.append((e.yaw_deg - g[0], e.pitch_deg - g[1]))
    rms = np.sqrt(np.mean(np.square(errs), axis=0))
    assert rms[0] < 2.0 and rms[1] < 4.5, rms


@needs_mediapipe
@pytest.mark.slow
def test_a_lid_margin_placed_high_does_not_pull_the_pitch_down(camera):
    """The fit places the upper lid's margin about 0.3 mm above the truth's (relative to the
    eyeball's centre, on every eye of the gaze benchmark's clips) and below the margin hang
    the lashes and the lid's shadow: the reader leaves a strip of
    :attr:`GazeSettings.upper_margin` iris radii under it unread. The known answer: renders
    of the person's face from a real photo (its lashes are the photo's) at known gazes, the
    head frontal and turned, read with the true pose and skin but the upper margins raised
    0.3 mm. Measured 2026-12-06: pitch RMS 0.63 deg (mean -0.10) with the default 0.25;
    with 0.1, the reader's setting before, 4.34 deg (mean -1.85: the lid read as iris pulls
    it down); yaw 0.41-0.43 either way."""
    from myoface.analysis.video import open_video
    from myoface.bench.headmotion import camera_renderer
    from myoface.face.personal import face_from_photo

    path = shared_path("video", "single_face.mp4")
    if not path.exists():
        pytest.skip("../shared/data/video/single_face.mp4 is not here")
    face, _ = face_from_photo(next(iter(open_video(path))), name="sample person")
    renderer = camera_renderer(face)
    skin = face.vertices.copy()
    for side in ("l", "r"):
        _, upper, _ = GazeEstimator(face)._eyes[side]
        skin[upper, 1] += 0.3
    errs: dict = {0.25: [], 0.1: []}
    for head in ((0, 0, 0), (25, 10, -5), (-20, -10, 8)):
        for g in ((15, -5), (-20, 10), (5, 12), (-25, -10), (8, 4)):
            pose = HeadPose.from_euler(*head, (0, 0, -400))
            img = renderer.render(None, pose=(pose.rotation, pose.translation_mm),
                                  gaze=tuple(np.radians(g)))  # fmt: skip
            for um, out in errs.items():
                r = GazeEstimator(face, GazeSettings(upper_margin=um)).read(img, camera, pose, skin)
                for e in (r.left, r.right):
                    assert e.state == "ok"
                    out.append((e.yaw_deg - g[0], e.pitch_deg - g[1]))
    rms = {um: np.sqrt(np.mean(np.square(e), axis=0)) for um, e in errs.items()}
    assert GazeSettings().upper_margin == 0.25
    assert rms[0.25][1] < 1.2 and rms[0.25][0] < 1.0, rms
    assert rms[0.1][1] > 2.5, rms  # (the phenomenon: the margin's strip read as eyeball)


def test_closed_lids_are_said(renderer, camera, default_face):
    """Lids closed by the palpebral orbicularis: no gaze, the state says ``closed``; an eye
    turned away from the camera is ``hidden``."""
    from myoface.model import build_face_model

    model = build_face_model(default_face)
    c = np.zeros(model.n_muscles)
    c[list(model.ids).index("orbicularis_oculi_palpebralis_l")] = 1.0
    skin = model.skin_vertices(model.relax(c).state)
    r = _read(renderer, camera, default_face, (0, 0, 0), (10, 0), skin)
    assert r.left.state == "closed" and np.isnan(r.left.yaw_deg)
    assert r.right.state == "ok"
    pose = HeadPose.from_euler(88, 0, 0, (0, 0, -400))
    est = GazeEstimator(default_face)
    img = np.zeros((480, 640, 3), np.uint8)
    far = est.read(img, camera, pose, default_face.vertices)
    assert far.right.state == "hidden"  # its axis 88 deg from the camera's line


def test_faded_contrast_says_closed():
    """An eye whose iris is much fainter than its usual contrast is said closed (a blink the
    landmarks do not close)."""
    est = GazeEstimator.__new__(GazeEstimator)
    est.settings = GazeSettings()
    est._contrasts = {"l": [], "r": []}
    for _ in range(10):
        assert est._closed_by_contrast("l", EyeGaze(1.0, 2.0, "ok", 0.8, -0.4)).ok
    faint = est._closed_by_contrast("l", EyeGaze(1.0, 2.0, "ok", 0.2, -0.1))
    assert faint.state == "closed" and np.isnan(faint.yaw_deg)


def test_smoother_averages_fixations_and_keeps_saccades():
    """Noise of 0.7 deg within a fixation is averaged (its SD falls); a 10 deg jump appears
    whole on its frame; a frame not read empties the history."""
    rng = np.random.default_rng(0)
    sm = GazeSmoother(GazeSettings())
    truth = np.r_[np.zeros(40), np.full(40, 10.0)]
    out = []
    for t in truth:
        n = rng.normal(0, 0.7, 2)
        g = sm.update(Gaze(EyeGaze(t + n[0], n[1], "ok"), EyeGaze(state="closed")))
        assert g.right.state == "closed"
        out.append(g.left.yaw_deg)
    out = np.array(out)
    assert np.std(out[5:40]) < 0.75 * 0.7
    assert out[40] == pytest.approx(10.0, abs=2.5)  # the saccade's frame: not pulled back
    assert np.std(out[45:] - 10) < 0.75 * 0.7
    sm.update(Gaze())  # not read: the history goes
    g = sm.update(Gaze(EyeGaze(-5.0, 0.0, "ok"), EyeGaze()))
    assert g.left.yaw_deg == -5.0


def test_settings_are_checked():
    with pytest.raises(MyofaceValueError, match="lids"):
        GazeSettings(lids="mediapipe")
    with pytest.raises(MyofaceValueError):
        GazeSettings(edge_px=0)
    with pytest.raises(MyofaceValueError, match="pupil"):
        GazeSettings(pupil=True)
    with pytest.raises(MyofaceValueError, match="reopen_frames"):
        GazeSettings(reopen_frames=-1)


def test_cells_and_the_common_gaze():
    g = Gaze(EyeGaze(10.0, -2.5, "ok"), EyeGaze(state="closed"))
    assert g.cells() == ["10.00", "-2.50", "", "", "ok", "closed"]
    assert g.common_rad() == pytest.approx((np.radians(10), np.radians(-2.5)))
    assert Gaze().common_rad() is None


# ------------------------------------------------------------------ the CSV


def _measurements(ids):
    from myoface.analysis.trackers.landmark_fit import FitMeasurement

    pose = HeadPose.from_euler(5, 0, 0, (0, 0, -500))
    z = np.zeros(len(ids))
    gazes = [
        Gaze(EyeGaze(10.0, 2.0, "ok"), EyeGaze(12.0, 1.0, "ok")),
        Gaze(EyeGaze(state="closed"), EyeGaze(state="closed")),
        None,  # no face
        Gaze(EyeGaze(-20.0, -5.0, "ok"), EyeGaze(state="hidden")),
    ]
    out = []
    for k, g in enumerate(gazes):
        if g is None:
            out.append(FitMeasurement(k, k / 30, "no_face", np.full(len(ids), np.nan), None))
        else:
            out.append(FitMeasurement(k, k / 30, "ok", z, pose, 0.3, gaze=g))
    return out


@pytest.fixture(scope="module")
def ids():
    from myoface.muscles.io import load_default_muscles

    return list(load_default_muscles().ids)


def test_gaze_columns_round_trip(tmp_path, ids):
    """The 3-D fit's rows carry each eye's gaze and state after the pose; read back as written;
    a contractions reader takes them for what they are (no warning, no muscle)."""
    from myoface.analysis.contractions_csv import (
        display_gaze,
        read_contractions_csv,
        read_gaze,
        write_contractions_csv,
    )

    path = tmp_path / "contractions.csv"
    write_contractions_csv(path, ids, _measurements(ids), 0.3)
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    header = list(rows[0])
    first = header.index(GAZE_COLUMNS[0])  # (the expression columns may follow them)
    assert header[first : first + 6] == [*GAZE_COLUMNS, *GAZE_STATE_COLUMNS]
    assert [r["gaze_l_state"] for r in rows] == ["ok", "closed", "", "ok"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_contractions_csv(path, ids)
    angles, states = read_gaze(path)
    np.testing.assert_allclose(angles[0], [10, 2, 12, 1])
    assert np.isnan(angles[1]).all() and np.isnan(angles[2]).all()
    np.testing.assert_allclose(angles[3, :2], [-20, -5])
    assert states == [("ok", "ok"), ("closed", "closed"), ("", ""), ("ok", "hidden")]
    common = display_gaze(angles)
    np.testing.assert_allclose(np.degrees(common[0]), [11, 1.5])
    np.testing.assert_allclose(common[1], common[0])  # held through the blink
    np.testing.assert_allclose(np.degrees(common[3]), [-20, -5])


@pytest.mark.parametrize(
    "cell, state, match",
    [("1e9", "ok", "within"), ("abc", "ok", "not a number"), ("", "ok", "without angles"),
     ("5", "blinking", "must be one of")],
)  # fmt: skip
def test_bad_gaze_cells(tmp_path, cell, state, match):
    from myoface.analysis.contractions_csv import read_gaze

    head = ["frame", "time_s", "quality", "zygomaticus_major_l", *GAZE_COLUMNS]
    head += GAZE_STATE_COLUMNS
    row = ["0", "0.0", "ok", "0.1", cell, "1.0", "2.0", "3.0", state, "ok"]
    path = tmp_path / "c.csv"
    path.write_text(",".join(head) + "\n" + ",".join(row) + "\n")
    with pytest.raises(MyofaceFormatError, match=match):
        read_gaze(path)


def test_no_gaze_columns(tmp_path):
    from myoface.analysis.contractions_csv import read_gaze

    path = tmp_path / "c.csv"
    path.write_text("frame,time_s,quality,zygomaticus_major_l\n0,0.0,ok,0.1\n")
    assert read_gaze(path) is None


def test_resynthesis_turns_the_eyes(tmp_path, ids, default_face):
    """read_performance gives the CSV's gaze; the resynthesis' eyes turn with it (the eye
    pixels change, the rest of the face does not)."""
    from myoface.analysis.contractions_csv import write_contractions_csv
    from myoface.analysis.resynthesis import read_performance, resynthesis_frames
    from myoface.model import build_face_model

    model = build_face_model(default_face)
    path = tmp_path / "contractions.csv"
    write_contractions_csv(path, ids, _measurements(ids), 0.3)
    perf = read_performance(path, model)
    assert perf.gaze.shape == (4, 2)
    np.testing.assert_allclose(np.degrees(perf.gaze[0]), [11, 1.5])
    still = list(resynthesis_frames(model, perf.contractions[:1], 96))[0]
    turned = list(resynthesis_frames(model, perf.contractions[:1], 96, gaze=perf.gaze[:1]))[0]
    diff = np.abs(still.astype(int) - turned).sum(axis=2) > 30
    assert 5 < diff.sum() < 0.05 * diff.size  # the eyes only
    assert read_performance(path, model, gaze=False).gaze is None
    with pytest.raises(MyofaceValueError, match="gaze"):
        list(resynthesis_frames(model, perf.contractions, 96, gaze=np.zeros((2, 2))))


# ------------------------------------------------------------------ the viewer's playback


def test_viewer_playback_carries_the_gaze(tmp_path, ids):
    """A contractions.csv with gaze, and a timeline with gaze events, play with the eyes
    turned; a CSV without gaze leaves them straight ahead."""
    from myoface.analysis.contractions_csv import write_contractions_csv
    from myoface.model import build_face_model
    from myoface.viewer.state import ViewerState

    st = ViewerState(build_face_model())
    path = tmp_path / "contractions.csv"
    write_contractions_csv(path, ids, _measurements(ids), 0.3)
    st.load_playback(path)
    assert np.degrees(st.gaze_at(0.0)) == pytest.approx((11, 1.5))
    assert np.degrees(st.gaze_at(0.04)) == pytest.approx((11, 1.5))  # the blink holds
    assert np.degrees(st.gaze_at(10.0)) == pytest.approx((-20, -5))
    tl = tmp_path / "look.toml"
    tl.write_text(
        '[[event]]\nkind = "gaze"\nyaw_deg = 20\npitch_deg = 0\nstart = 0.0\nduration = 1.0\n'
        "onset = 0.2\noffset = 0.2\n"
    )
    st.load_playback(tl)
    assert np.degrees(st.gaze_at(0.5)[0]) == pytest.approx(20, abs=0.5)
    plain = tmp_path / "plain.csv"
    plain.write_text("time_s,quality,jaw\n0,ok,0.1\n1.0,ok,0.6\n")
    st.load_playback(plain)
    assert st.gaze_at(0.5) is None


def test_viewer_scene_turns_the_eyes():
    """The scene's eyeballs turn about their own centres by the gaze (viser's handles: one per
    eye, placed at its centre)."""
    pytest.importorskip("viser")
    from myoface.model import build_face_model
    from myoface.viewer.app import FaceViewer
    from myoface.viewer.scene import _quaternion_wxyz

    v = FaceViewer(build_face_model(), port=0)
    try:
        sc = v.scene
        assert len(sc.eyes) == 2
        for eye, (_, _, centre) in zip(sc.eyes, v.renderer._eyeballs, strict=True):
            np.testing.assert_allclose(eye.position, centre * 1e-3, atol=1e-9)
        g = (np.radians(15.0), np.radians(-5.0))
        sc.set_gaze(g)
        want = _quaternion_wxyz(gaze_rotation(g))
        for eye in sc.eyes:
            np.testing.assert_allclose(eye.wxyz, want, atol=1e-9)
        sc.set_gaze(None)
        np.testing.assert_allclose(sc.eyes[0].wxyz, (1, 0, 0, 0), atol=1e-12)
    finally:
        v.close()


# ------------------------------------------------------------------ real video


@pytest.mark.slow
@pytest.mark.shared_data
def test_real_video_holds_its_gaze_and_says_the_blink(tmp_path):
    """single_face.mp4 (judged by eye, frame by frame: the person keeps looking at the phone's
    screen throughout, and blinks once, the eyes shut on frames 26-28): the blink's frames say
    closed, the others are read, and the reading stays put (measured 2026-12-02: SD 0.7-1.0 deg
    yaw, 1.7 deg pitch with the sockets; 0.9-1.1 and 1.1-1.3 without; the means within 0.6
    deg of each other; with the pupil in the last fine step 0.7-1.0 and 1.8, the pitch 0.9-1.3
    deg lower; with the pupil in every fine step the pitch flips between two readings, SD
    2.6-4.1, and at 2da1fc6 3.7: this test fails it). openface.csv has the gaze where the eyes
    were read.

    With the brow lowerers (issue 30) the fit lifts the head 0.6-0.7 mm through the smile and
    the left eye's pitch followed it: SD 2.95 deg, then 2.59 at fbe1b62, a strict xfail here.
    With the eyes' pitch yoked (:attr:`GazeSettings.yoke_pitch`, the mean of the two eyes'
    readings) 1.94 / 1.93 deg (left / right; measured 2026-12-02 on this command's output,
    frames 24-30 left out as below): the two eyes' noise partly averages out, the head's lift
    itself is not undone."""
    from myoface.cli import main
    from myoface.facemesh import mediapipe_available

    if not mediapipe_available():
        pytest.skip('needs pip install "myoface[mediapipe]"')
    video = shared_path("video", "single_face.mp4")
    out = tmp_path / "out"
    argv = ["analyze", str(video), "--tracker", "landmarks", "-o", str(out), "--quiet"]
    assert main([*argv, "--format", "openface"]) == 0
    with open(out / "contractions.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    for k in (26, 27, 28):
        assert rows[k]["gaze_l_state"] == rows[k]["gaze_r_state"] == "closed", rows[k]
    others = [r for k, r in enumerate(rows) if not 24 <= k <= 30]
    for side in "lr":
        ok = [r for r in others if r[f"gaze_{side}_state"] == "ok"]
        assert len(ok) >= 0.9 * len(others)
        a = np.array([[float(r[f"gaze_{side}_yaw_deg"]), float(r[f"gaze_{side}_pitch_deg"])]
                      for r in ok])  # fmt: skip
        assert (a.std(axis=0) < 2.5).all(), a.std(axis=0)
    with open(out / "openface.csv", newline="") as fh:
        of = list(csv.DictReader(fh))
    assert of[27]["gaze_angle_x"] == "" and of[27]["gaze_0_x"] == ""
    assert np.isfinite(float(of[0]["gaze_angle_x"]))
    g = np.array([float(of[0][f"gaze_0_{a}"]) for a in "xyz"])
    assert np.linalg.norm(g) == pytest.approx(1.0, abs=1e-5) and g[2] < -0.8  # towards the camera


def test_each_reading_keeps_where_its_frame_put_the_eyes(renderer, camera, default_face):
    """A reading carries the eyes' placement of its own frame (:attr:`Gaze.placed`: the
    socket's offset, the fit's opening), not the reader's state after later frames: the
    tracker hands the frames it measured while choosing its calibration over later, and the
    gaze benchmark's detail read the reader's last state for them (its openings' mean error
    27 px on 2026-12-04, where each frame's own is under 1 px)."""
    est = GazeEstimator(default_face)
    readings, openings = [], []
    for k, yaw in enumerate((-20, -10, 0, 10, 20)):
        head = HeadPose.from_euler(4 * k - 8, 2, 0, (3 * k, 0, -480))
        img = renderer.render(default_face.vertices, pose=(head.rotation, head.translation_mm),
                              gaze=(np.radians(yaw), 0.0))  # fmt: skip
        readings.append(est.measure(img, camera, head, default_face.vertices))
        openings.append({s: est.openings[s].copy() for s in ("l", "r")})
        want = {s: (est.offsets[s], est.openings[s]) for s in ("l", "r")}
        assert readings[-1].placed.keys() == want.keys()
    for g, op in zip(readings, openings, strict=True):
        for s in ("l", "r"):
            np.testing.assert_array_equal(g.placed[s][1], op[s])
    # the frames moved the head: the openings kept are the frames' own, not the last one's
    assert np.linalg.norm(readings[0].placed["l"][1] - readings[-1].placed["l"][1]) > 20


@pytest.mark.parametrize("prior_mm", [1e6, None])
def test_socket_finds_a_known_misplacement(renderer, camera, default_face, prior_mm):
    """The instrument on a known answer (GUIDE §8): each eye's socket template learnt from
    renders at known poses and gazes (the head within +-8 deg), a new frame (another gaze, the
    head turned 12 deg) read through a pose misplaced by a known ``delta`` (mm, head frame:
    the pose puts head point x where the truth has x - delta). The alignment alone (no prior
    on the shift) gives back ``delta`` within 0.25 mm (measured 2026-12-02: 0.08-0.21, the
    same on every delta: the template seen from another angle), the differences between
    deltas to 0.05 mm, and the eyeball's centre moved by it is where the renderer drew it
    within 0.35 px. With the default prior (:attr:`GazeSettings.socket_prior_mm`), which
    draws the shift towards none, the centre is still moved closer to the truth, by at least
    half of the misplacement."""
    settings = GazeSettings() if prior_mm is None else GazeSettings(socket_prior_mm=prior_mm)
    est = GazeEstimator(default_face, settings)
    rng = np.random.default_rng(1)
    for g in ((15, -5), (-20, 10), (5, 12), (-25, -10), (8, 4), (0, 0)):
        head = HeadPose.from_euler(*rng.uniform(-8, 8, 3), (0, 0, -500))
        img = renderer.render(default_face.vertices, pose=(head.rotation, head.translation_mm),
                              gaze=tuple(np.radians(g)))  # fmt: skip
        for side in ("l", "r"):
            patch, uv = est.sockets[side].sample(img, camera, head)
            c, r = est._iris_image(_eye_at(est, side, head), camera, head.rotation, *g)
            est.sockets[side].learn(patch, est.sockets[side].usable(uv, c, r))
    head = HeadPose.from_euler(12, -6, 3, (5, -3, -480))
    g = (-10, 6)
    img = renderer.render(default_face.vertices, pose=(head.rotation, head.translation_mm),
                          gaze=tuple(np.radians(g)))  # fmt: skip
    deltas = np.array([(0.0, 0.0), (1.5, -1.0), (-2.0, 0.8)])
    for side in ("l", "r"):
        c, r = est._iris_image(_eye_at(est, side, head), camera, head.rotation, *g)
        true = camera.project(head.apply(est.centres_mm[side])[None])
        got = []
        for delta in deltas:
            fit = HeadPose(head.rotation, head.translation_mm - head.rotation @ [*delta, 0.0])
            got.append(est.sockets[side].offset(img, camera, fit, c, r))
            moved = camera.project(fit.apply(est.centres_mm[side] + [*got[-1], 0.0])[None])
            before = camera.project(fit.apply(est.centres_mm[side])[None])
            miss, was = np.linalg.norm(moved - true), np.linalg.norm(before - true)
            if prior_mm is None:
                assert miss < max(0.5 * was, 0.35), (side, delta, miss, was)
            else:
                assert miss < 0.35, (side, delta, miss)
        got = np.array(got)
        if prior_mm is not None:
            np.testing.assert_allclose(got, deltas, atol=0.25, err_msg=side)
            np.testing.assert_allclose(got[1:] - got[0], deltas[1:] - deltas[0], atol=0.05)


def _eye_at(est, side, pose):
    """The reader's eye ``side`` placed by ``pose`` (for where its iris is in the image)."""
    from myoface.analysis.gaze import _Eye

    centre = pose.apply(est.centres_mm[side][None])[0]
    return _Eye(side, centre, None, 0.0)


def _taught_socket(renderer, camera, face, settings=None):
    """A reader whose sockets learnt six renders of ``face`` (known poses within +-8 deg and
    gazes, as in :func:`test_socket_finds_a_known_misplacement`)."""
    est = GazeEstimator(face, settings)
    rng = np.random.default_rng(1)
    for g in ((15, -5), (-20, 10), (5, 12), (-25, -10), (8, 4), (0, 0)):
        head = HeadPose.from_euler(*rng.uniform(-8, 8, 3), (0, 0, -500))
        img = renderer.render(face.vertices, pose=(head.rotation, head.translation_mm),
                              gaze=tuple(np.radians(g)))  # fmt: skip
        for side in ("l", "r"):
            patch, uv = est.sockets[side].sample(img, camera, head)
            c, r = est._iris_image(_eye_at(est, side, head), camera, head.rotation, *g)
            est.sockets[side].learn(patch, est.sockets[side].usable(uv, c, r))
    return est


def test_an_anchored_socket_keeps_its_first_frame(renderer, camera, default_face):
    """``socket_template="first"``: the template is the first frame learnt, never updated
    (ready after that one frame), and it aligns the frame it was learnt on to no offset."""
    est = GazeEstimator(default_face, GazeSettings(socket_template="first"))
    sock = est.sockets["l"]
    assert not sock.ready
    head = HeadPose.from_euler(5, -3, 2, (0, 0, -500))
    img = renderer.render(default_face.vertices, pose=(head.rotation, head.translation_mm),
                          gaze=(0.0, 0.0))  # fmt: skip
    patch, uv = sock.sample(img, camera, head)
    c, r = est._iris_image(_eye_at(est, "l", head), camera, head.rotation, 0.0, 0.0)
    sock.learn(patch, sock.usable(uv, c, r))
    assert sock.ready
    first = (sock._sum.copy(), sock._count.copy())
    sock.learn(patch + 50.0, sock.usable(uv, c, r))
    np.testing.assert_array_equal(sock._sum, first[0])
    np.testing.assert_array_equal(sock._count, first[1])
    d = sock.offset(img, camera, head, c, r)
    assert d is not None and np.abs(d).max() < 0.05, d
    with pytest.raises(MyofaceValueError, match="socket_template"):
        GazeSettings(socket_template="last")


@pytest.mark.parametrize(
    "expression",
    [
        pytest.param(
            {"corrugator_supercilii": 1.0, "depressor_supercilii": 1.0}, id="brows_lowered"
        ),
        pytest.param(
            {"frontalis_inner": 1.0, "frontalis_major": 1.0, "frontalis_outer": 1.0},
            id="brows_raised",
            marks=pytest.mark.xfail(strict=True, reason="the socket follows the lid skin up"),
        ),
        pytest.param({"orbicularis_oculi": 0.6}, id="squint"),
    ],
)
def test_the_socket_is_not_dragged_by_an_expression(renderer, camera, default_face, expression):
    """Known answer (GUIDE §8): the sockets taught on neutral renders, then a frame of the same
    face with an expression about the eyes, read through its true pose: the eyeball does not
    move, so the socket's offset should leave its centre where the renderer drew it, within
    0.5 px. Measured 2026-12-02 (the default settings): brows lowered (corrugator and
    depressor supercilii) 0.14 / 0.36 px (left / right eye); brows raised (the frontalis'
    three bellies) 0.75 / 1.17 px, upwards, and a squint (the orbital orbicularis at 0.6)
    0.24 / 1.06 px: the lids' skin and margins, which the socket aligns, move with those two.
    With the renderer's socket no longer black at the eyes' corners
    (:data:`myoface.render.dressing.SOCKET`, 2026-12-04): 0.06 / 0.28, 0.53 / (not reached:
    the left eye fails first) and 0.30 / 0.48 px: the squint is kept.
    Neither a smaller region (+-10 or +-8 mm tall, the brows left out) nor the opening left
    out (0.27 / 0.97 px raised) nor a fall-back on the patch's NCC (0.62-0.83 with these
    expressions, 0.25-0.6 on the benchmark's own frames) keeps them: xfail, strict."""
    from myoface.model import build_face_model

    est = _taught_socket(renderer, camera, default_face)
    model = build_face_model(default_face)
    ids = list(model.ids)
    c = np.zeros(model.n_muscles)
    for name, a in expression.items():
        for side in ("l", "r"):
            c[ids.index(f"{name}_{side}")] = a
    skin = model.skin_vertices(model.relax(c).state)
    head = HeadPose.from_euler(12, -6, 3, (5, -3, -480))
    g = (-10, 6)
    img = renderer.render(skin, pose=(head.rotation, head.translation_mm),
                          gaze=tuple(np.radians(g)))  # fmt: skip
    for side in ("l", "r"):
        cc, r = est._iris_image(_eye_at(est, side, head), camera, head.rotation, *g)
        d = est.sockets[side].offset(img, camera, head, cc, r)
        assert d is not None
        moved = camera.project(head.apply(est.centres_mm[side] + [*d, 0.0])[None])[0]
        true = camera.project(head.apply(est.centres_mm[side])[None])[0]
        assert np.linalg.norm(moved - true) < 0.5, (side, d)


def test_the_eyes_pitch_is_yoked(renderer, camera, default_face):
    """Both eyes read: each is given their mean pitch (the eyes' vertical rotations are yoked;
    the yaws are not: the eyes converge), the same readings otherwise; on renders at known
    gazes (the two eyes alike, as a person's vertical gaze is) the pitch's error falls."""
    errs = {True: [], False: []}
    for head in ((0, 0, 0), (25, 10, -5), (-20, -10, 8)):
        for g in ((15, -5), (-20, 10), (5, 12), (-25, -10), (8, 4)):
            r = {y: _read(renderer, camera, default_face, head, g,
                          est=GazeEstimator(default_face, GazeSettings(yoke_pitch=y)))
                 for y in (True, False)}  # fmt: skip
            alone, yoked = r[False], r[True]
            assert yoked.left.pitch_deg == yoked.right.pitch_deg
            mean = (alone.left.pitch_deg + alone.right.pitch_deg) / 2
            assert yoked.left.pitch_deg == pytest.approx(mean, abs=1e-9)
            for a, b in ((alone.left, yoked.left), (alone.right, yoked.right)):
                assert a.yaw_deg == b.yaw_deg and a.state == b.state == "ok"
            for y in (True, False):
                errs[y] += [e.pitch_deg - g[1] for e in (r[y].left, r[y].right)]
    rms = {y: float(np.sqrt(np.mean(np.square(errs[y])))) for y in errs}
    assert rms[True] < rms[False], rms


def test_the_lids_reopening_are_withheld(renderer, camera, default_face):
    """After a frame whose lids are said closed, the next :attr:`GazeSettings.reopen_frames`
    readings of that eye are withheld (``closed``: the lids reopen over frames, the iris half
    covered); the other eye, never closed, is read throughout."""
    from myoface.model import build_face_model

    model = build_face_model(default_face)
    c = np.zeros(model.n_muscles)
    c[list(model.ids).index("orbicularis_oculi_palpebralis_l")] = 1.0
    shut = model.skin_vertices(model.relax(c).state)
    for n, want in ((1, ["ok", "closed", "closed", "ok"]), (0, ["ok", "closed", "ok", "ok"])):
        est = GazeEstimator(default_face, GazeSettings(reopen_frames=n))
        got = [_read(renderer, camera, default_face, (0, 0, 0), (10, 0), skin, est)
               for skin in (None, shut, None, None)]  # fmt: skip
        assert [g.left.state for g in got] == want
        assert [g.right.state for g in got] == ["ok"] * 4
        assert np.isnan(got[2].left.pitch_deg) == (n == 1)
