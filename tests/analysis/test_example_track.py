"""The snake-tracking example (examples/track_synthetic_feature.py) does what it promises: nine
closed snakes follow the nine drifting ellipses, and the video shows each frame of the task with
the contours drawn in yellow where the snakes are (red only for escaped nodes, of which there are
none here)."""

import importlib.util

import numpy as np

from tests.conftest import REPO

N_FRAMES, SIZE = 6, 128


def _example():
    spec = importlib.util.spec_from_file_location(
        "track_example", REPO / "examples" / "track_synthetic_feature.py"
    )
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_example_tracks_and_writes_video(tmp_path, capsys):
    import imageio.v3 as iio

    from myoface.bench.snakes import ellipse_distance, ellipse_task

    mod = _example()
    drawn = []  # (contours, escaped masks) per frame, as the example drew them
    draw = mod.draw_contours

    def spy(frame, contours, escaped_mask=None):
        drawn.append(([c.copy() for c in contours], [m.copy() for m in escaped_mask]))
        return draw(frame, contours, escaped_mask)

    mod.draw_contours = spy
    out = tmp_path / "t.mp4"
    assert mod.main(["-o", str(out)], n_frames=N_FRAMES, size=SIZE) == 0
    assert "escaped nodes [0, 0, 0, 0, 0, 0, 0, 0, 0]" in capsys.readouterr().out
    frames = iio.imread(out, plugin="pyav").astype(int)
    assert frames.shape == (N_FRAMES, SIZE, SIZE, 3)
    assert len(drawn) == N_FRAMES
    task, centres, _ = ellipse_task(N_FRAMES, SIZE)  # the frames and truth the example used
    for k, ((contours, escaped), rgb) in enumerate(zip(drawn, frames, strict=True)):
        # The snakes follow the features: every node within 1 px of its ellipse's true edge
        # in every frame (the tracker's accuracy on this task, as test_snakes and
        # snakes.max_err_px hold it to), and none escaped.
        assert len(contours) == 9
        err = max(
            ellipse_distance(c, ctr).max() for c, ctr in zip(contours, centres[k], strict=True)
        )
        assert err < 1.0, (k, err)
        assert not any(m.any() for m in escaped), k
        node = np.zeros((SIZE, SIZE), bool)
        for c in contours:
            node[np.round(c[:, 1]).astype(int), np.round(c[:, 0]).astype(int)] = True
        # The video shows the task's frame (grey) where no node is drawn. The task adds noise
        # of sigma 4 grey levels, which H.264 may smooth away: at most E|N(0, 4)| = 3.2 on
        # average, plus one level of rounding.
        grey_err = np.abs(rgb.mean(axis=2) - task[k])[~node].mean()
        assert grey_err < 4.2, (k, grey_err)
        # ... and the contours in yellow where the snakes are, all the way round each: yellow
        # (255, 215, 0) has R - B = 255; the video keeps colour at half resolution (4:2:0), so
        # a 1-px line of nodes keeps 1/4 to 1/2 of it (64-128) before compression. Each
        # quarter of every contour must keep at least half the least of that (32) on average;
        # the grey frame has R - B about 0 (a few levels of codec noise).
        chroma = rgb[..., 0] - rgb[..., 2]
        for j, c in enumerate(contours):
            for q, arc in enumerate(np.array_split(c, 4)):
                ix = np.round(arc).astype(int)
                assert chroma[ix[:, 1], ix[:, 0]].mean() > 32, (k, j, q)
        assert np.abs(chroma[~node]).mean() < 8, k
