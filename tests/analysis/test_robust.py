"""The analysis never aborts a video: a face that leaves the frame and comes back, a hand over
the mouth, a turned head, a face that appears late."""

import csv
import json

import numpy as np
import pytest

from myoface.cli import main
from tests.conftest import needs_mediapipe, shared_path

#: the synthetic video: the image content shifted right by this many px per frame. The face
#: (about 140 px wide, centred in the 240 px frame) slides out past the right border, is gone
#: (200-240 px), and comes back to where it started
SHIFTS = [0, 0, 0, 0, 20, 60, 120, 200, 240, 240, 200, 120, 60, 20, 0, 0, 0, 0]
WIDTH, HEIGHT, FPS = 240, 160, 10
#: the muscles that move in it, and their contractions (a smile that rises and falls, the
#: brows raised slowly throughout)
MOVING = ("zygomaticus_major_l", "zygomaticus_major_r", "frontalis_major_l", "frontalis_major_r")
#: frames the face is out of (its centre past the right border)
GONE = [k for k, s in enumerate(SHIFTS) if s >= 200]
#: frames after its return, back in place
BACK = [k for k, s in enumerate(SHIFTS) if s == 0 and k > max(GONE)]
#: how close the contractions of the frames after the return must be to the truth. The closed
#: loop bounds the snakes' worst per-muscle RMSE without analysis by synthesis at 0.08 (256 px,
#: BENCHMARKS.md, depressor labii inferioris; the muscles moved here are within 0.02 there);
#: this face is ~140 px tall, so the same tracking error in pixels is ~1.8x as much contraction
#: as there (0.02 -> 0.036), and the CLI corrects once through the tissue where the closed loop
#: corrects twice: 0.08. Measured when written: at most 0.04 (the brows, 0.43 for 0.47).
TOLERANCE = 0.08


def _truth(n: int) -> np.ndarray:
    t = np.linspace(0.0, 1.0, n)
    smile = 0.8 * np.sin(np.pi * t) ** 2
    out = np.stack([smile, smile, 0.5 * t, 0.5 * t], axis=1)
    out[0] = 0.0
    return out


def _shifted(img: np.ndarray, dx: int) -> np.ndarray:
    """``img`` moved right by ``dx`` px, the background (its first column) filling in."""
    if dx == 0:
        return img
    out = np.empty_like(img)
    out[:, dx:] = img[:, :-dx]
    out[:, :dx] = img[:, :1]
    return out


@pytest.fixture(scope="module")
def scene():
    from myoface.model import build_face_model
    from myoface.render import Camera, Renderer, to_srgb8
    from myoface.render.dressing import default_skin_texture

    fm = build_face_model()
    cam = Camera.front(fm.face.vertices, width=WIDTH, height=HEIGHT, fov_deg=None)
    tex = to_srgb8(default_skin_texture(fm.face, 256, makeup=True))
    return fm, cam, Renderer(fm.face, cam, texture=tex)


def _skins(fm, truth):
    state = fm.rest_state()
    for c in truth:
        state = fm.relax(dict(zip(MOVING, c, strict=True)), state).state
        yield fm.skin_vertices(state)


@pytest.fixture(scope="module")
def leaving_video(scene, tmp_path_factory):
    """The face slides out of the frame and back (:data:`SHIFTS`) while it smiles; an H.264
    video, its initial contours (the model's sections projected by the known camera) and the
    true contractions."""
    from myoface.analysis.initfiles import save_init
    from myoface.analysis.sections import project_sections
    from myoface.render import VideoWriter

    fm, cam, r = scene
    d = tmp_path_factory.mktemp("leaving")
    truth = _truth(len(SHIFTS))
    with VideoWriter(d / "leaving.mp4", fps=FPS) as vw:
        for skin, dx in zip(_skins(fm, truth), SHIFTS, strict=True):
            vw.write(_shifted(r.render(skin), dx))
    save_init(d / "init.json", project_sections(fm, cam))
    return d / "leaving.mp4", d / "init.json", truth


def _read(out):
    with open(out / "contractions.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def _values(row, names) -> np.ndarray:
    return np.array([float(row[m]) if row[m] != "" else np.nan for m in names])


@pytest.mark.slow
def test_snakes_follow_a_face_that_leaves_the_frame_and_comes_back(leaving_video, tmp_path):
    """The default tracker (snakes, contours given: no MediaPipe needed) runs to the last
    frame: the frames without the face say so with empty values, and once the face is back
    (found again by searching the frame for the calibration's eye-and-nose region) the
    contours are re-initialised at its new place and the frames are measured again."""
    from myoface.analysis.sections import PAPER_MUSCLES

    video, init, truth = leaving_video
    out = tmp_path / "out"
    assert main(["analyze", str(video), "--init", str(init), "-o", str(out), "--quiet"]) == 0
    rows = _read(out)
    assert [int(r["frame"]) for r in rows] == list(range(len(SHIFTS)))
    quality = [r["quality"] for r in rows]
    for k in GONE:
        assert quality[k] == "face_lost", quality
    for k, r in enumerate(rows):
        v = _values(r, PAPER_MUSCLES)
        if quality[k] == "ok":
            assert np.isfinite(v).all(), (k, r)
        else:  # never invented values
            assert np.isnan(v).all() and r["jaw_angle_rad"] == "", (k, r)
    assert all(quality[k] == "ok" for k in range(4)), quality  # before it leaves
    for k in BACK:
        assert quality[k] == "ok", quality
        err = np.abs(_values(rows[k], MOVING) - truth[k])
        assert err.max() < TOLERANCE, (k, _values(rows[k], MOVING), truth[k])
        # the head frame is back where it started (the content is back in place)
        assert abs(float(rows[k]["head_dx_px"])) < 1.0, rows[k]
    side = json.loads((out / "analysis.json").read_text())
    assert [f["quality"] for f in side["frames"]] == quality


@needs_mediapipe
@pytest.mark.slow
def test_landmarks_follow_a_face_that_leaves_the_frame_and_comes_back(leaving_video, tmp_path):
    """The same video with MediaPipe's face mesh on every frame: frames without a face are
    ``no_face`` with empty values, the frames after the return are measured again."""
    from myoface.analysis.sections import PAPER_MUSCLES

    video, _, truth = leaving_video
    out = tmp_path / "out"
    assert main(["analyze", str(video), "--tracker", "landmarks", "-o", str(out), "--quiet"]) == 0
    rows = _read(out)
    assert [int(r["frame"]) for r in rows] == list(range(len(SHIFTS)))
    quality = [r["quality"] for r in rows]
    for k in GONE:
        assert quality[k] == "no_face", quality
    for k, r in enumerate(rows):
        v = _values(r, PAPER_MUSCLES)
        assert np.isfinite(v).all() if quality[k] == "ok" else np.isnan(v).all(), (k, r)
    for k in BACK:
        assert quality[k] == "ok", quality
    # measured again, and as well as before the face left. The landmark tracker's error on
    # this face is its own (on the frames before the face left, up to 0.49 for the zygomatic
    # majors, 0.2 on average; the closed loop's RMSE 0.11-0.14): the mean error after the
    # return is within half as much again of the mean before it (measured when written: 0.26
    # after, 0.20 before)
    z = [j for j, m in enumerate(MOVING) if m.startswith("zygomaticus")]
    before = [k for k in range(min(GONE)) if quality[k] == "ok"]

    def mean_error(ks):
        return np.mean([np.abs(_values(rows[k], MOVING)[z] - truth[k, z]) for k in ks])

    assert len(before) >= 4 and mean_error(BACK) < 1.5 * mean_error(before) + 0.05


def _analyze_frames(fm, init, frames):
    from myoface.analysis.trackers.snakes import Analyzer

    an = Analyzer(fm, init)
    try:
        return an, [an.measure(f, k) for k, f in enumerate(frames)]
    finally:
        an.close()


@pytest.mark.slow
def test_a_hand_over_the_mouth_is_reported_and_the_lips_found_again(scene):
    """A flat, skin-coloured "hand" covers the mouth for five frames: the lips' contour loses
    its edge (``escaped:lips``, empty values) and is put back where the model predicts the lips
    at the last estimate; when the hand goes, the frames are measured again."""
    from myoface.analysis.sections import project_sections

    fm, cam, r = scene
    init = project_sections(fm, cam)
    cx, cy = init["lips"].mean(axis=0)
    yy, xx = np.mgrid[0:HEIGHT, 0:WIDTH]
    hand = ((xx - cx - 5) / 45) ** 2 + ((yy - cy - 8) / 22) ** 2 < 1
    n = 14
    truth = _truth(n)
    frames = []
    for k, skin in enumerate(_skins(fm, truth)):
        img = r.render(skin)
        if 5 <= k <= 9:
            img = img.copy()
            img[hand] = (205, 160, 140)
        frames.append(img)
    an, ms = _analyze_frames(fm, init, frames)
    quality = [m.quality for m in ms]
    assert all(quality[k] == "escaped:lips" for k in range(5, 10)), quality
    assert all(np.isnan(ms[k].contractions).all() for k in range(5, 10))
    assert all(q == "ok" for q in quality[:5] + quality[10:]), quality
    cols = [an.ids.index(m) for m in MOVING]
    for k in range(10, n):
        err = np.abs(ms[k].contractions[cols] - truth[k])
        assert err.max() < TOLERANCE, (k, ms[k].contractions[cols], truth[k])


@pytest.mark.slow
def test_a_turned_head_is_not_read_as_muscle_action(scene):
    """The head turns about its vertical axis (0, 6, 12, 18, 24, 18, 12, 6, 0 degrees): the
    2-D analysis would read the foreshortened face as an asymmetric smile, so frames turned
    past about 10 degrees are ``head_turned`` (or lost), with empty values; the frontal frames
    before and after are measured."""
    from myoface.analysis.sections import project_sections

    fm, cam, r = scene
    init = project_sections(fm, cam)
    yaw_deg = [0, 0, 0, 6, 12, 18, 24, 18, 12, 6, 0, 0, 0]
    truth = _truth(len(yaw_deg))
    frames = []
    for skin, deg in zip(_skins(fm, truth), yaw_deg, strict=True):
        a = np.radians(deg)
        rot = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
        c = skin.mean(axis=0)
        frames.append(r.render((skin - c) @ rot.T + c))
    _, ms = _analyze_frames(fm, init, frames)
    quality = [m.quality for m in ms]
    for k, deg in enumerate(yaw_deg):
        if deg >= 18:
            assert quality[k] != "ok" and np.isnan(ms[k].contractions).all(), quality
        if deg == 0:
            assert quality[k] == "ok", quality


@needs_mediapipe
@pytest.mark.shared_data
@pytest.mark.slow
def test_a_face_that_appears_late_is_waited_for(tmp_path, capsys):
    """``noface_face.mov``: ~4 s of a cartoon title, then a face, then a black frame. Both
    trackers calibrate on the first frame with a face (the automatic initialisation searches
    the whole video, with a progress bar), measure the face, and report the frames without
    one with empty values."""
    from myoface.analysis.pipeline import Tracking, make_analyzer
    from myoface.analysis.video import open_video
    from myoface.facemesh import FaceMeshDetector
    from myoface.model import build_face_model

    path = shared_path("video", "noface_face.mov")
    video = open_video(path)
    first = None
    with FaceMeshDetector(video=False) as det:
        for k, frame in enumerate(video):
            if det.detect(frame) is not None:
                first = k
                break
    assert first is not None and first > 30  # later than the old search limit
    # the search shows its progress when asked
    an, at = make_analyzer(build_face_model(), video, show_progress=True)
    run = Tracking(video, an, at, max_frames=1)
    try:
        assert [m.index for _, m in run] == [first]
    finally:
        an.close()
    assert run.start == first and f"frame {first}" in an.describe()["init"]
    assert "searching for a face" in capsys.readouterr().err
    for tracker, missing in (("snakes", "face_lost"), ("landmarks", "no_face")):
        out = tmp_path / tracker
        assert main(["analyze", str(path), "--tracker", tracker, "-o", str(out), "--quiet"]) == 0
        side = json.loads((out / "analysis.json").read_text())
        rows = _read(out)
        frames = [int(r["frame"]) for r in rows]
        assert frames[-1] == video.n_frames - 1  # to the last frame
        quality = {int(r["frame"]): r["quality"] for r in rows}
        if tracker == "snakes":
            assert side["calibration_frame"] == first and frames[0] == first
        else:  # every frame, the ones before the face unmeasured
            assert frames[0] == 0 and all(quality[k] == "no_face" for k in range(first))
        assert quality[first] == "ok"
        assert quality[video.n_frames - 1] == missing  # the black frame
        measured = [k for k in range(first, video.n_frames) if quality[k] == "ok"]
        assert len(measured) >= 0.9 * (video.n_frames - 1 - first), quality
