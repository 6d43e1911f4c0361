"""The detector's own offsets on a face, by view (myoface.analysis.landmarks.TrackerOffsets),
taken off the points before the 3-D fit: on a synthetic detector that reads the head pitched
by a known, view-dependent angle (no MediaPipe, no renders: what is tested is the table, its
interpolation and the fit's use of it); the last test runs MediaPipe on one render (the table
taken from the calibration frame, FitSettings.tracker_offsets_frame)."""

from __future__ import annotations

import numpy as np
import pytest

from myoface.analysis.camera import HeadPose, PinholeCamera, rotmat
from myoface.analysis.landmarks import TrackerOffsets, view_angles, view_rotation
from myoface.analysis.modelfit import ModelFit
from myoface.analysis.weights import FitSettings, offset_spread_weights
from tests.conftest import needs_mediapipe

CAMERA = PinholeCamera.for_image(640, 480, 40.0)


def bias_deg(pose: HeadPose) -> float:
    """The synthetic detector's pitch error at ``pose``'s view: 3 deg, and a tenth of the
    view's elevation (it reads a turn short, as MediaPipe does)."""
    return 3.0 - 0.1 * view_angles(pose)[1]


def seen(skin: np.ndarray, pose: HeadPose) -> np.ndarray:
    """What the synthetic detector reports (V, 2): ``skin`` turned about its centroid by
    :func:`bias_deg` about the head's x axis, projected (x, y px; z not given)."""
    c = skin.mean(axis=0)
    turned = (skin - c) @ rotmat(np.array([np.radians(bias_deg(pose)), 0.0, 0.0])).T + c
    return CAMERA.project(pose.apply(turned))


class SyntheticReader:
    """Stands in for LandmarkSynthesis: the synthetic detector's points less the true ones."""

    def __init__(self):
        self.calls = 0

    def tracker_error(self, skin, pose):
        self.calls += 1
        err = seen(skin, pose) - CAMERA.project(pose.apply(skin))
        return np.column_stack([err, np.zeros(len(err))])


@pytest.fixture(scope="module")
def fm():
    from myoface.model import build_face_model

    return build_face_model()


def test_view_angles_invert_view_rotation():
    for az, el in ((0.0, 0.0), (25.0, -10.0), (-40.0, 30.0)):
        rot = view_rotation(az, el)
        np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-12)
        pose = HeadPose(rot, np.array([0.0, 0.0, -500.0]))
        np.testing.assert_allclose(view_angles(pose), (az, el), atol=1e-9)
    # the head on the axis: a yaw is a view of the opposite azimuth, a pitch of the same elevation
    np.testing.assert_allclose(
        view_angles(HeadPose.from_euler(20.0, 0.0, 0.0, (0, 0, -500))), (-20.0, 0.0), atol=1e-9
    )
    np.testing.assert_allclose(
        view_angles(HeadPose.from_euler(0.0, 10.0, 0.0, (0, 0, -500))), (0.0, 10.0), atol=1e-9
    )


def test_the_fit_recovers_the_pose_a_biased_detector_misreads(fm):
    """Without the table the pitch is off by the detector's bias; with it, within a tenth."""
    skin = fm.skin_vertices()
    poses = [
        HeadPose.from_euler(0.0, 0.0, 0.0, (0.0, 0.0, -500.0)),
        HeadPose.from_euler(20.0, -10.0, 5.0, (15.0, -5.0, -520.0)),
        HeadPose.from_euler(-28.0, 12.0, -6.0, (-10.0, 8.0, -480.0)),
    ]
    for pose in poses:
        errs = {}
        for with_table in (False, True):
            # (without the spread's weights, which render the views of a turning head:
            # test_the_spread_weighs_the_points_whose_offsets_move_with_the_view)
            fit = ModelFit(fm, CAMERA, FitSettings(offset_spread=0.0))
            reader = SyntheticReader()
            if with_table:
                fit.set_offsets(TrackerOffsets(reader, fit.neutral, CAMERA))
            r = fit.fit(seen(skin, pose))
            errs[with_table] = np.abs(r.pose.angles_deg - pose.angles_deg)
            if with_table:
                # only the cells around the view are rendered: four at most for one view
                assert 1 <= reader.calls <= 4
        bias = abs(bias_deg(pose))
        assert errs[False][1] > 0.7 * bias, (pose.angles_deg, errs)
        assert errs[True].max() < 0.1 * bias, (pose.angles_deg, errs)


def test_the_calibration_reads_corrected_points(fm):
    """The calibration pose measured on a biased detector's frames is right with the table
    (without, off by the bias: a rigid turn of the points is read as the head's), and the
    person's neutral stays the model's own."""
    skin = fm.skin_vertices()
    pose = HeadPose.from_euler(5.0, -4.0, 2.0, (0.0, 0.0, -500.0))
    frames = [seen(skin, pose)] * 3
    out = {}
    for with_table in (False, True):
        fit = ModelFit(fm, CAMERA)
        if with_table:
            fit.set_offsets(TrackerOffsets(SyntheticReader(), fit.neutral, CAMERA))
        cal = fit.calibrate(frames, index=0)
        out[with_table] = (
            np.abs(cal.pose.angles_deg - pose.angles_deg).max(),
            np.sqrt((cal.identity_mm**2).sum(1).mean()),
        )
    assert out[True][0] < 0.3 < out[False][0], out
    assert out[True][1] < 0.1, out  # mm RMS


def test_a_calibration_done_again_at_its_frame_uses_the_same_frames(fm):
    """``calibrate(frames, index, scores=...)`` (the calibration done again with the points
    corrected, FitTracker with FitSettings.tracker_offsets_frame) fits the person's neutral
    on the frames the first calibration chose around its frame; without the scores, on that
    frame alone."""
    from myoface.analysis.modelfit import CALIBRATION_FRAMES

    skin = fm.skin_vertices()
    rng = np.random.default_rng(3)
    frames = []
    for k in range(6):
        pose = HeadPose.from_euler(2.0 * k, -1.0, 0.5, (0.0, 0.0, -500.0))
        frames.append(seen(skin, pose) + rng.normal(0.0, 0.3, (len(skin), 2)))
    fit = ModelFit(fm, CAMERA)
    cal = fit.calibrate(frames)
    assert len(cal.extra["frames"]) == min(CALIBRATION_FRAMES, len(frames)) > 1, cal.scores
    again = fit.calibrate(frames, cal.index, scores=cal.scores)
    assert again.extra["frames"] == cal.extra["frames"]
    np.testing.assert_array_equal(again.scores, cal.scores)
    np.testing.assert_allclose(again.identity_mm, cal.identity_mm, atol=1e-9)
    assert fit.calibrate(frames, cal.index).extra["frames"] == [cal.index]


@needs_mediapipe
def test_the_default_face_takes_the_table_from_the_calibration_frame(fm):
    """With FitSettings.tracker_offsets_frame a model without a texture gets the table with
    the calibration frame as its texture: rendered at the calibration's pose it gives back
    the frame where it draws the face; by default (off) it gets none."""
    from myoface.analysis.synthesis import LandmarkSynthesis
    from myoface.analysis.trackers.landmark_fit import FitTracker
    from myoface.analysis.weights import FitSettings
    from myoface.render.degrade import coverage

    assert fm.face.texture is None
    pose = HeadPose.from_euler(8.0, -4.0, 0.0, (0.0, 0.0, -520.0))
    painter = LandmarkSynthesis(fm.face, CAMERA, (640, 480), detector=SyntheticReader())
    frame = painter.renderer.render(fm.skin_vertices(), pose=(pose.rotation, pose.translation_mm))
    for on in (False, True):
        tracker = FitTracker(fm, settings=FitSettings(tracker_offsets_frame=on), gaze=False,
                             calibration_frame=0)  # fmt: skip
        try:
            tracker.calibrate([frame])
            table = tracker.fit.offsets
            assert (table is not None) == on
            if on:
                ren = table.synthesis.renderer
                cal = tracker.calibration.pose
                back = ren.render(table.shape, pose=(cal.rotation, cal.translation_mm))
                inside = coverage(ren) > 0.99
                diff = np.abs(back.astype(float) - frame.astype(float))[inside].mean()
                # (the renderer's shading applied once more on the frame's: ~17 levels)
                assert inside.sum() > 5000 and diff < 25, (inside.sum(), diff)
        finally:
            tracker.close()


class ChinSlider(TrackerOffsets):
    """A detector's table whose offsets are known exactly: the chin's points (the lowest
    tenth of the face) read lower by 0.25 mm per degree of the view's azimuth, as MediaPipe's
    chin slides along the outline of a turned head (no renders: :meth:`offsets` is the
    detector's offset itself)."""

    def __init__(self, fm):
        skin = fm.skin_vertices()
        super().__init__(None, skin, CAMERA)
        self.chin = skin[:, 1] < np.percentile(skin[:, 1], 10)

    def offsets(self, pose):
        out = np.zeros_like(self.shape)
        out[self.chin, 1] = -0.25 * abs(view_angles(pose)[0])
        return out


def test_the_neutral_frame_is_chosen_on_corrected_points(fm):
    """The calibration scores each frame's expression on the points it will fit (the
    detector's offsets at that frame's view taken off): a neutral face turned 24 deg, whose
    detector lowers the chin 6 mm, is as neutral as the frontal frames after it, so the
    earliest frame calibrates (scored on the raw points, its chin read as an expression and
    a later frame chosen; issue 30: on the head-motion renders the neutral was then taken at
    the wrong view, and the chin raiser read 0.44 at rest)."""
    import myoface.analysis.modelfit as modelfit

    skin = fm.skin_vertices()
    table = ChinSlider(fm)
    poses = [HeadPose.from_euler(24.0, 0.0, 0.0, (0.0, 0.0, -500.0))]
    poses += [HeadPose.from_euler(0.0, 0.0, 0.0, (0.0, 0.0, -500.0))] * 4
    frames = [CAMERA.project(q.apply(skin + table.offsets(q))) for q in poses]
    chosen = {}
    for corrected in (False, True):
        old = modelfit.SCORE_CORRECTED
        modelfit.SCORE_CORRECTED = corrected
        try:
            # (the spread's weights off: they weigh the sliding chin less, which hides it)
            fit = ModelFit(fm, CAMERA, FitSettings(offset_spread=0.0))
            fit.set_offsets(table)
            cal = fit.calibrate(frames)
        finally:
            modelfit.SCORE_CORRECTED = old
        chosen[corrected] = (cal.index, np.round(cal.scores, 2).tolist())
    assert chosen[True][0] == 0, chosen
    assert chosen[False][0] != 0, chosen


def test_the_spread_weighs_the_points_whose_offsets_move_with_the_view(fm):
    """TrackerOffsets.spread: the RMS over the views of a turning head of each point's
    offset less its rigid part. :class:`ChinSlider`'s chin (0.25 mm a degree of azimuth, over
    -30..30 deg by 10: 0.25 * std(|azimuth|) = 2.4 mm RMS, of which the face's best rigid
    motion takes a little) spreads nearly that far, the rest of the face, which the detector
    reads where it is, hardly (only what the rigid fit spreads over it); the fit's weights
    (FitSettings.offset_spread) are offset_spread_weights of the spread."""
    from myoface.analysis.landmarks import OFFSET_AZIMUTHS_DEG

    table = ChinSlider(fm)
    pose = HeadPose.from_euler(0.0, 0.0, 0.0, (0.0, 0.0, -500.0))
    spread = table.spread(pose)
    az = OFFSET_AZIMUTHS_DEG[np.abs(OFFSET_AZIMUTHS_DEG) <= 30.0]
    expect = 0.25 * np.std(np.abs(az))
    assert expect > 2.0  # (the test means something: the chin's weight well below 1)
    assert (spread[table.chin] > 0.8 * expect).all(), spread[table.chin]
    assert (spread[table.chin] < 1.05 * expect).all(), spread[table.chin]
    assert spread[~table.chin].max() < 0.15 * expect, spread[~table.chin].max()
    skin = fm.skin_vertices()
    w = {}
    for scale in (0.0, 1.0):
        fit = ModelFit(fm, CAMERA, FitSettings(offset_spread=scale))
        fit.set_offsets(table)
        w[scale] = fit._weights(pose, skin)
    ratio = w[1.0] / w[0.0]
    np.testing.assert_allclose(ratio, offset_spread_weights(spread, 1.0, 1.0))
    assert (ratio[table.chin] < 0.25).all() and (ratio[~table.chin] > 0.9).all()


class ContextReader(SyntheticReader):
    """A detector whose error on the video's frames is not the table's: on a render laid
    over a frame (``context`` given) it reads the head pitched by :func:`context_bias_deg`,
    as it does the video itself; on the table's plain renders by :func:`bias_deg`."""

    def tracker_error(self, skin, pose, context=None):
        if context is None:
            return super().tracker_error(skin, pose)
        self.calls += 1
        err = seen_in_context(skin, pose) - CAMERA.project(pose.apply(skin))
        return np.column_stack([err, np.zeros(len(err))])


def context_bias_deg(pose: HeadPose) -> float:
    """The detector's pitch error among the video's surroundings: 2 deg more than on the
    table's renders, and it reads the view's elevation at half its change."""
    return 5.0 - 0.5 * view_angles(pose)[1]


def seen_in_context(skin: np.ndarray, pose: HeadPose) -> np.ndarray:
    """:func:`seen` with :func:`context_bias_deg`."""
    c = skin.mean(axis=0)
    turned = (skin - c) @ rotmat(np.array([np.radians(context_bias_deg(pose)), 0.0, 0.0])).T + c
    return CAMERA.project(pose.apply(turned))


def test_the_detectors_context_is_measured_at_the_calibration(fm):
    """ModelFit.measure_detector_context: where the detector errs on the video's frames
    otherwise than on the table's renders, the calibration corrected by the table alone is
    pitched by the difference; measured on the model laid over the calibration frames (the
    reader given the frame as its context), the calibration's pose comes within a tenth of
    a degree (the detector reading the render's pitch at half its change: the steps
    over-relaxed), and a later frame turned aside is corrected alike (the context added to
    the table at every view). Without a table there is nothing to measure."""
    skin = fm.skin_vertices()
    pose = HeadPose.from_euler(4.0, -3.0, 1.0, (0.0, 0.0, -500.0))
    frames = [seen_in_context(skin, pose)] * 3
    images = [np.zeros((4, 4, 3), np.uint8)] * 3  # (the reader does not look at them)
    fit = ModelFit(fm, CAMERA, FitSettings(offset_spread=0.0))
    reader = ContextReader()
    fit.set_offsets(TrackerOffsets(reader, fit.neutral, CAMERA))
    cal = fit.calibrate(frames, index=0)
    before = np.abs(cal.pose.angles_deg - pose.angles_deg).max()
    calls = reader.calls
    info = fit.measure_detector_context(images)
    after = np.abs(fit.calibration.pose.angles_deg - pose.angles_deg).max()
    assert before > 1.5 and after < 0.1, (before, after)
    assert info is not None and info["frames"] == 1 and info["context_rms_mm"] > 0.1, info
    assert fit.calibration.extra["detector_context"] == info
    assert reader.calls > calls  # (the frame's context read)
    # a later frame turned aside (the context's excess over the table's is the same there:
    # both depend on the elevation alone): the table with the context added corrects it
    later = HeadPose.from_euler(-15.0, -3.0, 1.0, (10.0, 0.0, -510.0))
    errs = {}
    for measured in (False, True):
        one = ModelFit(fm, CAMERA, FitSettings(offset_spread=0.0))
        one.set_offsets(TrackerOffsets(ContextReader(), one.neutral, CAMERA))
        one.calibrate(frames, index=0)
        if measured:
            one.measure_detector_context(images)
        r = one.fit(seen_in_context(skin, later))
        errs[measured] = np.abs(r.pose.angles_deg - later.angles_deg)
    assert errs[True][1] < 0.5 < 1.5 < errs[False][1], errs  # (pitch)
    assert errs[True].max() < 0.7, errs
    plain = ModelFit(fm, CAMERA)
    plain.calibrate(frames, index=0)
    assert plain.measure_detector_context(images) is None


def test_the_render_is_laid_over_the_frame_it_is_read_in(fm):
    """LandmarkSynthesis.tracker_error with a context: the detector is given the render
    over the frame, the frame's own pixels where the render drew no head, the render's on
    the face; without one, the renderer's own background."""
    from myoface.analysis.synthesis import LandmarkSynthesis

    class Grab:
        def detect(self, image):
            self.image = image
            return None

        def close(self):
            pass

    grab = Grab()
    syn = LandmarkSynthesis(fm.face, CAMERA, (640, 480), detector=grab)
    pose = HeadPose.from_euler(10.0, 0.0, 0.0, (0.0, 0.0, -520.0))
    room = np.zeros((480, 640, 3), np.uint8)
    room[..., 1] = 200
    assert syn.tracker_error(fm.skin_vertices(), pose, context=room) is None
    seen_img = grab.image
    nose = CAMERA.project(pose.apply(fm.skin_vertices()))[4].round().astype(int)
    np.testing.assert_array_equal(seen_img[:40, :40], room[:40, :40])
    assert np.abs(seen_img[nose[1], nose[0]].astype(int) - (0, 200, 0)).max() > 50
    syn.tracker_error(fm.skin_vertices(), pose)
    assert np.abs(grab.image[:40, :40].astype(int) - (0, 200, 0)).max() > 50
    with pytest.raises(Exception, match="context must be"):
        syn.tracker_error(fm.skin_vertices(), pose, context=room[:10])
