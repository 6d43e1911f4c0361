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
