"""README's Quickstart has exactly two commands, and CI runs the second one verbatim."""

import re

import numpy as np
import pytest

from tests.conftest import REPO, _mediapipe_available, shared_path


def quickstart_commands():
    text = (REPO / "README.md").read_text()
    section = text.split("## Quickstart", 1)[1].split("\n## ", 1)[0]
    return [m.strip() for m in re.findall(r"^    (\S.*)$", section, flags=re.M)]


def test_quickstart_has_two_commands():
    cmds = quickstart_commands()
    assert cmds == [
        'pip install -e ".[mediapipe]" && myoface demo',
        'pip install -e ".[test]" && pytest',
    ]


def test_ci_runs_the_readme_test_command():
    ci = (REPO / ".ci" / "run").read_text().splitlines()
    assert quickstart_commands()[1] in [line.strip() for line in ci]


def test_readme_python_examples_run(tmp_path, monkeypatch):
    """Every example of README's Python section runs, in order, as a user would paste them;
    the analysis example on the first frames of the real sample video."""
    text = (REPO / "README.md").read_text()
    block = text.split("## The face model in a few lines of Python", 1)[1].split("\n## ", 1)[0]
    codes = re.findall(r"```python\n(.*?)```", block, flags=re.S)
    assert len(codes) == 4
    monkeypatch.chdir(tmp_path)
    env: dict = {}
    for code in codes[:3]:
        exec(compile(code, "README.md", "exec"), env)
    import imageio.v3 as iio

    img = iio.imread(tmp_path / "smile.png")
    assert img.shape == (512, 512, 3)
    video = iio.imread(tmp_path / "surprise.mp4", plugin="pyav")
    assert video.shape == (25, 256, 256, 3)
    # the surprise grows: the last frame differs from the first where the brows rise
    assert np.abs(video[-1].astype(int) - video[0]).max() > 40
    assert env["sim"].skin.shape == (3, 468, 3)

    video_path = shared_path("video", "single_face.mp4")
    if not _mediapipe_available():
        pytest.skip("MediaPipe is not installed")
    frames = iio.imread(video_path, plugin="pyav")[:8]
    iio.imwrite(tmp_path / "face.mp4", frames, plugin="pyav", codec="libx264", fps=24)
    exec(compile(codes[3], "README.md", "exec"), env)
    result = env["result"]
    assert result.contractions.shape == (8, len(result.ids))
    assert result.quality.count("ok") == 8


def test_readme_analysis_stages_example_runs(tmp_path, monkeypatch, capsys):
    """The analysis section's stage-by-stage example, on the first frames of the sample video."""
    text = (REPO / "README.md").read_text()
    block = text.split("### The analysis in Python, stage by stage", 1)[1].split("\n#", 1)[0]
    (code,) = re.findall(r"```python\n(.*?)```", block, flags=re.S)
    video_path = shared_path("video", "single_face.mp4")
    if not _mediapipe_available():
        pytest.skip("MediaPipe is not installed")
    import imageio.v3 as iio

    frames = iio.imread(video_path, plugin="pyav")[:12]
    iio.imwrite(tmp_path / "clip.mp4", frames, plugin="pyav", codec="libx264", fps=30)
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "README.md", "exec"), {})
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 12 and all(" ok {" in line for line in lines)
