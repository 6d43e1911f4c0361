"""The photometric term (myoface.analysis.photometric) and the known warps it is judged on
(myoface.analysis.knownwarp.expression_warp)."""

import numpy as np
import pytest

from myoface.analysis.camera import PinholeCamera, rotmat
from myoface.analysis.estimate import skin_response
from myoface.analysis.knownwarp import MeshWarp, expression_warp
from myoface.analysis.photometric import Appearance, PhotometricTerm, SurfaceSamples
from myoface.analysis.terms import Estimate
from myoface.control import expression_contractions
from myoface.model import build_face_model
from tests.conftest import needs_mediapipe

cv2 = pytest.importorskip("cv2")


@pytest.fixture(scope="module")
def scene():
    """The default face in front of a camera, over a textured image (smooth noise: every
    sample sees a gradient), its vertices' projections the 'landmarks'."""
    model = build_face_model()
    cam = PinholeCamera.for_image(320, 240)
    shape = model.skin_vertices()
    rng = np.random.default_rng(0)
    img = cv2.GaussianBlur(rng.uniform(0, 255, (240, 320)).astype(np.float32), (0, 0), 2.0)
    img = cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX)
    frame = np.repeat(img[..., None], 3, axis=2).astype(np.uint8)
    from myoface.analysis.camera import HeadPose

    pose = HeadPose.from_euler(5, -3, 2, (0, 0, -450))
    return model, cam, shape, pose, frame


def test_samples_lie_on_their_triangles():
    model = build_face_model()
    s = SurfaceSamples.on(model.face.triangles, 4)
    assert len(s) == 3 * len(model.face.triangles)
    assert np.allclose(s.bary.sum(1), 1.0) and (s.bary > 0).all()
    with pytest.raises(Exception, match="subdivision"):
        SurfaceSamples.on(model.face.triangles, 2)


def test_the_photometric_jacobian_is_the_residuals_derivative(scene):
    """Gauss-Newton's rows against central differences of the residuals, for a rotation, a
    translation and a contraction, on every blur level."""
    model, cam, shape, pose, frame = scene
    app = Appearance.from_frame(frame, model.face, cam, pose, shape)
    jac = skin_response(model, model.ids)
    m = len(model.ids)
    free = np.arange(m)
    c = np.full(m, 0.1)
    shifted = np.roll(frame, (1, 2), axis=(0, 1))  # (a frame that differs: residuals != 0)
    term = PhotometricTerm(shifted, app, cam)

    def est_at(x):
        from myoface.analysis.camera import HeadPose

        p = HeadPose(rotmat(x[:3]) @ pose.rotation, pose.translation_mm + x[3:6])
        cc = c + x[6:]
        return Estimate(p, cc, shape + (jac.reshape(-1, m) @ cc).reshape(-1, 3), jac, free)

    e0 = est_at(np.zeros(6 + m))
    zyg = 6 + model.ids.index("zygomaticus_major_l")
    for level in range(len(app.levels)):
        term.restart()
        for _ in range(level):
            term.advance()
        term.prepare(e0)
        rows, _, use = term._rows(e0)
        assert len(use) > 1000
        for k, h in [(0, 1e-4), (4, 1e-2), (zyg, 1e-2)]:
            x = np.zeros(6 + m)
            x[k] = h
            _, rp, _ = term._rows(est_at(x))
            x[k] = -h
            _, rm, _ = term._rows(est_at(x))
            fd = (rp - rm) / (2 * h)
            ratio = float(fd @ rows[:, k] / (rows[:, k] @ rows[:, k]))
            assert np.corrcoef(fd, rows[:, k])[0, 1] > 0.95, (level, k)
            assert 0.85 < ratio < 1.15, (level, k, ratio)


def test_the_photometric_fit_finds_a_known_shift(scene):
    """The whole frame moved by 2 px: the fit (pixels only, landmarks weightless) moves the
    head so that the model's vertices land within 0.3 px of where the texture went."""
    from dataclasses import replace

    from myoface.analysis.modelfit import ModelFit
    from myoface.analysis.weights import FitSettings

    model, cam, shape, pose, frame = scene
    pts = cam.project(pose.apply(shape))  # (x, y only: no depth)
    s = replace(FitSettings(), photometric=True, photo_landmark_weight=1e-6, iterations=30)
    fit = ModelFit(model, cam, s)
    fit.calibrate([pts], 0)
    fit.set_appearance(frame)
    moved = np.ascontiguousarray(np.roll(frame, 2, axis=1))  # 2 px right
    r = fit.fit(pts, image=moved)
    uv = cam.project(r.pose.apply(fit.skin(r.contractions)))
    err = uv - (pts + [2.0, 0.0])
    inner = (pts[:, 0] > 10) & (pts[:, 0] < 300)
    assert np.sqrt((err[inner] ** 2).sum(1).mean()) < 0.3
    assert np.abs(r.contractions).max() < 0.1  # (a shift is the head's, not an expression)


def test_a_mesh_warp_moves_its_points_exactly_and_does_not_fold():
    rng = np.random.default_rng(1)
    pts = rng.uniform(50, 150, (60, 2))
    shifts = rng.normal(0, 3, (60, 2))
    w = MeshWarp(points=pts, shifts=shifts)
    assert w.min_jacobian() >= 0.2 - 1e-9  # (the shifts that would fold it are drawn in)
    kept = w.displacement(pts)
    assert np.allclose(w.moved(pts), pts + kept)
    assert np.allclose(w.displacement(np.array([[0.0, 0.0], [400.0, 10.0]])), 0.0)


def test_the_expression_warp_is_the_models_motion():
    """On the model's own projected vertices (frontal, 4 px per mm), surprise's warp moves
    every vertex by the model's skin displacement in pixels. The smile's skin folds in the
    image (the cheek bulges over the nasolabial fold: 12 % of the vertices measured
    2026-12-01), which a warp of one frame cannot show; there the shifts are drawn together
    until the warp does not fold, and everywhere else they are the model's. The lips' red
    is left out: the face rests with its lips together (0.2 mm apart), and
    surprise's open jaw parts them, a motion that tears the image between them, which a
    warp cannot do; their shifts, and those of the lips' red around them (two rings of
    triangles), are drawn together (on surprise, 32 vertices, 2026-12-02)."""
    model = build_face_model()
    rest = model.skin_vertices()
    lm = model.face.landmarks
    lips = np.union1d(lm["lip_upper_inner"], lm["lip_lower_inner"])
    tri = np.asarray(model.face.triangles)
    for _ in range(2):
        lips = np.unique(tri[np.isin(tri, lips).any(axis=1)])
    away = np.setdiff1d(np.arange(len(rest)), lips)
    pts = rest[:, :2] * [4.0, -4.0] + [320.0, 240.0]  # 4 px per mm, y down
    for name, unchanged in (("surprise", 1.0), ("happiness", 0.8)):
        c = expression_contractions(name, 0.8, model.ids)
        warp, state = expression_warp(pts, model, c)
        want = (model.skin_vertices(state) - rest)[:, :2] * [4.0, -4.0]
        got = warp.displacement(pts)
        same = (np.linalg.norm(got - want, axis=1) <= 0.05)[away]
        assert same.mean() >= unchanged, (name, same.mean())
        assert np.abs(want).max() > 4, name  # (it moves the face by millimetres)
        assert warp.min_jacobian() >= 0.2 - 1e-9, name
    with pytest.raises(Exception, match="one point per vertex"):
        expression_warp(pts[:10], model, c)


@pytest.mark.shared_data
@needs_mediapipe
def test_a_hand_over_the_mouth_is_not_an_expression():
    """The sample video's first frame smiling (a known warp: the model's smile, with fake head
    motion), and for four held frames a skin-toned blob over the mouth and chin: those frames
    are ``occluded`` (not measured), the others are measured, and after the blob the smile is
    read again as before it (the blob did not become an expression: before the occlusion
    test, the fit explained it by the zygomatici at 1.0)."""
    from myoface.analysis.pipeline import Tracking
    from myoface.analysis.sample import fetch_sample_video
    from myoface.analysis.trackers.landmark_fit import FitTracker
    from myoface.analysis.video import open_video
    from myoface.analysis.weights import FitSettings
    from myoface.bench.knownwarp import HOLD, NEUTRAL_FRAMES, RISE, _Clip, make_clip
    from myoface.facemesh import FaceMeshDetector

    frame = next(iter(open_video(fetch_sample_video(quiet=True))))
    with FaceMeshDetector(video=False) as det:
        pts = det.detect(frame)
    model = build_face_model()
    frames, _, true_c = make_clip(frame, pts, model, "happiness", True, quick=True)
    cx, cy = pts[[61, 291, 17, 0], :2].mean(0)
    yy, xx = np.mgrid[0 : frame.shape[0], 0 : frame.shape[1]]
    blob = (((xx - cx) / 45) ** 2 + ((yy - cy - 10) / 30) ** 2) < 1
    rng = np.random.default_rng(0)
    hand = np.clip(np.array([200, 150, 130]) + rng.normal(0, 12, frame.shape), 0, 255)
    rise = RISE // 2
    covered = set(range(NEUTRAL_FRAMES + rise + 1, NEUTRAL_FRAMES + rise + HOLD - 1))
    frames = [
        np.where(blob[..., None], hand, f).astype(np.uint8) if k in covered else f
        for k, f in enumerate(frames)
    ]
    tracker = FitTracker(model, fps=30.0, settings=FitSettings(photometric=True))
    try:
        video = _Clip(frames, 30.0)
        first = tracker.calibrate(iter(video), 0)
        measured = [m for _, m in Tracking(video, tracker, first)]
    finally:
        tracker.close()
    quality = [m.quality for m in measured]
    assert all(quality[k] == "occluded" for k in covered), quality
    assert all(q == "ok" for k, q in enumerate(quality) if k not in covered), quality
    zyg = [model.ids.index("zygomaticus_major_l"), model.ids.index("zygomaticus_major_r")]
    before, after = min(covered) - 1, max(covered) + 1
    assert np.allclose(true_c[before], true_c[after])  # (both in the held smile)
    assert (
        np.abs(measured[after].contractions[zyg] - measured[before].contractions[zyg]).max() < 0.1
    )
    assert measured[after].contractions[zyg].min() > 0.4  # (and it is a smile: truth 0.72)


@pytest.mark.shared_data
@needs_mediapipe
def test_a_looped_clip_does_not_drift():
    """The known-warp smile (head moving) played six times over: the last loop is read as the
    second was, and its apex as the first's (the appearance is always the calibration frame's, never the previous
    frame's, so nothing accumulates), and every contraction stays in [0, 1]."""
    from myoface.analysis.pipeline import Tracking
    from myoface.analysis.sample import fetch_sample_video
    from myoface.analysis.trackers.landmark_fit import FitTracker
    from myoface.analysis.video import open_video
    from myoface.analysis.weights import FitSettings
    from myoface.bench.knownwarp import _Clip, make_clip
    from myoface.facemesh import FaceMeshDetector

    frame = next(iter(open_video(fetch_sample_video(quiet=True))))
    with FaceMeshDetector(video=False) as det:
        pts = det.detect(frame)
    model = build_face_model()
    clip, _, true_c = make_clip(frame, pts, model, "happiness", True, quick=True)
    loops = 6
    video = _Clip(clip * loops, 30.0)
    tracker = FitTracker(model, fps=30.0, settings=FitSettings(photometric=True))
    try:
        first = tracker.calibrate(iter(video), 0)
        measured = [m for _, m in Tracking(video, tracker, first)]
    finally:
        tracker.close()
    c = np.array([m.contractions for m in measured])
    assert all(m.quality == "ok" for m in measured)
    assert np.nanmin(c) >= 0.0 and np.nanmax(c) <= 1.0
    n = len(clip)
    apex = int(np.argmax(true_c.sum(1)))
    first_apex, last_apex = c[apex], c[(loops - 1) * n + apex]
    assert np.abs(last_apex - first_apex).max() < 0.05, np.abs(last_apex - first_apex).max()
    # every loop after the first (which starts from the calibration, not from the clip's
    # last frame) is read frame for frame as the second was (measured: equal to 1e-3)
    second, last = c[n : 2 * n], c[(loops - 1) * n :]
    assert np.abs(last - second).max() < 0.02, np.abs(last - second).max()


def test_distance_to_a_closed_polyline():
    from myoface.analysis.photometric import distance_to_polyline

    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
    pts = np.array([[0.5, 0.5], [2.0, 0.5], [0.5, -1.0], [0.0, 0.5], [2.0, 2.0]])
    assert np.allclose(distance_to_polyline(pts, square), [0.5, 1.0, 1.0, 0.0, np.sqrt(2)])


def test_the_shading_field_follows_smooth_shading(scene, monkeypatch):
    """A frame lit as the calibration frame but darker towards one side of the face (a
    smooth multiplicative ramp, no motion): with the shading's smooth field
    (SHADE_FIELD_ORDER 2) the frame's light explains it, far better than one light's shading
    and the quarters' offsets alone."""
    import myoface.analysis.photometric as photometric
    from myoface.analysis.photometric import SHADE_FIELD_ORDER

    model, cam, shape, pose, frame = scene
    assert SHADE_FIELD_ORDER == 0  # (off by default: see its comment)
    app = Appearance.from_frame(frame, model.face, cam, pose, shape)
    uv = cam.project(pose.apply(shape))
    x = (np.arange(frame.shape[1]) - uv[:, 0].mean()) / np.ptp(uv[:, 0])
    ramp = np.clip(1.0 + 0.5 * x + 0.8 * x**2, 0.0, None)[None, :, None]
    lit = np.clip(frame * ramp, 0, 255).astype(np.uint8)
    m = len(model.ids)
    est = Estimate(pose, np.zeros(m), shape, skin_response(model, model.ids), np.arange(m))
    costs = {}
    for order in (0, 2):
        monkeypatch.setattr(photometric, "SHADE_FIELD_ORDER", order)
        term = PhotometricTerm(lit, app, cam)
        term.prepare(est)
        while term.settling:
            term.advance()
            term.prepare(est)
        costs[order] = term.cost(est)
    assert costs[2] < 0.3 * costs[0], costs
