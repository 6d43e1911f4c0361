"""VideoWriter's background encoding: the same file as in the caller's thread, errors reach the
caller, nothing is left behind on failure."""

import numpy as np
import pytest

from myoface.errors import MyofaceValueError
from myoface.render import VideoWriter


def _frames(n=12, h=48, w=64):
    rng = np.random.default_rng(0)
    base = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    return [np.roll(base, 3 * k, axis=1) for k in range(n)]


def test_background_writes_the_same_file(tmp_path):
    import imageio.v3 as iio

    for bg in (False, True):
        frames = _frames()
        with VideoWriter(tmp_path / f"{bg}.mp4", fps=12, background=bg) as vw:
            for f in frames:
                vw.write(f)
                f[:] = 0  # the writer copied the frame: the caller may reuse its array
        assert vw.n_frames == len(vw.encode_ms) == len(frames)
    a = iio.imread(tmp_path / "False.mp4", plugin="pyav")
    b = iio.imread(tmp_path / "True.mp4", plugin="pyav")
    assert a.shape == (len(frames), 48, 64, 3) and a.mean() > 60  # not the zeroed arrays
    np.testing.assert_array_equal(a, b)


def _face_like_frames(n=4, size=64):
    """Smooth shading with a little sensor noise: what a small render looks like to x264."""
    rng = np.random.default_rng(1)
    yy, xx = np.mgrid[0:size, 0:size]
    out = []
    for k in range(n):
        img = np.stack(
            [
                128 + 60 * np.sin((xx + 3 * k) / 9.0) * np.cos(yy / 13.0),
                100 + 50 * np.cos((yy - 2 * k) / 7.0),
                90 + 40 * np.sin((xx + yy + k) / 11.0),
            ],
            -1,
        )
        out.append(np.clip(img + rng.normal(0, 6, img.shape), 0, 255).astype(np.uint8))
    return out


def test_same_frames_give_the_same_file_whatever_came_before(tmp_path):
    """The same frames, encoded again and again in one process with other allocations in
    between, give one file: libx264's AVX-512 code made the bytes depend on the heap's old
    contents (2-6 distinct files in 40 encodes on an AVX-512 CPU before the cap)."""
    frames = _face_like_frames()
    rng = np.random.default_rng(2)
    junk = []
    files = set()
    for k in range(24):
        junk.append(bytearray(int(rng.integers(1, 400_000))))  # stir the heap
        if len(junk) > 12:
            junk.pop(int(rng.integers(len(junk))))
        path = tmp_path / f"{k}.mp4"
        with VideoWriter(path, fps=10, background=bool(k % 2)) as vw:
            for f in frames:
                vw.write(f)
        files.add(path.read_bytes())
    assert len(files) == 1


def test_background_encoder_error_reaches_the_caller(tmp_path):
    path = tmp_path / "v.mp4"
    vw = VideoWriter(path, fps=12, background=True)
    calls = []

    def broken(vf):
        calls.append(vf)
        if len(calls) == 3:
            raise RuntimeError("encoder failed")

    vw._encode = broken  # the background thread encodes through this
    with pytest.raises(RuntimeError, match="encoder failed"), vw:
        for f in _frames(40):
            vw.write(f)
    assert not path.exists() and not list(tmp_path.iterdir())


def test_background_abandoned_on_caller_error(tmp_path):
    path = tmp_path / "v.mp4"
    with pytest.raises(KeyError), VideoWriter(path, fps=12, background=True) as vw:
        for f in _frames(5):
            vw.write(f)
        raise KeyError("crash mid-video")
    assert not path.exists() and not list(tmp_path.iterdir())
    assert vw._thread is None  # joined


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"preset": "warp"}, "preset must be one of"), ({"quality_crf": 60}, "quality_crf")],
)
def test_bad_encoder_options(tmp_path, kwargs, match):
    with pytest.raises(MyofaceValueError, match=match):
        VideoWriter(tmp_path / "v.mp4", **kwargs)
