"""The lid margins' edge finder and term (myoface.analysis.lidedges) on known answers."""

import numpy as np
import pytest

from myoface.analysis.camera import HeadPose, PinholeCamera
from myoface.analysis.lidedges import LidEdgeSettings, LidEdgeTerm, MarginSamples, find_edges
from myoface.analysis.terms import Estimate


def _step_image(edge_y: float, h=40, w=60, dark=60.0, bright=180.0, blur=1.0):
    """An image whose rows above ``edge_y`` are dark and below bright (a blurred step)."""
    from scipy.special import erf

    y = np.arange(h)[:, None] * np.ones((1, w))
    v = dark + (bright - dark) * 0.5 * (1 + erf((y - edge_y) / (np.sqrt(2) * blur)))
    return np.repeat(v[..., None], 3, axis=2)


@pytest.mark.parametrize("edge_y", [19.3, 20.0, 20.75])
@pytest.mark.parametrize("start", [-2.0, -0.6, 0.0, 1.4])
def test_a_blurred_step_is_found_to_a_tenth_of_a_pixel(edge_y, start):
    img = _step_image(edge_y)
    uv = np.array([[20.0, edge_y + start], [35.0, edge_y + start]])
    nrm = np.array([[0.0, 1.0], [0.0, 1.0]])
    off, strength, ok = find_edges(img, uv, nrm)
    assert ok.all()
    assert np.abs(uv[:, 1] + off - edge_y).max() < 0.1
    assert strength.min() > 30


def test_no_edge_in_a_flat_image_is_clear():
    img = np.full((40, 60, 3), 120.0) + np.random.default_rng(0).normal(0, 0.5, (40, 60, 3))
    uv = np.array([[20.0, 20.0]])
    _, _, ok = find_edges(img, uv, np.array([[0.0, 1.0]]))
    assert not ok.any()


def test_an_edge_beyond_the_window_is_not_taken():
    img = _step_image(30.0)
    s = LidEdgeSettings(window_px=3.0)
    _, _, ok = find_edges(img, np.array([[20.0, 20.0]]), np.array([[0.0, 1.0]]), s)
    assert not ok.any()


def test_the_terms_jacobian_matches_its_residuals():
    """The normal equations' gradient against finite differences of the cost (Huber off)."""
    from myoface.face.io import load_default_face

    face = load_default_face()
    sm = MarginSamples(face)
    cam = PinholeCamera.for_image(640, 480, 40.0)
    pose = HeadPose.from_euler(10.0, -5.0, 3.0, translation_mm=(5, -3, -500))
    rng = np.random.default_rng(1)
    m = 3
    jac = rng.normal(0, 0.5, (face.n_vertices, 3, m))
    c = np.full(m, 0.3)

    def est_at(x):
        from myoface.analysis.camera import rotmat

        p = HeadPose(rotmat(x[:3]) @ pose.rotation, pose.translation_mm + x[3:6])
        cc = c + x[6:]
        shape = face.vertices + (jac.reshape(-1, m) @ cc).reshape(-1, 3)
        return Estimate(p, cc, shape, jac, np.arange(m))

    term = LidEdgeTerm(np.zeros((480, 640, 3)), sm, cam, LidEdgeSettings(huber=1e9))
    e0 = est_at(np.zeros(6 + m))
    _, _, uv = term._project(e0)
    term.used = np.arange(len(uv))
    nrm = rng.normal(size=(len(uv), 2))
    term.nrm = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
    term.target = (uv * term.nrm).sum(1) + rng.normal(0, 1.0, len(uv))
    term.mm_per_px = 1.0
    term.hw = np.ones(len(uv))
    _, b = term.normal_equations(e0)
    eps = 1e-6
    num = np.array([
        (term.cost(est_at(eps * np.eye(6 + m)[i])) - term.cost(est_at(-eps * np.eye(6 + m)[i])))
        / (2 * eps)
        for i in range(6 + m)
    ])  # fmt: skip
    # cost = sum r^2, b = -J^T r: the gradient is -2 b
    assert np.allclose(num, -2 * b, rtol=1e-4, atol=1e-4 * np.abs(num).max())


def test_closed_and_turned_away_eyes_are_not_read():
    from myoface.face.io import load_default_face

    face = load_default_face()
    sm = MarginSamples(face)
    cam = PinholeCamera.for_image(640, 480, 40.0)
    term = LidEdgeTerm(np.zeros((480, 640, 3)), sm, cam)
    m = 1
    jac = np.zeros((face.n_vertices, 3, m))

    def readable(shape, yaw):
        pose = HeadPose.from_euler(yaw, 0.0, 0.0, translation_mm=(0, 0, -500))
        est = Estimate(pose, np.zeros(m), shape, jac, np.arange(m))
        return term._readable(est, term._project(est)[2])

    v = face.vertices.copy()
    assert readable(v, 0.0).all()
    # the first eye closed: its upper margin's vertices onto its lower margin's mean
    upper, lower = sm.chains[0]
    v[upper[1:-1]] = v[lower].mean(0)
    ok = readable(v, 0.0)
    assert not ok[sm.eye == 0].any() and ok[sm.eye == 1].all()
    # the head turned 80 degrees: neither eye faces the camera within FACING_DEG
    assert not readable(face.vertices, 80.0).any()


@pytest.mark.slow
def test_the_fit_with_lid_edges_puts_biased_lids_back_on_the_rendered_margins(monkeypatch):
    """A render of the default face with a detector that puts the upper lids' points 2 px too
    high: the fit follows the points; with the lid edges (FitSettings.lid_edges, the edge
    reader: lidtemplate.READERS) its upper margins end nearer the rendered ones."""
    import myoface.analysis.lidtemplate as lt

    monkeypatch.setattr(lt, "READERS", ("edges",))
    from myoface.analysis.modelfit import ModelFit
    from myoface.analysis.weights import FitSettings
    from myoface.bench.headmotion import camera_renderer
    from myoface.model import build_face_model

    fm = build_face_model()
    cam = PinholeCamera.for_image(640, 480, 40.0)
    pose = HeadPose.from_euler(12.0, 6.0, 3.0, translation_mm=(10, 5, -450))
    skin = fm.skin_vertices()
    img = camera_renderer(fm.face).render(skin, pose=(pose.rotation, pose.translation_mm))
    sm = MarginSamples(fm.face)
    pc = pose.apply(skin)
    pts = cam.project(pc)
    for upper, _ in sm.chains:
        pts[upper[1:-1], 1] -= 2.0  # (up in the image)

    def upper_error(settings, image):
        fit = ModelFit(fm, cam, settings)
        r = fit.fit(pts, image=image)
        got = cam.project(r.pose.apply(sm.points(fit.shape(r.contractions))))
        want = cam.project(pose.apply(sm.points(skin)))
        d = ((got - want) * sm.normals(want)).sum(1)
        return float(np.abs(d[sm.lid == 0]).mean())

    without = upper_error(FitSettings(), None)
    with_edges = upper_error(FitSettings(lid_edges=True), img)
    assert without > 0.8  # (the points' bias shows)
    assert with_edges < 0.6 * without
