"""The optical-flow refinement of a detector's points (myoface.analysis.flow)."""

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")

from myoface.analysis.flow import FlowDetector, FlowRefiner  # noqa: E402
from myoface.errors import MyofaceValueError  # noqa: E402


def _texture(h=240, w=320, seed=0):
    rng = np.random.default_rng(seed)
    noise = rng.random((h, w)).astype(np.float32)
    img = cv2.GaussianBlur(noise, (0, 0), 2.0)
    img = (img - img.min()) / np.ptp(img) * 255
    return np.repeat(img[..., None], 3, axis=2).astype(np.uint8)


def _shift(img, dx, dy):
    m = np.float32([[1, 0, dx], [0, 1, dy]])
    return cv2.warpAffine(img, m, (img.shape[1], img.shape[0]), flags=cv2.INTER_CUBIC,
                          borderMode=cv2.BORDER_REFLECT)  # fmt: skip


def _points(n=30, seed=1):
    rng = np.random.default_rng(seed)
    xy = np.column_stack([rng.uniform(110, 210, n), rng.uniform(80, 160, n)])
    return np.column_stack([xy, rng.normal(0, 5, n)])  # (x, y, z)


def test_reads_the_image_motion_a_damped_detector_reads_short():
    img, p0 = _texture(), _points()
    ref = FlowRefiner()
    assert np.array_equal(ref.refine(img, p0), p0)  # the reference frame: as detected
    for k, (dx, dy) in enumerate([(1.5, -0.5), (3.25, -1.0), (5.0, -2.5), (6.5, -3.75)]):
        frame = _shift(img, dx, dy)
        detected = p0.copy()
        detected[:, :2] += 0.5 * np.array([dx, dy])  # reads half the motion
        out = ref.refine(frame, detected)
        err = out[:, :2] - (p0[:, :2] + [dx, dy])
        assert np.median(np.linalg.norm(err, axis=1)) < 0.1, k
        assert np.array_equal(out[:, 2], detected[:, 2])  # the depth stays the detector's
    assert ref.stats["frames"] == 5 and ref.stats["direct"] > 0.9 * 4 * len(p0)


def test_where_the_image_does_not_match_the_detector_stands():
    img, p0 = _texture(), _points()
    ref = FlowRefiner()
    ref.refine(img, p0)
    frame = _shift(img, 2.0, 1.0)
    covered = p0[:, 0] < 150
    assert covered.any() and (~covered).any()
    frame[:, :165] = 128  # the left part covered by a flat patch: nothing to track there
    detected = p0.copy()
    detected[:, :2] += [1.0, 0.5]
    out = ref.refine(frame, detected)
    assert np.array_equal(out[covered], detected[covered])
    moved = out[~covered, :2] - p0[~covered, :2]
    assert np.median(np.abs(moved - [2.0, 1.0])) < 0.1


def test_no_points_restarts_the_tracks():
    img, p0 = _texture(), _points()
    ref = FlowRefiner()
    ref.refine(img, p0)
    assert ref.refine(img, None) is None
    # the next frame with points is a new reference: returned as detected
    moved = _shift(img, 3.0, 0.0)
    p1 = p0.copy()
    p1[:, 0] += 1.0
    assert np.array_equal(ref.refine(moved, p1), p1)


def test_a_detector_wrapped():
    img, p0 = _texture(), _points()

    class Damped:
        closed = False

        def __init__(self):
            self.k = 0

        def detect(self, frame):
            self.k += 1
            return None if self.k == 3 else p0 + [0.5 * 2.0 * (self.k > 1), 0.0, 0.0]

        def close(self):
            self.closed = True

    inner = Damped()
    with FlowDetector(inner) as det:
        assert np.array_equal(det.detect(img), p0)
        out = det.detect(_shift(img, 2.0, 0.0))
        assert np.median(np.abs(out[:, 0] - p0[:, 0] - 2.0)) < 0.1
        assert det.detect(img) is None
    assert inner.closed


@pytest.mark.parametrize(
    "kw", [{"window": 1}, {"levels": -1}, {"fb_max_px": 0.0}, {"tolerance": -1.0}]
)
def test_bad_settings(kw):
    with pytest.raises(MyofaceValueError):
        FlowRefiner(**kw)


def test_flow_is_for_the_landmark_fit():
    from myoface.analysis.pipeline import make_analyzer

    with pytest.raises(MyofaceValueError, match="--flow"):
        make_analyzer(None, None, tracker="snakes", flow=True)


def test_the_fit_on_a_flow_refined_detector_reports_its_points():
    """On frames with nothing to track (flat), the detector's points stand: the fit measures
    what it measures without the flow, and analysis.json's description counts the points."""
    from myoface.analysis.camera import HeadPose, PinholeCamera
    from myoface.analysis.trackers.landmark_fit import FitTracker
    from myoface.model import build_face_model

    fm = build_face_model()
    cam = PinholeCamera.for_image(640, 480, 40.0)
    pose = HeadPose.from_euler(5.0, 0.0, 0.0, (0.0, 0.0, -500.0))
    pc = pose.apply(fm.face.vertices)
    pts = np.column_stack([cam.project(pc), np.zeros(len(pc))])

    class Fixed:
        def detect(self, frame):
            return pts.copy()

        def close(self):
            pass

    frame = np.full((480, 640, 3), 90, np.uint8)
    plain = FitTracker(fm, camera=cam, detector=Fixed())
    flowed = FitTracker(fm, camera=cam, detector=FlowDetector(Fixed()))
    a = [plain.measure(frame, k, k / 30) for k in range(2)]
    b = [flowed.measure(frame, k, k / 30) for k in range(2)]
    for x, y in zip(a, b, strict=True):
        np.testing.assert_allclose(x.contractions, y.contractions, atol=1e-9)
    stats = flowed.describe()["optical_flow_points"]
    assert stats["frames"] == 2 and stats["direct"] == 0
    assert stats["detector"] == len(pts)  # the second frame's: none tracked on a flat image
    assert "optical_flow_points" not in plain.describe()
    plain.close()
    flowed.close()
