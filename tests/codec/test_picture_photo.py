"""``myoface synth --in-photo``: the person's own photo animated, end to end from the command
line (MediaPipe finds the face; the sample video's first frame, made small, is the photo)."""

from __future__ import annotations

import numpy as np
import pytest

from myoface.cli import main
from tests.conftest import needs_mediapipe, shared_path


@pytest.fixture(scope="module")
def photo(tmp_path_factory):
    import cv2

    from myoface.analysis.video import open_video
    from myoface.render import write_image

    video = shared_path("video", "single_face.mp4")
    frame = next(iter(open_video(video)))
    small = cv2.resize(frame, (320, 180), interpolation=cv2.INTER_AREA)
    path = tmp_path_factory.mktemp("photo") / "person.png"
    write_image(path, small)
    return path, small


@needs_mediapipe
def test_photo_smiles_talks_and_its_background_stays(photo, tmp_path, capsys):
    import imageio.v3 as iio

    path, small = photo
    out = tmp_path / "talk.png"
    assert main(["synth", "--in-photo", str(path), "--viseme", "A", "-o", str(out)]) == 0
    said = capsys.readouterr().out
    assert "made from the photo" in said and f"wrote {out}" in said
    img = iio.imread(out)
    assert img.shape == small.shape
    diff = np.abs(img.astype(int) - small).sum(axis=2)
    # the face changed (the mouth opened: the model's mouth inside it) ...
    assert (diff > 30).sum() > 100
    # ... the picture's left and right fifths (the room) did not
    assert (diff[:, :64] == 0).all() and (diff[:, -64:] == 0).all()
    # a video of a blink: every frame the photo's size, the first the photo itself
    video = tmp_path / "blink.mp4"
    argv = ["synth", "--in-photo", str(path), "--au", "45=1", "--duration", "0.4", "--fps", "10"]
    assert main([*argv, "-o", str(video), "--quiet"]) == 0
    from myoface.analysis.video import open_video

    frames = np.array(list(open_video(video)))
    assert frames.shape[1:] == small.shape and len(frames) == 10
    assert np.abs(frames[0].astype(int) - small).mean() < 3.0  # H.264's own change
    # the apex (mid-video): the eyes shut, darker lashes over the eye, the room unchanged
    mid = frames[len(frames) // 2].astype(int)
    assert np.abs(mid - frames[0]).max() > 40


def test_photo_bad_input_is_one_line(tmp_path, capsys):
    out = tmp_path / "x.png"
    assert main(["synth", "--in-photo", str(tmp_path / "none.jpg"), "-o", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no such photo" in err[0]
    (tmp_path / "p.png").write_bytes(b"")
    argv = ["synth", "--in-photo", str(tmp_path / "p.png"), "--texture", "t.png", "-o", str(out)]
    assert main(argv) in (1, 2)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert not out.exists()
