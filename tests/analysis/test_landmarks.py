"""The landmark tracker and automatic initialisation (MediaPipe's face mesh, an optional extra),
and the acceptance test on the real face video (neutral -> smile -> neutral)."""

import numpy as np
import pytest

from myoface.analysis.landmarks import contours_from_landmarks, fit_similarity, rigid_vertices
from myoface.errors import MyofaceValueError
from tests.conftest import needs_mediapipe, shared_path


def test_fit_similarity_recovers_a_known_map():
    rng = np.random.default_rng(1)
    src = rng.normal(size=(30, 2)) * 20
    s_true = 1.3 * np.exp(1j * 0.2)
    z = (src[:, 0] + 1j * src[:, 1]) * s_true + (5 - 7j)
    dst = np.stack([z.real, z.imag], axis=1)
    s, ms, md = fit_similarity(src, dst)
    assert abs(s - s_true) < 1e-12
    zs = (src[:, 0] - ms[0] + 1j * (src[:, 1] - ms[1])) * s + (md[0] + 1j * md[1])
    assert np.allclose(np.stack([zs.real, zs.imag], 1), dst)
    with pytest.raises(MyofaceValueError, match="degenerate"):
        fit_similarity(np.ones((4, 2)), dst[:4])


def test_rigid_vertices_leave_out_what_muscles_move():
    from myoface.analysis.sections import model_fiducials
    from myoface.model import build_face_model

    fm = build_face_model()
    rigid = set(rigid_vertices(fm).tolist())
    assert len(rigid) >= 20  # enough points for a stable similarity fit
    moving = {
        f.vertex
        for f in model_fiducials(fm.face)
        if isinstance(f.vertex, int) and f.name.startswith(("lips", "chin", "eyebrow"))
    }
    assert not rigid & moving


def test_contours_from_landmarks_checks_the_topology(default_face):
    pts = default_face.vertices[:, :2] * np.array([10.0, -10.0]) + 300
    c = contours_from_landmarks(default_face, pts)
    assert "lips" in c and "hairline" not in c
    with pytest.raises(MyofaceValueError, match="468"):
        contours_from_landmarks(default_face, pts[:100])


@pytest.fixture(scope="module")
def real_video():
    import imageio.v3 as iio

    return iio.imread(shared_path("video", "single_face.mp4"), plugin="pyav")


def assert_smile(c: np.ndarray, ids: list) -> None:
    """Contractions (T, M) of the sample video: the zygomatic majors rise clearly in the smile
    (frames 25-65) and fall at the end; the frontalis stays low throughout. (Rows of NaN:
    frames not measured.)"""
    for s in "lr":
        z = c[:, ids.index(f"zygomaticus_major_{s}")]
        before, smile = np.nanmean(z[:15]), np.nanmean(z[25:65])
        last = z[np.isfinite(z)][-1]
        assert smile > 0.6 and smile > before + 0.5, (before, smile)
        assert last < smile - 0.3, (last, smile)
    brows = c[:, [i for i, m in enumerate(ids) if m.startswith("frontalis")]]
    top, mean = np.nanmax(brows), np.nanmean(brows)
    assert top < 0.5 and mean < 0.15, (top, mean)


@needs_mediapipe
@pytest.mark.shared_data
@pytest.mark.slow
def test_real_video_smile_with_the_landmark_tracker(real_video):
    """The sample video: neutral for ~17 frames, a broad smile from frame ~20 to ~68, back to
    neutral on the last frames (70-71). Zygomaticus major must rise clearly in the smile and
    fall at the end; the brows do not move in this video, so the frontalis must stay low.
    Measured when written: zygomatic majors 0.05-0.1 before, 1.0 during, 0.44 on the last
    frame; frontalis at most 0.39 (the right major belly, frames 5-18), mean 0.06."""
    from myoface.analysis.trackers.landmark_paper import PaperLandmarkTracker
    from myoface.model import build_face_model

    fm = build_face_model()
    an = PaperLandmarkTracker(fm)
    try:
        ms = [an.measure(f, k, k / 30) for k, f in enumerate(real_video)]
    finally:
        an.close()
    assert all(m.quality == "ok" for m in ms)
    assert_smile(np.array([m.contractions for m in ms]), list(an.ids))
    # the head frame: the scale stays near 1 (the subject barely moves toward the camera)
    assert all(abs(m.head_scale - 1) < 0.05 for m in ms)


@needs_mediapipe
@pytest.mark.shared_data
@pytest.mark.slow
@pytest.mark.xfail(
    strict=True,
    reason=(
        "known regression of the depressor labii inferioris as a sheet (2026-12-02): the "
        "snakes' lips contour sits on the teeth of the open smile (tools/snake_lips.py: top "
        "5.7 px below the upper lip's border, bottom 12.6 px above the lower lip's) and the "
        "curve fit explains it with the sheet, reading the smile's zygomatic majors at "
        "0.27-0.33; the lips' colour layer (Analyzer(mouth_colour=True), opt-in) reads them at "
        "0.92 but holds the left one at 0.62 on the last frame and weakens the fiducial "
        "estimator on the synthetic smile of test_cli_analyze (correlation 0.67 < 0.7)"
    ),
)
def test_real_video_smile_with_the_snakes(real_video):
    """The same video through the paper's tracker: snakes on the nine contours (initialised
    from MediaPipe on the first frame), the curve fit and the second pass from the model's
    prediction. Measured when written: zygomatic majors 0.00 before, 0.95-0.98 during the
    smile, 0.30-0.40 on the last frame; frontalis at most 0.32 (the right inner belly, before
    the smile), mean 0.02. The tracker's own check may set a frame or two of the smile aside
    (``misfit``: a contour farther than MISFIT_MM from any shape the model takes): since
    68c6775 the eyebrow and nasolabial contours' worst residuals in the smile are 4.7-5.0 mm,
    and the snakes, which settle on the nearest strong edge, go past 6 mm on one or two frames
    in some runs (frames 47 and 57 in one full test run, none when the test runs alone, none in
    another full run; why runs differ is not known: nothing on this path is threaded, and we
    suspect last-bit differences, e.g. of numpy's reductions with memory alignment, which the
    snakes' choice of edge amplifies)."""
    from myoface.analysis.landmarks import auto_init
    from myoface.analysis.trackers.snakes import Analyzer
    from myoface.model import build_face_model

    fm = build_face_model()
    k0, _, init, _ = auto_init(iter(real_video), fm.face)
    an = Analyzer(fm, init)
    ms = [an.measure(f, k, k / 30) for k, f in enumerate(real_video[k0:], start=k0)]
    bad = [(m.index, m.quality) for m in ms if m.quality != "ok"]
    assert len(bad) <= 3 and all(q.startswith("misfit:") for _, q in bad), bad
    assert_smile(np.array([m.contractions for m in ms]), list(an.ids))


@needs_mediapipe
@pytest.mark.shared_data
def test_no_face_video_fails_cleanly(tmp_path, capsys):
    from myoface.cli import main

    video = shared_path("video", "no_face.mp4")
    for tracker in ("snakes", "landmarks"):
        out = tmp_path / tracker
        argv = ["analyze", str(video), "-o", str(out), "--tracker", tracker, "--quiet"]
        assert main(argv) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "face" in err[0], err
        assert not out.exists()


@needs_mediapipe
@pytest.mark.shared_data
@pytest.mark.slow
def test_analyze_real_video_with_automatic_init(tmp_path, capsys):
    import csv
    import json

    from myoface.cli import main

    video = shared_path("video", "single_face.mp4")
    out = tmp_path / "auto"
    argv = ["analyze", str(video), "-o", str(out), "--max-frames", "6", "--quiet"]
    assert main([*argv, "--tracker", "snakes"]) == 0
    side = json.loads((out / "analysis.json").read_text())
    assert side["tracker"] == "snakes" and side["init"].startswith("automatic")
    with open(out / "contractions.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 6 and {"head_scale", "head_rot_deg", "jaw_angle_rad"} <= set(rows[0])
    # --init belongs to the snakes
    assert (
        main(
            [
                "analyze",
                str(video),
                "-o",
                str(tmp_path / "x"),
                "--tracker",
                "landmarks",
                "--init",
                "i.json",
            ]
        )
        == 1
    )
    assert "--init is for the snakes" in capsys.readouterr().err
