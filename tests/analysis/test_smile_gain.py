"""synth.smile_gain's measure (myoface.bench.smile.smile_gain) on displacement sequences whose
answer is known."""

from __future__ import annotations

import numpy as np
import pytest

from myoface.bench.smile import smile_gain


def _smile(n=30, peak=0.15):
    """The two mouth corners (T, 2, 2) rising to ``peak`` IOD up and out and back, with a held
    apex (frames 12-17)."""
    env = np.interp(np.arange(n), [0, 12, 17, 29], [0, 1, 1, 0])
    corners = np.array([[0.6, 0.8], [-0.6, 0.8]])  # out and up, each side
    return peak * env[:, None, None] * corners[None]


def test_the_ratio_is_the_resynthesis_gain_at_the_apex():
    d_in = _smile()
    ratio, detail = smile_gain(d_in, 0.55 * d_in)
    assert ratio == pytest.approx(0.55)
    assert detail["apex_frames"] == list(range(11, 19))  # the held frames and 11/12 either side
    assert detail["direction_cosine"] == pytest.approx(1.0)
    assert detail["input_iod"] == pytest.approx(0.15)


def test_only_the_apex_counts_and_nan_frames_are_left_out():
    """A resynthesis that lags on the rise but reaches the apex scores 1; frames without a face
    (NaN) are not compared; a motion in another direction shows in the cosine."""
    d_in = _smile()
    d_out = d_in.copy()
    d_out[:12] *= 0.3
    d_out[5] = np.nan
    ratio, _ = smile_gain(d_in, d_out)
    assert ratio == pytest.approx(1.0)
    down = d_in * np.array([1.0, -1.0])  # corners moving down instead of up
    _, detail = smile_gain(d_in, down)
    assert detail["direction_cosine"] == pytest.approx(0.36 - 0.64)


def test_a_still_input_is_refused():
    z = np.zeros((5, 2, 2))
    with pytest.raises(ValueError, match="do not move"):
        smile_gain(z, z)


def test_the_lateral_and_vertical_parts_say_where_the_gain_is_lost():
    """A resynthesis that widens the mouth as much as the input but raises its corners half as
    much: lateral 1, vertical 0.5 (each corner's way out taken from the input's side)."""
    d_in = _smile()
    d_out = d_in * np.array([1.0, 0.5])
    ratio, detail = smile_gain(d_in, d_out)
    assert detail["lateral_ratio"] == pytest.approx(1.0)
    assert detail["vertical_ratio"] == pytest.approx(0.5)
    assert 0.5 < ratio < 1.0
    _, detail = smile_gain(d_in, d_in * np.array([-1.0, 1.0]))  # corners drawn in, not out
    assert detail["lateral_ratio"] == pytest.approx(-1.0)


def test_the_smile_reach_says_when_the_muscles_are_at_their_bound():
    """:func:`smile_reach` on known answers: the model's own smile (the zygomatici at 0.6) is
    reached at a ratio of 1 with the zygomatici at 0.6 (within the 5 % that the reach's ridge
    takes off, as ``test_the_models_reach_finds_what_the_model_can_make`` allows); the same
    smile made 1.6 times larger than the model's strongest is reached short, its zygomatici at
    their bound, 1."""
    from myoface.analysis.fidelity import model_displacements
    from myoface.bench.smile import smile_reach
    from myoface.model import build_face_model

    fm = build_face_model()
    zyg = [fm.ids.index("zygomaticus_major_l"), fm.ids.index("zygomaticus_major_r")]
    table = np.zeros((4, fm.n_muscles))
    table[1:, zyg] = np.array([0.3, 0.6, 0.6])[:, None]
    d_in = model_displacements(fm, table)[0]["mouth_corners"]
    apex = [2, 3]
    reach = smile_reach(fm, d_in, apex)
    assert reach["ratio"] == pytest.approx(1.0, abs=0.05), reach
    assert reach["vertical_ratio"] == pytest.approx(1.0, abs=0.06), reach
    for m in ("zygomaticus_major_l", "zygomaticus_major_r"):
        assert reach["muscles_at_apex"][m] == pytest.approx(0.6, abs=0.08), reach
    big = smile_reach(fm, d_in * 1.6 / 0.6 * np.where(np.arange(4) > 1, 1.0, 0.0)[:, None, None],
                      apex)  # fmt: skip
    assert big["ratio"] < 0.9, big
    assert (
        min(big["muscles_at_apex"][m] for m in ("zygomaticus_major_l", "zygomaticus_major_r"))
        > 0.97
    )
