"""``myoface synth`` and ``myoface demo`` from the command line."""

import numpy as np
import pytest

from myoface.cli import main
from tests.conftest import REPO


def one_line_error(capsys, argv, match):
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and match in err[0], err


def test_synth_png_from_aus(tmp_path, capsys):
    import imageio.v3 as iio

    out = tmp_path / "smile.png"
    assert (
        main(
            [
                "synth",
                "--au",
                "12=0.7",
                "--au",
                "6=0.4",
                "-o",
                str(out),
                "--width",
                "96",
                "--height",
                "96",
                "--ssaa",
                "1",
            ]
        )
        == 0
    )
    img = iio.imread(out)
    assert img.shape == (96, 96, 3) and img.std() > 10


def test_synth_video_expression_and_timeline(tmp_path, capsys):
    import imageio.v3 as iio

    out = tmp_path / "s.mp4"
    assert (
        main(
            [
                "synth",
                "--expression",
                "surprise",
                "--intensity",
                "0.8",
                "--duration",
                "0.4",
                "--fps",
                "10",
                "-o",
                str(out),
                "--width",
                "64",
                "--height",
                "64",
                "--quiet",
            ]
        )
        == 0
    )
    frames = iio.imread(out, plugin="pyav")
    assert frames.shape[0] == int(round((0.4 + 0.5) * 10)) + 1
    mid, first = frames[len(frames) // 2].astype(int), frames[0].astype(int)
    assert np.abs(mid - first).mean() > 0.5  # the face moved
    out2 = tmp_path / "talk.mp4"
    assert (
        main(
            [
                "synth",
                "--timeline",
                str(REPO / "examples" / "talk.toml"),
                "--fps",
                "5",
                "-o",
                str(out2),
                "--width",
                "48",
                "--height",
                "48",
                "--quiet",
            ]
        )
        == 0
    )
    assert out2.stat().st_size > 0


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        (["--au", "3=0.5"], "unknown action unit AU3"),
        (["--au", "12=3"], "must be in [0, 1]; got '3'"),
        (["--expression", "joy"], "unknown expression 'joy'"),
        (["--muscle", "zygomaticus=2"], "must be in [0, 1]"),
        (["--au", "12=0.5", "--texture", "/nonexistent/skin.png"], "no such texture image"),
        ([], "nothing to show"),
    ],
)
def test_synth_bad_input(tmp_path, capsys, extra, match):
    out = tmp_path / "x.png"
    one_line_error(
        capsys, ["synth", *extra, "-o", str(out), "--width", "32", "--height", "32"], match
    )
    assert not out.exists() and not list(tmp_path.iterdir())


def test_synth_unwritable_output(tmp_path, capsys):
    one_line_error(
        capsys,
        ["synth", "--au", "12=0.5", "-o", str(tmp_path / "no" / "x.png")],
        "output folder does not exist",
    )


def test_demo_smoke(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "-o", str(out), "--size", "64", "--no-video", "--quiet"]) == 0
    assert (out / "expressions.png").stat().st_size > 1000
    assert (out / "muscles.png").exists()
    text = capsys.readouterr().out
    assert str(out.resolve()) in text
    ana = out / "analysis"
    assert (ana / "resynth.mp4").stat().st_size > 1000
    if "analysing the sample face video" in text:  # the real video (else the synthetic one)
        assert (ana / "person.myoface").is_file() and (ana / "resynth_person.mp4").is_file()
