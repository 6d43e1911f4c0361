"""``--photometric`` / ``--no-photometric`` (``myoface analyze``, ``myoface batch``): the 3-D
fit's photometric term (:attr:`~myoface.analysis.weights.FitSettings.photometric`), on by
default with the 3-D fit since 2026-12-05 and switched off from the command line; refused
where there is no 3-D fit (the snakes, ``--estimator paper``), where the default is off."""

import json
from types import SimpleNamespace

import numpy as np
import pytest

from myoface.cli import main
from myoface.errors import MyofaceValueError
from tests.conftest import needs_mediapipe, shared_path

SNAKES = (
    "--photometric is a term of the landmark tracker's 3-D fit; use it with --tracker landmarks"
)
PAPER = "--photometric is for the 3-D fit, not --estimator paper"


def _settings(*argv):
    from myoface.cli import build_parser
    from myoface.commands._common import analysis_settings

    return analysis_settings(build_parser().parse_args(["analyze", "v.mp4", "-o", "o", *argv]))


def test_the_option_reads_back_and_is_the_fits():
    assert _settings("--tracker", "landmarks", "--photometric")["photometric"] is True
    assert _settings("--tracker", "landmarks")["photometric"] is True  # (the default)
    assert _settings()["photometric"] is True
    assert _settings("--no-photometric")["photometric"] is False
    assert _settings("--tracker", "landmarks", "--estimator", "fit-synthesis")["photometric"]
    # where there is no 3-D fit the default is off, and --no-photometric is accepted
    for argv in (("--tracker", "snakes"), ("--tracker", "landmarks", "--estimator", "paper")):
        assert _settings(*argv)["photometric"] is False
        assert _settings(*argv, "--no-photometric")["photometric"] is False
    assert _settings("--photometric")["tracker"] == "landmarks"  # (the default tracker)
    with pytest.raises(MyofaceValueError) as e:
        _settings("--tracker", "snakes", "--photometric")
    assert str(e.value) == SNAKES
    for est in ("paper", "fiducials"):
        with pytest.raises(MyofaceValueError) as e:
            _settings("--tracker", "landmarks", "--estimator", est, "--photometric")
        assert str(e.value) == PAPER


def test_make_analyzer_gives_the_fit_the_setting(monkeypatch):
    """make_analyzer (the code path of analyze and of batch's workers) builds the FitTracker
    with FitSettings(photometric=...), the refine given kept beside it."""
    from myoface.analysis import pipeline

    made = []
    monkeypatch.setattr(pipeline, "FitTracker", lambda model, **kw: made.append(kw) or "fit")
    video = SimpleNamespace(n_frames=10, fps=25.0)
    for photometric in (True, False, None):
        an, first = pipeline.make_analyzer(
            None, video, "landmarks", calibration_frame=None, refine=2, photometric=photometric
        )
        assert (an, first) == ("fit", 0)
    # (None, the default: on with the 3-D fit)
    assert [kw["settings"].photometric for kw in made] == [True, False, True]
    assert [kw["settings"].refine for kw in made] == [2, 2, 2]
    assert made[0]["fps"] == 25.0 and made[0]["synthesis"] is False
    with pytest.raises(MyofaceValueError, match="--photometric is a term"):
        pipeline.make_analyzer(None, video, "snakes", photometric=True)
    with pytest.raises(MyofaceValueError, match="not --estimator paper"):
        pipeline.make_analyzer(None, video, "landmarks", estimator="paper", photometric=True)
    assert len(made) == 3


def test_batch_refuses_it_before_any_video_is_analysed(tmp_path, capsys):
    from myoface.analysis.batch import run_batch
    from myoface.render import VideoWriter

    video = tmp_path / "grey.mp4"
    with VideoWriter(video, fps=10) as vw:
        for _ in range(2):
            vw.write(np.full((64, 64, 3), 128, np.uint8))
    out = tmp_path / "out"
    paper = ["--tracker", "landmarks", "--estimator", "paper", "--photometric"]
    snakes = ["--tracker", "snakes", "--photometric"]
    for argv, why in ((snakes, SNAKES), (paper, PAPER)):
        assert main(["analyze", str(video), "-o", str(out), *argv, "--quiet"]) == 1
        assert capsys.readouterr().err.strip().splitlines() == [f"myoface analyze: error: {why}"]
        assert main(["batch", str(video), "-o", str(out), *argv, "--quiet"]) == 1
        assert capsys.readouterr().err.strip().splitlines() == [f"myoface batch: error: {why}"]
        assert not out.exists()
    with pytest.raises(MyofaceValueError, match="--photometric is a term"):
        run_batch([video], out, photometric=True)
    with pytest.raises(MyofaceValueError, match="True, False or None"):
        run_batch([video], out, tracker="landmarks", photometric=1)
    assert not out.exists()


@needs_mediapipe
@pytest.mark.shared_data
@pytest.mark.slow  # 7.5-9 s on a loaded 2-core machine: the model, four short analyses
def test_analyze_and_batch_with_photometric_on_the_sample_video(tmp_path):
    """Four frames of single_face.mp4, calibrated on frame 0: with --photometric (the
    default) every frame is measured, analysis.json records the fit's settings with the term
    on, and the contractions differ from --no-photometric's on the same frames (the term
    acts; measured
    2026-12-01: the largest difference over the muscles and the jaw 0 on the calibration
    frame, 0.033, 0.089 and 0.145 on frames 1-3); batch records it in done.json and gives its
    worker the same analysis."""
    import csv

    video = shared_path("video", "single_face.mp4")
    argv = ["--tracker", "landmarks", "--max-frames", "4", "--calibration-frame", "0", "--quiet"]

    def analysed(folder):
        doc = json.loads((folder / "analysis.json").read_text())
        with open(folder / "contractions.csv", newline="") as fh:
            rows = list(csv.DictReader(fh))
        assert [r["quality"] for r in rows] == ["ok"] * 4, rows
        skip = ("frame", "time_s", "quality", "residual_mm")
        # (the expression columns, expr_* and the label, are not contractions)
        skip += ("expression",)
        muscles = [
            k for k in rows[0] if k not in skip and not k.startswith(("head_", "gaze_", "expr_"))
        ]
        return doc, np.array([[float(r[k]) for k in muscles] for r in rows])

    assert main(["analyze", str(video), "-o", str(tmp_path / "photo"), *argv, "--photometric"]) == 0
    assert main(["analyze", str(video), "-o", str(tmp_path / "default"), *argv,
                 "--no-photometric"]) == 0  # fmt: skip
    assert main(["analyze", str(video), "-o", str(tmp_path / "implied"), *argv]) == 0
    doc, photo = analysed(tmp_path / "photo")
    doc0, default = analysed(tmp_path / "default")
    doc1, implied = analysed(tmp_path / "implied")  # (the default: the same as --photometric)
    assert doc1["fit_settings"] == doc["fit_settings"]
    np.testing.assert_allclose(implied, photo, atol=1e-9)
    assert doc["fit_settings"]["photometric"] is True
    assert doc0["fit_settings"]["photometric"] is False
    assert {k: v for k, v in doc["fit_settings"].items() if k != "photometric"} == {
        k: v for k, v in doc0["fit_settings"].items() if k != "photometric"
    }
    assert np.isfinite(photo).all()
    # the calibration frame: neutral in both (every contraction below 0.01: the default fit
    # leaves a muscle at 0.0003-0.0023 there from the landmarks' scatter, 2026-12-02)
    assert np.abs(photo[0]).max() < 0.01 and np.abs(default[0]).max() < 0.01, (photo[0], default[0])
    assert np.abs(photo[1:] - default[1:]).max() > 0.01

    out = tmp_path / "batch"
    assert (
        main(["batch", str(video), "-o", str(out), "--workers", "1", *argv, "--photometric"]) == 0
    )
    done = json.loads((out / "single_face" / "done.json").read_text())["settings"]
    assert done["photometric"] is True and done["tracker"] == "landmarks"
    batch_doc, batch = analysed(out / "single_face")
    assert batch_doc["fit_settings"] == doc["fit_settings"]
    np.testing.assert_allclose(batch, photo, atol=1e-4)


def test_two_pass_is_refused_without_the_photometric_fit(tmp_path, capsys):
    """``myoface analyze --two-pass`` registers the photometric fit's appearance: refused
    with MediaPipe's points alone and with the snakes, before anything is analysed."""
    from myoface.render import VideoWriter

    video = tmp_path / "grey.mp4"
    with VideoWriter(video, fps=10) as vw:
        for _ in range(2):
            vw.write(np.full((64, 64, 3), 128, np.uint8))
    out = tmp_path / "out"
    why = "--two-pass is for the landmarks' 3-D fit with its photometric term"
    for argv in (["--no-photometric"], ["--tracker", "snakes"]):
        assert main(["analyze", str(video), "-o", str(out), "--two-pass", *argv, "--quiet"]) == 1
        assert capsys.readouterr().err.strip().splitlines()[-1] == f"myoface analyze: error: {why}"
        assert not out.exists()


@needs_mediapipe
@pytest.mark.shared_data
@pytest.mark.slow  # ~15 s on a loaded 2-core machine: the model, three passes of 20 frames
def test_two_pass_registers_the_appearance_on_the_first_pass_neutral_frames(tmp_path):
    """``--two-pass`` on single_face.mp4's first 20 frames (at rest until frame 18): the
    appearance is registered on the first pass's frames labelled neutral, spread over the
    video (:func:`~myoface.analysis.pipeline.neutral_frames_of`, the same frames when the
    first pass is run again), and every frame is measured."""
    import csv

    from myoface.analysis.pipeline import make_analyzer, neutral_frames_of
    from myoface.analysis.video import open_video
    from myoface.model import load_face_model

    video = shared_path("video", "single_face.mp4")
    out = tmp_path / "two"
    assert main(["analyze", str(video), "-o", str(out), "--two-pass", "--max-frames", "20",
                 "--quiet"]) == 0  # fmt: skip
    doc = json.loads((out / "analysis.json").read_text())
    with open(out / "contractions.csv", newline="") as fh:
        assert [r["quality"] for r in csv.DictReader(fh)] == ["ok"] * 20
    model = load_face_model(None)
    an, first = make_analyzer(model, open_video(video), "landmarks", calibration_frame=None)
    views = neutral_frames_of(open_video(video), an, first, max_frames=20)
    cal = doc["calibration_frame"]
    assert 6 <= len(views) <= 12 and min(views) >= 2  # (three neutral frames running)
    assert doc["calibration"]["appearance_registered_on"] == [cal] + [
        k for k in sorted(views) if k != cal
    ]
