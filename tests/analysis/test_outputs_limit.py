"""The muscles at the model's limit: their share of the measured frames, and the note; the note
of a lone frame, its own neutral."""

import numpy as np
import pytest

from myoface.analysis.outputs import (
    AT_LIMIT,
    at_limit,
    limit_note,
    own_neutral_note,
    plot_contractions,
)


def test_at_limit_counts_the_measured_frames_at_the_bound():
    ids = ("a_l", "a_r", "b", "jaw")
    table = np.array(
        [
            [1.0, 0.2, 0.0, 0.1],
            [1.0, AT_LIMIT, 0.0, 0.1],
            [0.5, 0.3, 0.0, 1.0],
            [1.0, 1.0, 1.0, 1.0],  # (not measured: not counted)
        ]
    )
    quality = ["ok", "ok", "ok", "lost"]
    got = at_limit(ids, table, quality)
    # largest share first; the muscles that never reach it left out
    assert list(got) == ["a_l", "a_r", "jaw"]
    assert got == pytest.approx({"a_l": 2 / 3, "a_r": 1 / 3, "jaw": 1 / 3}, abs=1e-3)
    assert at_limit(ids, table, ["lost"] * 4) == {}
    assert at_limit(ids, np.full((3, 4), 0.98), ["ok"] * 3) == {}


def test_limit_note_names_the_muscles_held_there():
    assert limit_note({}) is None
    assert limit_note({"a": 0.05}) is None  # (below the share the note asks for)
    note = limit_note({"zygomaticus_major_l": 0.64, "risorius_l": 0.5, "mentalis_l": 0.02})
    assert note.startswith("note: 2 muscles at the model's limit")
    assert "zygomaticus_major_l 64%" in note and "risorius_l 50%" in note
    assert "mentalis" not in note
    # (both reasons a muscle sits there, as measured on the sample: docs/expressions.md)
    assert "more than the muscle can move it" in note and "another makes" in note
    many = {f"m{k}": 0.5 for k in range(9)}
    assert "and 3 more" in limit_note(many)


def test_plot_marks_the_frames_at_the_limit(tmp_path):
    import imageio.v3 as iio

    ids = ("a_l", "a_r", "jaw")
    times = np.arange(20) / 10
    table = np.zeros((20, 3))
    table[5:15, 0] = 1.0  # (a_l at the limit for a second)
    plot_contractions(tmp_path / "c.png", ids, times, table, ["ok"] * 20)
    img = iio.imread(tmp_path / "c.png")[..., :3].astype(int)
    # the ticks are red (matplotlib's tab:red, 214 39 40): some in the plot, none without
    red = (img[..., 0] > 180) & (img[..., 1] < 90) & (img[..., 2] < 90)
    assert red.sum() > 20
    plot_contractions(tmp_path / "d.png", ids, times, table * 0.5, ["ok"] * 20)
    img = iio.imread(tmp_path / "d.png")[..., :3].astype(int)
    red = (img[..., 0] > 180) & (img[..., 1] < 90) & (img[..., 2] < 90)
    assert red.sum() == 0


def test_a_lone_frame_is_said_to_be_its_own_neutral():
    """One frame analysed (a photo) is its own calibration, so it reads no expression: the
    note says so; with more frames, or the one frame not measured, there is none."""
    note = own_neutral_note(1, 1)
    assert note.startswith("note: one frame was analysed, and it is its own neutral")
    assert own_neutral_note(72, 72) is None
    assert own_neutral_note(0, 1) is None
