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


def test_region_gains_are_the_share_of_the_motion_read():
    """A tracker that reads half of one region's motion (plus a fixed offset of its own, which
    the displacements cancel) and all of another's scores 0.5 and 1; a region that does not
    move has no gain; a probe without a face is left out."""
    from myoface.bench.smile import region_gains

    rng = np.random.default_rng(3)
    true = np.repeat(rng.normal(100, 20, (1, 6, 2)), 4, axis=0)  # neutral + 3 probes
    true[1:, :4] += rng.normal(0, 3, (3, 4, 2))  # points 0-3 move; 4-5 stay
    read = true + 7.0  # the tracker's own offset
    read[1:, :2] = read[0, :2] + 0.5 * (true[1:, :2] - true[0, :2])
    read[2] = np.nan
    gains = region_gains(true, read, {"half": (0, 1), "all": (2, 3), "still": (4, 5)})
    assert gains["half"] == pytest.approx(0.5, abs=1e-3)
    assert gains["all"] == pytest.approx(1.0, abs=1e-3)
    assert gains["still"] is None
    with pytest.raises(ValueError, match="alike"):
        region_gains(true, read[:, :5], {"half": (0, 1)})
