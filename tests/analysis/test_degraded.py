"""The whole analysis on a degraded render with known answers: a face from a real photo,
turned, smiling, rendered and then degraded as a webcam would (moving light, blur, noise, H.264:
:func:`~myoface.bench.headmotion.degraded_sequence`), its frames read by MediaPipe and fitted
(the default 3-D fit, and with its photometric term): the head's pose and the smile's
contractions come back."""

import numpy as np
import pytest

from tests.conftest import needs_mediapipe, shared_path

#: neutral frames (the calibration's), then the smile rising over RISE frames and held
NEUTRAL, RISE, HOLD = 6, 6, 6
#: the true head pose: turned and tilted, a little further than a face at a desk turns
YAW, PITCH, ROLL = 20.0, -8.0, 5.0
SMILE = {"zygomaticus_major_l": 0.7, "zygomaticus_major_r": 0.7}


@pytest.fixture(scope="module")
def degraded_smile():
    return _degraded(SMILE)


def _degraded(smile: dict):
    """The clip of ``smile`` (contractions at the held smile) on the person's face, turned,
    rendered and degraded: (model, frames, MediaPipe's points, truth, poses, skins)."""
    from myoface.analysis.camera import HeadPose
    from myoface.analysis.video import open_video
    from myoface.bench.headmotion import DISTANCE_MM, degraded_sequence, detect_sequence
    from myoface.face.personal import face_from_photo
    from myoface.model import build_face_model

    path = shared_path("video", "single_face.mp4")
    if not path.exists():
        pytest.skip("../shared/data/video/single_face.mp4 is not here")
    face, _ = face_from_photo(next(iter(open_video(path))), name="sample person")
    fm = build_face_model(face)
    env = np.concatenate([np.zeros(NEUTRAL), np.linspace(0, 1, RISE + 1)[1:], np.ones(HOLD)])
    truth = np.array([fm.validate({k: v * a for k, v in smile.items()}) for a in env])
    pose = HeadPose.from_euler(YAW, PITCH, ROLL, (10.0, -5.0, -DISTANCE_MM))
    state, skins = fm.rest_state(), []
    for c in truth:
        state = fm.relax(c, state).state
        skins.append(fm.skin_vertices(state))
    poses = [pose] * len(truth)
    frames, _ = degraded_sequence(face, poses, np.array(skins))
    points, _ = detect_sequence(frames)
    return fm, frames, points, truth, poses, np.array(skins)


@needs_mediapipe
@pytest.mark.slow
@pytest.mark.shared_data
@pytest.mark.parametrize(
    "photometric",
    [False, True],
)
def test_pose_and_contractions_are_recovered_on_a_degraded_render(degraded_smile, photometric):
    """Over the held smile: the head's angles within 3 degrees RMS of the truth, the two
    zygomatici within 0.25 of their 0.7 (and of each other's reading within 0.25), no other
    muscle of the paper's twelve above 0.3, and the skin within 1.5 mm RMS of the true skin.
    Measured 2026-12-02 (default fit): head 1.9 degrees, zygomatici 0.50 and 0.55, the largest
    other of the twelve 0.08 (frontalis), skin 0.8 mm. With the photometric term: head 2.3
    degrees, zygomatici 0.46 and 0.60, the others 0.00, skin 0.63 mm (before its samples
    weighed less where the muscles move the skin, FitSettings.photo_model_error, it drove the
    depressor labii inferioris to 0.45: an expected failure then). With the detector's offsets
    on this face taken off its points (FitSettings.tracker_offsets, 2026-12-02): default fit,
    head 1.13 degrees, zygomatici 0.45 and 0.52, the largest other 0.24, skin 0.90 mm (an
    expected failure: the left zygomaticus 0.004 short)."""
    from myoface.analysis.weights import FitSettings
    from myoface.bench.headmotion import PAPER_MUSCLES, run_headmotion

    fm, frames, points, truth, poses, skins = degraded_smile
    settings = FitSettings(photometric=True) if photometric else None
    res = run_headmotion(fm, points, truth, poses, skins, settings=settings, frames=frames)
    held = slice(NEUTRAL + RISE, None)
    ang = res.angles_est[held] - res.angles_true[held]
    assert np.sqrt(np.nanmean(ang**2)) < 3.0, ang
    ids = list(fm.ids)
    zyg = [ids.index(k) for k in SMILE]
    got = np.nanmean(res.estimate[held], axis=0)
    assert np.all(np.abs(got[zyg] - 0.7) < 0.25), got[zyg]
    assert abs(got[zyg[0]] - got[zyg[1]]) < 0.25, got[zyg]
    others = [ids.index(m) for m in ids if m in PAPER_MUSCLES and m not in SMILE]
    assert got[others].max() < 0.3, {ids[i]: round(float(got[i]), 2) for i in others}
    assert np.nanmean(res.skin_rms_mm[held]) < 1.5, res.skin_rms_mm


@needs_mediapipe
@pytest.mark.slow
@pytest.mark.shared_data
def test_the_benchmark_fit_takes_frames_as_the_tracker_does(degraded_smile, monkeypatch):
    """``run_headmotion`` fits the frames itself; it takes each as ``FitTracker`` does
    (:func:`~myoface.analysis.trackers.landmark_fit.frame_quality`): on this render every frame
    is measured with the photometric term, and with a gate every frame fails (the occlusion's
    share above -1) none is, each counted as occluded (until 2026-12-04 the benchmark measured
    every frame whatever the gate said, and missed the tracker losing a turning head)."""
    import myoface.analysis.trackers.landmark_fit as lf
    from myoface.analysis.weights import FitSettings
    from myoface.bench.headmotion import run_headmotion

    fm, frames, points, truth, poses, skins = degraded_smile
    settings = FitSettings(photometric=True)
    res = run_headmotion(fm, points, truth, poses, skins, settings=settings, frames=frames)
    assert res.not_measured == {}
    assert np.isfinite(res.estimate).all()
    monkeypatch.setattr(lf, "OCCLUDED_FRACTION", -1.0)
    res = run_headmotion(fm, points, truth, poses, skins, settings=settings, frames=frames)
    assert res.not_measured == {"occluded": len(frames)}
    assert np.isnan(res.estimate).all()


@needs_mediapipe
@pytest.mark.slow
@pytest.mark.shared_data
@pytest.mark.parametrize("photometric, lid_edges", [(True, None), (True, True), (False, None)])
def test_the_benchmark_fit_reads_the_lids_as_the_tracker_does(degraded_smile, monkeypatch,
                                                              photometric, lid_edges):  # fmt: skip
    """Where the settings read the lids from the image (:attr:`~myoface.analysis.weights.
    FitSettings.reads_lids`), ``run_headmotion`` takes the calibration frame as the lids'
    reference, as ``FitTracker`` does, and each frame's fit builds the lids' term; by default
    (off with the photometric term) it does neither; the fit on the points alone reads them
    (until 2026-12-07 the benchmark never set the reference, and the points' fit had no image
    for them)."""
    from myoface.analysis.lidtemplate import LidTemplateTerm
    from myoface.analysis.modelfit import ModelFit
    from myoface.analysis.weights import FitSettings
    from myoface.bench.headmotion import run_headmotion

    fm, frames, points, truth, poses, skins = degraded_smile
    n = NEUTRAL + 2
    taken, built = [], []
    set_ref, edge_term = ModelFit.set_lid_reference, ModelFit.lid_edge_term

    def spy_ref(self, frame):
        taken.append(frame)
        return set_ref(self, frame)

    def spy_term(self, image):
        term = edge_term(self, image)
        built.append(term)
        return term

    monkeypatch.setattr(ModelFit, "set_lid_reference", spy_ref)
    monkeypatch.setattr(ModelFit, "lid_edge_term", spy_term)
    settings = FitSettings(photometric=photometric, lid_edges=lid_edges)
    res = run_headmotion(fm, points[:n], truth[:n], poses[:n], skins[:n], settings=settings,
                         frames=frames[:n])  # fmt: skip
    assert np.isfinite(res.estimate).all()
    if settings.reads_lids:
        assert len(taken) == 1 and taken[0] is frames[res.calibration_index]
        assert len(built) >= n
        assert all(any(isinstance(t, LidTemplateTerm) for t in b.terms) for b in built)
    else:
        assert taken == [] and built == []


@needs_mediapipe
@pytest.mark.slow
@pytest.mark.shared_data
@pytest.mark.parametrize("side", ["l", "r"])
def test_a_one_sided_smile_is_read_on_its_side(side):
    """The symmetry prior (FitSettings.symmetry_sigma) holds the two sides alike where the
    frames do not tell them apart, not where they do: a smile of one zygomaticus major (0.7)
    on the turned, degraded render is read by the default analysis on its side at 0.4 or more
    and on the other at 0.15 or less. Measured 2026-12-05 (the prior off / on): the person's
    left 0.58 / 0.54, right 0.65 / 0.63, the other side at most 0.03 / 0.02; with the head
    turned 30 degrees, left 0.48 / 0.42, right 0.64 / 0.60. A quadratic prior of sigma 0.1
    fails it (left 0.38)."""
    from myoface.analysis.weights import FitSettings
    from myoface.bench.headmotion import run_headmotion

    fm, frames, points, truth, poses, skins = _degraded({f"zygomaticus_major_{side}": 0.7})
    res = run_headmotion(fm, points, truth, poses, skins, settings=FitSettings(), frames=frames)
    got = np.nanmean(res.estimate[NEUTRAL + RISE :], axis=0)
    ids = list(fm.ids)
    other = "r" if side == "l" else "l"
    assert got[ids.index(f"zygomaticus_major_{side}")] >= 0.4, got
    assert got[ids.index(f"zygomaticus_major_{other}")] <= 0.15, got


@needs_mediapipe
@pytest.mark.slow
@pytest.mark.shared_data
def test_the_detector_is_read_among_the_frames_own_surroundings(degraded_smile):
    """The premise of FitSettings.detector_context, on a known answer: on the degraded
    render's neutral frame (the person's face among a cluttered room, turned 20 degrees),
    MediaPipe's points less its error on the person's model rendered at the true pose over
    that frame are nearer the true vertices than its points less the offsets' table (the
    model rendered on the plain background). Measured 2026-12-06: the raw points 4.7 px RMS
    from the true vertices, less the table's offsets 2.7, less the context's error 0.80."""
    from myoface.analysis.camera import PinholeCamera
    from myoface.analysis.landmarks import TrackerOffsets
    from myoface.bench.headmotion import FOV_DEG, SIZE

    fm, frames, points, truth, poses, skins = degraded_smile
    cam = PinholeCamera.for_image(SIZE[0], SIZE[1], FOV_DEG)
    table = TrackerOffsets.of_textured_face(fm.face, fm.face.vertices, cam, SIZE, False)
    try:
        pose, skin, p = poses[0], skins[0], np.asarray(points[0], dtype=np.float64)
        want = cam.project(pose.apply(skin))
        err = table.synthesis.tracker_error(skin, pose, context=frames[0])
        rms = {
            "raw": np.sqrt(((p[:, :2] - want) ** 2).sum(1).mean()),
            "table": np.sqrt(((table.correct(p, pose, skin)[:, :2] - want) ** 2).sum(1).mean()),
            "context": np.sqrt(((p[:, :2] - err[:, :2] - want) ** 2).sum(1).mean()),
        }
    finally:
        table.close()
    assert rms["context"] < 0.6 * rms["table"] < 0.6 * rms["raw"], rms


@needs_mediapipe
@pytest.mark.slow
@pytest.mark.shared_data
def test_the_tracker_calibrates_with_the_detectors_context(degraded_smile):
    """FitTracker with the person's own face measures the detector's context at its
    calibration (FitSettings.detector_context, on by default) and says so in its description
    (analysis.json's ``calibration.detector_context``); the calibration's head pose on the
    degraded render comes nearer the truth than without it. Measured 2026-12-06 (frame 0
    alone calibrating): the rotation 2.63 -> 1.41 deg from the truth's."""
    from myoface.analysis.camera import PinholeCamera, rotation_angle_deg
    from myoface.analysis.trackers.landmark_fit import FitTracker
    from myoface.analysis.weights import FitSettings
    from myoface.bench.headmotion import FOV_DEG, SIZE

    fm, frames, points, truth, poses, skins = degraded_smile
    cam = PinholeCamera.for_image(SIZE[0], SIZE[1], FOV_DEG)
    err, said = {}, {}
    for on in (False, True):
        an = FitTracker(fm, camera=cam, settings=FitSettings(detector_context=on), gaze=False,
                        calibration_frame=0)  # fmt: skip
        try:
            an.calibrate(frames[:NEUTRAL])
            err[on] = rotation_angle_deg(an.calibration.pose.rotation, poses[0].rotation)
            said[on] = an.describe()["calibration"].get("detector_context")
        finally:
            an.close()
    assert said[False] is None and said[True]["frames"] >= 1, said
    assert err[True] < 0.7 * err[False], err
