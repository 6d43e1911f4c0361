"""The snake-tracking example runs and writes its video."""

import importlib.util

from tests.conftest import REPO


def test_example_tracks_and_writes_video(tmp_path):
    import imageio.v3 as iio

    spec = importlib.util.spec_from_file_location(
        "track_example", REPO / "examples" / "track_synthetic_feature.py"
    )
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    out = tmp_path / "t.mp4"
    assert mod.main(["-o", str(out)], n_frames=6, size=128) == 0
    frames = iio.imread(out, plugin="pyav")
    assert frames.shape == (6, 128, 128, 3)
    assert (frames[..., 2] < 80).any()  # yellow contour pixels are drawn
